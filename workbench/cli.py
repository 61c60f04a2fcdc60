"""Command line: ``workbench scenes | show | run | study | reproduce``.

Examples (shell)::

    workbench scenes
    workbench show tp5
    workbench run tp1 --k 0.005 -o out/tp1.nc --plot out/tp1.png
    workbench run slab --set "traction_top=(0, 2*t)" --set gamma_nu=1 -o out/slab.nc
    workbench run --restart out/slab.nc --set T=2 -o out/slab-2.nc
    workbench study tp1 --k 0.04 0.02 0.01 --reference ode -o out/tp1-k.nc --plot out/tp1-k.png
    workbench reproduce all --out out/reproduction

Exit codes: 0 done; 2 a user's mistake (one line ``error: ...`` on stderr, before any
work); 3 the run diverged (the computed part is kept and marked incomplete); 4 an
output could not be written at the end (the result is kept elsewhere, and the
message says where); 130 (Ctrl-C) and 143 (SIGTERM) interrupted (a run keeps the steps it
recorded, as for 3), and so 129 (SIGHUP: the terminal closed), 152 (SIGXCPU: a CPU time limit), 138 and 140
(SIGUSR1, SIGUSR2: a scheduler's warning). Warnings are printed as one line ``warning: ...`` each.
"""
from __future__ import annotations

import argparse
import os
import sys
import warnings

from .errors import Interrupted, ParameterError

