"""The cases of a study: sweep axes, couplings, and case files keyed by everything that determines them.

A study sweeps *axes*, each a scene parameter with a list of values (``h``, ``k``,
``order`` and ``scheme`` always, with the scene's value when not swept; any other
scene parameter on request). Several *grids* (each a product of its axes) may be
united, e.g. different step sizes for the explicit and the implicit scheme.
*Couplings* derive one parameter from a case's other values (``k = 0.2 h``); a
coupled parameter is not an axis of its own.

A finished case is archived as one netCDF file. The file stores the canonical
JSON of everything that determines its Dataset (every scene value after the case
values were applied, the recorded and snapshot times, the workbench and NGSolve
versions, the digest of workbench's code) and its hash: a file whose inputs differ from the case's, or that
cannot be read (empty, truncated by a kill), is recomputed, and the reason is
reported (:func:`read_case`).

Examples
--------
>>> c = Case({"h": 0.05, "k": 0.01, "order": 2, "scheme": "implicit"})
>>> c.key, c.h
('h0.05_k0.01_p2_implicit', 0.05)
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..input.numerics import AXES as BASE_AXES
from ..input.numerics import REFINEMENT, is_adaptive

_PREFIX = {"h": "h", "k": "k", "order": "p", "scheme": ""}


class Case:
    """One case: a mapping from parameter names (axes and coupled ones) to values; hashable, ordered.

    Attribute access reads a value (``case.h``); :attr:`key` is the case's file stem.
    """

    __slots__ = ("_items",)

    def __init__(self, values: dict):
        object.__setattr__(self, "_items", tuple(values.items()))

    def __getattr__(self, name):
        for k, v in object.__getattribute__(self, "_items"):
            if k == name:
                return v
        raise AttributeError(name)

    def __setattr__(self, name, value):
        raise AttributeError("Case is immutable")

    def __getitem__(self, name):
        return self.values()[name]

    def get(self, name, default=None):
        return self.values().get(name, default)

    def values(self) -> dict:
        """The case's parameter values as a dict."""
        return dict(self._items)

    def __eq__(self, other):
        return isinstance(other, Case) and self._items == other._items

    def __hash__(self):
        return hash(self._items)

    def __repr__(self):
        return f"Case({self.values()})"

    @property
    def key(self) -> str:
        """File stem: the values as text (floats by their shortest exact repr), safe on any file system."""
        parts = []
        for name, value in self._items:
            text = repr(value) if isinstance(value, float) else str(value)
            parts.append(f"{_PREFIX[name]}{text}" if name in _PREFIX else f"{name}={text}")
        stem = re.sub(r"[^A-Za-z0-9._=+-]", "-", "_".join(parts))
        if len(stem) > 120:  # keep names short; the hash keeps them distinct
            stem = stem[:100] + "-" + hashlib.sha256(stem.encode()).hexdigest()[:16]
        return stem


def _values(name, values) -> list:
    """A sweep axis as a list: a sequence of values or a single value; text is refused (it would be read
    character by character), but for a choice (``scheme="explicit"``), where it is one value."""
    from ..input.parameters import PARAMETERS

    if isinstance(values, str) and name in PARAMETERS and PARAMETERS[name].kind == "choice":
        values = [values]
    if isinstance(values, (str, bytes)):
        raise ParameterError(f"{name} = {values!r}: give the values to sweep as a list, e.g. {name}=[0.1, 0.05]")
    if not isinstance(values, Iterable):
        values = [values]
    values = list(values)
    if not values:
        raise ParameterError(f"{name}: give at least one value to sweep")
    return values


