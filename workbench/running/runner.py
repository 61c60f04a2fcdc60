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
import dataclasses
import functools
import inspect
import json
import warnings
from pathlib import PurePath

import numpy as np

from .. import parallel
from ..discrete.world import finished, signals_held
from ..errors import Diverged, Interrupted, ParameterError
from ..expressions import Expression
from ..input import numerics as numerics_of
from ..input import scenes
from ..input.geometry import of_run
from ..input.models import MODELS
from ..output import results
from ..schemes import scheme_class
from ..schemes.stepping import AdaptiveSteps, FixedSteps, march, time_grid
from ..values import check_threads, closest_name
from . import adapt, follow, preflight
from . import restart as restarts
from .threads import blas_single_threaded, task_manager

#: Above this many steps only about MAX_RECORDS steps are recorded (evenly), unless asked otherwise.
MAX_RECORDS = 2000
#: Error-controlled runs record up to this many steps (their short steps are where things happen: thinned evenly in
#: time they would be the ones dropped).
MAX_RECORDS_ADAPTIVE = 20000

#: With space_tol > 0, the estimate in space is evaluated at recorded times at least this share of T apart (and at
#: the snapshots and T): about half a step's cost each (measured: 0.03 s against a step's 0.055 s at 5.5k dofs in
#: 2D, 0.46 s at 12k in 3D), so a run of thousands of records would spend more on it than on stepping.
ESTIMATE_SPACING = 0.02

__all__ = ["run", "time_grid", "MAX_RECORDS"]


def run(scene=None, *, restart=None, checkpoint=None, progress=None, record_times=None, times=None, limit=None,
        threads=None, model=None, **overrides):
    """Run a scene and return its Dataset (see :mod:`workbench.output.results` for the schema).

    Parameters
    ----------
    scene : str, path or Scene
        Built-in name (``workbench scenes`` lists them), TOML file or Scene. With ``restart`` it may be left
        out (the archive's scene, with ``overrides``); a built-in name then means the same (the archive's).
    restart : path, optional
        Continue the run archived there (or its last checkpoint) to T (:mod:`workbench.running.restart`):
        the result equals the run straight to T. Only T and the output options may differ from the
        archive's values (anything else is refused before any work, with the differences).
    checkpoint : path, optional
        Where to write the archive so far (records and restart state, atomically) every
        ``checkpoint_every`` accepted steps (the command line's ``-o``).
    progress : bool, optional
        Show a progress bar (default: only on a terminal).
    record_times : sequence of float, optional
        Times to record (the step controller lands on them). Default: every step, thinned
        to about 2000 records for longer runs (error-controlled runs: 20000); t = 0 and T always.
    times : sequence of float, optional
        A non-uniform time grid (overrides ``k``): from 0 to T, containing every snapshot
        and record time (else a ParameterError; without it the grid is made to contain them).
    limit : float, optional
        The displacement beyond which the run stops as diverged (default: 10 x the body's size).
    threads : int, optional
        Run the setup and the time loop inside NGSolve's TaskManager with this many threads
        (default: none; 1.1-1.9x faster on idle cores, slower on busy ones: docs/conventions.md).
    model : ModelA or ModelB, optional
        The physics to run instead of the scene's own (:func:`workbench.input.models.from_scene`), e.g.
        with a law replaced; its terms are recorded in the ``terms`` attribute.
    **overrides
        Scene parameters (``k=0.005``, ``gamma_nu=1``, ...).

    Raises
    ------
    workbench.ParameterError
        For any bad input, before work starts (:class:`workbench.running.restart.NoRestartState` for an
        archive that cannot be continued).
    workbench.Diverged
        When the state becomes non-finite or unbounded; ``err.dataset`` holds
        the steps computed before, marked ``status = "incomplete"``.
    """
    _check_options(overrides, checkpoint, limit, threads, progress)
    _check_objects(record_times=record_times, times=times, model=model, restart=restart)
    sc, resume = _scene_and_archive(scene, restart, overrides, model)
    _check_checkpoint(sc, checkpoint, inherited=restart is not None and "checkpoint_every" not in overrides)
    numerics = numerics_of.from_scene(sc, threads)
    grid, sync, record_times, given = _grid(sc, numerics, times, record_times, resume)
    physics = _on_archived_mesh(model or sc.model_of(), resume)
    world = parallel.world()
    parallel.check(sc, physics, numerics)
    preflight.refusals(sc, physics, numerics, grid, times, processes=world.size)
    call = _call(scene, dict(restart=restart, checkpoint=checkpoint), overrides,
                 dict(record_times=record_times, times=times, limit=limit, threads=threads, model=model))
    job = functools.partial(_Run, sc, numerics=numerics, world=world, call=call, resume=resume, checkpoint=checkpoint,
                            progress=progress, given_grid=given is not None, final=numerics.space_tol <= 0)
    with blas_single_threaded(), _quiet_unless_root(world):  # (space_tol > 0: repeated on, or refined to, finer meshes)
        return _driver(numerics)(job, physics, numerics, (grid, sync, record_times, limit))


