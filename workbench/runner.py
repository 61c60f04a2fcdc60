"""Run one scene: scene -> model -> discretisation -> scheme -> recorded Dataset.

Examples
--------
>>> import workbench
>>> ds = workbench.run("tp1", h=0.1, k=0.05, progress=False)
>>> ds.attrs["status"], ds.sizes["time"]
('complete', 21)
"""
from __future__ import annotations

import contextlib
import warnings

import numpy as np

from . import discretisation, parallel, preflight, results, scenes
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
RUN_OPTIONS = ("progress", "record_times", "times", "limit", "threads", "model", "restart", "checkpoint")

__all__ = ["run", "time_grid", "MAX_RECORDS"]


def run(scene=None, *, restart=None, checkpoint=None, progress=None, record_times=None, times=None, limit=None,
        threads=None, model=None, **overrides):
    """Run a scene and return its Dataset (see :mod:`workbench.results` for the schema).

    Parameters
    ----------
    scene : str, path or Scene
        Built-in name (``workbench scenes`` lists them), TOML file or Scene. With ``restart`` it
        may be left out (the archive's scene, with ``overrides``).
    restart : path, optional
        Continue the run archived there (or its last checkpoint) from its last time to T
        (:mod:`workbench.restart`): the result, old records and new, equals the run straight to
        T. Only T (>= the archive's time) and the output options may differ from the archive's
        values; anything else is refused, listing the differences, before any work.
    checkpoint : path, optional
        Where to write the archive so far (records and restart state, atomically) every
        ``checkpoint_every`` accepted steps; the final result is returned, not written there
        (the command line's ``-o`` writes it to the same file).
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
        Run the setup (assembly, factorisations, Model B's condensed contact system) and
        the time loop inside NGSolve's TaskManager with this many threads (default:
        none; measured 1.1-1.9x on idle cores, slower on busy ones; memory_hertz3d at
        h_contact = 0.01: 19.7 -> 8.9 s with 2, equal to 1e-10 relative). BLAS stays
        at one thread during a run (:mod:`workbench.threads`).
    model : ModelA or ModelB, optional
        The physics to run instead of the scene's own (:func:`workbench.models.from_scene`), e.g.
        with a law replaced; its terms are recorded in the ``terms`` attribute.
    **overrides
        Scene parameters (``k=0.005``, ``gamma_nu=1``, ...).

    Raises
    ------
    workbench.ParameterError
        For any bad input, before work starts (:class:`workbench.restart.NoRestartState` for an
        archive that cannot be continued).
    workbench.Diverged
        When the state becomes non-finite or unbounded; ``err.dataset`` holds
        the steps computed before, marked ``status = "incomplete"``.
    """
    from . import restart as restarts

    for key in overrides:
        if key not in scenes.PARAMETERS and key.lower() not in scenes.PARAMETERS:
            hint = closest_name(key, RUN_OPTIONS)
            if hint:
                raise ParameterError(f"unknown option {key!r} of workbench.run{hint}")
    resume = None
    if restart is not None:
        archive, state = restarts.read(restart)
        if "T" in overrides:  # (before the scene: the archive's snapshots after an earlier T would be refused first)
            restarts.check_time(restart, state, scenes.PARAMETERS["T"].check(overrides["T"]))
        sc = scenes.scene(scene, **overrides) if scene is not None else restarts.archived_scene(archive, **overrides)
        restarts.check(restart, archive, state, sc, (model or sc.model_of()).terms)
        resume = (archive, state, restart)
    elif scene is None:
        raise ParameterError("workbench.run: give a scene (a built-in name, a .toml file or a Scene), or restart=PATH "
                             "to continue an archived run")
    else:
        sc = scenes.scene(scene, **overrides)
    if sc["checkpoint_every"] and checkpoint is None:
        raise ParameterError(f"checkpoint_every = {sc['checkpoint_every']} needs a file to write the checkpoints to: "
                             "give -o OUT.nc (workbench.run: checkpoint=PATH)")
    if checkpoint is not None:
        from .files import check_output

        check_output(checkpoint, "checkpoint")
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, (int, float)) or not limit > 0):
        raise ParameterError(f"limit = {limit!r}: give the displacement bound in m, a number > 0")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ParameterError(f"threads = {threads!r}: give an integer >= 1 (NGSolve TaskManager threads)")
    sync = tuple(sc["snapshots"]) + (tuple(record_times) if record_times is not None else ())
    try:
        grid = time_grid(sc["T"], sc["k"], times, sync=sync)
    except ValueError as err:
        raise ParameterError(str(err)) from None
    if resume is not None and not sc.values.get("rtol", 0) > 0:
        restarts.check_grid(restart, grid, resume[1], resume[0])
    model = model or sc.model_of()
    parallel.check(sc, model)
    if not parallel.world().parallel:  # (several MPI processes: each holds its part, the serial estimate does not apply)
        preflight.resources(sc, model, len(grid) - 1)
    given = [] if scene is None else [repr(scene if isinstance(scene, str) else getattr(scene, "name", scene))]
    given += [f"{k}={results.brief(v)}" for k, v in (("restart", restart), ("checkpoint", checkpoint))
              if v is not None]
    given += [f"{k}={results.brief(v)}" for k, v in overrides.items()]
    given += [f"{k}={results.brief(v)}" for k, v in (("record_times", record_times), ("times", times),
                                                     ("limit", limit), ("threads", threads)) if v is not None]
    call = f"workbench.run({', '.join(given)})"
    with blas_single_threaded(), _quiet_unless_rank0():
        return _run(sc, model, grid, record_times, progress, limit, threads, call, resume, checkpoint)


