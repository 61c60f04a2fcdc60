"""Refinement studies: sweeps over h, k, element order, scheme and any scene parameter; errors, orders, cost.

A :class:`Study` runs one scene on many cases (each in a worker subprocess, in
this process, or on a dask.distributed cluster), archives every finished case at
once (keyed by everything that determines it, :mod:`.cases`), compares each case
with a reference (:mod:`.reference`), fits observed orders and measures the
speed/accuracy trade (:mod:`.evaluate`).

Examples
--------
>>> st = Study("tp1", k=[0.04, 0.02, 0.01], reference="ode", workers=0)
>>> ds = st.run(progress=False)
>>> round(float(ds.observed_order.sel(norm="error", along="k").squeeze()), 1)
1.0
"""
from __future__ import annotations

import os
import shutil
import tempfile
import time
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import xarray as xr

from ..errors import ParameterError
from ..input import numerics, scenes
from ..output import results
from . import evaluate, execute, reference, times
from .cases import BASE_AXES, Case, canonical, expand, extension, fingerprint, inputs, positive_int, read_case
from .evaluate import fit_order

__all__ = ["Study", "Case", "cheapest", "fit_order"]


class Study:
    """A sweep over cases of one scene.

    Parameters
    ----------
    scene : str, path or Scene
    h, k : float or sequence of float, optional
        Element sizes and time steps (default: the scene's). All combinations are
        run, unless ``k_over_h`` couples them (k_i = k_over_h * h_i).
    order, scheme : int/str or sequence, optional
        Element orders and schemes to sweep (default: the scene's).
    sweep : dict, optional
        More axes: any scene parameter and its values, e.g. ``{"c_nu": [1, 100, 1e4]}``.
    grids : list of dict, optional
        A union of grids instead of one product: each dict overrides the axes above,
        e.g. ``[{"scheme": ["implicit"], "k": [0.02, 0.01]}, {"scheme": ["explicit"], "k": [5e-4]}]``.
    couple : dict, optional
        Parameters computed from each case's values, e.g. ``{"k": lambda c: 0.2 * c["h"]}``
        (``k_over_h`` is this coupling), or ``{"gamma_nu": lambda c: 0.1 * c["c_nu"]}``; each must be a
        function of one axis, the same for all.
    reference : str, dict, object or None
        ``"auto"`` (default: the scene's exact or ODE reference where it has one, else
        ``"extrapolated"`` where a refinement series has three levels or more, else ``"finest"``,
        with a warning), ``"extrapolated"`` (each case against the next finer one, the errors
        extrapolated: :mod:`.reference`), ``"finest"`` (the finest case, then not reported as a
        case: biased orders), ``"ode"``/``"exact"`` (rod scenes:
        :func:`workbench.references.rod_reference`), a dict of discretisation values for a
        separate finer run, a solution object, or None (no errors). The Dataset's ``reference``
        attribute says which was used.
    measures : callable, optional
        ``measures(ds) -> dict`` of scalars computed from each case's Dataset; with a run
        reference, ``rel_error_<name>`` compares each with the reference's value.
    n_compare : int
        Number of common times at which whole fields are compared (default 10, T included): spread over the
        points every case's grid shares; where they share fewer than half of them, each case is compared at its
        own grid's points nearest them against a solution reference, and the sweep is refused against a run.
    workers : int
        Local worker subprocesses running cases in parallel (default 2); 0 runs the cases
        in this process, one after another.
    client : dask.distributed.Client or str, optional
        Run the cases on this cluster (or scheduler address) instead.
    **overrides
        Scene parameters for every case.
    """

    def __init__(self, scene, *, h=None, k=None, k_over_h=None, order=None, scheme=None, sweep=None, grids=None,
                 couple=None, reference="auto", measures=None, n_compare=10, workers=2, client=None, **overrides):
        _check_arguments(sweep=sweep, grids=grids, couple=couple, measures=measures, client=client)
        base = {name: value for name, value in (("h", h), ("k", k), ("order", order), ("scheme", scheme))
                if value is not None}
        for name in sweep or {}:
            if name in base:
                raise ParameterError(f"{name} is given twice (as {name}= and in sweep); give it once")
        base |= dict(sweep or {})
        couple = dict(couple or {})
        if k_over_h is not None:
            if k is not None or "k" in couple:
                raise ParameterError("give either k or k_over_h, not both")
            if isinstance(k_over_h, bool) or not isinstance(k_over_h, (int, float)) or not k_over_h > 0 \
                    or not np.isfinite(k_over_h):
                raise ParameterError(f"k_over_h = {k_over_h!r} must be a number > 0")
            c = float(k_over_h)  # (to 12 digits: 0.2 x 0.025 is 0.005000000000000001, in every case's file name)
            couple["k"] = lambda values: float(f"{c * values['h']:.12g}")
        self.coupled = tuple(couple)
        union = [dict(base, **g) for g in grids] if grids else [base]
        self.scene = _base_scene(scene, overrides, union[0], couple)
        if self.scene["checkpoint_every"] or any("checkpoint_every" in g for g in union):
            raise ParameterError("checkpoint_every applies to a single run with an output file (workbench run -o); a "
                                 "study archives each case as it finishes")
        self.cases, self.axes = expand(self.scene, union, couple)
        if 0.0 in self.axes.get("h_contact", []) and len(self.axes["h_contact"]) > 1:  # (0 sorted as the finest)
            raise ParameterError(f"sweep h_contact = {self.axes['h_contact']}: 0 stands for h / 10 and would be taken "
                                 "for the finest; give that size as a number")
        self.n_compare = positive_int("n_compare", n_compare)
        self.workers = positive_int("workers", workers, lower=0)
        self.client = client
        self.measures = measures
        self.layout = evaluate.Layout(self.cases, self.axes, self.coupled)
        self.reference_spec = reference
        self.reference = reference_obj = _reference(reference, self)
        self.listed = [c for c in self.cases if reference_obj is None or reference_obj.reported(c)]
        if reference_obj is not None and not self.listed:
            raise ParameterError("reference = 'finest' with a single case leaves nothing to compare: sweep at least two "
                                 "values (e.g. k=[0.02, 0.01]) or give a reference run or solution")
        self._scenes = {}
        self.dataset = None
        self.overhead = {}
        #: Whether each case is compared at its own grid's points nearest the comparison times: grids that share too
        #: few points, against a solution reference, which is known at any time (:mod:`.times`).
        self.own_times = False
        self.own_times = self.reference is not None and times.check(self)

    # -- backwards-compatible views -----------------------------------------------------------------
    @property
    def hs(self):
        return self.axes["h"] if "h" in self.axes else sorted({c.h for c in self.cases}, reverse=True)

    @property
    def ks(self):
        return self.axes["k"] if "k" in self.axes else sorted({c.k for c in self.cases}, reverse=True)

    @property
    def ref_case(self):
        """The reference case (the first, if cases of several physical settings each have one)."""
        if self.reference is None or self.reference.kind != "run":
            return None
        return self.reference.cases()[0]

    def scene_of(self, case: Case, snapshots=None):
        """The checked scene of one case (with the study's comparison times as snapshots)."""
        key = (case, None if snapshots is None else tuple(snapshots))
        if key not in self._scenes:
            extra = {} if snapshots is None else {"snapshots": tuple(snapshots)}
            self._scenes[key] = self.scene.with_(**case.values(), **extra)
        return self._scenes[key]

    def _adaptive(self, case) -> bool:
        """Whether the case runs error-controlled steps (rtol > 0): its k is only the first step."""
        return numerics.from_scene(self.scene_of(case)).adaptive

    # -- running ---------------------------------------------------------------------------------------
    def run(self, archive=None, *, progress=None, extend=True) -> xr.Dataset:
        """Run the cases that have no valid archive (each archived on completion in ``archive``), then evaluate.

        With ``archive`` (a folder), a sweep that was interrupted and is run again
        recomputes only the cases whose archive is missing, unreadable or made from
        other inputs (each such case is reported); the result is identical.

        A sweep run again with a longer T continues each case archived there from its
        final state (``extend``, default True; :func:`.cases.extension` says when a
        case can be): the cases' records up to the old T are reused, and the result
        equals that of a sweep run straight to the new T to round-off (the steps up
        to the old T were placed on that T's grid). Keep the old comparison times by
        taking a multiple of the old T (they are n_compare equal parts of [0, T]).
        ``extend=False`` recomputes such cases from t = 0. Without ``archive`` the cases are kept in a temporary
        folder while the study runs, removed after.
        """
        temporary = archive is None  # (a cache no one can name: removed with the study's result made, as it was
        archive = _archive_folder(archive)  # left in /tmp on every call, 1.4 GB of them found by an outside pass)
        try:
            return self._run_in(archive, progress, extend)
        finally:
            if temporary:
                held = _HELD.pop(str(archive), None)
                if held is not None:
                    held.close()
                shutil.rmtree(archive, ignore_errors=True)

    def _run_in(self, archive: Path, progress, extend: bool) -> xr.Dataset:
        from ..schemes.stepping import progress_bar

        record, compare = times.common(self)
        todo = list(dict.fromkeys(self.listed + (self.reference.cases() if self.reference else [])))
        runs, missing, expected, plans = self._archived(todo, archive, record, compare, extend)
        _fits(self.scene_of(c) for c in missing)
        tasks = [(c, (self.scene, c.values(), times.record_times(self, c, record, compare),
                      times.compared(self, c, compare),
                      {"case_inputs": canonical(expected[c]), "case_fingerprint": fingerprint(expected[c])},
                      plans.get(c)))
                 for c in missing]
        if self.client is not None:
            stream = execute.on_cluster(tasks, self.client)
        elif self.workers == 0:
            stream = execute.in_process(tasks)
        else:
            stream = execute.subprocesses(tasks, self.workers)
        t0 = time.perf_counter()
        bar = progress_bar(progress, total=len(todo), initial=len(todo) - len(missing), unit="case",
                           desc=f"study {self.scene.name}")  # (progress=False: tqdm not imported, as for a run)
        try:
            kept = True
            for case, ds in stream:
                kept = _keep(ds, archive / f"{case.key}.nc", warn=kept)
                runs[case] = ds
                bar.update()
        finally:
            bar.close()
        executed = time.perf_counter() - t0
        self.dataset = evaluate.study_dataset(self, runs, compare, _history(self))
        # (the cases run now: a resumed study counted the reused ones' time too, an outside pass)
        case_cost = float(sum(np.nansum([float(runs[c].attrs.get(n, np.nan)) for n in ("wall_time", "setup_time")])
                              for c in missing if c in runs))
        self.overhead = dict(execute=executed, cases=case_cost, new_cases=len(missing) - len(plans),
                             extended_cases=len(plans), evaluate=time.perf_counter() - t0 - executed)
        return self.dataset

    def _archived(self, todo, archive: Path, record, compare, extend: bool):
        """(the runs archived for these inputs, the cases to run (biggest first, so the pool ends evenly), every
        case's inputs, the plans of the cases that continue an archived run to a longer T)."""
        runs, missing, expected, plans = {}, [], {}, {}
        for case in todo:
            own = times.compared(self, case, compare)
            expected[case] = inputs(self.scene_of(case, own), times.record_times(self, case, record, compare), own)
            path = archive / f"{case.key}.nc"
            ds, reason = read_case(path, expected[case])
            if ds is not None:
                runs[case] = ds
                continue
            if reason and extend:
                plan, why = extension(path, expected[case])
                if plan is not None:
                    plans[case] = plan
                    missing.append(case)
                    continue
                reason = f"{reason} ({why})" if why else reason
            if reason:
                warnings.warn(f"study case {path}: {reason}; recomputing it", RuntimeWarning, stacklevel=3)
            missing.append(case)
        missing.sort(key=self._cost_estimate, reverse=True)
        return runs, missing, expected, plans

    def _cost_estimate(self, case):
        sc = self.scene_of(case)
        return float(sc.body.n_cells()) * case.order ** sc.dim / case.k

    # -- questions ---------------------------------------------------------------------------------------
    def assert_order(self, expected: float, tol: float = 0.1, *, norm: str = "error", along: str | None = None,
                     at_least: bool = False, max_error: float | None = None, **selection) -> None:
        """Check the fitted order(s): |order - expected| <= tol (or order >= expected - tol with ``at_least``).

        ``along`` defaults to "h+k" for coupled refinement sweeps (k = C h), else the swept refinement axis.
        ``max_error`` caps the smallest error, so a wrong constant cannot hide behind a good slope.
        ``selection`` picks some of the cases (e.g. ``order=2``); by default every fitted order is checked.
        """
        ds = self.dataset
        if ds is None:
            raise ParameterError("Study.assert_order: run the study first (Study.run)")
        _numbers("Study.assert_order", expected=expected, tol=tol, max_error=max_error)
        if norm not in ds.norm.values:
            raise ParameterError(f"Study.assert_order: norm = {norm!r}; the study has {', '.join(map(str, ds.norm.values))}")
        along = along or ("h+k" if self.layout.refining else ("h" if len(self.hs) > 1 else "k"))
        if selection:
            ds = ds.sel(selection)
        rates = ds.observed_order.sel(norm=norm, along=along).values.ravel()
        if not np.all(np.isfinite(rates)):
            raise AssertionError(f"no fitted order for {norm} along {along}: {rates}")
        bad = rates < expected - tol if at_least else np.abs(rates - expected) > tol
        if np.any(bad):
            raise AssertionError(f"observed order of {norm} along {along}: {np.round(rates, 3).tolist()}, "
                                 f"expected {'>= ' if at_least else ''}{expected} within {tol}")
        if max_error is not None:
            smallest = float(np.nanmin(ds[norm].values))
            if smallest > max_error:
                raise AssertionError(f"smallest {norm} = {smallest:.3g} exceeds the cap {max_error:.3g}")

    def cheapest(self, tolerance: float, *, error: str = "error", cost: str = "wall_time"):
        """The cheapest case whose ``error`` is <= ``tolerance`` (None if none reaches it)."""
        if self.dataset is None:
            raise ParameterError("Study.cheapest: run the study first (Study.run)")
        return cheapest(self.dataset, tolerance, error=error, cost=cost)