def checks(scene=None, *, threads=None, model=None, **overrides) -> dict:
    """The refusals of :func:`run` for the same arguments, without a step: the scene's, and those that need the
    body's matrices (the explicit scheme's stability limit, at u0 and one trial step on). Returns the scheme's
    checks (``k_crit`` for the explicit scheme). Several runs checked this way before the first starts are
    refused before any work (``workbench reproduce all``: a k too large for tp4 had been found after tp1-tp3 ran).

    >>> round(checks("tp4", h=0.05, k=0.01)["k_crit"], 3)
    0.052
    >>> checks("memory_slab", h=0.25, k=0.1)["linear_solver"]  # (every scheme's checks, not the explicit one's alone)
    'banded'
    >>> checks("tp4", h=0.05, k=0.1)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    workbench.errors.StepTooLarge: k = 0.1 s exceeds the predicted stability limit of the explicit scheme, ...
    """
    _check_options(overrides, None, None, threads)
    _check_objects(record_times=None, times=None, model=model, restart=None)
    sc, _ = _scene_and_archive(scene, None, overrides, model)
    numerics = numerics_of.from_scene(sc, threads)
    grid, sync, _, _ = _grid(sc, numerics, None, None, None)
    model, world = model or sc.model_of(), parallel.world()
    parallel.check(sc, model, numerics)
    preflight.refusals(sc, model, numerics, grid, None, processes=world.size)
    job = _Run(sc, model, numerics, world, call="")
    with blas_single_threaded():
        job.set_up(grid, sync)
    return job.checks


def _driver(numerics):
    """The run of a model on the mesh as given, or adapted by repeating the run, or during it (``space_adapt``)."""
    if numerics.space_tol <= 0:
        return _once
    return follow.run if numerics.space_adapt == "during" else adapt.run


def _on_archived_mesh(model, resume):
    """The model, on the last mesh of the archive it continues when that run adapted its mesh during itself."""
    if resume is None or "adapted_mesh" not in resume.archive:
        return model
    return dataclasses.replace(model, geometry=of_run(model.geometry, resume.archive))


def _once(job, model, numerics, execute_args):
    """The run of ``model`` (on the mesh as given)."""
    return job(model).execute(*execute_args)


def _check_checkpoint(sc, checkpoint, inherited: bool = False) -> None:
    """Checkpoints need a file; where the value is the continued archive's (``inherited``: the caller did not give
    it), the message says so and how to continue without them."""
    if sc["checkpoint_every"] and checkpoint is None:
        whose = "the archive's " if inherited else ""
        instead = ("; the archive's own path continues it in place), or checkpoint_every = 0 to continue without "
                   "checkpoints") if inherited else ")"
        raise ParameterError(f"{whose}checkpoint_every = {sc['checkpoint_every']} needs a file to write the "
                             f"checkpoints to: give -o OUT.nc (workbench.run: checkpoint=PATH{instead}")
    from ..output import invocation

    if checkpoint is not None and not sc["checkpoint_every"] and invocation.get() is None:  # (the command's -o: its
        # archive, with or without checkpoints; workbench.run's checkpoint is only where they go)
        warnings.warn(f"checkpoint = {str(checkpoint)!r}: nothing is written there, checkpoint_every is 0 (give "
                      "checkpoint_every = N to write the run so far every N steps; workbench.write(ds, PATH) writes "
                      "the result)", RuntimeWarning, stacklevel=3)


