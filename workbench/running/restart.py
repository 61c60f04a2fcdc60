"""Restart: the full state of a run in its archive, and the checks before a run goes on from it.

A run's archive (the Dataset of :func:`workbench.run`, and every checkpoint written during a run
with ``checkpoint_every = N``) holds, at its last time, everything the run needs to go on:

* the scheme's state (:meth:`workbench.schemes.base.Scheme.state`): u, v, beta, the accepted
  history, what the scheme keeps between steps (Model B: memory histories, the stored steps of a
  general kernel, the active set and contact forces) and the step sizes its cached factorisations
  were built from;
* the step controller's state (the grid index, or the error controller's t, k, err_prev, ...);
* the recorder's schedule (the step count, the last record, the thinning stride).

Arrays are variables ``state_NAME`` on dimensions ``state_dof``, ``state_history``, ``facet``, ...
(:data:`STATE_VARIABLES`), the rest one JSON attribute ``state_json``. Continuing restores all of it
and takes the steps the uninterrupted run takes, so that the result is bitwise the same.

Before any work, :func:`check` refuses a continuation that could not be that: any scene or
discretisation value other than T (and the output options ``checkpoint_every`` and snapshots after
the archive's time) that differs from the archive's, with the list of differences; a T before the
archive's time; a fixed grid on which the archive's time is not a point (:func:`check_grid`).

Examples
--------
>>> import numpy as np, tempfile, workbench
>>> path = tempfile.mkdtemp() + "/half.nc"
>>> p = workbench.write(workbench.run("tp1", h=0.1, k=0.0625, T=0.5, snapshots=(), progress=False), path)
>>> ds = workbench.run(restart=path, T=1.0, progress=False)
>>> straight = workbench.run("tp1", h=0.1, k=0.0625, T=1.0, snapshots=(), progress=False)
>>> bool(np.array_equal(ds.u_probe, straight.u_probe)), ds.attrs["restart_time"]
(True, 0.5)
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

from ..errors import ParameterError
from ..input import numerics, scenes
from ..output import results

PREFIX = "state_"
ATTR = "state_json"
#: Raised when the layout changes (an archive of another layout is refused, not misread).
FORMAT = 1
#: What a restart may change: the final time and the output options.
ALLOWED = ("T", "checkpoint_every")

#: (units, long_name) of the state variables every scheme has (a scheme says what its own are:
#: :attr:`workbench.schemes.base.Scheme.state_variables`).
STATE_VARIABLES = {
    "u": ("m", "restart state: displacement dofs"),
    "v": ("m/s", "restart state: velocity dofs"),
    "beta": ("1", "restart state: bonding field on the contact facets"),
    "history_time": ("s", "restart state: times of the accepted states kept (predictors, multistep formulas)"),
    "history_u": ("m", "restart state: displacement dofs of the accepted states kept"),
    "history_beta": ("1", "restart state: bonding field of the accepted states kept"),
    "time_grid": ("s", "restart state: the time grid the run was given (times=), which a continuation takes"),
}


class NoRestartState(ParameterError):
    """An archive that does not hold the state needed to continue its run."""


# -- the state in a Dataset -------------------------------------------------------------------------------------

def capture(scheme, steps, recorder) -> dict:
    """The full state of a run between two steps (copies); on several MPI processes in the serial order, on rank 0
    (None on the others; every rank must call it)."""
    state = scheme.d.gather_state(scheme.state(restart=True), scheme.distributed_layout)
    if state is None:
        return None
    return {"time": steps.t, "scheme_name": scheme.name, "scheme": state, "steps": steps.state(),
            "recorder": recorder.state(), "variables": scheme.state_variables}


def attach(ds: xr.Dataset, state: dict) -> xr.Dataset:
    """``ds`` with ``state`` (:func:`capture`) as ``state_*`` variables and the ``state_json`` attribute."""
    arrays, meta = _encode(state)
    described = STATE_VARIABLES | state.get("variables", {})
    variables = {}
    for name, (dims, data) in arrays.items():
        units, long_name = described.get(name, ("", f"restart state: {name}"))
        cf = {"long_name": long_name} | ({"units": units} if units else {})
        variables[PREFIX + name] = xr.Variable(dims, data, attrs=cf)
    ds.update(variables)  # (in one merge: one per variable took 33 ms a checkpoint on tp5, 6 variables)
    ds.attrs[ATTR] = json.dumps(meta)
    return ds


def has_state(ds: xr.Dataset) -> bool:
    return ATTR in ds.attrs


def without_state(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` without its restart state (a smaller archive that cannot be continued).

    >>> import workbench
    >>> ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    >>> has_state(ds), has_state(without_state(ds)), "state_u" in without_state(ds)
    (True, False, False)
    """
    out = ds.drop_vars([n for n in ds.variables if str(n).startswith(PREFIX)])
    out.attrs = {k: v for k, v in ds.attrs.items() if k != ATTR}
    return out