def _fits(scenes) -> None:
    """Refuse, before any case runs, a sweep with a case whose factorisation cannot fit in this machine's free
    memory, naming it (:func:`workbench.running.preflight.resources`): a P2 block at h = 0.005 was accepted, its case
    to be refused in its worker after the others had run (found by an outside pass)."""
    from ..running import preflight

    for sc in scenes:
        try:
            preflight.resources(sc, sc.model_of(), 0)
        except ParameterError as err:
            raise ParameterError(f"study case {', '.join(f'{n} = {sc[n]}' for n in ('h', 'order', 'k'))}: "
                                 f"{err}") from None


def _archive_folder(archive) -> Path:
    """The folder of a study's case archives (checked before any work; None: a new temporary folder), made."""
    if archive is not None:
        from ..output.files import check_output

        if not isinstance(archive, (str, os.PathLike)):
            raise ParameterError(f"Study.run: archive = {archive!r}: give a folder for the case archives")
        check_output(archive, "Study.run: archive", folder=True)
    if archive is None:
        _remove_stale_folders()
        archive = Path(tempfile.mkdtemp(prefix=f"workbench-study-{os.getpid()}-"))
        _HELD[str(archive)] = _hold(archive)
    archive = Path(archive).expanduser()
    archive.mkdir(parents=True, exist_ok=True)
    return archive