def _check_options(overrides: dict, checkpoint, limit, threads, progress=None) -> None:
    """The options of :func:`run` that are not scene values, checked before any work."""
    options = [name for name, p in inspect.signature(run).parameters.items() if p.kind is p.KEYWORD_ONLY]
    for key in overrides:
        if key not in scenes.PARAMETERS and key.lower() not in scenes.PARAMETERS:
            hint = closest_name(key, options)
            if hint:
                raise ParameterError(f"unknown option {key!r} of workbench.run{hint}")
    if checkpoint is not None:
        from ..output.files import check_output

        if not isinstance(checkpoint, (str, PurePath)):
            raise ParameterError(f"checkpoint = {checkpoint!r}: give the path of a file")

        check_output(checkpoint, "checkpoint")
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise ParameterError(f"progress = {progress!r}: give True or False (default: a bar only on a terminal)")
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, (int, float)) or not limit > 0):
        raise ParameterError(f"limit = {limit!r}: give the displacement bound in m, a number > 0")
    check_threads(threads, "threads =")


def _grid(sc, numerics, times, record_times, resume):
    """(the fixed-step grid, the times it must contain, the times to record, the grid given or None); a continued run's
    grid must start with the archive's, and it records at the times, and steps on the grid, its archive was given
    unless given others."""
    if record_times is None and resume is not None:
        record_times = resume.record_times
    if times is None and resume is not None:
        times = resume.times(sc["T"])
    sync = tuple(sc["snapshots"]) + (tuple(record_times) if record_times is not None else ())
    try:
        grid = time_grid(sc["T"], sc["k"], times, sync=sync)
    except ValueError as err:
        hint = ""
        if "snapshot or record" in str(err) and sc["snapshots"]:  # (a scene's own snapshots, which the user never set)
            whose = "" if "snapshots" in sc.set_by_user else ", the scene's"
            hint = f" (snapshots = {list(sc['snapshots'])}{whose}; snapshots=() takes none)"
        raise ParameterError(f"{err}{hint}") from None
    if resume is not None and not numerics.adaptive:
        restarts.check_grid(resume.path, grid, resume.state, resume.archive)
    return grid, sync, record_times, times


def _check_objects(record_times, times, model, restart) -> None:
    """The options of :func:`run` that take Python objects: of the kind they must be, before any work."""
    from ..input.models import MODELS

    for name, value in (("record_times", record_times), ("times", times)):
        if value is None:
            continue
        try:
            numbers = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            numbers = None
        if numbers is None or numbers.ndim != 1 or not np.all(np.isfinite(numbers)):
            raise ParameterError(f"{name} = {results.brief(value)}: give a sequence of finite times in s, e.g. "
                                 f"{name}=[0.1, 0.5]")
    if model is not None and not isinstance(model, tuple(MODELS.values())):
        raise ParameterError(f"model = {model!r}: give the physics of a scene (workbench.scene(...).model_of(), with "
                             "parts replaced), or leave it out")
    if restart is not None and (not isinstance(restart, (str, PurePath)) or not str(restart).strip()):
        raise ParameterError(f"restart = {restart!r}: give the path of an archive")


def _extremes(sc) -> list:
    """'name = value' for the values the user gave that are extreme (beyond 1e12 or below 1e-12 in magnitude, or a
    Poisson's ratio within 1e-4 of its limits): what a numerical failure of the setup comes from."""
    def numbers(value):  # (the entries of a matrix or a list of values too: elastic_tensor, prony)
        if isinstance(value, bool):
            return []
        if isinstance(value, (int, float)):
            return [float(value)]
        if isinstance(value, (list, tuple)):
            return [x for item in value for x in numbers(item)]
        return []

    out = []
    for name in sorted(sc.set_by_user):
        value = sc.values.get(name)
        found = numbers(value)
        poisson = name.startswith("nu") and isinstance(value, (int, float)) and (value < -1 + 1e-4 or value > 0.5 - 1e-4)
        if poisson or any(abs(x) > 1e12 or 0 < abs(x) < 1e-12 for x in found):
            out.append(f"{name} = {value:g}" if isinstance(value, (int, float)) else f"{name} = {results.brief(value)}")
    return out


@contextlib.contextmanager
def _naming_extremes(sc):
    """Inside the setup: a numerical failure (a factorisation of a matrix that is not positive definite in floating
    point, an eigenvalue iteration, an overflow) becomes a ParameterError naming the extreme values the user gave;
    a refusal of the step (k_crit) names them too."""
    from scipy.sparse.linalg import ArpackError

    extremes = _extremes(sc)
    try:
        yield
    except (np.linalg.LinAlgError, ArpackError, FloatingPointError, OverflowError, ZeroDivisionError) as err:
        raise ParameterError(f"{sc.name}: the setup failed numerically ({type(err).__name__}: "
                             f"{str(err).splitlines()[0][:80] if str(err) else ''}) with "
                             f"{', '.join(extremes) or 'these values'}: check them") from None
    except ParameterError as err:
        if not extremes:
            raise
        raise type(err)(f"{err} (values given that are extreme: {', '.join(extremes)})") from None