def expand(scene, grids, couple) -> tuple[list, dict]:
    """The cases of the union of ``grids`` (each a dict axis -> values), with ``couple`` applied.

    An axis that a grid does not name takes the scene's value there. Returns
    (cases, axes): ``axes`` maps every axis to its values in dimension order
    (refinement axes coarse to fine, others as first given). Every case is checked
    against the scene here, before any work.
    """
    couple = dict(couple or {})
    names = list(BASE_AXES) + [n for g in grids for n in g if n not in BASE_AXES]
    names = [n for i, n in enumerate(names) if n not in names[:i] and n not in couple]
    for grid in grids:
        for name in grid:
            if name in couple:
                raise ParameterError(f"{name} is both swept and coupled; give it one way")
    per_grid = [{n: [_coerce(scene, n, v) for v in _values(n, grid.get(n, [scene[n]]))] for n in names}
                for grid in grids]
    for g in per_grid:  # (a value twice made a second case of NaN errors and an index that selects two)
        for n, vals in g.items():
            twice = [v for i, v in enumerate(vals) if v in vals[:i]]
            if twice:
                raise ParameterError(f"{n}: {twice[0]!r} is given twice; give each value once")
    axes: dict = {}
    for n in names:
        vals = []
        for g in per_grid:
            vals += [v for v in g[n] if v not in vals]
        axes[n] = sorted(vals, reverse=True) if n in REFINEMENT else vals
    cases = []
    for g in per_grid:
        for combo in itertools.product(*(g[n] for n in names)):
            values = dict(zip(names, combo))
            for name, rule in couple.items():
                try:
                    coupled = rule(dict(values))
                except Exception as err:  # noqa: BLE001 (the user's function: named, its traceback kept as the cause)
                    raise ParameterError(f"couple: the function for {name} raised {type(err).__name__}: "
                                         f"{str(err)[:200]} (it is called with a case's values of "
                                         f"{', '.join(sorted(values))})") from err
                values[name] = _coerce(scene, name, coupled)
            case = Case(values)
            if case not in cases:
                cases.append(case)
    for case in cases:
        scene.with_(**case.values())  # a bad case fails here, naming its parameter
    return cases, axes


def _coerce(scene, name, value):
    """A sweep value as the scene would hold it (numbers from text, choices checked)."""
    from ..input.parameters import PARAMETERS

    param = PARAMETERS.get(name)
    if param is None:
        scene.with_(**{name: value})  # raises the scene's unknown-parameter error
        return value
    value = param.check(value)
    return float(value) if isinstance(value, float) else value


def inputs(case_scene, record_times, snapshots) -> dict:
    """Everything that determines a case's Dataset (what its archive is keyed by)."""
    from ..output.results import versions

    # (checkpoint_every is where a run writes, not what it computes)
    scene = {k: v for k, v in case_scene.plain().items() if k != "checkpoint_every"}
    v = versions()
    return {"scene": scene, "base_scene": case_scene.base, "model": case_scene.model,
            "record_times": [float(t) for t in record_times], "snapshots": [float(t) for t in snapshots],
            "workbench": v["version_workbench"], "workbench_code": v["version_workbench_code"],
            "ngsolve": v["version_ngsolve"]}