#: The lock files of this process's temporary case folders (:func:`_hold`), open while their studies run.
_HELD: dict = {}


def _hold(folder: Path):
    """A lock on ``folder/.alive`` for as long as the returned file is open: how another study tells this one is
    running, from any PID namespace sharing the folder (its process number alone told a study in another namespace
    gone: found by an outside pass); None where the system has no such locks."""
    try:
        import fcntl
    except ImportError:
        return None
    f = open(folder / ".alive", "w")
    fcntl.flock(f, fcntl.LOCK_EX)
    return f


def _unheld(folder: Path):
    """Whether ``folder``'s study is gone by its lock (True, False), or None where it has none."""
    try:
        import fcntl

        with open(folder / ".alive") as f:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return False
            return True
    except (ImportError, OSError):
        return None


def _remove_stale_folders() -> None:
    """Remove the temporary case folders of studies whose process is gone: a study killed (SIGTERM in a batch job,
    kill -9) left its folder behind, with its cases, which no later study reads (an outside pass found 1500 of them,
    1.4 GB). A study holds a lock in its folder while it runs (:func:`_hold`); a folder without one goes where the
    process in its name is gone, or, named without a process (older versions), once it is a day old."""
    import re
    import shutil
    import time

    from ..output.files import _alive

    root = Path(tempfile.gettempdir())
    try:
        entries = [e for e in root.iterdir() if e.name.startswith("workbench-study-") and e.is_dir()]
    except OSError:
        return
    for entry in entries:
        m = re.fullmatch(r"workbench-study-(\d+)-\w+", entry.name)
        try:
            stale = _unheld(entry)
            if stale is not None:
                pass
            elif m is not None:
                stale = int(m.group(1)) != os.getpid() and not _alive(int(m.group(1)))
            else:
                stale = time.time() - entry.stat().st_mtime > 86400.0
            if stale and entry.stat().st_uid == os.getuid():
                shutil.rmtree(entry, ignore_errors=True)
        except OSError:
            continue