def _blamed(err: Diverged, sc, disc) -> Diverged:
    """``err``, its message led by the scene's expression that is not finite at the failing step's time, where one
    is (on the body's vertices: 1/(t - 0.55) at t = 0.55, sqrt of a negative under part of a side). Else the message
    blamed the step or the scheme ("try a smaller k") for a load that no step can meet."""
    if err.time is None:
        return err
    points = disc.vertex_xyz.T if len(disc.vertex_xyz) else np.zeros((disc.dim, 1))
    found = scenes.not_finite(sc.values, [err.time], points)
    if not found and disc.world.size == 1:  # (a load NaN between the vertices only, at the quadrature points)
        F = disc.u.vec.CreateVector()
        disc.load_vector(err.time, F)
        if not np.all(np.isfinite(F.FV().NumPy())):
            given = [f"{k} = {scenes._clip(str(sc.values[k]))}" for k in sorted(sc.values)
                     if isinstance(sc.values[k], Expression) and sc.values[k].variables & {"x", "y", "z"}]
            found = f"the load is not finite at t = {err.time:g} ({'; '.join(given) or 'the loads given'})"
    if found:
        err.args = (f"{found}: no step can meet it ({err})",)
    return err


class _Resume:
    """A run continued from an archive: the archive, the state it holds, and where it was read from."""

    def __init__(self, archive, state, path):
        self.archive, self.state, self.path = archive, state, path

    def state_for(self, disc, scheme) -> dict:
        """The state to restore in ``scheme`` on ``disc`` (the archive's own)."""
        return self.state

    def settle(self, scheme) -> None:
        """(an archive's state is continued as it is)"""
        return None

    def provenance(self, attrs: dict) -> dict:
        return restarts.provenance(attrs, self.archive, self.path, self.state["time"])

    def times(self, T: float):
        """The time grid the archived run was given (``times=``, kept in its restart state) to ``T``, or None where
        it had none. Such an archive held its grid nowhere: it could not be continued, nor run again, from itself (an
        outside pass)."""
        grid = self.state["steps"].get("grid")
        if grid is None:
            return None
        at = np.flatnonzero(np.abs(grid - T) <= 1e-9 * max(abs(T), 1.0))
        if not at.size:
            raise ParameterError(f"restart {str(self.path)!r}: the archived run was given its own time grid (times=, "
                                 f"in its state_time_grid, from 0 to {grid[-1]:g} s), and T = {T:g} is not one of its "
                                 "times: give times= again, that grid carried on to T")
        return grid[: at[0] + 1]

    @property
    def record_times(self):
        """The ``record_times`` the archived run was given (its attribute), or None."""
        times = self.archive.attrs.get("record_times")
        return None if times is None else [float(t) for t in json.loads(times)]


def _scene_and_archive(scene, restart, overrides: dict, model):
    """(the scene, the archive to continue or None), checked: a restart may change only T and the output options."""
    if restart is None:
        if scene is None:
            raise ParameterError("workbench.run: give a scene (a built-in name, a .toml file or a Scene), or "
                                 "restart=PATH to continue an archived run")
        return scenes.scene(scene, **overrides), None
    archive, state = restarts.read(restart)
    if "T" in overrides:  # (before the scene: the archive's snapshots after an earlier T would be refused first)
        restarts.check_time(restart, state, scenes.PARAMETERS["T"].check(overrides["T"]))
    # a built-in name with the restart names the archive's run (its values, but those given), not the preset's
    # defaults: `workbench run slab --restart a.nc --T 2` goes on with the archive's h and scheme
    named = isinstance(scene, str) and scene in scenes.PRESETS
    if named and scene != archive.attrs.get("scene"):
        raise ParameterError(f"restart {str(restart)!r}: the archive is a run of {archive.attrs.get('scene')!r}, not "
                             f"{scene!r}; leave the scene out to continue it")
    try:
        sc = restarts.archived_scene(archive, **overrides) if scene is None or named else \
            scenes.scene(scene, **overrides)
    except ParameterError as err:
        moved = " (a mesh file moved since: give the scene at its new place with the restart, e.g. `workbench run " \
            "FILE.toml --restart ...`)" if str(err).startswith("mesh = ") and scene is None else ""
        raise restarts.NoRestartState(f"restart {str(restart)!r}: the archive's scene cannot be made again ({err})"
                                      f"{moved}") from None
    restarts.check(restart, archive, state, sc, (model or sc.model_of()).terms)
    return sc, _Resume(archive, state, restart)