EXIT_BAD_INPUT, EXIT_DIVERGED, EXIT_NOT_WRITTEN = 2, 3, 4
#: An error line longer than this is cut (an echoed 60 kB expression helps nobody).
MAX_LINE = 600


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one ``error:`` line (and the usage hint) like every other, and an option
    that takes one value refuses a second (argparse keeps the last silently: ``-o a.nc -o b.nc``)."""

    def error(self, message):
        raise ParameterError(f"{message} (see: {self.prog} --help)")

    def add_argument(self, *args, **kwargs):
        if kwargs.get("action") is None and kwargs.get("nargs") is None and args and args[0].startswith("-"):
            kwargs["action"] = _Once
        return super().add_argument(*args, **kwargs)


class _Once(argparse.Action):
    """An option given at most once."""

    def __call__(self, parser, namespace, values, option_string=None):
        given = namespace.__dict__.setdefault("_given_once", set())
        if self.dest in given:
            raise ParameterError(f"{option_string} is given twice ({getattr(namespace, self.dest)!r} and {values!r}); "
                                 "give it once")
        given.add(self.dest)
        setattr(namespace, self.dest, values)


def _one_line(text: str) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= MAX_LINE else text[: MAX_LINE - 3] + "..."


def _show_warning(message, category, filename, lineno, file=None, line=None):
    _say(f"warning: {_one_line(message)}", sys.stderr)


def _overrides(args, swept=()) -> dict:
    """Scene overrides from ``--set`` and the options ``--h --k --T --order --scheme``.

    A name given twice (two ``--set``, or ``--set k=`` beside ``--k``) is refused. In a
    study the options in ``swept`` are sweep axes, not scene values: they are left out
    here, and a ``--set`` of the same name beside them is refused too.
    """
    out = {}
    for item in args.set or []:
        if "=" not in item:
            raise ParameterError(f"--set {item!r}: write name=value, e.g. --set gamma_nu=0.5")
        name, value = item.split("=", 1)
        name = name.strip()
        if name in out:
            raise ParameterError(f"--set {name} is given twice ({out[name]!r} and {value.strip()!r}); give it once")
        out[name] = value.strip()
    from .input.numerics import AXES

    for name in AXES + ("T",):
        value = getattr(args, name, None)
        if value is None:
            continue
        if name in out:
            raise ParameterError(f"{name} is given twice (--{name} and --set {name}=...); give it once")
        if name not in swept:
            out[name] = value
    return out


def _check_outputs(args, *, cases=None) -> None:
    """Every output target is checked before any work (a bad path would lose the whole run)."""
    from pathlib import Path

    from .output.files import check_output

    given = {}
    if getattr(args, "output", None) is not None:
        given["-o"] = check_output(args.output, "-o")
        if cases:
            given["-o (its case folder)"] = check_output(args.output + ".cases", "-o (its case folder)", folder=True)
    for option, folder in (("plot", False), ("pareto", False), ("vtk", True)):
        value = getattr(args, option, None)
        if value is not None:
            given[f"--{option}"] = check_output(value, f"--{option}", folder=folder)
    seen = {}
    for option, path in given.items():  # two outputs in one file: the later would replace the earlier
        key = Path(os.path.abspath(path))
        if key in seen:
            raise ParameterError(f"{seen[key]} and {option} name the same path {str(path)!r}; give each its own")
        seen[key] = option
    if any(getattr(args, option, None) is not None for option in ("plot", "pareto")):
        _check_backend()  # (first: matplotlib's import fails half-done on a backend it does not know)
        from .plotting import file_format

        for option in ("plot", "pareto"):
            if getattr(args, option, None) is not None:
                file_format(getattr(args, option), f"--{option}")


def _check_backend() -> None:
    """A figure is drawn after the run: a matplotlib backend that does not exist (MPLBACKEND) is refused before it."""
    backend = os.environ.get("MPLBACKEND")
    if not backend:
        return
    if "matplotlib" not in sys.modules:  # (its import itself fails on a backend it does not know, half-done)
        os.environ.pop("MPLBACKEND")
        try:
            import matplotlib  # noqa: F401
        finally:
            os.environ["MPLBACKEND"] = backend
    import matplotlib
    from matplotlib import rcsetup

    try:
        rcsetup.validate_backend(backend)
    except ValueError:
        raise ParameterError(f"MPLBACKEND = {backend!r} is not a matplotlib backend; unset it or give one such as "
                             "'Agg' (files only)") from None
    matplotlib.rcParams["backend"] = backend  # (what its import does with MPLBACKEND)


def _threads(value):
    from .values import check_threads

    return check_threads(value, "--threads")


def _write_or_keep(ds, path=None):
    """(exit code, where ``ds`` now is): ``path`` written, or a copy in the temporary folder (``path`` None: only
    there), or None when that failed too; a failure is one ``error:`` line."""
    import tempfile
    from datetime import datetime
    from pathlib import Path

    from .output import results
    from .output.files import safe_name

    err = None
    if path is not None:
        try:
            results.write(ds, path)
            return 0, path
        except OSError as e:
            err = e
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    keep = Path(tempfile.gettempdir()) / f"workbench-kept-{safe_name(ds.attrs.get('scene', 'run'))}-{stamp}.nc"
    what = f"{path} could not be written ({err.strerror or err}); " if err is not None else ""
    try:
        results.write(ds, keep)
    except OSError as err2:
        _say(_one_line(f"error: {what}keeping the result in {keep} failed too ({err2.strerror or err2})"), sys.stderr)
        return EXIT_NOT_WRITTEN, None
    if err is not None:
        _say(_one_line(f"error: {what}the result is kept in {keep}"), sys.stderr)
    return (EXIT_NOT_WRITTEN if err is not None else 0), keep


def _write_extras(ds, outputs, kept) -> int:
    """Write the figures and files after the archive: ``outputs`` is a list of (option, path, write(path) -> text).

    A write that fails (disk full, folder gone) is one ``error:`` line saying where the results are kept (the
    archive, else a copy made now in the temporary folder); the others are still written. Exit code.
    """
    code = 0
    for option, path, write in outputs:
        try:
            text = write(path)
        except OSError as err:
            if kept is None:
                _, kept = _write_or_keep(ds)
            where = f"the results are kept in {kept}" if kept is not None else "the results could not be kept"
            _say(_one_line(f"error: {option} {path} could not be written ({err.strerror or err}); {where}"), sys.stderr)
            code = EXIT_NOT_WRITTEN
            continue
        _say(text)
    return code


def cmd_scenes(args) -> int:
    from .input.scenes import PRESETS

    width = max(map(len, PRESETS))
    for name, preset in PRESETS.items():
        _say(f"{name:<{width}}  {preset.geometry:<5}  {preset.description}", listing=True)
    return 0


def cmd_show(args) -> int:
    from .input.scenes import scene

    sc = scene(args.scene, **_overrides(args))
    _say(f"{sc.name} ({sc.geometry}, {sc.dim}D, Model {sc.model}): {sc.description}", listing=True)
    _say(f"terms assembled on the contact boundary: {', '.join(sc.terms) or 'none'}\n", listing=True)
    import shutil
    import textwrap

    width = max(100, shutil.get_terminal_size((120, 24)).columns)
    limits = (18, 28, 10, 26)  # (a long value or range wraps in its column instead of widening the table)
    rows = [(n, str(v), u, r, m) for n, v, u, r, m in sc.table()]
    w = [min(limits[i], max(len(r[i]) for r in rows + [("parameter", "value", "unit", "allowed", "")])) for i in range(4)]
    meaning = max(30, width - sum(w) - 8)
    _say(f"{'parameter':<{w[0]}}  {'value':<{w[1]}}  {'unit':<{w[2]}}  {'allowed':<{w[3]}}  meaning", listing=True)
    for r in rows:
        cells = [textwrap.wrap(r[i], w[i]) or [""] for i in range(4)] + [textwrap.wrap(r[4], meaning) or [""]]
        for j in range(max(map(len, cells))):
            line = "  ".join(f"{(c[j] if j < len(c) else ''):<{w[i]}}" for i, c in enumerate(cells[:4]))
            _say(f"{line}  {cells[4][j] if j < len(cells[4]) else ''}".rstrip(), listing=True)
    return 0


def _status_line(ds) -> str:
    a = ds.attrs
    status, steps = a["status"], f"{a['nsteps']} steps"
    if status == "incomplete" and "step" in ds.coords and ds.sizes.get("time", 0):
        status += f" at t = {float(ds.time.values[-1]):.6g} of T = {float(a['T']):g} s"
        if "accepted_steps" not in a:  # (the last step it kept, of those planned; error-controlled steps are not
            steps = f"{int(ds.step.values[-1])} of {a['nsteps']} steps"  # planned: "N of N" said nothing)
    return (f"{a['scene']}: {status}, {steps} of the {a['scheme']} scheme in {a['wall_time']:.3g} s "
            f"(setup {a['setup_time']:.3g} s), ndof {a['ndof']}")


def _stopped_beside(args, ds) -> str:
    """Where a run that stopped (diverged) writes what it computed: ``-o``, unless that file is the state this run
    went on from or wrote its checkpoints to (``--restart`` the same file, or ``checkpoint_every``): an archive of a
    stopped run holds no state to go on from, so it goes beside it, as ``NAME.stopped.nc``, and the state stays."""
    from pathlib import Path

    out = Path(args.output)
    continued = args.restart is not None and Path(args.restart).exists() and out.exists() \
        and out.resolve() == Path(args.restart).resolve()
    checkpointed = int(ds.attrs.get("checkpoint_every", 0) or 0) > 0 and out.is_file()
    return str(out.with_name(f"{out.stem}.stopped{out.suffix}")) if continued or checkpointed else args.output


def cmd_run(args) -> int:
    from .errors import Diverged

    _check_outputs(args)
    overrides = _overrides(args)
    if args.scene is None and args.restart is None:
        raise ParameterError("give a scene (a built-in name or a .toml file), or --restart ARCHIVE to continue a run "
                             "(see: workbench run --help)")
    _threads(args.threads)
    if args.restart is not None and not args.restart.strip():
        raise ParameterError("--restart '': give the path of an archive to continue")
    if args.restart is None:  # the values checked first, before NGSolve and xarray load (0.2 s, not 0.9 s, a mistake)
        from .input.scenes import scene

        _not_an_input(args, scene(args.scene, **overrides))
    from .discrete.world import keep_finished
    from .running.runner import run

    _first_signal_stops()
    kept, after = keep_finished(), 0  # (a stop signal just after the run's end, its result on its way here: kept)
    try:
        # -o is also where checkpoints go (checkpoint_every): a killed run goes on with the same command + --restart
        ds = run(args.scene, restart=args.restart, checkpoint=args.output,
                 progress=False if args.no_progress else None, threads=_threads(args.threads), **overrides)
        _stop_listening()  # (what is left is to keep the run)
        code = 0
    except Diverged as err:
        _stop_listening()  # (a stop signal while a diverged run was kept lost it, an outside pass)
        if err.dataset is None:  # (several MPI processes: rank 0 has the result and says it)
            return EXIT_DIVERGED
        _say(_one_line(f"error: {err}"), sys.stderr)
        ds, code = err.dataset, EXIT_DIVERGED
    except Interrupted as err:  # (Ctrl-C, SIGTERM: the steps before are written as a diverged run's are)
        if err.dataset is None and _other_rank():  # (several MPI processes: rank 0 has the result and says it)
            return 128 + err.signal
        ds, code, after = _stopped_after(err, kept) if err.dataset is None else (err.dataset, 128 + err.signal, 0)
        if err.dataset is not None:
            _say(_one_line(f"error: {err}"), sys.stderr)
    except KeyboardInterrupt as err:
        ds, code, after = _stopped_after(err, kept)
    finally:
        keep_finished(False)
    if ds is None:  # (several MPI processes: rank 0 holds the result and writes it)
        return code
    return _write_run(args, ds, code) or after


def _stopped_after(err, kept: list):
    """(the run's Dataset, 0: it is written as a complete run, the exit code after) for a stop signal that came after
    the run had finished (``kept``: :func:`~workbench.discrete.world.keep_finished`), before its archive was
    written; ``err`` raised again where no run had finished (the signal stopped the setup: nothing computed)."""
    from .discrete.world import stopped_by

    if not kept:
        raise err
    signum = err.signal if isinstance(err, Interrupted) else 2
    ds, failure = kept[-1]
    if failure is not None:  # (a diverged run, on its way here: kept as one)
        _say(_one_line(f"error: {failure}"), sys.stderr)
        return ds, EXIT_DIVERGED, 0
    _say(f"error: {stopped_by(signum)} after the run had completed: its results are kept", sys.stderr)
    return ds, 0, 128 + signum


def _not_an_input(args, sc) -> None:
    """Refuse an output that names the run's own scene file or mesh file: ``-o rocker.msh`` replaced the mesh with
    the archive, without a word (found by an outside pass)."""
    from pathlib import Path

    inputs = {}
    if str(args.scene).endswith(".toml"):
        inputs[Path(args.scene).expanduser().resolve()] = "scene file"
    if isinstance(sc.values.get("mesh"), str):
        inputs[Path(sc.values["mesh"]).expanduser().resolve()] = "mesh file"
    for option in ("output", "plot"):
        value = getattr(args, option, None)
        if value is not None and Path(value).expanduser().resolve() in inputs:
            raise ParameterError(f"{'-o' if option == 'output' else '--plot'} {value!r} is the run's own "
                                 f"{inputs[Path(value).expanduser().resolve()]}, which it would replace; give "
                                 "another name")


def _write_run(args, ds, code: int) -> int:
    """The status line, ``-o``'s archive, then ``--plot`` and ``--vtk`` (a stopped run's too: ``code`` says why it
    stopped, 0 where it did not); the exit code. Ctrl-C and SIGTERM are ignored from here (:func:`_stop_listening`)."""
    _stop_listening()
    return _write_outputs(args, ds, code)


def _first_signal_stops() -> None:
    """One process: the first Ctrl-C or SIGTERM stops the run (KeyboardInterrupt, Interrupted), and the ones after
    it are ignored while the steps it kept are written. A second Ctrl-C 10 ms after the first, while the records became
    a Dataset, lost the archive (found by an outside pass). Several MPI processes keep their stop requests."""
    import signal
    import threading

    from .discrete.world import launched, stop_signals, stopped_by

    if launched() > 1 or threading.current_thread() is not threading.main_thread():
        return

    def stop(signum, frame):
        _stop_listening()
        if signum != signal.SIGINT:
            raise Interrupted(stopped_by(signum), signal=signum)
        raise KeyboardInterrupt

    for s in stop_signals():
        signal.signal(s, stop)


def _stop_listening() -> None:
    """SIGINT and SIGTERM ignored from now on, in the main thread: the run has stopped, and what is left is to keep
    what it computed. A second Ctrl-C while an interrupted run's archive was written lost it, or hung the process on
    netCDF's lock; one just after it ended the process by the signal, exit -2 (found by an outside pass)."""
    import signal
    import threading

    from .discrete.world import stop_signals

    if threading.current_thread() is threading.main_thread():
        for s in stop_signals():
            signal.signal(s, signal.SIG_IGN)