def _keep(ds, path: Path, warn: bool) -> bool:
    """Write a case's archive; whether it was written. The case archives are a cache: one that cannot be written (a
    full disk) is warned about (once: ``warn``) and the study goes on with the runs in memory."""
    try:
        results.write(ds, path)
        return True
    except OSError as err:
        if warn:
            warnings.warn(f"the case archive {path} could not be written ({err.strerror or err}): the study "
                          "goes on without keeping its cases (a study run again recomputes them)", RuntimeWarning,
                          stacklevel=3)
        return False


def _numbers(where: str, **values) -> None:
    """Refuse a value that is neither None nor a number (a ParameterError naming it)."""
    for name, value in values.items():
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ParameterError(f"{where}: {name} = {value!r}; give a number")


def _base_scene(scene, overrides, grid, couple):
    """The study's scene: ``overrides`` checked together with the axis values of a case.

    The scene's own values of the swept and coupled parameters are replaced in every case, so they
    need not agree with the overrides (``T=1e-3`` with the preset's k = 0.01, while k is swept
    below T): when the overrides alone are refused, they are checked with the first case's values
    instead, and a refusal then is that case's (every case is checked again in :func:`expand`).
    """
    try:
        return scenes.scene(scene, **overrides)
    except ParameterError as alone:
        first = {}
        for name, values in grid.items():
            if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
                values = [values]
            values = list(values)
            if not values:
                raise alone from None
            first[name] = values[0]
        try:
            own = scenes.scene(scene)  # the scene's values of the axes not swept, for the couplings
            names = list(BASE_AXES) + [n for n in first if n not in BASE_AXES]
            values = {n: first[n] if n in first else own[n] for n in names if n not in couple}
            coupled = {n: rule(dict(values)) for n, rule in couple.items()}
        except Exception:  # noqa: BLE001 (a bad axis or coupling is reported by expand, naming it)
            raise alone from None
        return scenes.scene(scene, **(dict(overrides) | first | coupled))


