"""User mistakes are caught, named and refused before any work (issue 9, items 9-14).

The contract pinned here:

* **Command line.** A user's mistake exits with code 2 and writes exactly one non-empty line to stderr,
  ``error: ...``, which names the offending parameter, option or file, holds no ``Traceback`` and is
  readable (at most 1000 characters, so a 30000-term expression is not echoed back). It happens before
  any work: quickly, and no output file or folder is created (not even the valid ones asked for in the
  same call). Only internal defects may show a traceback.
* **Python API.** :class:`workbench.ParameterError` (a ``ValueError``) whose message names the parameter.
* **Outputs.** Every ``-o``, ``--plot`` and ``--vtk`` target is checked before the run; if writing still
  fails at the end (disk full) the result is kept elsewhere and the message says where. Stale hidden
  ``.NAME.*.tmp`` files are cleaned up by the next write of NAME; damaged study cases are recomputed.
* **Names reaching the file system** (a TOML ``name``) are sanitised: files stay inside the requested folder.

Command-line cases run in subprocesses (``python -m workbench.cli``); to keep the file fast on two cores,
the next command-line case (in file order) is started while the current one is checked (see :class:`_Runner`).
"""
from __future__ import annotations

import errno
import json
import os
import re
import shutil
import subprocess
import sys
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import workbench
from workbench import ParameterError

#: A refusal must come before any work: well within this many seconds (the import alone takes ~2 s).
FAST = 15.0
#: Address-space cap for the cases that today build huge meshes or grids (so they cannot exhaust the machine).
MEMCAP = 4 << 30
#: A clear error line is not an echo of a 60 kB expression.
MAX_LINE = 1000

RUN_TINY = ("--h", "0.1", "--k", "0.05", "--no-progress")


# ------------------------------------------------------------------------------------------------------
# running the command line
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Cli:
    """One command-line call: ``args`` (``{D}`` is replaced by the case folder), files made by ``setup(d)``,
    and the names of which the error line must contain at least one."""

    args: tuple
    names: tuple = ()
    setup: object = None
    timeout: float = 60.0
    memcap: bool = False


@dataclass
class Result:
    args: list
    cwd: Path
    before: set
    rc: int | None
    out: str
    err: str
    elapsed: float
    timed_out: bool = False
    timeout: float = 0.0

    def new_paths(self) -> list[str]:
        return sorted(_listing(self.cwd) - self.before)

    def lines(self) -> list[str]:
        return [line for line in self.err.splitlines() if line.strip()]

    def show(self) -> str:
        tail = self.err[-3000:]
        return (f"\n$ workbench {' '.join(self.args)[:300]}\n(cwd {self.cwd}) exit {self.rc} after {self.elapsed:.1f} s"
                f"{' (TIMED OUT)' if self.timed_out else ''}\n--- stdout:\n{self.out[-1000:]}\n--- stderr:\n{tail}")


def _listing(d: Path) -> set:
    """Every file and folder below ``d`` (relative), without following into unreadable folders."""
    out = set()
    for root, dirs, files in os.walk(d):
        for n in dirs + files:
            out.add(str((Path(root) / n).relative_to(d)))
    return out


def _command(args, memcap):
    if not memcap:
        return [sys.executable, "-m", "workbench.cli", *args]
    code = ("import resource, runpy; resource.setrlimit(resource.RLIMIT_AS, (%d, %d)); "
            "runpy.run_module('workbench.cli', run_name='__main__', alter_sys=True)" % (MEMCAP, MEMCAP))
    return [sys.executable, "-c", code, *args]