@contextlib.contextmanager
def _quiet_unless_rank0():
    """On several MPI processes the ranks other than 0 give no warnings (rank 0 gives them for all)."""
    if parallel.world().root:
        yield
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _run(sc, model, grid, record_times, progress, limit, threads, call, resume=None, checkpoint=None):
    from . import restart as restarts

    adaptive = sc.values.get("rtol", 0) > 0
    with results.Clock() as setup, task_manager(threads):  # (threads given: the factorisations and the condensed
        disc = discretisation.build(model, sc)            # contact systems use them too)
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
    world = disc.world
    if world.parallel:  # rank 0 records the serial shell, the ranks send their parts
        serial = disc.shell.disc
        recorder = parallel.GatheringRecorder(disc.shell, results.Recorder(serial, sc["T"], sc["snapshots"],
                                                                           record_times, MAX_RECORDS)
                                              if world.root else None)
    else:
        serial = disc
        recorder = results.Recorder(disc, sc["T"], sc["snapshots"], record_times,
                                    MAX_RECORDS_ADAPTIVE if adaptive else MAX_RECORDS, every_step=adaptive)
    if resume is not None:
        restarts.restore(resume[1], disc, scheme, steps, recorder, resume[0])
    if limit is None:
        limit, origin = 10.0 * model.geometry.size, "10 x the body's largest extent, the default limit"
    else:
        origin = f"limit = {limit:g} m, as given"
    g = model.geometry

    def attrs(status, failure=None, wall=0.0, cpu=0.0):
        """The Dataset's attributes: provenance, the discretisation, cost, outcome (and both parts of a restart)."""
        if adaptive:
            taken = recorder.extra.get("step_size", [])
            control = {"k_actual": float(np.nanmax(taken)) if len(taken) > 1 else float("nan"),
                       "nsteps": steps.accepted_steps, "accepted_steps": steps.accepted_steps,
                       "rejected_steps": steps.rejected_steps}
        else:
            control = {"k_actual": steps.k_max, "nsteps": steps.taken if status == "checkpoint" else steps.n_steps}
        extra = {
            "scheme": scheme.name, "h_max": g.h_max(), "cells": "x".join(map(str, g.cells())),
            **control, "ndof": serial.ndof, "threads": threads or 1, "mpi_processes": world.size,
            "setup_time": setup.wall, "wall_time": wall, "cpu_time": cpu, "status": status,
            "failure": "" if failure is None else str(failure),
            "failure_type": "" if failure is None else type(failure).__name__,
        } | checks
        out = results.provenance(sc, extra, call, model.terms)
        return out if resume is None else restarts.provenance(out, resume[0], resume[2], resume[1]["time"])

    after_step = None
    if checkpoint is not None and sc["checkpoint_every"] > 0:
        every, failed = sc["checkpoint_every"], []

        def after_step(t, n):
            """Every ``every`` steps (counted from the run's start, so a continued run keeps the schedule), the
            archive so far with the state to go on from, written atomically: a kill leaves the previous one."""
            if n % every or steps.done():  # (the final archive is the caller's to write)
                return
            state = restarts.capture(scheme, steps, recorder)  # (several MPI processes: every rank, rank 0 writes)
            if not world.root:
                return
            ds = restarts.attach(recorder.dataset(attrs("checkpoint", None, *clock.elapsed())), state)
            try:
                results.write(ds, checkpoint)
            except OSError as err:  # a full disk should not stop a long run: say so once, go on
                if not failed:
                    failed.append(err)
                    warnings.warn(f"checkpoint {checkpoint} could not be written at t = {t:.6g} s "
                                  f"({err.strerror or err}); the run goes on", RuntimeWarning, stacklevel=2)

    failure = None
    with results.Clock() as clock, task_manager(threads):
        try:
            march(disc, scheme, steps, recorder, progress=progress, limit=limit, limit_origin=origin,
                  resume=resume is not None, after_step=after_step)
        except Diverged as err:
            failure = err
    ds = None  # (several MPI processes: rank 0 holds the records)
    if world.root:
        ds = recorder.dataset(attrs("complete" if failure is None else "incomplete", failure, clock.wall, clock.cpu))
    if failure is not None:
        failure.dataset = ds
        raise failure
    state = restarts.capture(scheme, steps, recorder)  # (several MPI processes: every rank; rank 0's Dataset)
    return restarts.attach(ds, state) if world.root else None