def _history(study) -> str:
    from datetime import datetime, timezone

    from ..output import invocation
    from ..output.results import brief

    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    axes = ", ".join(f"{k}={brief(v)}" for k, v in study.axes.items() if len(v) > 1)
    return f"{stamp} {invocation.get() or f'workbench.Study({study.scene.name!r}, {axes})'}"


def _check_arguments(*, sweep, grids, couple, measures, client) -> None:
    """The Study's arguments that take Python objects: of the kind they must be, before any work (a parameter's name
    and values are checked against the scene by :func:`.cases.expand`)."""
    from ..input.parameters import PARAMETERS
    from ..values import closest_name

    for what, table in (("sweep", sweep), ("couple", couple)):
        if table is not None and not isinstance(table, dict):
            raise ParameterError(f"{what} = {table!r}: give a dict of parameter names to "
                                 + ("lists of values" if what == "sweep" else "functions of a case's values"))
        for name in table or {}:
            if name not in PARAMETERS:
                raise ParameterError(f"{what}: {name!r} is not a parameter" + closest_name(str(name), PARAMETERS))
    for what, table in (("sweep", sweep), ("couple", couple), *(("grids", g) for g in grids or ())):
        if isinstance(table, dict) and "T" in table:  # (its cases were compared on [0, the scene's T] alone)
            raise ParameterError(f"{what}: T is the time every case is compared to, the same for all: give it once "
                                 "(T=..., --set T=...), and one study per T to compare horizons")
    for name, rule in (couple or {}).items():
        if not callable(rule):
            raise ParameterError(f"couple: {name} = {rule!r} is not a function of a case's values")
    if grids is not None and (not isinstance(grids, (list, tuple)) or not grids
                              or not all(isinstance(g, dict) for g in grids)):
        raise ParameterError(f"grids = {grids!r}: give a non-empty list of dicts (axis -> values), one per grid")
    for grid in grids or ():
        if not grid:
            raise ParameterError("grids: an empty dict sweeps nothing; give each grid at least one axis, e.g. "
                                 "{'k': [0.02, 0.01]}")
        for name in grid:
            if name not in PARAMETERS:
                raise ParameterError(f"grids: {name!r} is not a parameter" + closest_name(str(name), PARAMETERS))
    if measures is not None and not callable(measures):
        raise ParameterError(f"measures = {measures!r}: give a function of a case's Dataset returning a dict of numbers")
    if isinstance(client, (int, float, bool)):
        raise ParameterError(f"client = {client!r}: give a dask.distributed Client or a scheduler address")
    if isinstance(client, str):
        import importlib.util

        if importlib.util.find_spec("distributed") is None:  # (a ModuleNotFoundError traceback, an outside pass)
            raise ParameterError(f"client = {client!r} (--scheduler): a dask cluster needs dask.distributed, which is "
                                 "not installed: pip install 'workbench[dask]'")