def _execute(args, cwd: Path, timeout: float = 60.0, memcap: bool = False, before=None) -> Result:
    before = _listing(cwd) if before is None else before
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    t0 = time.perf_counter()
    try:
        p = subprocess.run(_command(args, memcap), cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
        rc, out, err, timed_out = p.returncode, p.stdout, p.stderr, False
    except subprocess.TimeoutExpired as e:
        dec = (lambda b: b.decode(errors="replace") if isinstance(b, bytes) else (b or ""))
        rc, out, err, timed_out = None, dec(e.stdout), dec(e.stderr), True
    return Result(list(args), cwd, before, rc, out, err, time.perf_counter() - t0, timed_out, timeout)


class _Runner:
    """Runs the command-line cases, starting the next one (in file order) while the current one is checked.

    Every case list is registered with :func:`_cases` in the order its test runs, so while a test checks its
    result the next subprocess already runs on the other core. Under pytest-xdist nothing is started ahead
    (the other worker may own the next case).
    """

    order: list = []  # (group, key) in file order

    def __init__(self, factory):
        self.factory = factory
        self.pool = ThreadPoolExecutor(max_workers=2)
        self.futures = {}
        self.ahead = 0 if os.environ.get("PYTEST_XDIST_WORKER") else 1

    def _submit(self, group: str, key: str):
        if (group, key) in self.futures:
            return
        spec = _GROUPS[group][key]
        d = self.factory.mktemp(re.sub(r"[^A-Za-z0-9]+", "_", f"{group}_{key}")[:40])
        if spec.setup is not None:
            spec.setup(d)
        args = [a.replace("{D}", str(d)) for a in spec.args]
        before = _listing(d)
        self.futures[group, key] = self.pool.submit(_execute, args, d, spec.timeout, spec.memcap, before)

    def __call__(self, group: str, key: str) -> Result:
        i = self.order.index((group, key))
        for g, k in self.order[i:i + 1 + self.ahead]:
            self._submit(g, k)
        return self.futures[group, key].result()

    def close(self):
        self.pool.shutdown(wait=True)


_GROUPS: dict = {}


def _cases(group: str, cases: dict) -> dict:
    """Register a parametrised list of command-line cases (in the order the tests run)."""
    _GROUPS[group] = cases
    _Runner.order.extend((group, key) for key in cases)
    return cases


@pytest.fixture(scope="module")
def cli(tmp_path_factory):
    runner = _Runner(tmp_path_factory)
    yield runner
    runner.close()


def _names(line: str, name: str) -> bool:
    if re.fullmatch(r"\w+", name):
        return re.search(rf"(?<![A-Za-z0-9_]){re.escape(name)}(?![A-Za-z0-9_])", line) is not None
    return name in line


def assert_refused(res: Result, *names: str, fast: bool = True, no_outputs: bool = True) -> str:
    """Exit 2, one line ``error: ...`` naming one of ``names``, no traceback, before any work."""
    assert not res.timed_out, f"still running after {res.timeout:.0f} s: must be refused before any work" + res.show()
    assert "Traceback" not in res.err, "a user's mistake must not end in a traceback" + res.show()
    assert res.rc == 2, f"exit code {res.rc}, expected 2 (bad input)" + res.show()
    lines = res.lines()
    assert len(lines) == 1, f"stderr has {len(lines)} lines, expected exactly one 'error: ...' line" + res.show()
    line = lines[0]
    assert line.startswith("error: "), res.show()
    assert len(line) <= MAX_LINE, f"error line of {len(line)} characters" + res.show()
    if names:
        assert any(_names(line, n) for n in names), f"the error line does not name {' or '.join(names)}" + res.show()
    if fast:
        assert res.elapsed < FAST, f"refused only after {res.elapsed:.1f} s: check before any work" + res.show()
    if no_outputs:
        assert not res.new_paths(), f"created {res.new_paths()} although the input was refused" + res.show()
    return line


def _files(**named):
    """A setup writing files: name -> text (str) or bytes; a name ending in '/' makes a folder."""
    def setup(d: Path):
        for name, content in named.items():
            p = d / name
            if name.endswith("/"):
                p.mkdir(parents=True)
                continue
            p.parent.mkdir(parents=True, exist_ok=True)
            (p.write_bytes if isinstance(content, bytes) else p.write_text)(content)
    return setup


def _mkdirs(*names):
    return _files(**{n.rstrip("/") + "/": None for n in names})


def _readonly(d: Path):
    """``readonly_dir`` that cannot be written into; as root (permissions do not stop writes) a regular file."""
    ro = d / "readonly_dir"
    ro.mkdir()
    os.chmod(ro, 0o555)
    if os.access(ro, os.W_OK):
        os.chmod(ro, 0o755)
        ro.rmdir()
        ro.write_text("a regular file where a folder is needed\n")


# ------------------------------------------------------------------------------------------------------
# item 9: inputs that end in a Python traceback today
# ------------------------------------------------------------------------------------------------------
OUT = ("-o", "out.nc")
STUDY = ("study", "tp1", "--k", "0.1", "0.05", "--h", "0.1", "--workers", "0", "--no-progress", "-o", "st.nc")
SLAB_TINY = ("--h", "0.1", "--T", "0.01", "--no-progress")
LONG_SUM = "+".join(["t"] * 30000)

ITEM9 = _cases("item9", {
    "toml-binary": Cli(("run", "bin.toml", *RUN_TINY, *OUT), ("bin.toml",),
                       _files(**{"bin.toml": bytes(range(256)) * 4})),
    "toml-is-a-directory": Cli(("run", "d.toml", *RUN_TINY, *OUT), ("d.toml",), _mkdirs("d.toml")),
    "toml-parameters=5": Cli(("run", "s.toml", *RUN_TINY, *OUT), ("parameters",),
                             _files(**{"s.toml": 'scene = "slab"\nparameters = 5\n'})),
    "toml-scene=[slab]": Cli(("run", "s.toml", *RUN_TINY, *OUT), ("scene",),
                             _files(**{"s.toml": 'scene = ["slab"]\n'})),
    "toml-traction=5": Cli(("run", "s.toml", *RUN_TINY, *OUT), ("traction",),
                           _files(**{"s.toml": 'scene = "slab"\ntraction = 5\n'})),
    "rod-delta=1/t": Cli(("run", "rod", *RUN_TINY, "--set", "delta=1/t", *OUT), ("delta",)),
    "rod-delta=1/0": Cli(("run", "rod", *RUN_TINY, "--set", "delta=1/0", *OUT), ("delta",)),
    "rod-delta=10**400": Cli(("run", "rod", *RUN_TINY, "--set", "delta=10**400", *OUT), ("delta",)),
    "rod-u0=1/x": Cli(("run", "rod", *RUN_TINY, "--set", "u0=1/x", *OUT), ("u0",)),
    "slab-traction=1/0": Cli(("run", "slab", *SLAB_TINY, "--set", "traction_top=(0, 1/0)", *OUT), ("traction_top",)),
    "literal-401-digits": Cli(("run", "slab", *SLAB_TINY, "--set", "traction_top=(0, " + "1" * 401 + ")", *OUT),
                              ("traction_top",)),
    "expression-30000-terms": Cli(("run", "slab", *SLAB_TINY, "--set", f"traction_top=(0, {LONG_SUM})", *OUT),
                                  ("traction_top",), memcap=True),
    "expression-5000-deep-minus": Cli(("run", "slab", *SLAB_TINY, "--set", "traction_top=(0, " + "-" * 5000 + "t)",
                                       *OUT), ("traction_top",), memcap=True),
    "expression-5000-deep-parentheses": Cli(("run", "slab", *SLAB_TINY, "--set",
                                             "traction_top=(0, " + "(" * 5000 + "t" + ")" * 5000 + ")", *OUT),
                                            ("traction_top",)),
    "expression-5000-power-tower": Cli(("run", "slab", *SLAB_TINY, "--set",
                                        "traction_top=(0, " + "**".join(["t"] * 5000) + ")", *OUT),
                                       ("traction_top",), memcap=True),
    "--k 1e-300": Cli(("run", "tp1", "--h", "0.1", "--k", "1e-300", "--no-progress", *OUT), ("k",),
                      timeout=FAST + 5, memcap=True),
    "--set T=1e9": Cli(("run", "tp1", "--h", "0.1", "--set", "T=1e9", "--no-progress", *OUT), ("T",),
                       timeout=FAST + 5, memcap=True),
    "--h 1e-4 (cannot fit in memory)": Cli(("run", "slab", "--h", "1e-4", "--T", "0.01", "--no-progress", *OUT),
                                           ("h",), timeout=FAST + 5, memcap=True),
    "E=1e200-explicit": Cli(("run", "slab", *SLAB_TINY, "--set", "E=1e200", *OUT), ("E", "k_crit")),
    "m_nu=1e10": Cli(("run", "tp1", *RUN_TINY, "--set", "m_nu=1e10", "--set", "L=10", *OUT), ("m_nu", "L", "k_crit")),
    "study --reference h=abc": Cli((*STUDY, "--reference", "h=abc"), ("reference",)),
    "study --compare 0": Cli((*STUDY, "--reference", "ode", "--compare", "0"), ("compare", "n_compare")),
    "study --compare -3": Cli((*STUDY, "--reference", "ode", "--compare", "-3"), ("compare", "n_compare")),
})


@pytest.mark.slow
@pytest.mark.parametrize("key", list(ITEM9))
def test_traceback_inputs_are_one_line_errors(cli, key):
    """Each of these inputs ends in a Python traceback (or a 10 kB echo) today. Expected: exit 2, one line
    ``error: ...`` naming the parameter, option or file, printed before any mesh, grid or case is built
    (fast, no output file created). Huge grids and meshes are estimated (steps, dofs, memory) and refused."""
    assert_refused(cli("item9", key), *ITEM9[key].names)


MATHTEXT = _cases("mathtext", {
    "run --plot": Cli(("run", "s.toml", *RUN_TINY, "--T", "0.2", "--plot", "p.png"), ("name",),
                      _files(**{"s.toml": 'scene = "tp1"\nname = "$x^$"\n'})),
})


@pytest.mark.slow
@pytest.mark.parametrize("key", list(MATHTEXT))
def test_scene_name_with_dollars_and_plot(cli, key):
    """A TOML ``name`` with ``$...$`` (not valid mathtext) and ``--plot``: today the run completes and then
    matplotlib's mathtext parser raises a traceback while saving. Expected: the name is shown literally and the
    plot is written (exit 0, no traceback), or it is refused before the run (exit 2, one line naming ``name``)."""
    res = cli("mathtext", key)
    assert "Traceback" not in res.err, res.show()
    if res.rc == 0:
        assert (res.cwd / "p.png").is_file() and (res.cwd / "p.png").stat().st_size > 1000, res.show()
    else:
        assert_refused(res, "name")


# ------------------------------------------------------------------------------------------------------
# item 10: output paths checked before the run
# ------------------------------------------------------------------------------------------------------
def _path_cases():
    base = ("run", "tp1", *RUN_TINY)
    return {
        "-o is a directory": Cli((*base, "-o", "out.nc", "--plot", "good.png"), ("out.nc",), _mkdirs("out.nc")),
        "-o parent is a file": Cli((*base, "-o", "a_file/out.nc", "--plot", "good.png"), ("a_file",),
                                   _files(a_file="x\n")),
        "-o in a read-only folder": Cli((*base, "-o", "readonly_dir/out.nc", "--plot", "good.png"), ("readonly_dir",),
                                        _readonly),
        "--plot is a directory": Cli((*base, "-o", "good.nc", "--plot", "out.png"), ("out.png",), _mkdirs("out.png")),
        "--plot parent is a file": Cli((*base, "-o", "good.nc", "--plot", "a_file/out.png"), ("a_file",),
                                       _files(a_file="x\n")),
        "--plot in a read-only folder": Cli((*base, "-o", "good.nc", "--plot", "readonly_dir/out.png"),
                                            ("readonly_dir",), _readonly),
        "--vtk is a regular file": Cli((*base, "-o", "good.nc", "--vtk", "vtkdir"), ("vtkdir",), _files(vtkdir="x\n")),
        "--vtk parent is a file": Cli((*base, "-o", "good.nc", "--vtk", "a_file/vtkdir"), ("a_file",),
                                      _files(a_file="x\n")),
        "--vtk in a read-only folder": Cli((*base, "-o", "good.nc", "--vtk", "readonly_dir/vtkdir"),
                                           ("readonly_dir",), _readonly),
    }


PATHS = _cases("paths", _path_cases())


@pytest.mark.slow
@pytest.mark.parametrize("key", list(PATHS))
def test_bad_output_path_refused_before_the_run(cli, key):
    """An ``-o``, ``--plot`` or ``--vtk`` target that cannot be written (an existing directory where a file is
    wanted or a file where a folder is wanted, a read-only folder, a parent that is a regular file) is found
    before any work: exit 2, one line naming the path, and no output at all, not even the valid one asked for
    in the same call. Today the run is done first and then lost in a traceback (or written despite
    the target, e.g. ``--plot`` onto a folder writes ``out.png.png``)."""
    assert_refused(cli("paths", key), *PATHS[key].names)


def test_disk_full_at_the_end_keeps_the_result(tmp_path, monkeypatch, capsys):
    """If writing ``-o`` still fails after the run (here: the disk is full), the computed result is not lost:
    it is kept in another file, the message says where (that file exists and loads as the run's result),
    the exit code is non-zero, there is no traceback, and no temporary file is left in the full folder."""
    from workbench import cli as cli_module

    full = tmp_path / "full"
    full.mkdir()
    target = full / "out.nc"
    real = xr.Dataset.to_netcdf

    def no_space(self, path=None, *args, **kwargs):
        if path is not None and Path(path).resolve().parent == full.resolve():
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(self, path, *args, **kwargs)

    monkeypatch.setattr(xr.Dataset, "to_netcdf", no_space)
    monkeypatch.chdir(tmp_path)
    try:
        code = cli_module.main(["run", "tp1", "--h", "0.5", "--k", "0.5", "--no-progress", "-o", str(target)])
    except SystemExit as e:
        code = e.code
    except Exception as e:  # noqa: BLE001
        pytest.fail(f"a full disk ends in a traceback: {type(e).__name__}: {e}")
    cap = capsys.readouterr()
    text = cap.out + "\n" + cap.err
    assert code not in (0, None), f"exit {code} although {target} was not written\n{text}"
    assert "Traceback" not in cap.err and "out.nc" in cap.err, text
    kept = []
    for token in re.findall(r"[^\s'\"`]+", text):
        token = token.rstrip(".,;:)]}").lstrip("([{")
        p = Path(token)
        if token and p.is_file() and p.resolve() != target.resolve():
            kept.append(p.resolve())
    assert kept, f"the message does not say where the result was kept\n{text}"
    try:
        ds = workbench.load(kept[0])
        assert ds.attrs["scene"] == "tp1" and "u_probe" in ds and ds.attrs["status"] == "complete"
    finally:
        for p in kept:
            if tmp_path not in p.parents:
                p.unlink(missing_ok=True)
    assert not list(full.iterdir()), f"left behind in the full folder: {list(full.iterdir())}"


@pytest.mark.parametrize("command", ["run", "checkpoints", "study"])
def test_an_output_folder_made_a_file_during_the_run_keeps_the_result(tmp_path, monkeypatch, capsys, command):
    """The folder of ``-o`` removed and a file made in its place while the run goes on: the checks that refuse such
    a path before a run (a ParameterError, exit 2) met it at the end and threw the result away. Now that is a failed
    write like a full disk's: the run is kept in the temporary folder (exit 4, the message says where), a checkpoint
    that cannot be written is a warning and the run goes on, and a study whose cases' folder went finishes without
    them."""
    import tempfile

    from workbench import cli as cli_module
    from workbench.output import results

    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)
    folder = tmp_path / "out"
    folder.mkdir()
    real, calls = results.write, []

    def write_then_break(ds, path):  # (the first write lands; the folder is then a file)
        calls.append(path)
        done = real(ds, path)
        if len(calls) == 1:
            broken = Path(path).parent
            shutil.rmtree(broken)
            broken.write_text("a file now")
        return done

    monkeypatch.setattr(results, "write", write_then_break)
    if command == "run":  # (the run itself breaks the folder: its -o is written once, at the end)
        from workbench.running import runner

        real_run = runner.run

        def run_then_break(*args, **kwargs):
            ds = real_run(*args, **kwargs)
            shutil.rmtree(folder)
            folder.write_text("a file now")
            return ds

        monkeypatch.setattr(runner, "run", run_then_break)
    argv = {"run": ["run", "tp1", *RUN_TINY, "-o", str(folder / "a.nc")],
            "checkpoints": ["run", "tp1", *RUN_TINY, "--set", "checkpoint_every=5", "-o", str(folder / "a.nc")],
            "study": ["study", "tp1", "--k", "0.1", "0.05", "--h", "0.1", "--reference", "ode", "--workers", "0",
                      "--no-progress", "-o", str(tmp_path / "s.nc")]}[command]
    if command == "study":
        folder = tmp_path / "s.nc.cases"
    code = cli_module.main(argv)  # (it shows warnings as "warning: ..." lines on stderr)
    err = capsys.readouterr()
    if command == "study":
        assert code == 0 and "its cases were not kept" in err.out, err
        assert f"warning: the case archive {folder}" in err.err and "the study goes on" in err.err, err
        assert workbench.load(tmp_path / "s.nc").sizes["k"] == 2
        return
    assert code == 4 and "Traceback" not in err.err, err
    kept = re.search(r"the result is kept in (\S+)$", err.err.strip()).group(1)
    ds = workbench.load(kept)
    assert ds.attrs["status"] == "complete" and ds.sizes["time"] == 21
    if command == "checkpoints":
        assert "could not be written at t = " in err.err and "the run goes on" in err.err, err