def _plain(value):
    """JSON-able scalars and containers (NumPy scalars as Python's; floats keep every bit through repr)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _dims(name, shape, ndof, stacked=False):
    """Dimension names: ``state_dof`` for the (first) axis of length ndof, else ``state_NAME_AXIS`` (an axis named
    as its variable would make the variable a coordinate)."""
    out = []
    for j, n in enumerate(shape):
        dof = n == ndof and "state_dof" not in out and not (stacked and j == 0)
        out.append("state_dof" if dof else f"{PREFIX}{name}_{j}")
    return tuple(out)


def _encode(state):
    s = state["scheme"]
    ndof = s["u"].size
    arrays = {"u": (("state_dof",), s["u"]), "v": (("state_dof",), s["v"])}
    if s["beta"] is not None:
        arrays["beta"] = (("facet",), s["beta"])
    history = s["history"]
    if history:
        arrays["history_time"] = (("state_history",), np.array([h[0] for h in history], dtype=float))
        arrays["history_u"] = (("state_history", "state_dof"), np.stack([h[1] for h in history]))
        if history[0][2] is not None:
            arrays["history_beta"] = (("state_history", "facet"), np.stack([h[2] for h in history]))
    steps = dict(state["steps"])
    if "grid" in steps:  # (a grid of the user's, times=: an array, not JSON text in an attribute)
        arrays["time_grid"] = ((f"{PREFIX}time_grid_0",), np.asarray(steps.pop("grid"), dtype=float))
        steps["grid"] = "time_grid"
    extra = {}
    for key, value in s["extra"].items():
        if key in arrays:
            raise AssertionError(f"scheme state {key!r} would overwrite a state variable")
        if isinstance(value, np.ndarray):
            extra[key] = {"array": list(value.shape), "dtype": value.dtype.str}
            if value.size:  # (netCDF cannot hold a dimension of length 0 as a fixed one)
                arrays[key] = (_dims(key, value.shape, ndof), value)
        elif isinstance(value, list) and value and all(isinstance(v, np.ndarray) for v in value):
            stacked = np.stack(value)
            extra[key] = {"arrays": len(value)}
            arrays[key] = (_dims(key, stacked.shape, ndof, stacked=True), stacked)
        elif isinstance(value, list) and value and all(isinstance(v, (float, np.floating)) for v in value):
            extra[key] = {"floats": len(value)}
            arrays[key] = ((f"{PREFIX}{key}_0",), np.asarray(value, dtype=float))
        else:
            extra[key] = {"value": _plain(value)}
    meta = {"format": FORMAT, "time": float(state["time"]), "scheme_name": state["scheme_name"], "ndof": ndof,
            "k_last": float(s["k_last"]), "u_scale": float(s["u_scale"]), "history": len(history), "extra": extra,
            "cache": _plain(s.get("cache", [])), "steps": _plain(steps),
            "recorder": _plain(state["recorder"])}
    return arrays, meta


def decode(ds: xr.Dataset) -> dict:
    """The state stored by :func:`attach` (NoRestartState if there is none)."""
    if ATTR not in ds.attrs:
        raise NoRestartState("the archive has no restart state")
    meta = json.loads(ds.attrs[ATTR])
    if meta.get("format") != FORMAT:
        raise NoRestartState(f"the archive's restart state has layout {meta.get('format')}, this workbench reads "
                             f"layout {FORMAT}")

    def arr(name):
        return np.array(ds[PREFIX + name].values)  # (a copy: the scheme owns it from now on)

    beta = arr("beta") if PREFIX + "beta" in ds else None
    history = []
    if meta["history"]:
        ht, hu = arr("history_time"), arr("history_u")
        hb = arr("history_beta") if PREFIX + "history_beta" in ds else None
        history = [(float(ht[i]), hu[i], None if hb is None else hb[i]) for i in range(len(ht))]
    extra = {}
    for key, spec in meta["extra"].items():
        if "array" in spec:
            extra[key] = arr(key) if PREFIX + key in ds else np.empty(spec["array"], dtype=np.dtype(spec["dtype"]))
        elif "arrays" in spec:
            extra[key] = list(arr(key))
        elif "floats" in spec:
            extra[key] = [float(t) for t in arr(key)]
        else:
            extra[key] = spec["value"]
    scheme = {"u": arr("u"), "v": arr("v"), "beta": beta, "k_last": meta["k_last"], "u_scale": meta["u_scale"],
              "history": history, "extra": extra, "cache": meta["cache"]}
    steps = dict(meta["steps"])
    if "grid" in steps:
        steps["grid"] = arr(steps["grid"])
    return {"time": meta["time"], "scheme_name": meta["scheme_name"], "ndof": meta["ndof"], "scheme": scheme,
            "steps": steps, "recorder": meta["recorder"]}


def restore(state: dict, disc, scheme, steps, recorder, archive: xr.Dataset) -> None:
    """Put the run back where the archive left it (the discretisation must be the archive's)."""
    ndof = disc.ndof_global  # (several MPI processes: the archive is in the serial order)
    if state["ndof"] != ndof or state["scheme_name"] != scheme.name:
        raise ParameterError(f"the archive's restart state is for {state['ndof']} dofs of the {state['scheme_name']} "
                             f"scheme, this run has {ndof} of the {scheme.name} scheme (an archive of another "
                             "workbench version?); run it again from the start")
    scheme.restore(disc.scatter_state(state["scheme"], scheme.distributed_layout))
    steps.restore(state["steps"])
    recorder.resume(archive, state["recorder"])


# -- reading an archive, and what may differ -----------------------------------------------------------------------

def read(path):
    """(Dataset, state) of the archive at ``path``; ParameterError if it cannot be read, NoRestartState if it holds
    no state to continue from."""
    from ..values import check_utf8_path

    check_utf8_path(path, "restart")  # ("cannot be read as an archive" of a good archive in a folder named in Latin-1)
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"restart {str(path)!r}: no such archive" + (" (a directory)" if path.is_dir() else ""))
    try:
        ds = results.load(path)
    except Exception as err:  # any failure to read: not an archive (empty, truncated, another format)
        raise ParameterError(f"restart {str(path)!r} cannot be read as an archive ({type(err).__name__})") from None
    if not has_state(ds):
        a = ds.attrs
        if "parameters_json" not in a:
            why = "it is not the archive of a workbench run"
        elif a.get("status") == "incomplete":
            stopped = a.get("failure_type") or "incomplete"
            why = f"its run stopped ({stopped}), so its last state is not one to go on from"
        else:
            why = "it was written before workbench stored the state in its archives, or without it (without_state)"
        raise NoRestartState(f"restart {str(path)!r}: the archive has no restart state: {why}; run it again from the "
                             "start")
    try:
        state = decode(ds)
        _check_consistent(ds, state)
    except NoRestartState as err:
        raise NoRestartState(f"restart {str(path)!r}: {err}; run it again from the start") from None
    except Exception as err:  # noqa: BLE001 (an edited or truncated archive: any fault means it cannot be continued)
        raise NoRestartState(f"restart {str(path)!r}: the archive's restart state is damaged ({type(err).__name__}: "
                             f"{str(err).splitlines()[0][:80] if str(err) else 'no detail'}); run it again from the "
                             "start") from None
    return ds, state