def _write_outputs(args, ds, code: int) -> int:
    kept, said = None, []
    if args.output:  # (the archive first: a status line that could not be printed lost the run, before it)
        target = _stopped_beside(args, ds) if code else args.output
        written, kept = _write_or_keep(ds, target)
        if written == 0:
            partial = code and ds.attrs.get("status") != "complete"  # (an adaptive run stopped between meshes keeps
            said.append(f"wrote {target}" + (" (incomplete: see attrs 'failure')" if partial else  # a complete one)
                                             " (stopped: see attrs 'space_stop')" if code else ""))
        if target != args.output:
            said.append(f"{args.output} keeps the state the run can go on from (--restart {args.output})")
        code = code or written
    for line in [_status_line(ds)] + said:
        _say(line)
    outputs = []
    if args.plot:
        def plot(path):
            from . import plotting

            plotting.overview(ds, path)
            return f"wrote {path}"

        outputs.append(("--plot", args.plot, plot))
    if args.vtk:
        def vtk_files(path):
            from .output import vtk

            if "snapshot_time" not in ds.coords:  # (a run stopped before its first: a note, its own exit code kept)
                return f"no VTK files written to {path}/: the run stopped before its first snapshot"
            return f"wrote {len(vtk.export(ds, path))} VTK files to {path}/ (open the .pvd in ParaView)"

        outputs.append(("--vtk", args.vtk, vtk_files))
    extras = _write_extras(ds, outputs, kept)  # written whatever the code so far (a diverged run is plotted too)
    code = code or extras
    if not args.output and not args.plot:
        _say(_summary(ds))
    return code