#: ``workbench`` (its console entry) that sends itself ``signal`` in the step after t = 0.1 s.
_SIGNALLED_AT = """
import os, signal, sys
from workbench.schemes import stepping
from workbench.cli import console

advance, SIGNAL = stepping._advance, int(sys.argv.pop(1))

def advance_then_signal(scheme, steps, t_prev, t):
    if t_prev >= 0.1:
        os.kill(os.getpid(), SIGNAL)
    return advance(scheme, steps, t_prev, t)

stepping._advance = advance_then_signal
sys.exit(console())
"""


@pytest.mark.parametrize("signum, code", [(2, 130), (15, 143), (1, 129), (24, 152), (10, 138)],
                         ids=["SIGINT", "SIGTERM", "SIGHUP", "SIGXCPU", "SIGUSR1"])
def test_a_run_stopped_by_a_signal_writes_the_steps_it_took(tmp_path, signum, code):
    """Ctrl-C (SIGINT) or SIGTERM (a batch scheduler's time limit) ended ``workbench run -o`` with nothing written:
    every step computed was lost. Now the steps recorded before are written as a diverged run's are (incomplete, the
    message in ``failure``), and the exit code is 128 + the signal's number. SIGHUP (the terminal closed), SIGXCPU (a
    CPU time limit) and SIGUSR1 (a scheduler's warning) still ended the process at once (an outside pass); now the
    same."""
    p = subprocess.run([sys.executable, "-c", _SIGNALLED_AT, str(signum), "run", "tp5", "--h", "0.1", "--k", "0.01",
                        "--T", "1", "--no-progress", "-o", "a.nc"], cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == code and "Traceback" not in p.stderr, p.stderr
    assert "interrupted" in p.stderr or "terminated" in p.stderr
    ds = workbench.load(tmp_path / "a.nc")
    assert ds.attrs["status"] == "incomplete" and ds.attrs["failure_type"] == "Interrupted"
    assert float(ds.time[-1]) == pytest.approx(0.1) and "its steps to t = 0.1 s are kept" in ds.attrs["failure"]


_SIGNALLED_AFTER_THE_LOOP = """
import os, sys
from workbench.running.threads import lean_process
lean_process()  # (first, as the command does: xarray then looks for dask as it does there)
from workbench.cli import console
from workbench.output import results
dataset, SIGNAL = results.Recorder.dataset, int(sys.argv.pop(1))

def signalled(self, attrs):
    os.kill(os.getpid(), SIGNAL)
    return dataset(self, attrs)

results.Recorder.dataset = signalled
sys.exit(console())
"""


@pytest.mark.parametrize("signum", [15, 1])
def test_a_signal_after_the_last_step_does_not_lose_the_run(tmp_path, signum):
    """A stop signal landing after the last step, while the records became a Dataset or the state to go on from was
    captured, lost the complete run: "error: interrupted", no archive (an outside pass, at 1 s of 3 s on a block).
    The loop is over then: the signal is dropped, and the archive written."""
    p = subprocess.run([sys.executable, "-c", _SIGNALLED_AFTER_THE_LOOP, str(signum), "run", "tp1", *RUN_TINY, "-o",
                        "a.nc"], cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == 0 and "Traceback" not in p.stderr and "interrupted" not in p.stderr, p.stderr
    assert workbench.load(tmp_path / "a.nc").attrs["status"] == "complete"


_SIGNALLED_ON_THE_WAY_BACK = """
import os, sys
from workbench.running.threads import lean_process
lean_process()
from workbench.cli import console
from workbench.running import runner
once, SIGNAL = runner._once, int(sys.argv.pop(1))

def signalled(*args):
    ds = once(*args)
    os.kill(os.getpid(), SIGNAL)  # (the run's hold on signals is over: the Dataset is on its way to the command)
    return ds

runner._once = signalled
sys.exit(console())
"""


@pytest.mark.parametrize("signum", [2, 15])
def test_a_signal_after_the_run_returned_does_not_lose_it(tmp_path, signum):
    """Between the end of the run's own hold on stop signals and the command's (the Dataset on its way back through
    the calls, 0.2 ms on tp4) a stop signal lost the complete run: "error: interrupted", no archive. The command now
    holds each finished run (``world.keep_finished``) and writes it, saying the signal came after the run, with the
    signal's exit code."""
    p = subprocess.run([sys.executable, "-c", _SIGNALLED_ON_THE_WAY_BACK, str(signum), "run", "tp1", *RUN_TINY, "-o",
                        "a.nc"], cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == 128 + signum and "Traceback" not in p.stderr, p.stderr
    assert "after the run had completed: its results are kept" in p.stderr, p.stderr
    assert "incomplete" not in p.stdout + p.stderr  # (it is written as the complete run it is, an outside pass)
    assert workbench.load(tmp_path / "a.nc").attrs["status"] == "complete"
    # (with checkpoints to -o: the complete run there, not beside it as a stopped one)
    p = subprocess.run([sys.executable, "-c", _SIGNALLED_ON_THE_WAY_BACK, str(signum), "run", "tp1", *RUN_TINY,
                        "--set", "checkpoint_every=3", "-o", "c.nc"], cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == 128 + signum and not (tmp_path / "c.stopped.nc").exists(), p.stderr
    assert workbench.load(tmp_path / "c.nc").attrs["status"] == "complete"


_SIGNALLED_AROUND = """
import importlib, os, sys
from workbench.running.threads import lean_process
lean_process()
spec, when, nth, signum = sys.argv[1:5]
del sys.argv[1:5]
module, _, name = spec.partition(":")
owner = importlib.import_module(module)
*path, attr = name.split(".")
for part in path:
    owner = getattr(owner, part)
original, calls = getattr(owner, attr), [0]

def wrapped(*args, **kwargs):
    calls[0] += 1
    if calls[0] == int(nth) and when == "before":
        os.kill(os.getpid(), int(signum))
    out = original(*args, **kwargs)
    if calls[0] == int(nth) and when == "after":
        os.kill(os.getpid(), int(signum))
    return out

setattr(owner, attr, wrapped)
from workbench.cli import console
sys.exit(console())
"""

FOLLOWING = ("run", "slab", "--h", "0.25", "--k", "0.05", "--T", "0.5", "--scheme", "implicit", "--set",
             "space_tol=0.2", "--no-progress")


def _signalled_at(tmp_path, where: str, when: str, nth: int, *args, signum: int = 15):
    return subprocess.run([sys.executable, "-c", _SIGNALLED_AROUND, where, when, str(nth), str(signum), *args],
                          cwd=tmp_path, capture_output=True, text=True)


@pytest.mark.parametrize("where, when, nth, mode, kept", [
    ("workbench.running.follow:_warned", "after", 1, "during", "whole"),  # (the meshes' records merged: run over)
    ("workbench.running.adapt:_with_levels", "after", 1, "repeat", "whole"),  # (the levels added: the run is over)
    ("workbench.running.adapt:_stop", "after", 8, "repeat", "whole"),  # (the loop said it was over)
    ("workbench.running.adapt:_stop", "after", 1, "repeat", "first level"),  # (the loop going on to a finer mesh)
    ("workbench.running.runner:_Run.set_up", "before", 2, "during", "records"),  # (a finer mesh set up: not over)
    ("workbench.running.follow:Follow.refine", "before", 1, "during", "records"),  # (the first pass judged)
    ("workbench.running.follow:Carried", "after", 1, "during", "records"),  # (the finer mesh's start made)
])
def test_a_stop_signal_at_an_adaptive_runs_end_keeps_its_whole_result_or_nothing(tmp_path, where, when, nth, mode,
                                                                                  kept):
    """The command kept the last run it saw finish, which for an adaptive run was one mesh's: a stop signal while the
    first finer mesh was set up wrote the first pass, which the run had just rejected (ndof 20 of 1734), as "the run
    had completed"; one while the meshes' records were merged wrote the last mesh's alone, without its mesh; one as
    the loop decided it was over lost every level (two outside passes). Only an adaptive run's merged result is kept
    now; once the loop is over, the signal is dropped. Stopped while a finer mesh is set up, the run keeps the
    records of the meshes before, to the time it went back to, as incomplete (it had lost them)."""
    p = _signalled_at(tmp_path, where, when, nth, *FOLLOWING, "--set", f"space_adapt={mode}", "-o", "a.nc")
    assert "Traceback" not in p.stderr, p.stderr
    ds = workbench.load(tmp_path / "a.nc")
    if kept == "records":  # (stopped during the run: its records so far, nothing said to be complete)
        assert p.returncode == 143 and "completed" not in p.stderr and "before a finer mesh's steps" in p.stderr
        assert ds.attrs["status"] == "incomplete" and ds.attrs["space_stop"] == "interrupted"
        assert float(ds.time[0]) == 0.0 and 0.0 < float(ds.time[-1]) <= 0.5 + 1e-12
        assert ds.refinement_ndof.values.size == 0 or ds.refinement_ndof.values[-1] == ds.attrs["ndof"]
        # (no state to go on from: a first pass's state at T, kept, was continued as a complete run that never
        # refined, an outside pass)
        again = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "--restart", "a.nc", "-o", "b.nc"],
                               cwd=tmp_path, capture_output=True, text=True)
        assert again.returncode == 2 and "no restart state" in again.stderr, again.stderr
        return
    assert ds.attrs["status"] == "complete" and float(ds.time[0]) == 0.0
    if kept == "first level":
        assert p.returncode == 143 and ds.attrs["space_stop"] == "interrupted" and ds.attrs["ndof"] == 20, p.stderr
        return
    assert p.returncode == 0, p.stderr
    assert ds.attrs["space_stop"] == "met" and "adapted_mesh" in ds and ds.attrs["ndof"] > 1000


def test_a_stop_signal_in_a_later_meshs_steps_keeps_every_meshs_records(tmp_path):
    """A run that follows its solution, stopped in the steps of a finer mesh, kept that mesh's records alone (one
    record, t = 0.15), where a diverged run's are merged across its meshes (an outside pass); now both are."""
    p = _signalled_at(tmp_path, "workbench.running.follow:Follow.consider", "after", 16, *FOLLOWING, "--set",
                      "space_adapt=during", "-o", "a.nc")
    assert p.returncode == 143 and "Traceback" not in p.stderr, p.stderr
    ds = workbench.load(tmp_path / "a.nc")
    assert ds.attrs["status"] == "incomplete" and float(ds.time[0]) == 0.0 and ds.sizes["time"] > 2
    assert len(set(ds.ndof.values.tolist())) > 1  # (records of more than one mesh)


_SIGNALLED_AS_IT_DIVERGES = """
import os, sys
from workbench.running.threads import lean_process
lean_process()
from workbench.errors import Diverged
from workbench.running import runner
execute = runner._Run.execute

def signalled(*args):
    try:
        return execute(*args)
    except Diverged:
        os.kill(os.getpid(), 15)  # (the run's hold is over: the diverged run unwinds to the command)
        raise

runner._Run.execute = signalled
from workbench.cli import console
sys.exit(console())
"""


@pytest.mark.parametrize("adaptive", [(), ("--set", "space_tol=0.2", "--set", "space_adapt=repeat")])
def test_a_stop_signal_as_a_diverged_run_unwinds_keeps_it(tmp_path, adaptive):
    """A diverged run unwinds through the run's calls to the command with its records; a stop signal on the way lost
    them, "error: terminated", no archive (two outside passes: a run on one mesh, then an adaptive one). The command
    and the adaptive loops keep the diverged run, and it is written as such (exit 3)."""
    p = subprocess.run([sys.executable, "-c", _SIGNALLED_AS_IT_DIVERGES, "run", "tp4", "--h", "0.25", "--k", "0.2",
                        "--T", "4", "--set", "allow_unstable=true", *adaptive, "--no-progress", "-o", "v.nc"],
                       cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == 3 and "Traceback" not in p.stderr and "beyond the bound" in p.stderr, p.stderr
    assert workbench.load(tmp_path / "v.nc").attrs["status"] == "incomplete"


def test_a_stop_signal_while_a_diverged_run_is_kept_does_not_lose_it(tmp_path):
    """A stop signal while the message of a diverged run was made ended the command, "error: terminated", nothing
    written (an outside pass): the signals are ignored from the run's end on, whatever its end."""
    p = _signalled_at(tmp_path, "workbench.cli:_one_line", "after", 3, "run", "tp4", "--h", "0.25", "--k", "0.2",
                      "--T", "4", "--set", "allow_unstable=true", "--no-progress", "-o", "v.nc")
    assert p.returncode == 3 and "Traceback" not in p.stderr, p.stderr
    assert workbench.load(tmp_path / "v.nc").attrs["status"] == "incomplete"


def test_a_second_command_in_the_same_process_does_not_write_the_first_run(tmp_path, monkeypatch):
    """The command's hold on a finished run was never emptied: a second ``cli.main`` in the same process (a notebook,
    a test), stopped in its setup, wrote the first command's run (tp1) into its own archive as complete (an outside
    pass)."""
    import signal

    from workbench import cli
    from workbench.running import runner

    monkeypatch.chdir(tmp_path)
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        assert cli.main(["run", "tp1", "--h", "0.1", "--k", "0.05", "-o", "first.nc", "--no-progress"]) == 0
        set_up = runner._Run.set_up

        def stopped(job, *args):
            raise KeyboardInterrupt

        monkeypatch.setattr(runner._Run, "set_up", stopped)
        assert cli.main(["run", "tp4", "--h", "0.25", "--k", "0.01", "--T", "0.1", "-o", "second.nc",
                         "--no-progress"]) == 130
        assert not (tmp_path / "second.nc").exists()
        monkeypatch.setattr(runner._Run, "set_up", set_up)
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)


def test_a_run_whose_messages_cannot_be_shown_still_writes_its_archive(tmp_path):
    """The status line was printed before the archive was written: a log on a full disk (or a reader of the pipe that
    left, a terminal gone, a locale that cannot encode the scene's name) lost the whole run to an OSError or a
    UnicodeEncodeError (an outside pass). Now the archive comes first, and a message that cannot be shown is dropped
    or escaped."""
    (tmp_path / "s.toml").write_text('scene = "tp1"\nname = "Prüfung β"\n', encoding="utf-8")
    with open("/dev/full", "w") as full:
        p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "tp1", *RUN_TINY, "-o", "a.nc"],
                           cwd=tmp_path, stdout=full, stderr=subprocess.PIPE, text=True)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert workbench.load(tmp_path / "a.nc").attrs["status"] == "complete"
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "s.toml", *RUN_TINY, "-o", "b.nc"], cwd=tmp_path,
                       capture_output=True, env=dict(os.environ, PYTHONIOENCODING="latin-1"))
    assert p.returncode == 0 and b"Traceback" not in p.stderr, p.stderr
    assert "Pr\\xfcfung \\u03b2" in p.stdout.decode("latin-1") or "Prüfung \\u03b2" in p.stdout.decode("latin-1")
    assert workbench.load(tmp_path / "b.nc").attrs["status"] == "complete"