def _check_consistent(ds: xr.Dataset, state: dict) -> None:
    """The parts of an archive a continuation reads, checked against each other (an edited archive fails here)."""
    a = ds.attrs
    for key in ("scene", "base_scene", "parameters_json"):
        if not isinstance(a.get(key), str):
            raise NoRestartState(f"the archive has no {key} attribute (text)")
    if not isinstance(json.loads(a["parameters_json"]), dict):
        raise NoRestartState("the archive's parameters_json is not a table of values")
    s = state["scheme"]
    if s["u"].shape != (state["ndof"],) or s["v"].shape != (state["ndof"],):
        raise NoRestartState(f"the archive's state holds {s['u'].size} displacement dofs, its record says "
                             f"{state['ndof']}")
    for key in ("time", "steps", "recorder"):
        if key not in state or (key != "time" and not isinstance(state[key], dict)):
            raise NoRestartState(f"the archive's restart state has no {key}")
    if "time" not in ds.dims or "step" not in ds.variables or ds["step"].dims != ("time",):
        raise NoRestartState("the archive has no record over time (a time dimension with its step numbers), which a "
                             "continuation extends")
    last, recorded = float(state["recorder"]["last"]), ds.time.values
    if recorded.size and recorded[-1] < last - 1e-9 * max(abs(last), 1.0):
        # (a continuation appends to the records it finds: a gap from the cut to the state's time, without a word)
        raise NoRestartState(f"its records end at t = {recorded[-1]:.6g} s, but its run recorded up to t = {last:.6g} "
                             "s (records cut, e.g. by ds.isel(time=...)): continue from the archive as it was written")