def _say(text: str, stream=None, listing: bool = False) -> None:
    """print ``text``, where the terminal or pipe may be gone (an ssh session dropped, a reader that left, a log on a
    full disk, a stream closed) or may not encode it (a Latin-1 locale, a scene named in Greek): a message that cannot
    be shown is dropped, or its characters escaped, and the command goes on to write what it computed. A ``listing``
    (``show``, ``scenes``: nothing to write) stops where its reader left, as Unix tools do (exit 141)."""
    stream = sys.stdout if stream is None else stream
    if stream is None:  # (the process was started with it closed)
        return
    try:
        try:
            print(text, file=stream)
        except UnicodeEncodeError:
            encoding = stream.encoding or "ascii"
            print(text.encode(encoding, "backslashreplace").decode(encoding), file=stream)
    except BrokenPipeError:
        if listing:
            raise
    except (OSError, ValueError):
        pass


def _summary(ds) -> str:
    lines = []
    last = ds.isel(time=-1)
    for p in ds.probe.values:
        xyz = ", ".join(f"{float(ds[f'probe_{c}'][p]):g}" for c in ds.component.values)
        u = ", ".join(f"{float(v):.6g}" for v in last.u_probe.sel(probe=p).values)
        lines.append(f"  u({xyz}; t={float(last.time):g}) = ({u})")
    if "beta" in ds:
        lines.append(f"  beta at t={float(last.time):g}: min {float(last.beta.min()):.6g}, max {float(last.beta.max()):.6g}")
    return "\n".join(lines)