def canonical(obj) -> str:
    """Canonical JSON (sorted keys, floats by repr), so equal inputs give equal text."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def fingerprint(obj) -> str:
    return hashlib.sha256(canonical(obj).encode()).hexdigest()


def read_case(path: Path, expected: dict):
    """(Dataset, None) if ``path`` holds the case made from ``expected``; else (None, reason) or (None, None)
    if there is no file."""
    from ..output import results

    path = Path(path)
    if not path.exists():
        return None, None
    try:
        ds = results.load(path)
    except Exception as err:  # empty, truncated, not netCDF: any failure to read means recompute
        # (the path is said beside the reason: here its name alone, so that the cut keeps the reader's message)
        detail = str(err).splitlines()[0].replace(str(path), path.name) if str(err) else "no detail"
        return None, f"unreadable ({type(err).__name__}: {detail if len(detail) <= 100 else detail[:97] + '...'})"
    stored = ds.attrs.get("case_inputs")
    if stored is None:
        return None, "made by an older workbench (no record of its inputs)"
    if ds.attrs.get("case_fingerprint") == fingerprint(expected):
        return ds, None
    return None, "made with other inputs: " + differences(json.loads(stored), expected)


#: What may differ between a shorter run and a case that continues it (extension of T).
_EXTENDED = ("T", "snapshots")


def extension(path: Path, expected: dict):
    """(plan, None) if the case archived at ``path`` can be continued to the case of ``expected`` (a longer T,
    all else equal); else (None, reason).

    The continued case is the restart of the archived run (:mod:`workbench.running.restart`) to the new T, recording the
    old records and the new ones after the old T. It is possible when the archive holds its final state, its run
    took fixed steps (an error-controlled run landed on its own T, which a run straight to the new T does not),
    its record times are those of the new case up to the old T and its snapshots include the new case's
    comparison times there. The plan: ``restart`` (the path), ``T`` (the archive's), ``snapshots`` and
    ``record_times`` for the continued run (the archive's up to its T, the new case's after), ``keep`` (the new
    case's snapshot times).
    """
    from ..output import results
    from ..running import restart

    try:
        ds = results.load(path)
        old = json.loads(ds.attrs["case_inputs"])
    except Exception:  # noqa: BLE001 (read_case has said why the file is not this case)
        return None, None
    a, b = old.get("scene", {}), expected["scene"]
    T0, T = float(a.get("T", np.inf)), float(b["T"])
    others = [k for k in set(old) | set(expected) if k not in ("scene", "record_times", "snapshots")
              and canonical(old.get(k)) != canonical(expected.get(k))]
    others += [k for k in set(a) | set(b) if k not in _EXTENDED and canonical(a.get(k)) != canonical(b.get(k))]
    if others or not T0 < T:
        return None, None
    tol = 1e-9 * T  # (relative: a run of T = 1e-9 s is no coarser in time than one of 1 s)
    if is_adaptive(b.get("rtol", 0.0)):
        return None, "an error-controlled case is not continued to a longer T (its steps landed on its own T)"
    if b.get("kernel_approximation") == "exponentials":
        return None, "its kernel's exponential sum was fitted on [0, T], another fit for the longer T"
    if not restart.has_state(ds) or ds.attrs.get("status") != "complete":
        return None, "its archive holds no state to continue from"
    new_records = np.asarray(expected["record_times"], dtype=float)
    old_records = np.asarray(old["record_times"], dtype=float)
    before = new_records[new_records <= T0 + tol]
    if before.size != old_records.size or np.abs(before - old_records).max(initial=0.0) > tol:
        return None, f"its record times up to its T = {T0:g} are not the longer case's"
    stored = ds.snapshot_time.values if "snapshot_time" in ds.coords else np.array([])
    wanted = [t for t in expected["snapshots"] if t <= T0 + tol]
    missing = [t for t in wanted if stored.size == 0 or np.abs(stored - t).min() > tol]
    if missing:
        return None, (f"it has no field at the comparison time(s) {', '.join(f'{t:g}' for t in missing[:3])} s (the "
                      f"comparison times move with T: a multiple of its T = {T0:g} keeps them)")
    # the run's own snapshot times up to T0 (a restart must keep them), which may be more than its fields kept
    own = json.loads(ds.attrs["parameters_json"]).get("snapshots", [])
    return {"restart": str(path), "T": T0,
            "snapshots": [float(t) for t in own if t <= T0 + tol] + [float(t) for t in expected["snapshots"]
                                                                      if t > T0 + tol],
            "record_times": [float(t) for t in old_records] + [float(t) for t in new_records if t > T0 + tol],
            "keep": [float(t) for t in expected["snapshots"]]}, None


def differences(old: dict, new: dict, limit: int = 6) -> str:
    """'gamma_nu 0.1 -> 1.5, L 1 -> 0.2' for the entries that differ (scene values first)."""
    out = []
    flat_old = dict(old.get("scene", {}), **{k: v for k, v in old.items() if k != "scene"})
    flat_new = dict(new.get("scene", {}), **{k: v for k, v in new.items() if k != "scene"})
    for key in sorted(set(flat_old) | set(flat_new), key=lambda k: (k not in new.get("scene", {}), k)):
        a, b = flat_old.get(key, "(absent)"), flat_new.get(key, "(absent)")
        if canonical(a) != canonical(b):
            out.append(f"{key} {_short(a)} -> {_short(b)}")
    more = f" and {len(out) - limit} more" if len(out) > limit else ""
    return ", ".join(out[:limit]) + more if out else "(none visible)"


def _short(value) -> str:
    text = value if isinstance(value, str) else canonical(value)
    return text if len(text) <= 40 else text[:37] + "..."


def positive_int(name: str, value, lower: int = 1) -> int:
    """An integer option >= ``lower``, or a ParameterError naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or int(value) != value or value < lower:
        raise ParameterError(f"{name} = {value!r}: give an integer >= {lower}")
    return int(value)