def archived_scene(ds: xr.Dataset, *, whole: bool = False, **overrides):
    """The scene of an archive with ``overrides``: the values its user gave (``set_by_user_json``), the rest the
    scene's own for the new values (the preset's snapshot times up to a longer T, say); ``whole``: every value as
    archived (``parameters_json``; so are archives that do not say what their user gave)."""
    a = ds.attrs
    values = json.loads(a["parameters_json"])
    if "stored_mesh" in ds and "mesh" not in overrides and not Path(str(values.get("mesh", ""))).is_file():
        # (a mesh given as a Python object, its file in a cache cleared since)
        from ..input.meshes import restore

        overrides = dict(overrides, mesh=str(restore(str(ds.stored_mesh.values))))
    if not whole and "set_by_user_json" in a:
        values = {name: values[name] for name in json.loads(a["set_by_user_json"]) if name in values}
    elif not whole:
        values = _given(a, values)
    return scenes.make(a["scene"], values | overrides, base=a["base_scene"], description=a.get("description", ""))


def _given(a, values: dict) -> dict:
    """What the user of an archive that does not say (written before ``set_by_user_json``) gave, as far as its
    values tell: those its scene would not have made by itself from the others (a default, a value derived from
    another, snapshot times from T). Taken as given, every value said that options left at their defaults acted
    (atol without rtol, say) on each continuation."""
    def made(given: dict) -> dict:
        return scenes.make(a["scene"], given, base=a["base_scene"]).plain()

    try:
        own = made({})
    except ParameterError:
        return values
    given = {n: v for n, v in values.items() if json.dumps(v, sort_keys=True) != json.dumps(own.get(n), sort_keys=True)}
    for name in list(given):  # (each left out in turn: kept where the others do not make it)
        rest = {n: v for n, v in given.items() if n != name}
        try:
            again = made(rest).get(name)
        except ParameterError:
            continue
        if json.dumps(again, sort_keys=True) == json.dumps(given[name], sort_keys=True):
            given = rest
    return given