def test_a_scene_file_with_a_byte_order_mark_and_a_cluster_without_dask(tmp_path, monkeypatch):
    """Found by an outside pass: a TOML file saved with a UTF-8 byte-order mark (Windows editors) was refused as an
    "invalid statement" at its first line, which looks valid in the editor; now read. A study given a scheduler
    address where dask.distributed is not installed ended in a ModuleNotFoundError traceback; now refused by name."""
    import importlib.util

    (tmp_path / "bom.toml").write_bytes(b"\xef\xbb\xbf" + b'scene = "tp1"\n[parameters]\nh = 0.1\n')
    assert workbench.scene(str(tmp_path / "bom.toml"))["h"] == 0.1
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "distributed" else
                        find_spec(name, *a))
    with pytest.raises(ParameterError, match=r"dask.distributed.*pip install 'workbench\[dask\]'"):
        workbench.Study("tp1", k=[0.1, 0.05], client="tcp://127.0.0.1:1")


def test_names_that_are_not_utf8_are_refused_before_the_run(tmp_path):
    """A folder or file named in another encoding (Latin-1 on an old system, a share, a zip file): the run was done,
    then nothing could be written, not even the copy in the temporary folder (netCDF takes UTF-8 only, and the scene
    file's path is an attribute); an expression with such a byte, a traceback; a good archive in such a folder,
    "cannot be read as an archive" (an outside pass). Each is now refused before any work, naming it."""
    folder = os.fsencode(tmp_path) + b"/Messung_D\xe4mpfer"
    os.mkdir(folder)
    examples = Path(__file__).resolve().parent.parent / "docs" / "examples"
    with open(folder + b"/slab.toml", "wb") as f:
        f.write((examples / "slab_pull.toml").read_bytes())
    workbench.write(workbench.run("tp1", h=0.1, k=0.05, T=0.1, progress=False), tmp_path / "a.nc")
    with open(folder + b"/a.nc", "wb") as f:
        f.write((tmp_path / "a.nc").read_bytes())
    cases = [(["run", os.fsdecode(folder + b"/slab.toml"), "-o", "out.nc"], tmp_path),
             (["run", "tp1", "-o", "out.nc"], folder),
             (["run", "--restart", "a.nc", "--T", "0.2", "-o", "b.nc"], folder),
             (["run", "tp1", "--set", os.fsdecode(b"traction_top=(0, t)\xff")], tmp_path)]
    for args, cwd in cases:
        p = subprocess.run([sys.executable, "-m", "workbench.cli", *args, "--no-progress"], cwd=cwd,
                           capture_output=True, text=True, errors="backslashreplace")
        assert p.returncode == 2 and "Traceback" not in p.stderr and "not UTF-8" in p.stderr, (args, p.stderr)
    assert not any(name.endswith(b".nc") and name != b"a.nc" for name in os.listdir(folder))


def test_a_run_short_of_memory_for_its_snapshots_keeps_its_records(tmp_path, monkeypatch):
    """Under a memory limit (``ulimit -v``, a scheduler's h_vmem) a run of 1000 snapshots did every step, then a
    MemoryError while its snapshots became arrays lost them all; one inside a checkpoint ended the run, where the docs
    say a failed checkpoint only warns (an outside pass). Now the checkpoint warns and the run goes on, and the final
    archive drops the snapshots, with a warning, and keeps every record."""
    from workbench.output import results

    def short_of_memory(self, coords, data, snaps=None):
        raise MemoryError

    monkeypatch.setattr(results.Recorder, "_snapshot_variables", short_of_memory)
    with pytest.warns(RuntimeWarning) as said:
        ds = workbench.run("tp1", h=0.1, k=0.05, T=0.5, snapshots=(0.1, 0.2), checkpoint_every=4,
                           checkpoint=tmp_path / "c.nc", progress=False)
    messages = [str(w.message) for w in said]
    assert any("could not be written at t = 0.2 s (out of memory); the run goes on" in m for m in messages), messages
    assert any("3 field snapshots" in m and "dropped" in m for m in messages), messages
    assert ds.attrs["status"] == "complete" and ds.sizes["time"] == 11 and "snapshot_time" not in ds.coords
    assert ds.attrs["snapshots_dropped"] == 3 and ds.attrs["snapshots_dropped_units"] == "1"  # (said in the archive)


def test_snapshots_that_will_not_fit_in_memory_are_warned_about_before_the_run(monkeypatch):
    """20,000 snapshots of a 3D block (about 64 GB) were taken without a word (an outside pass): the estimate of
    their memory, against the memory free, is now a warning before the run (here a machine of 1 MB free; the
    factorisation's own check refuses far above that)."""
    from workbench.running import preflight

    sc = workbench.scene("tp4", h=0.1, k=0.05, T=0.5, snapshots=tuple(np.arange(1, 10) * 0.05))
    est = preflight.estimate(sc.model_of().geometry, sc["order"])
    monkeypatch.setattr(preflight, "available_memory", lambda: 2 * est.bytes)
    with pytest.warns(RuntimeWarning, match=r"snapshots: the 10 field snapshots hold about .* GB until the archive"):
        workbench.run(sc, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        workbench.run(sc.with_(snapshots=()), progress=False)


def test_the_memory_free_counts_an_address_space_limit():
    """The memory checks before a run read the machine's MemAvailable alone: under ``ulimit -v`` (or a job's control
    group) a run was planned as if it had the whole machine (an outside pass)."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, resource.getrlimit(resource.RLIMIT_AS)[1]))

    p = subprocess.run([sys.executable, "-c", "from workbench.running.preflight import available_memory; "
                        "print(available_memory())"], capture_output=True, text=True, preexec_fn=limit)
    assert p.returncode == 0 and 0 < float(p.stdout) < 3 * 2**30, (p.stdout, p.stderr)


def test_the_memory_free_counts_a_jobs_control_group_less_its_file_cache(tmp_path):
    """A batch job's control group (cgroup v2, or v1) limits it below the machine's memory; its usage counts the
    file cache the kernel gives back on demand, which is free memory to a run (an outside pass: 7.5 of 7.9 GiB used
    were cache, and a run needing 0.4 GB was refused)."""
    from workbench.running.preflight import available_memory

    GiB = 2**30
    for version, line, folder, files in (
            ("v2", "0::/job", "job", {"memory.max": 8 * GiB, "memory.current": int(7.9 * GiB),
                                      "memory.stat": f"anon 1\ninactive_file {int(7.5 * GiB)}\n"}),
            ("v1", "4:memory:/job", "memory/job", {"memory.limit_in_bytes": 8 * GiB,
                                                   "memory.usage_in_bytes": int(7.9 * GiB),
                                                   "memory.stat": f"cache 2\ntotal_inactive_file {int(7.5 * GiB)}\n"})):
        root = tmp_path / version
        (root / folder).mkdir(parents=True)
        for name, value in files.items():
            (root / folder / name).write_text(f"{value}\n")
        (root / "cgroup").write_text(line + "\n")
        free = available_memory(str(root / "cgroup"), str(root))
        assert free == pytest.approx(min(7.6 * GiB, available_memory("/nonexistent")), rel=1e-9), version


def test_a_file_size_limit_is_named_when_the_archive_cannot_be_written(tmp_path):
    """Under ``ulimit -f`` the archive failed with netCDF's own words alone, "NetCDF: HDF error", as a full disk does
    (an outside pass): the limit is named now."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (40_000, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))

    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "tp4", "--no-progress", "-o", "f.nc"],
                       cwd=tmp_path, capture_output=True, text=True, preexec_fn=limit)
    assert p.returncode == 4 and "Traceback" not in p.stderr, p.stderr
    assert "files are limited to 0.04 MB here by ulimit -f" in p.stderr, p.stderr