def _reference(text):
    from .input.parameters import PARAMETERS
    from .values import closest_name

    if text in (None, "auto", "extrapolated", "finest", "ode", "exact"):
        return text or "auto"
    out = {}
    for part in text.split(","):
        if "=" not in part:
            raise ParameterError(f"--reference {text!r}: give auto, extrapolated, finest, ode, exact or a finer "
                                 "run, e.g. h=0.003,k=0.0005")
        key, value = (s.strip() for s in part.split("=", 1))
        param = PARAMETERS.get(key)
        if param is None:
            raise ParameterError(f"--reference {text!r}: {key!r} is not a parameter" + closest_name(key, PARAMETERS))
        try:
            out[key] = param.check(value)
        except ParameterError as err:
            raise ParameterError(f"--reference {text!r}: {err}") from None
    return out


def _sweeps(items) -> dict:
    """``--sweep NAME=V1,V2,...`` as {NAME: [V1, V2, ...]} (values as text: the parameter table reads them; a comma
    inside parentheses belongs to a value, as in an expression ``(0, t)``)."""
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ParameterError(f"--sweep {item!r}: write name=value1,value2, e.g. --sweep c_nu=1,100,1e4")
        name, text = (s.strip() for s in item.split("=", 1))
        if name in out:
            raise ParameterError(f"--sweep {name} is given twice; give its values once")
        values, depth, start = [], 0, 0
        for i, ch in enumerate(text + ","):
            depth += (ch in "([") - (ch in ")]")
            if ch == "," and depth == 0:
                values.append(text[start:i].strip())
                start = i + 1
        out[name] = [v for v in values if v]
        if not out[name]:
            raise ParameterError(f"--sweep {name}=: give at least one value")
    return out


#: The study's own options that ``--set`` cannot give (a scene value would have been passed twice: a traceback),
#: with the command's option that gives them (None: Python's Study(...) alone).
_STUDY_OPTIONS = {"reference": "--reference", "workers": "--workers", "n_compare": "--compare",
                  "client": "--scheduler", "k_over_h": "--k-over-h", "sweep": "--sweep", "grids": None,
                  "couple": None, "measures": None}


def _refuse_study_options(overrides: dict, axes) -> None:
    """``--set`` of a study's own option or of one of its axes (h, k, order, scheme: those given by --set, the
    others are left out of ``overrides``), refused naming the option that gives it."""
    for name, value in overrides.items():
        if name in _STUDY_OPTIONS:
            how = f"give {_STUDY_OPTIONS[name]}" if _STUDY_OPTIONS[name] else "give it to Study(...) in Python"
            raise ParameterError(f"--set {name}={value}: {name} is the study's own option, not a scene value; {how}")
        if name in axes:
            raise ParameterError(f"--set {name}={value}: {name} is an axis of the study; give --{name} {value} "
                                 "(several values sweep it)")