def _text(value) -> str:
    if isinstance(value, float):
        short = f"{value:g}"
        return short if float(short) == value else repr(value)
    text = value if isinstance(value, str) else json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def differences(old, new, t: float, old_terms: str, new_terms: str) -> list:
    """'E 1000 -> 2000' for every value of ``new`` (a Scene) that differs from ``old``'s, but T and the output
    options (snapshots only up to the time t)."""
    out = []
    for what, a, b in (("scene", old.base, new.base), ("model", old.model, new.model), ("terms", old_terms, new_terms)):
        if a != b:
            out.append(f"{what} {a} -> {b}")
    a, b = old.plain(), new.plain()
    tol = 1e-9 * max(1.0, t)
    for key in list(a) + [k for k in b if k not in a]:
        if key in ALLOWED:
            continue
        va, vb = a.get(key, "(absent)"), b.get(key, "(absent)")
        said = ""
        if key == "snapshots" and isinstance(va, list) and isinstance(vb, list):  # later ones are output options
            later = [s for s in vb if s > t + tol]
            va, vb = [s for s in va if s <= t + tol], [s for s in vb if s <= t + tol]
            # (a restart asking for later snapshots alone was refused as "[0.33] -> []", an outside pass)
            said = (f" (the snapshots up to t = {t:g} s are the archive's: give them with the later ones, "
                    f"snapshots = {', '.join(f'{x:g}' for x in va + later)})")
        if json.dumps(va, sort_keys=True) != json.dumps(vb, sort_keys=True):
            out.append(f"{key} {_text(va)} -> {_text(vb)}{said}")
    return out


def check(path, archive: xr.Dataset, state: dict, scene, model_terms) -> None:
    """Refuse (ParameterError) a continuation of ``archive`` as ``scene`` that the archive's run would not be."""
    t = state["time"]
    # (a default changed since by another version is a difference; a mesh file moved since, given again at its new
    # place with the same content (its digest), is the archive's mesh: the archive's path would not be found)
    digest = json.loads(archive.attrs["parameters_json"]).get("mesh_digest")
    moved = {"mesh": scene["mesh"]} if digest and scene.values.get("mesh_digest") == digest else {}
    old = archived_scene(archive, whole=True, **moved)
    diff = differences(old, scene, t, archive.attrs.get("terms", ""), ",".join(model_terms) or "none")
    if diff:
        raise ParameterError(f"restart {str(path)!r}: the run asked for differs from the archive's in "
                             f"{', '.join(diff)}; a restart may change only T (to >= {t:g} s, the archive's time) and "
                             f"the output options (checkpoint_every, snapshots after t = {t:g} s): start a new run for "
                             "other values")
    if old.values.get("space_tol", 0.0) > 0 and old.values.get("space_adapt", "repeat") != "during":
        raise ParameterError(f"restart {str(path)!r}: the run was refined adaptively (space_tol = {old['space_tol']:g}), "
                             "on meshes that follow its whole history: a longer run would adapt to a longer one, so "
                             "run again from 0 to the new T (space_adapt = 'during' runs can be continued)")
    check_time(path, state, scene["T"])
    longer = scene["T"] > old["T"] * (1 + 1e-12)
    if longer and scene.values.get("kernel_approximation") == "exponentials":
        # the Prony histories belong to the exponentials fitted on [0, old T]; a longer T fits others
        raise ParameterError(f"restart {str(path)!r}: its kernel is a sum of exponentials fitted on [0, {old['T']:g}] s "
                             f"(kernel_approximation = 'exponentials'), and T = {scene['T']:g} would need another fit, "
                             "whose memory histories the archive does not hold: run again from 0 to the new T (or with "
                             "the quadrature)")
    if longer and numerics.from_scene(scene).adaptive and archive.attrs.get("status") != "checkpoint":
        warnings.warn(f"restart {str(path)!r}: the error-controlled run landed on its own T = {old['T']:g} s, which a "
                      f"run straight to T = {scene['T']:g} does not: the continued steps differ from that run's (the "
                      "result meets the same tolerance, not bitwise)", RuntimeWarning, stacklevel=3)
    a = archive.attrs
    now = results.versions()
    compared = ("version_workbench", "version_workbench_code", "version_ngsolve")
    changed = [f"{k[8:]} {a[k]} -> {now[k]}" for k in compared if k in a and a[k] != now[k]]
    if changed:
        warnings.warn(f"restart {str(path)!r}: the archive was made by other versions ({', '.join(changed)}); the "
                      "continued run may differ from an uninterrupted one: by round-off, or, where the code changed, by "
                      "what its change changed", RuntimeWarning, stacklevel=3)