def _call(scene, paths: dict, overrides: dict, options: dict) -> str:
    """The Python call that makes this result, for the ``history`` attribute (long sequences by their ends). A Scene
    object is written as the call that makes it, with the values it was given (its name alone ran another run)."""
    given = [] if scene is None else [_scene_call(scene) if isinstance(scene, scenes.Scene)
                                      else repr(str(scene) if isinstance(scene, PurePath) else scene)]
    given += [f"{k}={results.brief(v)}" for k, v in paths.items() if v is not None]
    given += [f"{k}={results.brief(v)}" for k, v in overrides.items()]
    given += [f"{k}={_model_call(v) if k == 'model' else results.brief(v)}" for k, v in options.items()
              if v is not None]
    return f"workbench.run({', '.join(given)})"


def _model_call(model) -> str:
    """A model given to the run (``model=``), for its history: its kind and terms, and the values of its contact
    terms, one of the user's own among them perhaps, which no scene names (the history had left it out: an outside
    pass).

    >>> import workbench
    >>> _model_call(workbench.scene("tp1").model_of())  # doctest: +ELLIPSIS
    '<ModelA, terms compliance, adhesion: NormalCompliance(c_nu=1.0, m_nu=1.0, gap=0.0, L=0.3), AdhesivePull(...)>'
    """
    terms = model.contact.terms if isinstance(model, MODELS["A"]) else ()
    values = [f"{type(t).__name__}({', '.join(f'{k}={v!r}' for k, v in vars(t).items())})" for t in terms]
    return f"<{type(model).__name__}, terms {', '.join(model.terms)}{': ' + ', '.join(values) if values else ''}>"


def _scene_call(sc) -> str:
    """``workbench.scene(NAME or FILE, given values)`` for the Scene ``sc`` (a file's mesh and boundaries are the
    file's own); its name alone where nothing was given (a built-in scene)."""
    own = ("mesh", "mesh_digest", "boundaries") if sc.source else ()
    values = [f"{k}={repr(str(sc[k])) if isinstance(sc[k], Expression) else results.brief(sc[k])}"
              for k in sorted(sc.set_by_user) if k not in own and k in sc.values]
    origin = repr(sc.source or sc.name)
    return f"workbench.scene({', '.join([origin] + values)})" if values or sc.source else origin


@contextlib.contextmanager
def _quiet_unless_root(world):
    """On several MPI processes the ranks other than 0 give no warnings (rank 0 gives them for all)."""
    if world.root:
        yield
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