def cmd_study(args) -> int:
    from pathlib import Path

    import numpy as np

    from .study import Study

    _check_outputs(args, cases=True)
    from .input.numerics import AXES as axes

    sweep = _sweeps(args.sweep)
    overrides = _overrides(args, swept=tuple(axes) + tuple(sweep))
    _refuse_study_options(overrides, axes)
    for name in sweep:
        if name in overrides or getattr(args, name, None) is not None:
            raise ParameterError(f"{name} is given twice (--sweep {name}=... and as a value); give it once")
    given = {name: getattr(args, name) for name in axes if getattr(args, name) is not None}
    st = Study(args.scene, k_over_h=args.k_over_h, reference=_reference(args.reference), n_compare=args.compare,
               workers=args.workers, client=args.scheduler, sweep=sweep or None, **given, **overrides)
    archive = Path(args.output + ".cases") if args.output else None
    ds = st.run(archive, progress=False if args.no_progress else None)
    code, kept = 0, None
    if args.output:
        code, kept = _write_or_keep(ds, args.output)
        if code == 0:
            kept_cases = archive.is_dir() and any(archive.glob("*.nc"))  # (its folder may have gone during the run)
            _say(f"wrote {args.output}" + (f" (cases in {archive}/)" if kept_cases else " (its cases were not kept)"))
    missing = along_rtol = False
    for norm in ("error", "error_V", "error_Q", "error_beta", "error_beta_end"):
        rates = ds.observed_order.sel(norm=norm)
        found = {str(a): [round(float(r), 3) if np.isfinite(r) else "n/a" for r in rates.sel(along=a).values.ravel()]
                 for a in rates.along.values if np.isfinite(rates.sel(along=a).values).any()}
        if found:
            missing |= any("n/a" in v for v in found.values())
            along_rtol |= "rtol" in found
            _say(f"observed order of {norm}: {found}")
    if along_rtol:  # (not an order of the scheme: how the error follows the tolerance asked)
        _say("(along rtol: the slope of the error against the tolerance, 1 where the error is proportional to it)")
    if missing:
        _say("(n/a: no order to fit there: errors of 0, or, with the extrapolated reference, differences between "
              "levels that do not fall)")
    o = st.overhead
    if o["new_cases"] or o["extended_cases"]:
        ran = f"{o['new_cases']} new case(s)" + (f" and continuing {o['extended_cases']} archived at a shorter T"
                                                 if o["extended_cases"] else "")
        _say(f"study: {o['execute']:.1f} s running {ran} (the cases' own setup + time loops, summed over workers: "
              f"{o['cases']:.1f} s), {o['evaluate']:.1f} s comparing fields")
    outputs = []
    for option, path, draw in (("--plot", args.plot, "convergence"), ("--pareto", args.pareto, "pareto")):
        if path:
            def write(p, draw=draw):
                from . import plotting

                getattr(plotting, draw)(ds, p)
                return f"wrote {p}"

            outputs.append((option, path, write))
    extras = _write_extras(ds, outputs, kept)
    return code or extras


def cmd_reproduce(args) -> int:
    import time
    from pathlib import Path

    from .errors import Diverged, NotWritten
    from .output.files import check_output
    from .paper import reproduction

    check_output(args.out, "--out", folder=True)
    overrides = _overrides(args, swept=("h", "k"))
    problems = reproduction.PROBLEMS if args.problem == "all" else (args.problem,)
    for problem in problems:  # (every problem checked first, its k_crit too: tp1-tp3 were written before tp4 refused)
        try:
            reproduction.check(problem, args.h, args.k, **overrides)
        except ParameterError as err:
            raise ParameterError(f"{problem}: {err}") from None
    code = 0
    for problem in problems:
        t0 = time.perf_counter()
        try:
            result = reproduction.reproduce(problem, args.out, h=args.h, k=args.k, side=not args.no_side,
                                            vtk=args.vtk, **overrides)
        except Diverged as err:  # as `workbench run`: say so, keep what was computed, exit 3 (after the others)
            _say(_one_line(f"error: {err}"), sys.stderr)
            if err.dataset is not None:
                written, where = _write_or_keep(err.dataset, Path(args.out) / f"{problem}_diverged.nc")
                if written == 0:
                    _say(f"  wrote {where} (incomplete: see attrs 'failure')\n")
            code = EXIT_DIVERGED
            continue
        except NotWritten as err:  # keep the run (exit 4, after the other problems)
            _, where = _write_or_keep(err.dataset)  # (a copy in the temporary folder; if that fails, it says so)
            if where is not None:
                _say(_one_line(f"error: {err.filename} could not be written ({err.strerror}); the result is kept in "
                               f"{where}"), sys.stderr)
            code = max(code, EXIT_NOT_WRITTEN)
            continue
        _say(reproduction.report(problem, result))
        _say(f"  wrote {len(result['files'])} files to {args.out} ({time.perf_counter() - t0:.1f} s)\n")
    return code


def _add_scene_args(p, run_options=True, optional=False):
    p.add_argument("scene", nargs="?" if optional else None,
                   help="built-in scene name (see 'workbench scenes') or a .toml scene file"
                   + (" (with --restart: the archive's, unless given)" if optional else ""))
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter (repeatable)")
    if run_options:
        p.add_argument("--h", type=float, help="element size")
        p.add_argument("--k", type=float, help="time step")
        p.add_argument("--T", type=float, help="final time")
        p.add_argument("--order", type=int, help="polynomial order of the displacement")
        from .input.numerics import SCHEMES

        p.add_argument("--scheme", choices=tuple(SCHEMES), help="time scheme")


