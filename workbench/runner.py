"""Run one scene: scene -> model -> discretisation -> scheme -> recorded Dataset.

Examples
--------
>>> import workbench
>>> ds = workbench.run("tp1", h=0.1, k=0.05, progress=False)
>>> ds.attrs["status"], ds.sizes["time"]
('complete', 21)
"""
from __future__ import annotations

import warnings

import numpy as np

from . import discretisation, preflight, results, scenes
from .errors import Diverged, ParameterError
from .parameters import closest_name
from .schemes import scheme_class
from .schemes.stepping import AdaptiveSteps, FixedSteps, march, time_grid
from .threads import blas_single_threaded, task_manager

#: Above this many steps only about MAX_RECORDS steps are recorded (evenly), unless asked otherwise.
MAX_RECORDS = 2000
#: Error-controlled runs record up to this many steps (their short steps are where things happen: thinned evenly in
#: time they would be the ones dropped).
MAX_RECORDS_ADAPTIVE = 20000
#: The keyword arguments of :func:`run` that are not scene parameters.
RUN_OPTIONS = ("progress", "record_times", "times", "limit", "threads", "model")

__all__ = ["run", "time_grid", "MAX_RECORDS"]


def run(scene, *, progress=None, record_times=None, times=None, limit=None, threads=None, model=None, **overrides):
    """Run a scene and return its Dataset (see :mod:`workbench.results` for the schema).

    Parameters
    ----------
    scene : str, path or Scene
        Built-in name (``workbench scenes`` lists them), TOML file or Scene.
    progress : bool, optional
        Show a progress bar (default: only on a terminal).
    record_times : sequence of float, optional
        Times to record (the step controller lands on them). Default: every step, thinned
        to about 2000 records for longer runs (error-controlled runs: 20000); t = 0 and T always.
    times : sequence of float, optional
        A non-uniform time grid (overrides ``k``): from 0 to T, containing every snapshot
        and record time (else a ParameterError; without it the grid is made to contain them).
    limit : float, optional
        Displacement (max over dofs) beyond which the run is stopped as diverged
        (default: 10 x the body's largest extent).
    threads : int, optional
        Run assembly inside NGSolve's TaskManager with this many threads (default:
        none; measured 1.1-1.9x on idle cores, slower on busy ones). BLAS stays at
        one thread during a run (:mod:`workbench.threads`).
    model : ModelA or ModelB, optional
        The physics to run instead of the scene's own (:func:`workbench.models.from_scene`), e.g.
        with a law replaced; its terms are recorded in the ``terms`` attribute.
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
    for key in overrides:
        if key not in scenes.PARAMETERS and key.lower() not in scenes.PARAMETERS:
            hint = closest_name(key, RUN_OPTIONS)
            if hint:
                raise ParameterError(f"unknown option {key!r} of workbench.run{hint}")
    sc = scenes.scene(scene, **overrides)
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, (int, float)) or not limit > 0):
        raise ParameterError(f"limit = {limit!r}: give the displacement bound in m, a number > 0")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ParameterError(f"threads = {threads!r}: give an integer >= 1 (NGSolve TaskManager threads)")
    sync = tuple(sc["snapshots"]) + (tuple(record_times) if record_times is not None else ())
    try:
        grid = time_grid(sc["T"], sc["k"], times, sync=sync)
    except ValueError as err:
        raise ParameterError(str(err)) from None
    model = model or sc.model_of()
    preflight.resources(sc, model, len(grid) - 1)
    given = [repr(scene if isinstance(scene, str) else getattr(scene, "name", scene))]
    given += [f"{k}={results.brief(v)}" for k, v in overrides.items()]
    given += [f"{k}={results.brief(v)}" for k, v in (("record_times", record_times), ("times", times),
                                                     ("limit", limit), ("threads", threads)) if v is not None]
    call = f"workbench.run({', '.join(given)})"
    with blas_single_threaded():
        return _run(sc, model, grid, record_times, progress, limit, threads, call)


def _run(sc, model, grid, record_times, progress, limit, threads, call):
    adaptive = sc.values.get("rtol", 0) > 0
    with results.Clock() as setup:
        disc = discretisation.build(model, sc)
        scheme = scheme_class(sc["scheme"])(disc)
        if adaptive:
            sync = tuple(sc["snapshots"]) + (tuple(record_times) if record_times is not None else ())
            steps = AdaptiveSteps(sc["T"], sc["k"], rtol=sc["rtol"], atol=sc["atol"], k_min=sc["k_min"],
                                  k_max=sc["k_max"] or sc["T"], order=scheme.order, sync=sync,
                                  admissible=scheme.admissible_step)
            checks = scheme.preflight(sc["k"])
        else:
            steps = FixedSteps(grid)
            checks = scheme.preflight(steps.k_max)
    # (an error-controlled run resolves debonding by its own steps: the fixed-step resolution warning is moot)
    for message in preflight.warnings_for(sc, model) + ([] if adaptive else scheme.warnings()):
        warnings.warn(message, RuntimeWarning, stacklevel=3)
    recorder = results.Recorder(disc, sc["T"], sc["snapshots"], record_times,
                                MAX_RECORDS_ADAPTIVE if adaptive else MAX_RECORDS, every_step=adaptive)
    if limit is None:
        limit, origin = 10.0 * model.geometry.size, "10 x the body's largest extent, the default limit"
    else:
        origin = f"limit = {limit:g} m, as given"
    failure = None
    with results.Clock() as clock, task_manager(threads):
        try:
            march(disc, scheme, steps, recorder, progress=progress, limit=limit, limit_origin=origin)
        except Diverged as err:
            failure = err
    g = model.geometry
    if adaptive:
        taken = recorder.extra.get("step_size", [])
        control = {"k_actual": float(np.nanmax(taken)) if len(taken) > 1 else float("nan"),
                   "nsteps": steps.accepted_steps, "accepted_steps": steps.accepted_steps,
                   "rejected_steps": steps.rejected_steps}
    else:
        control = {"k_actual": steps.k_max, "nsteps": steps.n_steps}
    extra = {
        "scheme": scheme.name, "h_max": g.h_max(), "cells": "x".join(map(str, g.cells())),
        **control, "ndof": disc.ndof, "threads": threads or 1,
        "setup_time": setup.wall, "wall_time": clock.wall, "cpu_time": clock.cpu,
        "status": "complete" if failure is None else "incomplete",
        "failure": "" if failure is None else str(failure),
        "failure_type": "" if failure is None else type(failure).__name__,
    } | checks
    ds = recorder.dataset(results.provenance(sc, extra, call, model.terms))
    if failure is not None:
        failure.dataset = ds
        raise failure
    return ds