class _Run:
    """One run, put together: the discretisation, the scheme and its step controller, the recorder, the checkpoints
    and the Dataset's attributes (scene -> model -> discretisation -> scheme -> recorded Dataset)."""

    def __init__(self, sc, model, numerics, world, call, *, resume=None, checkpoint=None, progress=None,
                 given_grid=False, final=True):
        self.sc, self.model, self.numerics, self.world, self.call = sc, model, numerics, world, call
        self.given_grid = given_grid  # (times=: the grid is kept in the restart state)
        self.final = final  # (its Dataset is the run's result: not one mesh's of an adaptive run, world.finished)
        self.failed = None  # (the failure its run ended in, with its records: kept should a signal replace it)
        self.resume, self.checkpoint, self.progress = resume, checkpoint, progress
        self.failed_checkpoint, self.record_times = None, None
        # (space_tol > 0: the estimate in space; per element the largest indicator and what marking uses, over the run)
        self.estimator = self.indicators = self.marking = None
        self.space_estimate, self.largest_norm = 0.0, 0.0
        self.follow = None  # (space_adapt = "during": refines the mesh at an estimate time, follow.Follow)

    def _controller(self, scheme, sync) -> AdaptiveSteps:
        """The error control of the run's steps: landing on the ``sync`` times and on the kinks of the scene's loads
        (``Expression.kinks``: a ramp held from some time stopped backward Euler at k_min there)."""
        sc, n = self.sc, self.numerics
        timed = self.model.loads.in_time()  # (not the scene's every expression in t: a memory kernel's t is a lag)
        kinks = sorted({k for v in timed for k in v.kinks(sc["T"])})
        # (the loads at a grid of 5 points an axis over the body's box: the same on every process, whatever its part)
        xyz = [g.ravel() for g in np.meshgrid(*[np.linspace(lo, hi, 5) for lo, hi in self.model.geometry.bbox])]
        loads = [functools.partial(lambda v, t: np.ravel(v(*xyz, t=t)), v) for v in timed]
        return AdaptiveSteps(sc["T"], n.k, rtol=n.rtol, atol=n.atol, k_min=n.k_min, k_max=n.largest_step,
                             order=scheme.order, sync=sync, admissible=scheme.admissible_step, kinks=kinks,
                             loads=loads)

    def set_up(self, grid, sync):
        """The discretisation and the scheme, with the scheme's checks before its first step (:func:`checks`)."""
        sc, n = self.sc, self.numerics
        with results.Clock() as setup, task_manager(n.threads), _naming_extremes(sc):
            self.disc = disc = parallel.discretise(self.model, sc, n)  # (threads: the factorisations use them too)
            self.scheme = scheme = scheme_class(n.scheme)(disc)
            if n.adaptive:
                self.steps = self._controller(scheme, sync)
                self.checks = scheme.preflight(n.k)
            else:
                self.steps = FixedSteps(grid, given=self.given_grid)
                self.checks = scheme.preflight(self.steps.k_max)
        self.setup_time = setup.wall
        return disc, scheme

    def execute(self, grid, sync, record_times, limit):
        """Set up, step from 0 (or the archive's time) to T, and return the Dataset (None on ranks other than 0);
        a run that diverges raises with the Dataset of what it computed."""
        sc, n = self.sc, self.numerics
        self.record_times = record_times  # (kept in the archive: a continuation records at the same times)
        disc, scheme = self.set_up(grid, sync)
        # (an error-controlled run resolves debonding by its own steps: the fixed-step resolution warning is moot)
        for message in preflight.warnings_for(sc, self.model, self.checks) + ([] if n.adaptive else scheme.warnings()):
            warnings.warn(message, RuntimeWarning, stacklevel=4)
        every = n.adaptive  # error-controlled runs keep every step (their short steps are where things happen)
        self.recorder = disc.recording(lambda d: results.Recorder(
            d, scheme.observer(d), sc["T"], sc["snapshots"], record_times,
            MAX_RECORDS_ADAPTIVE if every else MAX_RECORDS, every_step=every), scheme.observer(disc))
        if n.space_tol > 0:
            from ..discrete.estimator import Estimator

            self.estimator = Estimator(disc, scheme.observer(disc), goal=n.space_goal, edge=n.edge_tol > 0)
        if self.resume is not None:
            restarts.restore(self.resume.state_for(disc, scheme), disc, scheme, self.steps, self.recorder,
                             self.resume.archive)
            self.resume.settle(scheme)
        origin = f"limit = {limit:g} m, as given" if limit is not None else \
            "10 x the body's largest extent, the default limit"
        limit = limit if limit is not None else 10.0 * self.model.geometry.size
        failure = None
        with results.Clock() as self.clock, task_manager(n.threads):
            try:
                march(disc, scheme, self.steps, self._observe(), progress=self.progress, limit=limit,
                      limit_origin=origin, resume=self.resume is not None, after_step=self._after_step())
            except Diverged as err:
                failure = _blamed(err, sc, disc)
            except KeyboardInterrupt as err:  # (Ctrl-C; SIGTERM on the command line: the steps before are kept)
                if self.world.parallel and not (isinstance(err, Interrupted) and err.together):  # (a raw interrupt:
                    raise  # the ranks stopped in different places, nothing to gather; a signal's: stepping)
                failure = err if isinstance(err, Interrupted) else Interrupted()
                kept = self.recorder.times[-1] if self.recorder.times else self.steps.t  # (a record cut: taken back)
                failure.args = (f"{sc.name}: {failure.args[0] if failure.args else 'interrupted'}; its steps to t = "
                                f"{kept:.6g} s are kept",)
        with signals_held(drop=True):  # (the loop is over: a stop signal while the records became a Dataset or the
            return self._finish(failure, scheme)  # state was captured lost a complete run, an outside pass)

    def _finish(self, failure, scheme):
        """The run's Dataset with the state to go on from, or ``failure`` raised with the records."""
        ds = self._records(failure) if self.world.root else None  # (several MPI processes: rank 0 holds them)
        if failure is not None:
            failure.dataset, self.failed = ds, failure  # (kept, should a stop signal come as it unwinds)
            if self.final and isinstance(failure, Diverged):
                finished(ds, failure)
            raise failure
        state = restarts.capture(scheme, self.steps, self.recorder)  # (several MPI processes: every rank)
        ds = restarts.attach(ds, state) if self.world.root else None
        if self.final:  # (the command line's: kept should a stop signal come before the archive is written)
            finished(ds)
        return ds

    def _records(self, failure):
        """The records' Dataset, after the loop ended as ``failure`` says (None: complete); None where an interrupt
        left nothing to keep."""
        status = "complete" if failure is None else "incomplete"
        try:
            try:
                return self.recorder.dataset(self.attrs(status, failure, self.clock.wall, self.clock.cpu))
            except MemoryError:
                dropped = _drop_snapshots(self.recorder)
                if not dropped:
                    raise
                return self.recorder.dataset(self.attrs(status, failure, self.clock.wall, self.clock.cpu)
                                             | {"snapshots_dropped": dropped, "snapshots_dropped_units": "1"})
        except Exception:
            if not isinstance(failure, Interrupted):
                raise
            return None

    def attrs(self, status, failure=None, wall=0.0, cpu=0.0) -> dict:
        """The Dataset's attributes: provenance, the discretisation, cost, outcome (and both parts of a restart)."""
        steps, g = self.steps, self.model.geometry
        if self.numerics.adaptive:
            taken = self.recorder.extra.get("step_size", [])
            control = {"k_actual": float(np.nanmax(taken)) if len(taken) > 1 else float("nan"),
                       "nsteps": steps.accepted_steps, "accepted_steps": steps.accepted_steps,
                       "rejected_steps": steps.rejected_steps}
        else:
            control = {"k_actual": steps.k_max, "nsteps": steps.taken if status == "checkpoint" else steps.n_steps,
                       "steps_taken": steps.taken}  # (nsteps: those planned; a stopped run took fewer, an outside pass)
        extra = {
            "scheme": self.scheme.name, "h_max": g.h_max(), "cells": "x".join(map(str, g.cells())),
            **control, "ndof": self.disc.ndof_global, "threads": self.numerics.threads or 1,
            "mpi_processes": self.world.size, "setup_time": self.setup_time, "wall_time": wall, "cpu_time": cpu,
            "status": status, "failure": "" if failure is None else str(failure),
            "failure_type": "" if failure is None else type(failure).__name__,
        } | self.checks | self.scheme.used()
        if self.record_times is not None:
            extra["record_times"] = [float(t) for t in self.record_times]  # (JSON text in the archive)
        out = results.provenance(self.sc, extra, self.call, self.model.terms)
        if self.resume is None:
            return out
        return self.resume.provenance(out)

    def _observe(self):
        """The loop's output callback: the recorder's, and with space_tol > 0 the estimate in space at the recorded
        times at least ESTIMATE_SPACING T apart, the snapshots and T (``space_error_estimate(time)``, NaN between; each
        element's largest indicator kept for marking)."""
        recorder = self.recorder
        if self.estimator is None:
            return recorder.record

        last = [-np.inf]

        def observe(t, final=False, control=None):
            wanted, snapshot = recorder.due(t, final)
            if wanted and (final or snapshot or t - last[0] >= ESTIMATE_SPACING * self.sc["T"] * (1 - 1e-9)):
                last[0] = t
                # (a goal is the pressure the archive shows, at the snapshots and T; a mesh that follows the solution
                # refines at any estimate time, for that time's)
                e = self.estimator.evaluate(t, goal=bool(final or snapshot or self.follow is not None))
                self._keep(e)
                self.space_estimate, self.largest_norm = max(self.space_estimate, e.total), max(self.largest_norm, e.norm)
                control = (control or {}) | {"space_error_estimate": e.total}  # (made relative by adapt.run)
                displacement = float(np.abs(self.disc.u.vec.FV().NumPy()).max())
                if self.estimator.edges is not None:  # (a body at rest, below atol, presses by round-off: no edge)
                    judged = e.edge is not None and displacement > self.numerics.atol
                    control["contact_edge_resolution"] = e.edge.resolution if judged else np.nan
                if self.follow is not None:
                    self.follow.consider(e, self.model.geometry, self.disc.mesh, displacement)
            recorder.take(t, wanted, snapshot, control=control)
            if self.follow is not None and last[0] == t:
                self._follow(t)

        return observe

    def _keep(self, e) -> None:
        """Each element's largest indicator over the run, and what marking uses: with a goal, the largest of the
        goal's products over the times that have them (a product is not an indicator: the two are not mixed)."""
        self.indicators = e.indicators if self.indicators is None else np.maximum(self.indicators, e.indicators)
        if e.weights is not None:
            self.marking = e.marking if self.marking is None else np.maximum(self.marking, e.marking)

    @property
    def marked(self) -> np.ndarray:
        """What the run's marking uses (:meth:`_keep`): the goal's products, or without them the indicators."""
        return self.marking if self.marking is not None else self.indicators

    def _after_step(self):
        """The checkpoint writer the loop calls after each accepted step (None without checkpoints)."""
        every = self.sc["checkpoint_every"]
        if self.checkpoint is None or every <= 0 or self.follow is not None:  # (following: at its estimate times)
            return None

        def after_step(t, n):
            """Every ``every`` steps (counted from the run's start, so a continued run keeps the schedule), the
            archive so far with the state to go on from, written atomically: a kill leaves the previous one."""
            if n % every or self.steps.done():  # (the final archive is the caller's to write)
                return
            state = restarts.capture(self.scheme, self.steps, self.recorder)  # (every rank; rank 0 writes)
            if not self.world.root:
                return
            with signals_held():  # (a Ctrl-C inside netCDF's write left its lock taken: delivered after the write)
                self._write(lambda: restarts.attach(self.recorder.dataset(self.attrs("checkpoint", None,
                                                                                     *self.clock.elapsed())), state), t)

        return after_step

    def _follow(self, t) -> None:
        """At an estimate time of a run whose mesh follows the solution (:mod:`.follow`): keep the state to go back
        to, or, when the estimate asked for a finer mesh, stop with the records and the state kept last."""
        if self.follow.watching:
            self.follow.kept.append((t, restarts.capture(self.scheme, self.steps, self.recorder)))
            return
        if self.follow.geometry is None:
            self.follow.saved = (t, restarts.capture(self.scheme, self.steps, self.recorder))
            self._checkpoint_following(t)
            return
        ds = self.recorder.dataset(self.attrs("refined", None, *self.clock.elapsed()))
        raise follow.Refine(self.follow.saved, ds, self.follow.geometry)

    def _checkpoint_following(self, t) -> None:
        """A run that follows its solution writes its checkpoints at the estimate times that met the tolerance, at
        least ``checkpoint_every`` steps apart: a continuation then goes back to where the run itself would go back
        to, and equals the run straight through. The archive is on the current mesh, with every mesh's records."""
        every, n = self.sc["checkpoint_every"], self.steps.taken
        if self.checkpoint is None or every <= 0 or self.steps.done() or n < self.follow.checkpoint_step + every:
            return
        self.follow.checkpoint_step = n

        def made():
            ds = self.recorder.dataset(self.attrs("checkpoint", None, *self.clock.elapsed()))
            return restarts.attach(follow.merge(self.follow.segments + [(self.disc, ds, None)], self.follow, self),
                                   self.follow.saved[1])

        self._write(made, t)

    def _write(self, made, t) -> None:
        """Write the checkpoint ``made()`` returns (atomically); a full disk, or too little memory to make it (a
        MemoryError ended the run, an outside pass), should not stop a long run: say so once, go on."""
        try:
            results.write(made(), self.checkpoint)
        except (OSError, MemoryError) as err:
            if self.failed_checkpoint is None:
                self.failed_checkpoint = err
                why = "out of memory" if isinstance(err, MemoryError) else err.strerror or err
                warnings.warn(f"checkpoint {self.checkpoint} could not be written at t = {t:.6g} s "
                              f"({why}); the run goes on", RuntimeWarning, stacklevel=3)


def _drop_snapshots(recorder) -> int:
    """Where the memory left cannot hold the field snapshots made into arrays (a run of many snapshots under a limit
    such as ``ulimit -v``, a scheduler's ``h_vmem``): drop them and keep the records, with a warning; a MemoryError
    there lost every step after the run was done (found by an outside pass). How many: 0 where there are none; the
    archive says so in ``snapshots_dropped``."""
    dropped = len(recorder.snaps)
    if not dropped:
        return 0
    recorder.snaps.clear()
    warnings.warn(f"out of memory while the {dropped} field snapshots were made into the archive: they are dropped, "
                  "the records of every step kept (ask for fewer snapshots, or for more memory)", RuntimeWarning,
                  stacklevel=4)
    return dropped