def build_parser() -> argparse.ArgumentParser:
    from . import __version__
    from .input.numerics import SCHEMES

    parser = _Parser(prog="workbench", description=__doc__.split("\n")[0])
    parser.add_argument("--version", action="version", version=f"workbench {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.set_defaults(func=cmd_scenes)
    p = sub.add_parser("show", help="list a scene's parameters with value, unit, allowed range and meaning")
    _add_scene_args(p, run_options=True)
    p.set_defaults(func=cmd_show)
    p = sub.add_parser("run", help="run a scene, write a netCDF archive and plots")
    _add_scene_args(p, optional=True)
    p.add_argument("-o", "--output", help="netCDF archive to write (atomically; also the checkpoints of "
                   "checkpoint_every)")
    p.add_argument("--restart", metavar="ARCHIVE", help="continue the run archived in ARCHIVE (or its last "
                   "checkpoint) to T; only T and output options may differ")
    p.add_argument("--plot", help="PNG overview plot to write")
    p.add_argument("--vtk", metavar="DIR", help="write VTK (.vtu + .pvd) files of the snapshots for ParaView")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--threads", type=int, help="NGSolve TaskManager threads for assembly (default: off)")
    p.set_defaults(func=cmd_run)
    p = sub.add_parser("study", help="refinement sweep over h, k, order, scheme: errors, observed orders, cost")
    p.add_argument("scene", help="built-in scene name or .toml file")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter (repeatable)")
    p.add_argument("--h", type=float, nargs="+", help="element sizes")
    p.add_argument("--k", type=float, nargs="+", help="time steps (all combinations with --h)")
    p.add_argument("--k-over-h", type=float, help="couple k = C h instead of --k")
    p.add_argument("--order", type=int, nargs="+", help="element orders")
    p.add_argument("--scheme", nargs="+", choices=tuple(SCHEMES), help="schemes to sweep")
    p.add_argument("--sweep", action="append", metavar="NAME=V1,V2,...",
                   help="sweep any scene parameter over these values (repeatable), e.g. --sweep c_nu=1,100,1e4")
    p.add_argument("--reference", help="auto (default: exact/ODE where there is one, else extrapolated from a "
                   "series of three levels, else finest) | extrapolated | finest | ode | exact | h=..,k=..[,order=..]")
    p.add_argument("--compare", type=int, default=10, help="number of common times at which fields are compared")
    p.add_argument("--workers", type=int, default=2, help="local worker processes (0: in this process)")
    p.add_argument("--scheduler", help="dask.distributed scheduler address (run the cases there)")
    p.add_argument("-o", "--output", help="netCDF archive of the study (cases archived in OUTPUT.cases/)")
    p.add_argument("--plot", help="convergence plot (PNG, PDF, SVG, ... by the suffix)")
    p.add_argument("--pareto", help="error-vs-cost plot (PNG, PDF, SVG, ... by the suffix)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=cmd_study)
    p = sub.add_parser("reproduce", help="the paper's test problems 1-5: archives, Figs. 2-19, key numbers")
    p.add_argument("problem", choices=("tp1", "tp2", "tp3", "tp4", "tp5", "all"), help="which problem (or all)")
    p.add_argument("--out", default="out/reproduction", help="output folder (default out/reproduction)")
    p.add_argument("--h", type=float, help="element size (default: the preset = the paper's resolution)")
    p.add_argument("--k", type=float, help="time step (default: the preset = the paper's resolution)")
    p.add_argument("--no-side", action="store_true", help="skip the side studies (sign flip, convention)")
    p.add_argument("--vtk", action="store_true", help="also write ParaView files to OUT/vtk")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a scene parameter (repeatable)")
    p.add_argument("--no-progress", action="store_true", help="accepted as for run and study (reproduce shows none)")
    p.set_defaults(func=cmd_reproduce)
    return parser


def main(argv=None) -> int:
    import shlex

    from .output import invocation

    argv = sys.argv[1:] if argv is None else list(argv)
    token = None
    stdout = sys.stdout
    with warnings.catch_warnings():
        warnings.simplefilter("default", RuntimeWarning)
        warnings.showwarning = _show_warning
        try:
            if _other_rank():  # (several MPI processes: rank 0 speaks for all; the others say nothing)
                sys.stdout = open(os.devnull, "w")
                warnings.simplefilter("ignore")
            _utf8_arguments(argv)
            args = build_parser().parse_args(argv)
            token = invocation.set(shlex.join(["workbench"] + argv))
            _one_case_per_launch(args.command)
            return args.func(args)
        except ParameterError as err:
            if sys.stdout is stdout:
                _say(_one_line(f"error: {err}"), sys.stderr)
            return EXIT_BAD_INPUT
        except KeyboardInterrupt as err:
            from .discrete.world import stopped_by

            _say(f"error: {stopped_by(err.signal) if isinstance(err, Interrupted) else 'interrupted'}", sys.stderr)
            return 128 + err.signal if isinstance(err, Interrupted) else 130
        except BrokenPipeError:  # the reader left (`workbench show tp5 | head`): stop quietly, as Unix tools do
            try:
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            except OSError:
                pass
            return 141
        finally:  # main() called in a session (a notebook, a test): later library calls are not this command
            if token is not None:
                invocation.reset(token)
            if sys.stdout is not stdout:
                sys.stdout.close()
                sys.stdout = stdout


def _utf8_arguments(argv) -> None:
    """Refuse an argument holding bytes that are not UTF-8 (a name typed in another encoding): in an expression it
    ended in a UnicodeEncodeError traceback, in a path after the run, with its archive lost (an outside pass)."""
    from .values import not_utf8

    for arg in argv:
        shown = not_utf8(arg)
        if shown is not None:
            raise ParameterError(f"the argument '{shown}' holds bytes that are not UTF-8 (typed or named in another "
                                 "encoding): give it in UTF-8, or rename the file or folder it names")


def _one_case_per_launch(command: str) -> None:
    """Several MPI processes share one case (``workbench run``); a sweep or the reproduction would run whole on every
    rank: refused by name."""
    from .discrete.world import launched

    if launched() <= 1:  # (no launcher: NGSolve and MPI are not imported for this)
        return
    from .parallel import world

    w = world()
    if w.parallel and command in ("study", "reproduce"):
        raise ParameterError(f"workbench {command} on {w.size} MPI processes: an MPI launch runs one case "
                             "(workbench run SCENE); start the sweep with one process (its cases run in worker "
                             "processes, or on a dask cluster with --scheduler)")


def _other_rank() -> bool:
    """Whether this process is one of several MPI ranks of a distributed run, and not rank 0 (:mod:`.parallel`)."""
    from .discrete.world import launched

    if launched() <= 1:
        return False
    from .parallel import world

    return not world().root


def _terminate_as_interrupt() -> None:
    """SIGTERM (a batch scheduler's time limit, ``kill``) stops the command as Ctrl-C does, so a run keeps the steps
    it recorded (exit 143). On several MPI processes both signals ask every rank to stop after the current step,
    together (:func:`workbench.discrete.world.request_stop`), instead of raising where each rank happens to be."""
    import signal

    from .discrete.world import launched, request_stop, stop_signals, stopped_by

    def interrupt(signum, frame):
        raise Interrupted(stopped_by(signum), signal=signum)

    for signum in stop_signals():
        if launched() > 1:
            signal.signal(signum, lambda signum, frame: request_stop(signum))
        elif signum != signal.SIGINT:
            signal.signal(signum, interrupt)


def console() -> int:
    """The ``workbench`` command, a process of its own: one that runs no sweep skips what it does not use
    (:func:`workbench.running.threads.lean_process`, first: the module imports nothing heavy); ``study`` may send
    its cases to a dask cluster. On several MPI processes an unexpected error on one rank ends them all (the others
    would wait for it in their next exchange). A Ctrl-C before :func:`main` listens (while the modules load) ends
    the command as one inside it does, without a traceback."""
    try:
        if sys.argv[1:2] != ["study"]:
            from .running.threads import lean_process

            lean_process()
        _terminate_as_interrupt()
        return main()
    except KeyboardInterrupt:
        _say("error: interrupted", sys.stderr)
        return 130
    except Exception:
        from .parallel import abort_on_error

        abort_on_error()
        raise


def command() -> None:
    """The ``workbench`` executable: :func:`console`, after which a run on one process ends at once. Its results are
    written and closed by then, and the interpreter's teardown only gave back memory the system takes back anyway:
    0.2 s of the 4 s a run of the 3D Hertz body at 47k dofs takes (its matrices, factors and mesh freed one by one).
    A study (worker processes to join) and a run on several MPI processes (MPI to finalize) exit as usual."""
    code = console()
    if sys.argv[1:2] == ["run"]:
        from .discrete.world import launched

        if launched() <= 1:
            for stream in (sys.stdout, sys.stderr):
                try:
                    if stream is not None:  # (None: started with it closed)
                        stream.flush()
                except (OSError, ValueError):  # (a reader that left, a stream closed: nothing more to say)
                    pass
            os._exit(code)
    sys.exit(code)


if __name__ == "__main__":  # pragma: no cover
    command()
