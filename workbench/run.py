"""Run one scene: scene -> discretisation -> scheme -> recorded Dataset.

Examples
--------
>>> import workbench
>>> ds = workbench.run("tp1", h=0.1, k=0.05, progress=False)
>>> ds.attrs["status"], ds.sizes["time"]
('complete', 21)
"""
from __future__ import annotations

import math

import numpy as np

import warnings

from . import discretisation, meshes, results, scenes, stability
from .schemes import SCHEMES, Diverged, march, time_grid
from .threads import blas_single_threaded, task_manager

#: Above this many steps only about MAX_RECORDS steps are recorded (evenly), unless asked otherwise.
MAX_RECORDS = 2000


def _steps_at(times, wanted, what):
    """Indices of the grid times closest to ``wanted``; each must lie on the grid."""
    wanted = np.atleast_1d(np.asarray(wanted, dtype=float))
    idx = np.searchsorted(times, wanted)
    idx = np.clip(idx, 1, len(times) - 1)
    left = np.where(np.abs(times[idx - 1] - wanted) <= np.abs(times[idx] - wanted), idx - 1, idx)
    tol = 1e-9 * max(1.0, times[-1])
    off = np.abs(times[left] - wanted) > tol
    if what == "record_times" and np.any(off):
        bad = wanted[off][0]
        raise ValueError(f"record_times: t = {bad:g} is not a time of the grid (k = {times[1] - times[0]:g})")
    return left


def run(scene, *, progress=None, record_times=None, times=None, limit=None, threads=None, **overrides):
    """Run a scene and return its Dataset (see :mod:`workbench.results` for the schema).

    Parameters
    ----------
    scene : str, path or Scene
        Built-in name (``workbench scenes`` lists them), TOML file or Scene.
    progress : bool, optional
        Show a progress bar (default: only on a terminal).
    record_times : sequence of float, optional
        Times to record (must be grid times). Default: every step, thinned to
        about 2000 records for longer runs; t = 0 and T always.
    times : sequence of float, optional
        A non-uniform time grid (overrides ``k``).
    limit : float, optional
        Displacement (max over dofs) beyond which the run is stopped as diverged
        (default: 10 x the body's largest extent).
    threads : int, optional
        Run assembly inside NGSolve's TaskManager with this many threads (default:
        none; measured 1.1-1.9x on idle cores, slower on busy ones).
    **overrides
        Scene parameters (``k=0.005``, ``gamma_nu=1``, ...).

    Raises
    ------
    workbench.ParameterError
        For any bad input, before work starts.
    workbench.Diverged
        When the state becomes non-finite or unbounded; ``err.dataset`` holds
        the steps computed before, marked ``status = "incomplete"``.
    """
    sc = scenes.scene(scene, **overrides)
    grid = time_grid(sc["T"], sc["k"], times)
    n_steps = len(grid) - 1
    if record_times is None:
        stride = max(1, math.ceil(n_steps / MAX_RECORDS))
        record = set(range(0, n_steps + 1, stride)) | {n_steps}
    else:
        record = set(_steps_at(grid, record_times, "record_times").tolist()) | {0}
    snaps = set(_steps_at(grid, sc["snapshots"], "snapshots").tolist()) if sc["snapshots"] else set()
    snaps.add(n_steps)

    given = [repr(scene if isinstance(scene, str) else getattr(scene, "name", scene))]
    given += [f"{k}={v!r}" for k, v in overrides.items()]
    given += [f"{k}={v!r}" for k, v in (("record_times", record_times), ("times", times), ("limit", limit),
                                        ("threads", threads)) if v is not None]
    call = f"workbench.run({', '.join(given)})"
    with blas_single_threaded():
        return _run(sc, grid, record, snaps, progress, limit, threads, call)


def _run(sc, grid, record, snaps, progress, limit, threads, call):
    n_steps = len(grid) - 1
    _warn_locking(sc)
    with results.Clock() as setup:
        disc = discretisation.build(sc)
        scheme = SCHEMES[sc["scheme"]](disc)
        checks = _bonding_resolution(sc, float(np.max(np.diff(grid))))
        if sc["scheme"] == "explicit":
            est = stability.critical_step(sc, disc, scheme.solver)
            k_max = float(np.max(np.diff(grid)))
            checks = {"k_crit": est.k_crit, "stability_override": 0}
            if k_max > est.k_crit:
                if not sc["allow_unstable"]:
                    stability.check(sc, k_max, est)
                warnings.warn(f"k = {k_max:.3g} s > predicted k_crit = {est.k_crit:.3g} s: running the explicit "
                              "scheme anyway (allow_unstable)", RuntimeWarning, stacklevel=3)
                checks["stability_override"] = 1
    recorder = results.Recorder(disc, grid, record, snaps)
    if limit is None:
        limit = 10.0 * max(sc.values.get(k, 0.0) for k in ("length", "width", "depth", "height"))
    failure = None
    with results.Clock() as clock, task_manager(threads):
        try:
            march(disc, scheme, grid, recorder, progress=progress, limit=limit)
        except Diverged as err:
            failure = err
    extra = {
        "scheme": scheme.name, "h_max": meshes.h_max(sc), "cells": "x".join(map(str, meshes.cells(sc))),
        "k_actual": float(np.max(np.diff(grid))), "nsteps": n_steps, "ndof": disc.ndof, "threads": threads or 1,
        "setup_time": setup.wall, "wall_time": clock.wall, "cpu_time": clock.cpu,
        "status": "complete" if failure is None else "incomplete",
        "failure": "" if failure is None else str(failure),
    } | checks
    ds = recorder.dataset(results.provenance(sc, extra, call))
    if failure is not None:
        failure.dataset = ds
        raise failure
    return ds


#: Presets that keep the paper's P1 elements on purpose (documented in docs/choices.md).
_PAPER_P1 = ("tp4", "tp5")


def _warn_locking(sc):
    """P1 simplices lock in bending on a thin body: warn (the block preset's P1 tip was 50 % low at h = 0.05)."""
    if sc.dim < 2 or sc["order"] != 1 or sc.model != "A" or (sc.base in _PAPER_P1 and "order" not in sc.set_by_user):
        return
    ext = scenes._extent(sc.geometry, sc.values)
    ratio = min(ext) / max(ext)
    if ratio <= 0.25:
        warnings.warn(f"{sc.name}: P1 elements on a thin body (thickness / length = {ratio:.2g}) lock in bending, so "
                      "displacements come out too small (the block at h = 0.05: 50 %; the slab at h = 0.0125: 5 %); "
                      "order = 2 converges at the same cost", RuntimeWarning, stacklevel=4)


def _bonding_resolution(sc, k):
    """Warn when debonding is faster than the step: 1 / (gamma_nu L^2 beta0) < 10 k."""
    if sc.model != "A" or "adhesion" not in sc.terms:
        return {}
    rate = sc["gamma_nu"] * sc["L"] ** 2 * sc["beta0"]
    resolved = k * rate <= 0.1
    if not resolved:
        warnings.warn(f"k gamma_nu L^2 beta0 = {k * rate:.3g}: debonding (time scale {1 / rate:.3g} s) is faster "
                      f"than the step, so the bonding field is not resolved where |u_nu| ~ L (O(1) errors in beta "
                      f"possible); use k <= {0.1 / rate:.2g} s for an accurate beta", RuntimeWarning, stacklevel=4)
    return {"bonding_resolved": int(resolved)}