def test_closed_streams_an_unencodable_study_a_looping_link_and_a_cache_under_home(tmp_path, monkeypatch):
    """Found by an outside pass on this stop's fixes: a run started with stdout closed wrote its archive, then ended
    in an AttributeError, exit 1 (the early exit flushed None); with stderr closed the progress bar's check failed
    before the first step, nothing written; ``study`` and ``show`` under an ASCII encoding with a scene named in Greek
    ended in a traceback, the study's figure lost; ``-o`` naming a link that loops, a RuntimeError traceback;
    WORKBENCH_CACHE = "~/x" made a folder named "~"."""
    run = [sys.executable, "-m", "workbench.cli", "run", "tp1", *RUN_TINY]
    for closed, name in ((1, "a.nc"), (2, "b.nc")):
        p = subprocess.run(run + ["-o", name], cwd=tmp_path, stdout=None if closed == 2 else subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL if closed == 1 else None,
                           preexec_fn=lambda fd=closed: os.close(fd))
        assert p.returncode == 0 and workbench.load(tmp_path / name).attrs["status"] == "complete", closed
    (tmp_path / "g.toml").write_text('scene = "tp1"\nname = "πλάκα"\n', encoding="utf-8")
    ascii_env = dict(os.environ, PYTHONIOENCODING="ascii")
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "study", "g.toml", "--k", "0.1", "0.05", "--h", "0.1",
                        "--reference", "exact", "--workers", "0", "--no-progress", "-o", "s.nc", "--plot", "s.png"],
                       cwd=tmp_path, capture_output=True, env=ascii_env)
    assert p.returncode == 0 and b"Traceback" not in p.stderr and (tmp_path / "s.png").exists(), p.stderr
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "show", "g.toml"], cwd=tmp_path, capture_output=True,
                       env=ascii_env)
    assert p.returncode == 0 and b"\\u03c0" in p.stdout, p.stderr
    (tmp_path / "loop.nc").symlink_to("loop.nc")
    p = subprocess.run(run + ["-o", "loop.nc"], cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == 2 and "loops" in p.stderr and "Traceback" not in p.stderr, p.stderr
    from workbench.input import meshes

    monkeypatch.setenv("WORKBENCH_CACHE", "~/cache_of_workbench")
    assert meshes.cache_folder() == Path.home() / "cache_of_workbench" / "meshes"


def test_a_ctrl_c_while_the_command_loads_ends_it_without_a_traceback(monkeypatch, capsys):
    """A Ctrl-C in the first tenth of a second of a command, while its modules load and before it listened for the
    signal, ended in a KeyboardInterrupt traceback. Now: "error: interrupted", exit 130, as later in the command."""
    from workbench import cli
    from workbench.running import threads

    def loading():
        raise KeyboardInterrupt

    monkeypatch.setattr(threads, "lean_process", loading)
    monkeypatch.setattr(sys, "argv", ["workbench", "run", "tp1"])
    assert cli.console() == 130
    assert capsys.readouterr().err.strip() == "error: interrupted"


def test_an_interrupted_run_in_python_carries_what_it_computed(monkeypatch):
    """In a notebook, the kernel's interrupt (KeyboardInterrupt) inside a step: ``workbench.Interrupted``, still a
    KeyboardInterrupt, whose ``dataset`` holds the steps before."""
    from workbench.schemes import stepping

    advance = stepping._advance

    def interrupted(scheme, steps, t_prev, t):
        if t_prev >= 0.05:
            raise KeyboardInterrupt
        return advance(scheme, steps, t_prev, t)

    monkeypatch.setattr(stepping, "_advance", interrupted)
    with pytest.raises(KeyboardInterrupt) as err:
        workbench.run("tp1", h=0.1, k=0.01, T=0.2, progress=False)
    assert isinstance(err.value, workbench.errors.Interrupted)
    ds = err.value.dataset
    assert ds.attrs["status"] == "incomplete" and float(ds.time[-1]) == pytest.approx(0.05)


#: A command line whose figure and VTK writes fail with a full disk (the archive, if any, is written).
_FULL_AT_THE_END = """
import errno, sys
import matplotlib.figure
from workbench.output import vtk
from workbench.cli import main

def no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")

matplotlib.figure.Figure.savefig = no_space
vtk._write_vtu = no_space
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("archive", [True, False], ids=["with -o", "without -o"])
def test_plot_and_vtk_failing_at_the_end_exit_4_and_say_where_the_result_is(tmp_path, archive):
    """``--plot`` / ``--vtk`` that cannot be written after the run (disk full) ended in a traceback (exit 1): exit 4
    (as for ``-o``), one ``error:`` line per failed output naming it and where the result is kept (the archive, or a
    copy in the temporary folder without ``-o``), which loads as the run."""
    out = ["-o", "a.nc"] if archive else []
    p = subprocess.run([sys.executable, "-c", _FULL_AT_THE_END, "run", "tp1", *RUN_TINY, *out, "--plot", "a.png",
                        "--vtk", "vtk"], cwd=tmp_path, capture_output=True, text=True,
                       env=dict(os.environ, TMPDIR=str(tmp_path)))
    lines = [line for line in p.stderr.splitlines() if line.strip()]
    assert p.returncode == 4 and "Traceback" not in p.stderr, p.stderr
    assert len(lines) == 2 and lines[0].startswith("error: --plot a.png could not be written"), p.stderr
    assert lines[1].startswith("error: --vtk vtk could not be written"), p.stderr
    kept = {re.search(r"the results are kept in (\S+)$", line).group(1) for line in lines}
    assert len(kept) == 1
    kept = Path(tmp_path, kept.pop())
    assert kept == tmp_path / "a.nc" if archive else kept.parent == tmp_path
    assert workbench.load(kept).attrs["status"] == "complete"


@pytest.mark.slow
def test_reproduce_of_a_diverging_run_exits_3(tmp_path):
    """A run of ``workbench reproduce`` that diverges (tp1 pulled beyond 10 x its length) ended in a traceback: exit 3
    as ``workbench run``, one ``error:`` line, and the computed part kept (marked incomplete)."""
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "reproduce", "tp1", "--no-side", "--out", "r",
                        "--set", "delta=-0.6 - 100*t"], cwd=tmp_path, capture_output=True, text=True)
    lines = [line for line in p.stderr.splitlines() if line.strip()]
    assert p.returncode == 3 and "Traceback" not in p.stderr, p.stderr
    assert len(lines) == 1 and lines[0].startswith("error: tp1: a displacement of"), p.stderr
    ds = workbench.load(tmp_path / "r" / "tp1_diverged.nc")
    assert ds.attrs["status"] == "incomplete" and ds.sizes["time"] > 1


@pytest.mark.parametrize("scene, values, name, steps", [
    # a division by zero at a grid time (Python's floats raised ZeroDivisionError there: a traceback, nothing kept)
    ("rod", dict(h=0.1, k=0.05, delta="0.01/(t-0.55)+0.01/0.55"), "delta = ", 11),
    ("tp4", dict(h=0.1, k=0.01, point_force="(0, 0.01/(t-0.55)+0.01/0.55)"), "point_force = ", 55),
    # NaN between the vertices only (at the traction's quadrature points): the implicit step's Newton met a NaN
    # residual and said "try a smaller k"
    ("tp4", dict(h=0.1, scheme="implicit", traction_top="(0, sqrt(abs(x-0.25)-0.04))"), "traction_top = ", 1),
])
def test_a_load_that_is_not_finite_at_a_step_stops_the_run_naming_it(scene, values, name, steps):
    """The run stops as a diverged one (the steps before kept, marked incomplete) and the message leads with the
    expression that is not finite at that time, not with the step size."""
    with pytest.raises(workbench.Diverged) as err:
        workbench.run(scene, progress=False, **values)
    lead, _, after = str(err.value).partition(": no step can meet it")
    assert name in lead and "is not finite at t = " in lead and after, err.value
    ds = err.value.dataset
    assert ds.attrs["status"] == "incomplete" and ds.sizes["time"] == steps and name in ds.attrs["failure"]


# ------------------------------------------------------------------------------------------------------
# item 11: damaged study cases and stale temporary files
# ------------------------------------------------------------------------------------------------------
STUDY11 = ("study", "tp1", "--k", "0.1", "0.05", "--h", "0.1", "--reference", "ode", "--workers", "0",
           "--no-progress", "-o", "st.nc")


@pytest.fixture(scope="module")
def study_archive(tmp_path_factory):
    d = tmp_path_factory.mktemp("study11")
    res = _execute(STUDY11, d)
    assert res.rc == 0, res.show()
    return d


@pytest.mark.slow
@pytest.mark.parametrize("damage", ["empty", "truncated"])
def test_damaged_case_file_is_recomputed(study_archive, tmp_path, damage):
    """A study rerun whose case folder holds an empty or truncated case file (a killed or full-disk write)
    crashes today with an ``OSError`` traceback. Expected: the damaged case is detected, recomputed and rewritten
    (the others are left untouched), a warning on stderr names the file, a stale hidden ``.NAME.*.tmp`` of that
    case is removed by the rewrite, the run exits 0, and the study result equals the undamaged one."""
    work = tmp_path / "w"
    shutil.copytree(study_archive, work)
    cases = sorted((work / "st.nc.cases").glob("*.nc"))
    assert len(cases) == 2
    bad, good = cases
    data = bad.read_bytes()
    bad.write_bytes(b"" if damage == "empty" else data[: len(data) // 2])
    stale = bad.parent / f".{bad.name}.k1ll3d_q.tmp"  # as left by a kill today
    stale.write_bytes(data[:100])
    old = time.time() - 3600
    os.utime(stale, (old, old))
    good_bytes, good_mtime = good.read_bytes(), good.stat().st_mtime_ns
    original = workbench.load(study_archive / "st.nc")

    res = _execute(STUDY11, work)
    assert "Traceback" not in res.err, res.show()
    assert res.rc == 0, res.show()
    assert bad.name in res.err, "the warning must name the damaged case file" + res.show()
    workbench.load(bad)  # rewritten, readable
    assert good.read_bytes() == good_bytes and good.stat().st_mtime_ns == good_mtime, "an intact case was rewritten"
    assert not stale.exists(), "the stale temporary file of the rewritten case was not removed"
    again = workbench.load(work / "st.nc")
    for name in ("error", "error_V", "error_Q", "error_beta"):
        np.testing.assert_allclose(again[name].values, original[name].values, rtol=1e-12, equal_nan=True)


def test_next_write_removes_stale_tmp_files_of_the_same_target(tmp_path):
    """A kill during :func:`workbench.write` leaves ``.X.nc.<random>.tmp`` behind; today nothing ever removes
    it. Expected: the next ``write`` of ``X.nc`` removes the stale temporaries of ``X.nc`` (older than the write:
    today's ``.X.nc.<8 random>.tmp`` and a ``.X.nc.<pid>.<hex>.tmp`` of a process that is gone), and only those:
    a temporary still being written (newer than the write, its process alive), temporaries of other targets
    (``Y.nc``, ``X.nc2``) and other files are kept."""
    ds = workbench.run("tp1", h=0.5, k=0.5, progress=False)
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    old, future = time.time() - 3600, time.time() + 600
    stale = [tmp_path / ".X.nc.abc123xy.tmp", tmp_path / f".X.nc.{gone.pid}.0badc0de.tmp"]
    keep = [tmp_path / ".Y.nc.abc123xy.tmp", tmp_path / ".X.nc2.abc123xy.tmp", tmp_path / "X.nc.notes.txt"]
    busy = tmp_path / f".X.nc.{os.getppid()}.feedbeef.tmp"  # another live writer, still at work
    for p in stale + keep + [busy]:
        p.write_bytes(b"partial")
        os.utime(p, (future, future) if p == busy else (old, old))
    workbench.write(ds, tmp_path / "X.nc")
    assert [p.name for p in stale if p.exists()] == [], "stale temporaries of X.nc are left behind"
    assert all(p.exists() for p in keep + [busy]), "files that are not stale temporaries of X.nc were removed"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["X.nc", busy.name] + [p.name for p in keep])


# ------------------------------------------------------------------------------------------------------
# item 13: silently accepted today; each must be refused (or honoured and said)
# ------------------------------------------------------------------------------------------------------
STUDY_TP2 = ("study", "tp2", "--k", "0.1", "0.05", "--h", "0.1", "--reference", "ode", "--workers", "0",
             "--no-progress", "-o", "st.nc")
ITEM13 = _cases("item13", {
    "study --h 0.1 --set h": Cli((*STUDY_TP2, "--set", "h=0.05"), ("h",)),
    "study --k .. --set k": Cli((*STUDY_TP2, "--set", "k=0.01"), ("k",)),
    "study --order 1 --set order": Cli((*STUDY_TP2, "--order", "1", "--set", "order=2"), ("order",)),
    "study --scheme explicit --set scheme": Cli((*STUDY_TP2, "--scheme", "explicit", "--set", "scheme=implicit"),
                                                  ("scheme",)),
    "duplicate --set E": Cli(("run", "slab", *SLAB_TINY, "--set", "E=1000", "--set", "E=2000", *OUT), ("E",)),
    "--set k beside --k": Cli(("run", "tp1", *RUN_TINY, "--set", "k=0.1", *OUT), ("k",)),
    "--threads 0": Cli(("run", "tp1", *RUN_TINY, "--threads", "0", *OUT), ("threads",)),
    "--threads -2": Cli(("run", "tp1", *RUN_TINY, "--threads", "-2", *OUT), ("threads",)),
    "--workers -1": Cli(("study", "tp1", "--k", "0.1", "0.05", "--h", "0.1", "--reference", "ode", "--workers", "-1",
                         "--no-progress", "-o", "st.nc"), ("workers",)),
})


@pytest.mark.slow
@pytest.mark.parametrize("key", list(ITEM13))
def test_silently_dropped_options_are_refused(cli, key):
    """Today these run and exit 0 while part of the input is dropped (a study's ``--set h/k/order/scheme`` beside
    the sweep over the same name, the first of two ``--set`` of one name, ``--set k=`` beside ``--k``) or is
    meaningless (``--threads 0`` or negative, ``--workers -1``). Expected: exit 2 before any work, one line naming
    the parameter or option."""
    assert_refused(cli("item13", key), *ITEM13[key].names)


STUDY_SET = _cases("studyset", {
    "h": Cli(("study", "tp2", "--k", "0.1", "0.05", "--reference", "ode", "--workers", "0", "--no-progress",
              "--set", "h=0.1", "-o", "st.nc"), ("h",)),
    "scheme": Cli(("study", "tp2", "--k", "0.1", "0.05", "--h", "0.1", "--reference", "ode", "--workers", "0",
                   "--no-progress", "--set", "scheme=implicit", "-o", "st.nc"), ("scheme",)),
})


@pytest.mark.parametrize("key, value", [("h", 0.1), ("scheme", "implicit")])
def test_study_set_of_a_discretisation_name_is_honoured_or_refused(cli, key, value):
    """``workbench study tp2 --set h=0.1`` (no ``--h`` sweep) drops the value today: the cases run with the
    scene's h = 0.01. Expected: honoured (every case uses it: the study's ``h``/``scheme`` coordinate is exactly
    that value) or refused (exit 2 before any work, one line naming it)."""
    res = cli("studyset", key)
    assert "Traceback" not in res.err, res.show()
    if res.rc == 2:
        assert_refused(res, key)
        return
    assert res.rc == 0, res.show()
    got = workbench.load(res.cwd / "st.nc")[key].values.tolist()
    assert got == [value], f"--set {key}={value} was dropped: the study ran {key} = {got}" + res.show()


ONE_CASE = _cases("onecase", {
    "one-case study": Cli(("study", "slab", "--k", "0.1", "--h", "0.1", "--workers", "0", "--no-progress", "-o",
                           "st.nc")),
    "one-case rod study": Cli(("study", "tp1", "--k", "0.1", "--h", "0.1", "--workers", "0", "--no-progress", "-o",
                               "st.nc"))})


def test_one_case_study_is_not_a_success(cli):
    """A study of one case of a scene without an exact reference (the slab) has nothing to compare it with: it once
    exited 0 and wrote a result whose every error is NaN. Expected: a non-zero exit (2, found before the run) with
    one clear ``error: ...`` line about the cases or the reference (and no warning about a biased reference before
    it), no traceback and no study archive with NaN errors."""
    res = cli("onecase", "one-case study")
    assert "Traceback" not in res.err, res.show()
    assert res.rc not in (0, None), "a study with nothing to compare must not succeed" + res.show()
    lines = res.lines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.show()
    assert "case" in lines[0] or "reference" in lines[0], res.show()
    assert not (res.cwd / "st.nc").exists(), "a study archive of NaN errors was written" + res.show()


def test_one_case_of_a_rod_is_measured_against_its_exact_solution(cli):
    """The rod has an exact (ODE) reference, the default's first choice: one case is a measurement, not a mistake;
    its errors are finite and the archive says which reference it used."""
    res = cli("onecase", "one-case rod study")
    assert res.rc == 0 and "Traceback" not in res.err, res.show()
    ds = workbench.load(res.cwd / "st.nc")
    assert "rod_reference" in ds.attrs["reference"], ds.attrs["reference"]
    assert np.isfinite(ds.error.values).all() and 0 < float(ds.error.max()) < 0.1, ds.error.values


SHADOW = _cases("shadow", {"./tp1 file": Cli(("run", "tp1", *RUN_TINY, "-o", "out.nc"), (), _files(
    tp1='scene = "tp2"\ndescription = "a file that happens to be called tp1"\n'))})


@pytest.mark.slow
def test_file_named_like_a_builtin_scene_is_not_silent(cli):
    """A file ``./tp1`` in the working directory silently replaces the built-in ``tp1`` today, while the archive
    records ``scene = "tp1"``. Expected, either: refused as ambiguous (exit 2, one line naming ``tp1``), or run with
    one of the two and said so on the terminal (a message naming ``tp1`` and the file), and the archive honest:
    if the file was used, its ``scene`` attribute is not the bare built-in name ``tp1`` or an attribute records
    the file's path."""
    res = cli("shadow", "./tp1 file")
    assert "Traceback" not in res.err, res.show()
    if res.rc == 2:
        assert_refused(res, "tp1")
        return
    assert res.rc == 0, res.show()
    text = (res.out + "\n" + res.err).lower()
    assert re.search(r"\bfile\b", text) and "tp1" in text, \
        "the choice between ./tp1 and the built-in tp1 is not said" + res.show()
    ds = workbench.load(res.cwd / "out.nc")
    used_file = ds.attrs["base_scene"] == "tp2"
    if used_file:
        path = str((res.cwd / "tp1").resolve())
        recorded = [k for k, v in ds.attrs.items() if isinstance(v, str) and (path in v or "./tp1" in v)]
        assert ds.attrs["scene"] != "tp1" or recorded, \
            f"the archive says scene = 'tp1' (the built-in) but the file {path} was used" + res.show()
    else:
        assert ds.attrs["base_scene"] == "tp1", res.show()


@pytest.mark.parametrize("name, value, bad", [
    ("u0", "y", "y"),
    ("u0", "0*z", "z"),
    ("u0", "x*y", "y"),
    ("delta", "y", "y"),
])
def test_rod_expressions_refuse_y_and_z(name, value, bad):
    """A rod is 1D: ``y`` and ``z`` in its expressions are a mistake. Today ``u0`` accepts them (evaluated as 0).
    Expected: ParameterError naming the parameter and the variable."""
    with pytest.raises(ParameterError) as err:
        workbench.run("rod", h=0.5, k=0.5, progress=False, **{name: value})
    msg = str(err.value)
    assert name in msg and f"'{bad}'" in msg, msg
    # (the variables said to be allowed are the parameter's own: u0 is a field in space, which listed t too, where
    # u0 = 't' is refused; an outside pass, December 2026)
    assert msg.endswith("(allowed: x)" if name == "u0" else "(allowed variables: t, constant: pi)"), msg


@pytest.mark.parametrize("scene, extra", [
    ("memory_slab", dict(h=0.5, k=0.25)),
    ("memory_rod", dict(h=0.25, k=0.25)),
])
def test_kernel_without_kernel_E_is_refused(scene, extra):
    """A relaxation ``kernel`` with ``kernel_E = 0`` (the default) has no effect: today the memory term is
    silently dropped. Expected: ParameterError naming ``kernel_E``."""
    with pytest.raises(ParameterError, match="kernel_E"):
        workbench.run(scene, prony=(), kernel="exp(-t)", progress=False, **extra)


def _claimed_snapshots(ds):
    claimed = []
    for text in (ds.attrs.get("snapshots", "[]"), json.dumps(json.loads(ds.attrs["parameters_json"]).get("snapshots"))):
        value = json.loads(text) if isinstance(text, str) else text
        claimed += [float(v) for v in np.atleast_1d(value or [])]
    return claimed


@pytest.mark.parametrize("scene, overrides, wanted", [
    ("tp1", dict(h=0.1, k=0.1, snapshots=(0.123,)), 0.123),
    ("memory_slab", dict(h=0.5), 0.25),  # the preset's own 0.25 with its k = 0.02
])
def test_off_grid_snapshot_is_refused_or_honest(scene, overrides, wanted):
    """A snapshot time off the time grid is moved to the nearest grid time today (0.123 -> 0.1; memory_slab's
    0.25 -> 0.24) while the archive still says 0.123. Expected: refused (ParameterError naming ``snapshots``), or
    honoured (a snapshot at exactly that time), or the archive records the true time (its ``snapshots`` no longer
    claims the requested time) or says the time was moved/interpolated. Never a moved time that the archive
    still claims silently."""
    try:
        ds = workbench.run(scene, progress=False, **overrides)
    except ParameterError as err:
        assert "snapshots" in str(err), str(err)
        return
    times = ds.snapshot_time.values
    if np.any(np.abs(times - wanted) < 1e-12):
        return
    claimed = _claimed_snapshots(ds)
    if not any(abs(t - wanted) < 1e-12 for t in claimed):
        return
    texts = [str(v).lower() for v in list(ds.attrs.values()) + list(ds.snapshot_time.attrs.values())]
    said = any(str(wanted) in t and any(w in t for w in ("moved", "nearest", "interpolat", "shifted")) for t in texts)
    assert said, (f"snapshot asked at t = {wanted}, stored at {times.tolist()}, and the archive still claims "
                  f"{claimed} without saying that the time was moved")


@pytest.mark.parametrize("k", [0.1, 0.01])
def test_requested_times_on_the_grid_are_kept_exactly(k):
    """0.3 is on the grid of k = 0.1 only to round-off (3 * 0.1 != 0.3; linspace gives 0.30000000000000004): a snapshot
    or record asked at 0.3 is there, at exactly 0.3 (``ds.sel(time=0.3)`` works), for k = 0.1 and 0.01."""
    wanted = [0.1, 0.3, 0.7]
    ds = workbench.run("tp1", k=k, h=0.1, snapshots=wanted, record_times=wanted, progress=False)
    assert ds.time.values.tolist() == [0.0] + wanted + [1.0]
    assert ds.snapshot_time.values.tolist() == wanted + [1.0]
    assert float(ds.u_probe.sel(time=0.3).isel(probe=0, component=0)) != 0.0


def test_requested_times_off_a_given_grid_are_refused():
    """With a user grid (``times=``) a snapshot or record time off it was dropped silently, and a grid that ends before
    T lost the final snapshot (an AttributeError): both are ParameterErrors naming ``times`` before any work, as is a
    record time after T."""
    grid = [0.0, 0.1, 0.3, 0.7, 1.0]
    with pytest.raises(ParameterError, match=r"times: the snapshot or record time 0\.5 is not on the given grid"):
        workbench.run("tp1", times=grid, snapshots=(0.5,), progress=False)
    with pytest.raises(ParameterError, match=r"times: the snapshot or record time 0\.5"):
        workbench.run("tp1", times=grid, snapshots=(), record_times=[0.5], progress=False)
    with pytest.raises(ParameterError, match="times: the grid ends at 0.7, not at T = 1"):
        workbench.run("tp1", times=grid[:-1], snapshots=(), progress=False)
    with pytest.raises(ParameterError, match=r"times: a step of 1e-14 s is below the times told apart"):
        workbench.run("tp1", times=[0.0, 1e-14, 0.5, 1.0], snapshots=(), progress=False)
    # the scene's own snapshots, which the user never set, are named as such, with the way to take none
    with pytest.raises(ParameterError, match=r"time 0\.2 is not on .*\(snapshots = \[0\.2, .*\], the scene's; "
                                             r"snapshots=\(\) takes none\)$"):
        workbench.run("tp2", scheme="implicit", times=[0.0, 0.5, 1.0], progress=False)
    with pytest.raises(ParameterError, match="record time 1.5 is outside the run"):
        workbench.run("tp1", k=0.1, record_times=[0.5, 1.5], progress=False)
    ds = workbench.run("tp1", h=0.1, times=np.arange(0.0, 1.05, 0.1), snapshots=(0.3, 0.7), record_times=[0.3],
                       progress=False)
    assert ds.time.values.tolist() == [0.0, 0.3, 1.0] and ds.snapshot_time.values.tolist() == [0.3, 0.7, 1.0]


def test_toml_traction_table_conflicts_with_parameters(tmp_path):
    """A TOML file setting ``traction_top`` in ``[parameters]`` and ``top`` in ``[traction]``: today the
    ``[traction]`` value silently wins. Expected: ParameterError naming ``traction_top``."""
    f = tmp_path / "both.toml"
    f.write_text('scene = "slab"\n[parameters]\ntraction_top = "(0, 1)"\n[traction]\ntop = "(0, 2)"\n')
    with pytest.raises(ParameterError, match="traction_top"):
        workbench.scene(f)


def test_model_given_to_a_scene_file_says_the_file_names_it(tmp_path):
    """``model=`` with a scene file (a body from a mesh file among them) said it "applies to a body from a mesh",
    which the file's body was: the file names its model itself."""
    f = tmp_path / "s.toml"
    f.write_text('scene = "tp1"\n')
    with pytest.raises(ParameterError, match=r"^model = 'B': a scene file names its model in the file"):
        workbench.scene(f, model="B")
    with pytest.raises(ParameterError, match=r"^model = 'B' applies to a body from a mesh \(mesh=...\); a built-in"):
        workbench.scene("tp1", model="B")


def test_the_step_count_bounds_fixed_steps_only():
    """T / k beyond 10^7 steps is refused for fixed steps; under error control k is the first step alone (a run of
    rtol = 1e-4 from k = 1e-8 takes a few dozen steps) and was refused all the same."""
    with pytest.raises(ParameterError, match=r"k = 1e-08 and T = 1 make 1e\+08 time steps; at most 1e\+07"):
        workbench.scene("tp2", scheme="bdf2", k=1e-8)
    assert workbench.scene("tp2", scheme="bdf2", rtol=1e-4, k=1e-8)["k"] == 1e-8


@pytest.mark.parametrize("name", ['""', '"   "'])
def test_toml_empty_name_is_refused(tmp_path, name):
    """``name = ""`` made the status line ": complete" and an archive named by nothing: refused, naming the file's
    own name as what leaving it out gives."""
    f = tmp_path / "run.toml"
    f.write_text(f'scene = "tp1"\nname = {name}\n')
    with pytest.raises(ParameterError, match=r"^run.toml: name = '\s*': give a name, or leave it out \(the file's: 'run'\)"):
        workbench.scene(f)


@pytest.mark.parametrize("name", ["k", "h"])
def test_study_scalar_string_is_not_read_character_by_character(name):
    """``Study("tp1", k="0.1")`` iterates over the characters of "0.1" today and fails with a bare
    ``ValueError`` about '.'. Expected: ParameterError naming the parameter (a sequence of numbers is needed)."""
    from workbench.study import Study

    with pytest.raises(ParameterError) as err:
        Study("tp1", workers=0, **{name: "0.1"})
    assert re.search(rf"(?<![A-Za-z0-9_]){name}(?![A-Za-z0-9_])", str(err.value)), str(err.value)


@pytest.mark.parametrize("scene, wrong, right", [("slab", "e", "E"), ("slab", "NU", "nu")])
def test_unknown_parameter_hint_ignores_case(scene, wrong, right):
    """``e=1`` gets no hint today (the match is case-sensitive). Expected: "did you mean 'E'?"."""
    with pytest.raises(ParameterError) as err:
        workbench.scene(scene, **{wrong: 1})
    assert f"did you mean {right!r}" in str(err.value), str(err.value)


def test_misspelt_run_option_is_offered_the_option():
    """``workbench.run("tp1", progres=False)`` is offered the scene parameter 'probes' today. Expected: a
    ParameterError that suggests the run option 'progress'."""
    with pytest.raises(ParameterError) as err:
        workbench.run("tp1", h=0.5, k=0.5, progres=False)
    msg = str(err.value)
    assert "progres" in msg and "'progress'" in msg and "'probes'" not in msg, msg


def test_points_given_as_a_numpy_array_are_points():
    """probes=np.array([[0.5, 0.05]]) was refused ("expected a list of coordinate tuples") where a NumPy
    elastic_tensor is taken: an array of points is read as its rows."""
    assert workbench.scene("slab", probes=np.array([[0.5, 0.05], [1.0, 0.1]]))["probes"] == ((0.5, 0.05), (1.0, 0.1))
    assert workbench.scene("tp1", probes=np.array([[0.5]]))["probes"] == ((0.5,),)


@pytest.mark.parametrize("value", ["none", "None", None, ""])
def test_an_empty_list_typed_as_the_table_shows_it_is_taken(value):
    """The parameter table shows prony's empty default as "none"; typed back (``--set prony=none``, ``prony=None``)
    it was refused with a message about points ("give points as '(x, y); (x, y)'"). It is the empty list now, for
    every list-valued parameter; a list that cannot be read says tuples."""
    assert workbench.scene("memory_rod", prony=value)["prony"] == ()
    assert workbench.scene("tp1", snapshots=value)["snapshots"] == ()
    assert workbench.scene("slab", elastic_tensor=value)["elastic_tensor"] == ()
    with pytest.raises(ParameterError, match=r"prony = 'nothing': give tuples as '\(a, b\); \(c, d\)' or a JSON "
                                             r"list, or none"):
        workbench.scene("memory_rod", prony="nothing")


@pytest.mark.parametrize("scene, key, value", [
    ("slab", "probes", "(0.5,)"),
    ("slab", "probes", "[[0.5]]"),
    ("slab", "probes", [(0.5, 0.05, 0.0)]),
    ("tp1", "probes", [(0.5, 0.0)]),
    ("tp4", "point_force_at", [(1.0,)]),
])
def test_point_with_wrong_number_of_coordinates(scene, key, value):
    """A point with the wrong number of coordinates is reported today as "not inside the body" (or as a format
    error). Expected: ParameterError naming the parameter and saying the number of coordinates is wrong."""
    with pytest.raises(ParameterError) as err:
        workbench.scene(scene, **{key: value})
    msg = str(err.value)
    assert key in msg and "coordinate" in msg and "not inside" not in msg, msg


@pytest.mark.parametrize("scene, values, said", [
    ("tp1", dict(h=0.5, k=0.05, k_max=0.1, atol=1e-6), "atol = 1e-06, k_max = 0.1 have no effect without rtol > 0"),
    ("tp4", dict(h=0.1, T=0.02, adhesion=False, gamma_nu=5.0), "gamma_nu = 5.0 has no effect without adhesion = true"),
    ("memory_slab", dict(h=0.25, T=0.2, max_dofs=500, space_goal="pressure"),
     "max_dofs = 500, space_goal = pressure have no effect without space_tol > 0"),
])
def test_a_value_that_acts_only_with_another_that_is_off_is_warned_about(scene, values, said):
    """k_max without error control, gamma_nu without adhesion: ignored without a word before. A warning names them
    (they are the user's, so not refused: a scene file may keep them for another run); given where they act, none."""
    with pytest.warns(RuntimeWarning, match=re.escape(said)):
        workbench.run(scene, progress=False, **values)
    on = dict(values, rtol=1e-3, scheme="implicit") if "k_max" in values else dict(values, space_tol=0.3) \
        if "max_dofs" in values else dict(values, adhesion=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        warnings.filterwarnings("ignore", message=".*lock in bending")
        workbench.run(scene, progress=False, **on)


def test_a_kernel_the_exponentials_do_not_fit_within_kernel_tol_is_warned_about():
    """kernel_approximation = 'exponentials' on cos(20 t) fits to 6.7e-2 with 32 terms, not to kernel_tol = 1e-6:
    the archive's kernel_fit_error said so, the run did not. A kernel that fits (exp(-t)) says nothing."""
    values = dict(h=0.25, k=0.05, T=1.0, kernel_E=0.5, prony=(), kernel_approximation="exponentials")
    with pytest.warns(RuntimeWarning, match=r"fits the kernel to 0\.067 of its largest value with 32 terms on "
                                            r"\[0, 1\] s, not to kernel_tol = 1e-06"):
        ds = workbench.run("memory_rod", kernel="cos(20*t)", progress=False, **values)
    assert ds.attrs["kernel_fit_error"] > 1e-6
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        ds = workbench.run("memory_rod", kernel="exp(-t)", progress=False, **values)
    assert ds.attrs["kernel_fit_error"] <= 1e-6


def test_a_contact_tol_the_solver_auto_took_does_not_read_is_warned_about():
    """contact_tol with contact_solver = 'auto' on few points (the condensed solver, exact per active set) was
    recorded in the archive and ignored without a word; with 'condensed' it is refused before the run."""
    values = dict(h=0.2, T=0.1, contact_tol=1e-7)
    with pytest.warns(RuntimeWarning, match=re.escape("contact_tol = 1e-07 has no effect: contact_solver = 'auto' "
                                                      "took the condensed solver here")):
        ds = workbench.run("memory_slab", progress=False, **values)
    assert ds.attrs["contact_solver_used"] == "condensed"
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        ds = workbench.run("memory_slab", progress=False, contact_solver="coupled", **values)
    assert ds.attrs["contact_solver_used"] == "coupled"


@pytest.mark.parametrize("scene, values, made", [
    ("tp3", dict(h=0.25, T=0.02, omega=5.0), dict(delta="0.05*t")),
    ("hertz", dict(h=0.5, T=0.02, tau=0.2), dict(a1=1.0, a2=2.0)),
])
def test_a_presets_own_value_that_only_makes_values_given_too_is_warned_about(scene, values, made):
    """tp3's omega makes its delta, the Hertz scenes' tau their viscosity a1, a2: given with those, it was ignored
    without a word. A warning names it; given alone (it makes them), none."""
    name = next(iter(set(values) - {"h", "T"}))
    with pytest.warns(RuntimeWarning, match=re.escape(f"{name} = {values[name]} has no effect with "
                                                      f"{', '.join(made)} given")):
        workbench.run(scene, progress=False, **values, **made)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        ds = workbench.run(scene, progress=False, **values)
    assert ds.attrs["status"] == "complete"


def test_tau_with_a_viscosity_and_an_elastic_tensor_given_is_warned_about():
    """With ``elastic_tensor`` given, ``tau`` makes the viscous tensor tau G; with a1 and a2 given too, theirs stands
    and tau has no effect, which no warning said (it named only the viscous tensor)."""
    C = [[2692.3, 1153.8, 0.0], [1153.8, 2692.3, 0.0], [0.0, 0.0, 769.2]]
    with pytest.warns(RuntimeWarning, match=re.escape("tau = 0.2 has no effect with a1, a2 given (it only makes the "
                                                      "preset's viscous_tensor)")):
        workbench.run("hertz", h=0.5, T=0.02, tau=0.2, elastic_tensor=C, a1=1.0, a2=2.0, progress=False)


@pytest.mark.parametrize("scene, values", [
    ("hertz", dict(h=0.25, T=0.04, probes=((0.0, 0.5), (0.9, 0.1)))),  # (a half-disc: its box's corner)
    ("hertz3d", dict(h=0.5, T=0.04, probes=((0.9, 0.9, 0.1),))),
])
def test_a_probe_in_the_bodys_box_but_outside_its_mesh_is_refused_by_name(scene, values, monkeypatch):
    """A scene checks its probes against the body's box; a curved body does not fill it, and a probe there failed at
    the first record with NGSolve's TypeError (a traceback, nothing kept). Refused by name after the mesh is made,
    before any factorization."""
    from workbench.discrete import solvers

    monkeypatch.setattr(solvers, "factor", lambda *a, **k: pytest.fail("factored before the probes were checked"))
    with pytest.raises(ParameterError, match=r"^probes: point \(0\.9, .*lies in the body's box but outside its mesh"):
        workbench.run(scene, progress=False, **values)


# ------------------------------------------------------------------------------------------------------
# item 14: names that reach the file system are sanitised
# ------------------------------------------------------------------------------------------------------
VTK_DIR = "a/b/vtk"


def _named(name_toml):
    return _files(**{"s.toml": f'scene = "tp1"\nname = {name_toml}\n'})


def _absolute_name(d: Path):
    (d / "s.toml").write_text(f'scene = "tp1"\nname = {json.dumps(str(d / "elsewhere" / "x"))}\n')


ITEM14 = _cases("item14", {
    "name=../../x": Cli(("run", "s.toml", *RUN_TINY, "--T", "0.2", "--vtk", VTK_DIR), (), _named('"../../x"')),
    "name=absolute path": Cli(("run", "s.toml", *RUN_TINY, "--T", "0.2", "--vtk", VTK_DIR), (), _absolute_name),
    "name with NUL": Cli(("run", "s.toml", *RUN_TINY, "--T", "0.2", "--vtk", VTK_DIR), (), _named('"a\\u0000b"')),
})


@pytest.mark.slow
@pytest.mark.parametrize("key", list(ITEM14))
def test_toml_name_cannot_escape_the_vtk_folder(cli, key):
    """The TOML ``name`` is the VTK file stem: today ``../../x`` or an absolute path writes outside the requested
    folder, and a NUL ends in a traceback after the run. Expected: the name is sanitised, the run succeeds and
    every file written (the .vtu and .pvd files) lies inside the ``--vtk`` folder (a name with a NUL may
    instead be refused before the run: exit 2, one line naming ``name``)."""
    res = cli("item14", key)
    if key == "name with NUL" and res.rc == 2:  # a control character may instead be refused, naming `name`
        assert_refused(res, "name")
        return
    assert "Traceback" not in res.err and res.rc == 0, res.show()
    vtk = res.cwd / VTK_DIR
    written = [p for p in res.new_paths() if (res.cwd / p).is_file()]
    outside = [p for p in written if vtk not in (res.cwd / p).resolve().parents]
    assert not outside, f"written outside {VTK_DIR}: {outside}" + res.show()
    assert list(vtk.glob("*.pvd")) and list(vtk.glob("*.vtu")), res.show()


def test_run_stays_the_function_after_the_study_imports_the_runner():
    """Importing the module that holds ``run`` (as the Study does) must not replace ``workbench.run``."""
    import subprocess
    import sys

    code = ("import workbench.study, workbench.running.runner, workbench\n"
            "ds = workbench.run('tp1', h=0.25, k=0.25, progress=False)\n"
            "print(type(workbench.run).__name__, ds.attrs['status'])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["function", "complete"]


@pytest.mark.slow
def test_output_piped_into_head_ends_quietly():
    """`workbench show tp5 | head -1`: the reader leaves early (here: before the first line, `| true`); the command
    stops without a traceback."""
    for reader in ("head -1", "true"):
        p = subprocess.run(f"{sys.executable} -m workbench.cli show tp5 | {reader}", shell=True, capture_output=True,
                           text=True)
        assert "Traceback" not in p.stderr and "BrokenPipe" not in p.stderr, (reader, p.stderr)
        assert p.stdout.startswith("tp5") or reader == "true"


def test_k_min_above_t_and_a_contact_solver_with_nothing_to_solve_are_named():
    """Found by an outside pass: k_min = 2 with T = 0.05 was refused naming k ("k = 0.01 (the first step) must lie in
    [2, 0.05]"), and contact_solver with neither contact nor adhesion ran without a word."""
    with pytest.raises(workbench.ParameterError, match=r"k_min = 2 is larger than T = 0.05; allowed: 0 < k_min"):
        workbench.run("slab", scheme="implicit", rtol=1e-3, k_min=2.0, T=0.05, k=0.01, progress=False)
    with pytest.warns(RuntimeWarning, match=r"contact_solver = coupled has no effect without contact or adhesion"):
        workbench.run("slab", contact=False, adhesion=False, contact_solver="coupled", scheme="implicit", T=0.02,
                      k=0.01, h=0.1, progress=False)


def test_more_threads_than_four_a_core_are_refused_before_any_work():
    """--threads 256 was in the allowed range (1 to 256) and ended after the setup in NGSolve's "Could not allocate
    localheap" traceback on a 2-core machine with 23 GB (each thread reserves its own working memory; found by an
    outside pass). The range is 1 to four per core, on the command line and in Python."""
    cores = os.cpu_count() or 1
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "tp1", "--threads", str(4 * cores + 1),
                        "--no-progress"], capture_output=True, text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr and f"from 1 to {4 * cores}" in p.stderr, p.stderr
    with pytest.raises(workbench.ParameterError, match=f"threads = {4 * cores + 1}: give an integer from 1 to"):
        workbench.run("tp1", threads=4 * cores + 1, progress=False)
    workbench.run("tp1", h=0.1, k=0.1, threads=2, progress=False)