def _reference(spec, study):
    return reference.make(spec, study.scene, study.cases, study.axes, study.layout)


def cheapest(ds: xr.Dataset, tolerance: float, *, error: str = "error", cost: str = "wall_time"):
    """The cheapest case of a study Dataset with ``ds[error] <= tolerance``, as a dict."""
    for name in (error, cost):
        if name not in ds:
            raise ParameterError(f"cheapest: {name!r} is not a variable of the study (errors: "
                                 f"{', '.join(n for n in ds.data_vars if str(n).startswith('error'))})")
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not tolerance >= 0:
        raise ParameterError(f"cheapest: tolerance = {tolerance!r}: give a number >= 0")
    extra = [d for d in ds[error].dims if d not in ds["wall_time"].dims]
    if extra:  # (error_probe: a case would be taken for one probe's error alone)
        raise ParameterError(f"cheapest: {error!r} has the dimension(s) {extra} beyond the cases' (a case would be "
                             "taken for one of them alone): give a case's error, such as 'error'")
    err = ds[error]
    c = ds[cost] + (ds["setup_time"] if cost == "wall_time" else 0)
    ok = (err <= tolerance) & np.isfinite(c)
    if not bool(ok.any()):
        return None
    masked = c.where(ok)
    flat = int(np.nanargmin(masked.values))
    idx = np.unravel_index(flat, masked.shape)
    point = {d: masked[d].values[i] for d, i in zip(masked.dims, idx)}
    sel = ds.isel(dict(zip(masked.dims, idx)))
    return {**{d: (v.item() if isinstance(v, np.generic) else v) for d, v in point.items()},
            "h": float(sel.h), "k": float(sel.k), error: float(sel[error]), cost: float(masked.values[idx])}