def check_time(path, state: dict, T) -> None:
    """Refuse a final time T before the archive's."""
    t = state["time"]
    if T < t - 1e-9 * max(1.0, t):
        raise ParameterError(f"restart {str(path)!r}: T = {T:g} is before the archive's time t = {t:g} s; a restart "
                             "goes on from there (give T >= that)")


def check_grid(path, grid: np.ndarray, state: dict, archive: xr.Dataset) -> None:
    """A fixed-step continuation goes on with the grid of the run straight to the new T, from the archive's step:
    refuse it if the archive's time is not that grid point (to round-off); warn if its steps are not the grid's
    bitwise (then the continued run equals the straight one to round-off only)."""
    i, t = int(state["steps"]["index"]), state["time"]
    T = float(grid[-1])
    tol = 1e-9 * T  # (relative: a run of T = 1e-9 s is no coarser in time than one of 1 s)
    if i >= len(grid) or abs(grid[i] - t) > tol:
        where = f"t = {float(grid[i])!r} s there" if i < len(grid) else "beyond its end"
        raise ParameterError(f"restart {str(path)!r}: the archive's time t = {t!r} s (step {i}) is not step {i} of the "
                             f"time grid to T = {T:g} ({where}): the new T divides time into other steps; choose a T "
                             "that is a whole number of the archive's steps from 0 (an archive run on a grid of its "
                             "own: give times= again, that grid carried on to T)")
    steps, times = archive.step.values, archive.time.values
    if len(steps) and (steps.max() >= len(grid) or np.abs(grid[steps] - times).max() > tol):
        raise ParameterError(f"restart {str(path)!r}: the archive's recorded times are not points of the time grid to "
                             f"T = {T:g}: it was run on another grid (times=..., or other record times)")
    if grid[i] != t or not np.array_equal(grid[steps], times):
        j = int(np.argmax(grid[steps] != times)) if not np.array_equal(grid[steps], times) else None
        a, b = (float(times[j]), float(grid[steps[j]])) if j is not None else (t, float(grid[i]))
        warnings.warn(f"restart {str(path)!r}: the archive's steps differ from those of the grid to T = {T:g} by "
                      f"round-off (t = {a!r} there, {b!r} here): the continued run equals a run straight to T to "
                      "round-off, not bitwise", RuntimeWarning, stacklevel=3)


def provenance(attrs: dict, archive: xr.Dataset, path, t: float) -> dict:
    """The attributes of a continued run: both parts' history lines, where it was continued from, the costs summed."""
    old = archive.attrs
    out = dict(attrs)
    out["history"] = f"{old.get('history', '')}\n{attrs['history']}".strip()
    out["restarted_from"] = str(path)
    out["restart_time"], out["restart_time_units"] = float(t), "s"
    for key in ("setup_time", "wall_time", "cpu_time"):  # the cost of the whole result
        if key in old and key in out:
            out[key] = float(old[key]) + float(out[key])
    return out
