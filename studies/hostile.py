"""Hostile-tester harness (issue 25): bad, extreme and faulty inputs through the CLI and the Python API.

Run (from the repository root, in the project's virtualenv)::

    python studies/hostile.py                        # every input, one at a time -> data/hostile/results.json, summary.md
    python studies/hostile.py --tag before           # -> results_before.json, summary_before.md
    python studies/hostile.py --quick                # ~60 inputs covering every class (a few minutes)
    python studies/hostile.py --only 'restart|mesh'  # inputs whose id matches a regular expression
    python studies/hostile.py --list                 # list the inputs, run nothing
    python studies/hostile.py --code HEAD            # test the package as committed at HEAD (git archive of
                                                     # workbench/ into a temporary folder, put first on PYTHONPATH)

Other options: ``--jobs N`` (inputs run in parallel; default 1: the machine is shared), ``--timeout S``
(wall seconds per input, default 90), ``--mem-limit GB`` (address-space limit of every input's process
tree, default 6: a hostile input must not take the shared machine down; an input that needs more fails
as the user's would on a smaller machine), ``--package DIR`` (a folder holding ``workbench/`` to test
instead of the installed one), ``--out DIR`` (default data/hostile), ``--keep`` (keep the work folders).
A full run takes 30-60 minutes (most of it in the inputs that hang until the timeout).

Every input runs as its own process (``workbench ...`` or ``python -c SNIPPET``) in a fresh temporary
folder (its working directory; ``TMPDIR`` points into it, so a result "kept in the temporary folder" is
found and checked), with ``MPLBACKEND=Agg``, stdin closed, in a session of its own whose whole process
group is killed at the timeout. Python API inputs run their snippet in a tiny wrapper: a
``workbench.ParameterError`` prints ``error: <message>`` and exits 2 (what a user sees), a
``workbench.Diverged`` prints ``error: ...`` and exits 3 (the CLI's code), anything else propagates as a
traceback (exit 1); Python warnings print as ``warning: ...`` lines, as on the command line. Some inputs
need root (a full disk is a 200 kB tmpfs filled up, a read-only folder a read-only tmpfs, a character
device is made with mknod); without root they are recorded as ``skipped`` with the reason.

Each input has an id, the issue's class it stands for (``issue``: data_lost, traceback,
silently_accepted, hang, unclear, wrongly_refused, or own = more of the same spirit), the command or
snippet, and an expectation:

* ``refuse``                -- must be refused: exit 2 with one ``error:`` line;
* ``refuse-naming:W1|W2``   -- refused, and the error line names W1 or W2 (what the user typed, e.g.
                               the parameter ``tau``; a bare name matches as a whole word, ``re:...`` is
                               a regular expression);
* ``run``                   -- a valid input: must run (exit 0, or 3 if it diverges keeping its data);
* ``either``                -- running and a clean refusal are both fine;
* ``either-naming:W``       -- running is fine; a refusal must name W;
* ``keep-data``             -- anything clean is fine, but no result may be lost (see the checks).

The outcome of each input, from its exit code, stderr and the file system afterwards (first match):

* ``skipped``           -- the input could not be set up here (no root, argv too long ...), see ``note``;
* ``harness_error``     -- the harness's own setup failed (should never happen);
* ``hang``              -- still running at the timeout (the process group was killed);
* ``data_lost``         -- a data check failed: ``-o`` given and exit 0/3 but the archive is missing or
                           unreadable (or a PNG sits there), exit 3 and the archive is not marked
                           incomplete, exit 4 (or "kept in" said) but the kept copy is missing or
                           unreadable, a requested ``--plot``/``--vtk`` missing after exit 0, a character
                           device replaced by a regular file, the archive of a restart destroyed ...
                           (a traceback at the same time is in ``flags``);
* ``traceback``         -- ``Traceback`` in stderr, or an exit code other than 0/2/3/4 (a signal: negative);
* ``silently_accepted`` -- the expectation is refuse(-naming) but the exit code was 0 (or a check found that
                           an input it must refuse did something, e.g. an expression executed code);
* ``ran``               -- exit 0, or exit 3 (diverged) with its data kept (``flags``: diverged);
* ``write_failed``      -- exit 4 with a clean ``error:`` line and the result kept elsewhere (checked);
* ``messy_error``       -- exit 2 or 4 but stderr is not exactly one ``error:`` line (plus ``warning:`` lines);
* ``wrongly_refused``   -- the expectation is run, but it was refused (exit 2, clean);
* ``unclear``           -- a refusal (exit 2, clean) whose line does not name the expected words;
* ``clean_error``       -- exit 2, stderr exactly one line ``error: ...`` (``warning:`` lines allowed).

``slow_error`` is informational, not an outcome: a clean error (clean_error / unclear / wrongly_refused)
that took more than 0.5 s wall as a whole process (the project wants errors within 0.5 s); the summary
counts them separately. Other flags: ``diverged`` (exit 3), ``accepted_then_diverged`` (exit 3 for an
input that must be refused), ``litter`` (a temporary ``.NAME.*.tmp`` left beside an output), ``exit4``,
``traceback`` (on a data_lost input), ``data_lost_too`` (on a hang).

Outputs (``--out``, default data/hostile): ``results[_TAG].json`` -- ``{"meta": ..., "results": [one
record per input]}``, each record with id, issue, kind, command, expect, outcome, flags, exit code, wall
time, the first and last lines of stderr, the tail of stdout/stderr, the data check's verdict and notes;
``summary[_TAG].md`` -- counts per outcome and per issue class, and every input whose outcome is not
clean_error / ran / skipped with its command and the first line of its stderr.

The harness never raises on an odd outcome: every input is recorded, whatever it does.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import datetime
import json
import os
import re
import resource
import shlex
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SLOW_ERROR = 0.5  # s: a clean error should take at most this long (as a whole process)
CLEAN = ("clean_error", "ran", "skipped")


class Skip(Exception):
    """The input cannot be set up on this machine (no root, ...): recorded as skipped."""


@dataclass
class Input:
    id: str
    issue: str
    expect: str
    args: list | None = None        # workbench argv (CLI input)
    code: str | None = None         # Python snippet (API input)
    setup: object = None            # setup(wd) -> None | cleanup callable; may raise Skip
    check: object = None            # check(wd, result) -> None | reason | (outcome, reason)
    quick: bool = False
    timeout: float | None = None
    env: dict = field(default_factory=dict)
    note: str = ""

    @property
    def kind(self):
        return "cli" if self.args is not None else "py"

    def command(self, limit=None) -> str:
        text = shlex.join(["workbench"] + [str(a) for a in self.args]) if self.args is not None \
            else "python: " + self.code
        if limit and len(text) > limit:
            text = text[: limit - 20] + f"... [{len(text)} chars]"
        return text


INPUTS: list[Input] = []


def add(id, issue, expect, args=None, *, code=None, **kw):
    if any(i.id == id for i in INPUTS):
        raise SystemExit(f"duplicate input id {id}")
    INPUTS.append(Input(id=id, issue=issue, expect=expect, args=args, code=code, **kw))


# ----------------------------------------------------------------------------------------------------------------
# Settings that keep a valid run cheap (seconds)
# ----------------------------------------------------------------------------------------------------------------
COARSE = {
    "tp1": dict(h=0.1, k=0.05, T=0.2), "tp2": dict(h=0.1, k=0.05, T=0.2), "tp3": dict(h=0.1, k=0.05, T=0.2),
    "rod": dict(h=0.1, k=0.05, T=0.2),
    "slab": dict(h=0.1, k=0.01, T=0.05), "tp4": dict(h=0.1, k=0.01, T=0.05), "tp5": dict(h=0.1, k=0.01, T=0.05),
    "block": dict(h=0.2, k=0.001, T=0.005),
    "memory_rod": dict(k=0.05, T=0.2), "memory_slab": dict(h=0.25, k=0.05, T=0.2),
    "memory_block": dict(h=0.25, k=0.05, T=0.1),
    "hertz": dict(k=0.05, T=0.1), "hertz3d": dict(k=0.05, T=0.1),
    "memory_hertz": dict(T=0.5), "memory_hertz3d": dict(T=0.5),
}


def _given(extra) -> set:
    names = set()
    extra = [str(e) for e in extra]
    for i, tok in enumerate(extra):
        if tok in ("--h", "--k", "--T", "--order", "--scheme"):
            names.add(tok[2:])
        if tok == "--set" and i + 1 < len(extra) and "=" in extra[i + 1]:
            names.add(extra[i + 1].split("=", 1)[0].strip())
        if tok.startswith("--set="):
            names.add(tok[6:].split("=", 1)[0].strip())
    return names


def coarse(scene, extra=()) -> list:
    given = _given(extra)
    out = []
    for name, value in COARSE.get(scene, {}).items():
        if name not in given:
            out += [f"--{name}", repr(value) if isinstance(value, float) else str(value)]
    return out


def RUN(scene, *extra) -> list:
    """``workbench run SCENE <coarse settings not given in extra> *extra``."""
    return ["run", scene, *coarse(scene, extra), *extra]


STUDY = ["study", "tp1", "--h", "0.1", "--k", "0.1", "0.05", "--set", "T=0.2", "--reference", "ode", "--workers", "0",
         "--no-progress"]
PY_STUDY = 'workbench.Study("tp1", h=0.1, k=[0.1, 0.05], T=0.2, reference="ode", workers=0'
PY_RUN = 'workbench.run("tp1", h=0.1, k=0.05, T=0.2, progress=False'
PY_STUDY_NOREF = 'workbench.Study("tp1", h=0.1, k=[0.1, 0.05], T=0.2, workers=0'


# ----------------------------------------------------------------------------------------------------------------
# Setup helpers: each returns setup(wd) -> None | cleanup
# ----------------------------------------------------------------------------------------------------------------
def chain(*setups):
    def setup(wd):
        cleanups = []
        try:
            for s in setups:
                c = s(wd)
                if callable(c):
                    cleanups.append(c)
        except BaseException:
            for c in reversed(cleanups):
                _quiet(c)
            raise
        return (lambda: [_quiet(c) for c in reversed(cleanups)]) if cleanups else None
    return setup


def _quiet(fn):
    try:
        fn()
    except Exception:
        pass


def files(**contents):
    """Text (str) or bytes files in the work folder; keys may not hold '/', use files_at for sub-paths."""
    return files_at(contents)


def files_at(contents: dict):
    def setup(wd):
        for name, content in contents.items():
            p = wd / name
            p.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(content, bytes):
                p.write_bytes(content)
            else:
                p.write_text(content, encoding="utf-8")
    return setup


def fifo(name):
    def setup(wd):
        os.mkfifo(wd / name)
    return setup


def symlink(name, target):
    def setup(wd):
        os.symlink(target, wd / name)
    return setup


def chardev(name):
    def setup(wd):
        try:
            os.mknod(wd / name, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        except PermissionError as err:
            raise Skip(f"mknod needs root ({err})")
    return setup


def mkdirs(*names):
    def setup(wd):
        for n in names:
            (wd / n).mkdir(parents=True, exist_ok=True)
    return setup


def _mount(target: Path, options: str):
    target.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(target)], capture_output=True, text=True)
    if r.returncode != 0:
        raise Skip(f"cannot mount a tmpfs ({(r.stderr or r.stdout).strip()[:200]})")

    def cleanup():
        if subprocess.run(["umount", str(target)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(target)], capture_output=True)
    return cleanup


def full_disk(name="full", size="200k"):
    """A tmpfs of ``size`` at wd/name, filled to the last byte (a full disk)."""
    def setup(wd):
        target = wd / name
        cleanup = _mount(target, f"size={size}")
        try:
            with open(target / ".filler", "wb") as f:
                block = b"\0" * 4096
                while True:
                    f.write(block)
                    f.flush()
        except OSError:
            pass
        return cleanup
    return setup


def readonly_dir(name="ro"):
    def setup(wd):
        return _mount(wd / name, "ro,size=100k")
    return setup


FIXTURES: dict = {}
FIXTURE_LOCK = threading.Lock()
FIXTURE_DIR: Path | None = None
CHILD_ENV: dict = {}


def fixture(name) -> Path:
    """A shared file made once per harness run (archives); Skip if it cannot be made."""
    with FIXTURE_LOCK:
        if name in FIXTURES:
            if isinstance(FIXTURES[name], Exception):
                raise Skip(f"fixture {name}: {FIXTURES[name]}")
            return FIXTURES[name]
        try:
            FIXTURES[name] = _make_fixture(name)
        except Exception as err:
            FIXTURES[name] = err
            raise Skip(f"fixture {name}: {err}")
        return FIXTURES[name]


FIXTURE_COMMANDS = {
    "tp1.nc": ["run", "tp1", "--h", "0.1", "--k", "0.1", "--no-progress", "-o", "tp1.nc"],
    "tp5.nc": ["run", "tp5", "--h", "0.1", "--k", "0.01", "--T", "0.05", "--no-progress", "-o", "tp5.nc"],
    "memory_rod.nc": ["run", "memory_rod", "--k", "0.05", "--T", "0.2", "--no-progress", "-o", "memory_rod.nc"],
    "study.nc": STUDY + ["-o", "study.nc"],
}


def _make_fixture(name) -> Path:
    folder = FIXTURE_DIR
    r = subprocess.run(WORKBENCH + FIXTURE_COMMANDS[name], cwd=folder, env=CHILD_ENV, capture_output=True, text=True,
                       timeout=300)
    p = folder / name
    if r.returncode != 0 or not p.exists():
        raise RuntimeError(f"exit {r.returncode}: {r.stderr.strip()[-300:]}")
    return p


def archive(dest="a.nc", source="tp1.nc", modify=None):
    """A copy of a real archive at wd/dest; ``modify(xarray.Dataset) -> Dataset`` corrupts it (written with xarray),
    ``modify`` given as bytes -> bytes works on the raw file instead (``raw=True`` variant below)."""
    def setup(wd):
        src = fixture(source)
        if modify is None:
            shutil.copy(src, wd / dest)
            return
        import xarray as xr

        ds = xr.load_dataset(src)
        ds = modify(ds)
        ds.to_netcdf(wd / dest)
    return setup


def archive_bytes(dest, fn, source="tp1.nc"):
    def setup(wd):
        (wd / dest).write_bytes(fn(fixture(source).read_bytes()))
    return setup


# ----------------------------------------------------------------------------------------------------------------
# gmsh 2.2 files, written here
# ----------------------------------------------------------------------------------------------------------------
NAMES2D = {1: "bottom", 2: "right", 3: "top", 4: "left", 5: "body"}
NAMES3D = {1: "bottom", 2: "right", 3: "top", 4: "left", 5: "front", 6: "back", 7: "body"}


def grid2d(nx=2, ny=2, W=1.0, H=1.0):
    """Nodes {id: [x, y, z]} and elements [(gmsh type, physical tag, [node ids])] of a structured triangle mesh."""
    nodes = {}
    nid = lambda i, j: j * (nx + 1) + i + 1  # noqa: E731
    for j in range(ny + 1):
        for i in range(nx + 1):
            nodes[nid(i, j)] = [W * i / nx, H * j / ny, 0.0]
    elems = []
    for i in range(nx):
        elems.append((1, 1, [nid(i, 0), nid(i + 1, 0)]))
        elems.append((1, 3, [nid(i + 1, ny), nid(i, ny)]))
    for j in range(ny):
        elems.append((1, 2, [nid(nx, j), nid(nx, j + 1)]))
        elems.append((1, 4, [nid(0, j + 1), nid(0, j)]))
    for j in range(ny):
        for i in range(nx):
            a, b, c, d = nid(i, j), nid(i + 1, j), nid(i + 1, j + 1), nid(i, j + 1)
            elems += [(2, 5, [a, b, c]), (2, 5, [a, c, d])]
    return nodes, elems


def grid3d(nx=2, ny=2, nz=1, W=1.0, D=1.0, H=0.5):
    """A structured tetrahedral mesh (6 tets per cube, Kuhn), its boundary triangles tagged by side."""
    import itertools

    nid = lambda i, j, k: k * (nx + 1) * (ny + 1) + j * (nx + 1) + i + 1  # noqa: E731
    nodes = {}
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                nodes[nid(i, j, k)] = [W * i / nx, D * j / ny, H * k / nz]
    tets = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                for perm in itertools.permutations(range(3)):
                    p = [i, j, k]
                    path = [nid(*p)]
                    for axis in perm:
                        p[axis] += 1
                        path.append(nid(*p))
                    tets.append(path)
    count = {}
    for t in tets:
        for f in itertools.combinations(t, 3):
            key = tuple(sorted(f))
            count[key] = count.get(key, 0) + 1
    elems = []
    eps = 1e-12
    for f, n in count.items():
        if n != 1:
            continue
        xyz = [nodes[v] for v in f]
        side = None
        for tag, axis, value in ((1, 2, 0.0), (3, 2, H), (4, 0, 0.0), (2, 0, W), (5, 1, 0.0), (6, 1, D)):
            if all(abs(p[axis] - value) < eps for p in xyz):
                side = tag
        elems.append((2, side, list(f)))
    elems += [(4, 7, t) for t in tets]
    return nodes, elems


def msh(nodes, elems, names=NAMES2D, dims=None) -> str:
    dims = dims or {t: (2 if n == "body" else 1) for t, n in names.items()}
    out = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(names))]
    out += [f'{dims[t]} {t} "{n}"' for t, n in names.items()]
    out += ["$EndPhysicalNames", "$Nodes", str(len(nodes))]
    out += [f"{i} {' '.join(repr(float(c)) if not isinstance(c, str) else c for c in xyz)}" for i, xyz in nodes.items()]
    out += ["$EndNodes", "$Elements", str(len(elems))]
    for n, (typ, tag, vs) in enumerate(elems, 1):
        out.append(f"{n} {typ} 2 {tag} {tag} {' '.join(map(str, vs))}")
    out += ["$EndElements", ""]
    return "\n".join(out)


def msh2d(mutate=None, **kw) -> str:
    nodes, elems = grid2d(**kw)
    if mutate:
        nodes, elems = mutate(nodes, elems) or (nodes, elems)
    return msh(nodes, elems, NAMES2D)


def msh3d(mutate=None, **kw) -> str:
    nodes, elems = grid3d(**kw)
    if mutate:
        nodes, elems = mutate(nodes, elems) or (nodes, elems)
    return msh(nodes, elems, NAMES3D, dims={t: (3 if n == "body" else 2) for t, n in NAMES3D.items()})


ROLES2D = {"bottom": "contact", "left": "clamped", "top": "traction", "right": "free"}
ROLES3D = {"bottom": "contact", "left": "clamped", "top": "traction", "right": "free", "front": "free", "back": "free"}


def toml_value(v):
    return json.dumps(v) if isinstance(v, str) else (str(v).lower() if isinstance(v, bool) else repr(v))


def mesh_toml(geometry="body.msh", roles=None, params=None, model=None, scene=None, dim=2, extra="") -> str:
    roles = ROLES2D if roles is None and dim == 2 else ROLES3D if roles is None else roles
    if params is None:
        params = {"traction": "(0, -t)" if dim == 2 else "(0, 0, -t)", "k": 0.05, "T": 0.1}
        if model == "B":
            params = {"traction": params["traction"], "k": 0.05, "T": 0.1}
    lines = [f"geometry = {json.dumps(geometry)}"]
    if model is not None:
        lines.append(f"model = {toml_value(model)}")
    if scene is not None:
        lines.append(f"scene = {toml_value(scene)}")
    lines.append(extra)
    lines.append("[boundaries]")
    lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in roles.items()]
    lines.append("[parameters]")
    lines += [f"{k} = {toml_value(v)}" for k, v in params.items()]
    return "\n".join(lines) + "\n"


def mesh_case(msh_text, toml_text=None, msh_name="body.msh", **toml_kw):
    return files_at({msh_name: msh_text, "body.toml": toml_text if toml_text is not None
                     else mesh_toml(geometry=msh_name, **toml_kw)})


SLAB_TOML = 'scene = "slab"\n[parameters]\nh = 0.1\nk = 0.01\nT = 0.05\n'


# ----------------------------------------------------------------------------------------------------------------
# Checks: check(wd, res) -> None | reason | (outcome, reason)
# ----------------------------------------------------------------------------------------------------------------
def _magic(path: Path) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(8)
    except OSError:
        return b""


def netcdf_status(path: Path):
    """(ok, status or reason): whether ``path`` is a readable netCDF archive, and its attrs['status']."""
    path = Path(path)
    if not path.exists():
        return False, "missing"
    if path.is_dir():
        return False, "a directory"
    if not path.is_file():
        return False, "not a regular file"
    head = _magic(path)
    if head.startswith(b"\x89PNG"):
        return False, "a PNG (a plot was written over it)"
    try:
        import netCDF4

        with netCDF4.Dataset(str(path)) as d:
            status = d.getncattr("status") if "status" in d.ncattrs() else "(no status attribute)"
        return True, str(status)
    except Exception as err:
        return False, f"unreadable ({type(err).__name__}: {str(err)[:80]})"


def still_chardev(name):
    def check(wd, res):
        p = wd / name
        try:
            st = os.lstat(p)
        except OSError:
            return f"the device node {name} is gone"
        if not stat.S_ISCHR(st.st_mode):
            return f"the device node {name} was replaced by a {'regular file' if stat.S_ISREG(st.st_mode) else 'non-device'}"
        return None
    return check


def archive_intact(name):
    """The archive given as input (e.g. to --restart) must still be a readable archive afterwards."""
    def check(wd, res):
        ok, why = netcdf_status(wd / name)
        return None if ok else f"the input archive {name} is {why} afterwards"
    return check


def no_file(name, outcome="silently_accepted"):
    def check(wd, res):
        return (outcome, f"{name} was created: the input executed code") if (wd / name).exists() else None
    return check


def all_checks(*checks):
    def check(wd, res):
        for c in checks:
            r = c(wd, res)
            if r:
                return r
        return None
    return check


def _opt_values(args, *names):
    """Values of an option (all occurrences) in argv."""
    out = []
    args = [str(a) for a in args]
    for i, a in enumerate(args):
        for n in names:
            if a == n and i + 1 < len(args):
                out.append(args[i + 1])
            elif a.startswith(n + "=") and n.startswith("--"):
                out.append(a[len(n) + 1:])
    return out


def generic_checks(inp: Input, wd: Path, rc: int, stderr: str):
    """The data checks every CLI input gets; returns (reason or None, flags)."""
    flags = []
    kept = re.findall(r"kept in (\S+?\.nc)\b", stderr)
    for k in kept:
        ok, why = netcdf_status(Path(k) if os.path.isabs(k) else wd / k)
        if not ok:
            return f"stderr says the result is kept in {k}, but it is {why}", flags
    if "could not be kept" in stderr or "failed too" in stderr:
        return "the result could not be written and was not kept anywhere", flags
    if inp.args is None:
        return None, flags
    args = [str(a) for a in inp.args]
    outs = _opt_values(args, "-o", "--output")
    out = outs[-1] if outs else None
    cmd = args[0] if args else ""
    if rc == 4 and not kept:
        return "exit 4 (not written) but stderr names no kept copy", flags
    if out and cmd in ("run", "study") and rc in (0, 3):
        p = Path(out) if os.path.isabs(out) else wd / out
        ok, why = netcdf_status(p)
        if not ok:
            return f"-o {out}: exit {rc} but the archive is {why}", flags
        if rc == 3 and why != "incomplete":
            return f"-o {out}: exit 3 but the archive's status is {why!r}, not 'incomplete'", flags
    if rc == 0 and cmd in ("run", "study"):  # (an option given twice: argparse keeps the last)
        for p in [v[-1] for v in (_opt_values(args, "--plot"), _opt_values(args, "--pareto")) if v]:
            if p == out or not p:
                continue  # (the same path as the archive: the archive check decides; '': nothing asked for)  # (the same path as the archive: the archive check above decides)
            q = Path(p) if os.path.isabs(p) else wd / p
            if not (q.is_file() and _magic(q).startswith(b"\x89PNG")):
                return f"{p}: exit 0 but the PNG asked for is missing (or not a PNG)", flags
        for v in [v for v in _opt_values(args, "--vtk")[-1:] if v]:
            q = Path(v) if os.path.isabs(v) else wd / v
            if not (q.is_dir() and any(q.glob("*.pvd"))):
                return f"--vtk {v}: exit 0 but no .pvd was written there", flags
    for o in outs + _opt_values(args, "--plot", "--pareto"):
        q = Path(o) if os.path.isabs(o) else wd / o
        try:
            if any(q.parent.glob(f".{q.name}.*.tmp")):
                flags.append("litter")
        except (OSError, ValueError):
            pass
    return None, flags


# ----------------------------------------------------------------------------------------------------------------
# The inputs
# ----------------------------------------------------------------------------------------------------------------
def build_inputs():  # noqa: C901 (a long list, on purpose)
    # ============================================ data lost ===================================================
    I = "data_lost"  # noqa: E741
    add("dl_plot_same_as_archive", I, "keep-data", RUN("tp1", "-o", "out.nc", "--plot", "out.nc"), quick=True)
    add("dl_plot_same_as_archive_dotslash", I, "keep-data", RUN("tp1", "-o", "out.nc", "--plot", "./out.nc"))
    add("dl_plot_same_as_archive_abs", I, "keep-data", RUN("tp1", "-o", "out.nc", "--plot", "@WD@/out.nc"))
    add("dl_plot_same_as_archive_slab", I, "keep-data", RUN("tp5", "-o", "r.nc", "--plot", "r.nc"))
    add("dl_vtk_same_as_archive", I, "keep-data", RUN("tp5", "-o", "out.nc", "--vtk", "out.nc"))
    add("dl_plot_symlink_to_archive", I, "keep-data", RUN("tp1", "-o", "out.nc", "--plot", "link.png"),
        setup=symlink("link.png", "out.nc"),
        check=lambda wd, res: None if netcdf_status(wd / "out.nc")[0] else "out.nc lost (plot written through a link)")
    add("dl_output_is_restart_archive", I, "keep-data",
        ["run", "--restart", "a.nc", "--set", "T=1.5", "--no-progress", "-o", "a.nc"], setup=archive("a.nc"))
    add("dl_full_disk_run", I, "keep-data", RUN("tp1", "-o", "full/out.nc"), setup=full_disk(), quick=True)
    add("dl_full_disk_run_memory", I, "keep-data", RUN("memory_slab", "-o", "full/out.nc"), setup=full_disk())
    add("dl_full_disk_plot", I, "keep-data", RUN("tp5", "-o", "out.nc", "--plot", "full/out.png"),
        setup=full_disk())
    add("dl_full_disk_plot_only", I, "keep-data", RUN("tp5", "--plot", "full/out.png"), setup=full_disk())
    add("dl_full_disk_vtk", I, "keep-data", RUN("tp5", "-o", "out.nc", "--vtk", "full/vtk"), setup=full_disk())
    add("dl_full_disk_and_tmp_full", I, "keep-data", RUN("tp1", "-o", "full/out.nc"),
        setup=chain(full_disk("full"), full_disk("full2")), env={"TMPDIR": "@WD@/full2"},
        note="both the target and the temporary folder are full: a copy could only go elsewhere (cwd, home)")
    add("dl_full_disk_checkpoints", I, "keep-data",
        RUN("tp1", "--set", "checkpoint_every=1", "-o", "full/out.nc"), setup=full_disk())
    add("dl_full_disk_restart_output", I, "keep-data",
        ["run", "--restart", "a.nc", "--set", "T=1.5", "--no-progress", "-o", "full/b.nc"],
        setup=chain(archive("a.nc"), full_disk()))
    add("dl_checkpoint_every_1e308", I, "keep-data", RUN("tp1", "--set", "checkpoint_every=1e308", "-o", "out.nc"),
        quick=True)
    add("dl_checkpoint_every_inf", I, "keep-data", RUN("tp1", "--set", "checkpoint_every=inf", "-o", "out.nc"))
    add("dl_checkpoint_every_1e20", I, "keep-data", RUN("tp1", "--set", "checkpoint_every=1e20", "-o", "out.nc"))
    add("dl_checkpoint_every_1", "own", "run", RUN("tp1", "--set", "checkpoint_every=1", "-o", "out.nc"))
    add("dl_checkpoint_every_1_memory", "own", "run",
        RUN("memory_slab", "--set", "checkpoint_every=1", "-o", "out.nc"))
    add("dl_checkpoint_without_output", "own", "either", RUN("tp1", "--set", "checkpoint_every=1"))
    add("dl_chardev_output", I, "refuse", RUN("tp1", "-o", "dev"), setup=chardev("dev"),
        check=still_chardev("dev"), quick=True)
    add("dl_chardev_plot", I, "refuse", RUN("tp1", "--plot", "dev"), setup=chardev("dev"), check=still_chardev("dev"))
    add("dl_chardev_vtk", I, "refuse", RUN("tp5", "--vtk", "dev"), setup=chardev("dev"), check=still_chardev("dev"))
    add("dl_chardev_checkpoint", I, "refuse", RUN("tp1", "--set", "checkpoint_every=2", "-o", "dev"),
        setup=chardev("dev"), check=still_chardev("dev"))
    add("dl_chardev_study", I, "refuse", STUDY + ["-o", "dev"], setup=chardev("dev"), check=still_chardev("dev"))
    add("dl_chardev_reproduce", I, "refuse", ["reproduce", "tp1", "--h", "0.1", "--k", "0.1", "--no-side", "--out",
                                              "dev"], setup=chardev("dev"), check=still_chardev("dev"))
    add("dl_study_full_disk", I, "keep-data", STUDY + ["-o", "full/s.nc"], setup=full_disk(), quick=True)
    add("dl_study_plot_same_as_archive", I, "keep-data", STUDY + ["-o", "s.nc", "--plot", "s.nc"])
    add("dl_study_pareto_same_as_archive", I, "keep-data", STUDY + ["-o", "s.nc", "--pareto", "s.nc"])
    add("dl_study_plot_full_disk", I, "keep-data", STUDY + ["-o", "s.nc", "--plot", "full/p.png"], setup=full_disk())
    add("dl_output_dangling_symlink", "own", "keep-data", RUN("tp1", "-o", "link.nc"),
        setup=symlink("link.nc", "nowhere/x.nc"))
    add("dl_output_symlink_to_dir", "own", "refuse", RUN("tp1", "-o", "link.nc"),
        setup=chain(mkdirs("d"), symlink("link.nc", "d")))
    add("dl_output_into_nested_new_dirs", "own", "run", RUN("tp1", "-o", "a/b/c/out.nc"))
    add("dl_reproduce_full_disk", I, "keep-data",
        ["reproduce", "tp1", "--h", "0.1", "--k", "0.1", "--no-side", "--out", "full/r"], setup=full_disk())
    add("dl_api_write_full_disk", I, "either",
        code=f'ds = {PY_RUN})\nworkbench.write(ds, "full/x.nc")', setup=full_disk(),
        note="the API raises: an OSError traceback is what Python users get (no data kept by the API)")
    add("dl_api_write_chardev", I, "refuse", code=f'ds = {PY_RUN})\nworkbench.write(ds, "dev")',
        setup=chardev("dev"), check=still_chardev("dev"))
    add("dl_api_checkpoint_chardev", I, "refuse",
        code=f'{PY_RUN}, checkpoint_every=2, checkpoint="dev")', setup=chardev("dev"), check=still_chardev("dev"))

    # ============================================ tracebacks ==================================================
    I = "traceback"  # noqa: E741
    add("tb_traction_complex", I, "refuse-naming:traction_top", RUN("slab", "--set", "traction_top=(0, (-1)**0.5)"),
        quick=True)
    add("tb_traction_pole_t003", I, "either-naming:traction_top", RUN("slab", "--set", "traction_top=(0, 1/(t-0.03))"),
        quick=True)
    add("tb_hertz_load_pole", I, "either-naming:load", RUN("hertz", "--set", "load=1/(t-0.05)"), quick=True)
    # (a new user's pass, 2026-12: a pole between the scene's sampled times, a probe in the box of a curved body,
    # a study's --plot over tolerances)
    add("tb_delta_pole_off_the_sampled_times", "own", "either-naming:delta",
        RUN("rod", "--T", "1", "--set", "delta=0.01/(t-0.55)+0.01/0.55", "-o", "out.nc"), quick=True)
    add("tb_probe_outside_a_curved_body", "own", "refuse-naming:probes", RUN("hertz", "--set", "probes=(0.9, 0.1)"),
        quick=True)
    add("tb_study_plot_of_tolerances", "own", "run", ["study", "tp2", "--sweep", "rtol=1e-2,1e-3", "--scheme", "bdf2",
                                                      "--workers", "0", "--no-progress", "-o", "s.nc", "--plot", "s.png"])
    # (the third and fourth outside passes, 2026-12: a study option by --set, a figure's format, the table's "none")
    add("sa_study_set_reference", "own", "refuse-naming:reference",
        ["study", "tp1", "--k", "0.1", "0.05", "--set", "reference=finest", "--workers", "0", "--no-progress"],
        quick=True)
    add("tb_plot_of_an_unknown_format", "own", "refuse-naming:--plot", RUN("tp1", "-o", "out.nc", "--plot", "f.docx"),
        quick=True)
    add("tb_prony_none_as_the_table_shows", "own", "run", RUN("memory_rod", "--set", "prony=none", "-o", "out.nc"),
        quick=True)
    # (the fifth and sixth outside passes, 2026-12: a segmentation fault in MKL's Schur complement on the coarsest rod)
    add("tb_rod_of_two_cells_implicit", "own", "run", RUN("tp1", "--h", "0.5", "--set", "scheme=implicit", "-o",
                                                         "out.nc"), quick=True)
    add("tb_memory_rod_of_two_cells_fitted_kernel", "own", "run",
        RUN("memory_rod", "--h", "0.5", "--k", "0.01", "--set", "kernel=cos(20*t)", "--set", "kernel_E=0.5", "--set",
            "prony=none", "--set", "kernel_approximation=exponentials", "-o", "out.nc"))
    add("sa_study_sweep_of_T", "own", "refuse-naming:T",
        ["study", "rod", "--k", "0.04", "0.02", "--sweep", "T=0.5,1", "--workers", "0", "--no-progress"])
    add("tb_hertz_load_1_over_t", I, "either-naming:load", RUN("hertz", "--set", "load=1/t"))
    add("tb_hertz_load_log_t", I, "either-naming:load", RUN("hertz", "--set", "load=log(t)"))
    add("tb_hertz_load_sqrt_neg", I, "refuse-naming:load", RUN("hertz", "--set", "load=sqrt(-1)"))
    add("tb_hertz_load_sqrt_t_minus", I, "either-naming:load", RUN("hertz", "--set", "load=sqrt(t-0.05)"))
    add("tb_hertz_load_exp_overflow", I, "either-naming:load", RUN("hertz", "--set", "load=exp(1000*t)"))
    add("tb_hertz_load_huge_power", I, "either-naming:load", RUN("hertz", "--set", "load=10**400"))
    add("tb_hertz3d_load_pole", I, "either-naming:load", RUN("hertz3d", "--set", "load=1/(t-0.05)"))
    add("tb_memory_hertz_load_pole", I, "either-naming:load", RUN("memory_hertz", "--set", "load=1/(t-0.25)",
                                                                    "--k", "0.25"))
    add("tb_traction_log_neg", I, "refuse-naming:traction_top", RUN("slab", "--set", "traction_top=(0, log(-1))"))
    add("tb_traction_zero_pow_neg", I, "refuse-naming:traction_top", RUN("slab", "--set", "traction_top=(0, 0**-1)"))
    add("tb_traction_2_pow_10000", I, "refuse-naming:traction_top", RUN("slab", "--set", "traction_top=(0, 2**10000)"))
    add("tb_traction_1e308_squared", I, "either-naming:traction_top",
        RUN("slab", "--set", "traction_top=(0, 1e308*1e308)"))
    add("tb_traction_1_over_x", I, "either-naming:traction_top", RUN("slab", "--set", "traction_top=(0, 1/x)"))
    add("tb_traction_1_over_x_minus_half", I, "either-naming:traction_top",
        RUN("slab", "--set", "traction_top=(0, 1/(x-0.5))"))
    add("tb_traction_complex_pow_t", I, "either-naming:traction_top",
        RUN("slab", "--set", "traction_top=(0, (-1)**t)"))
    add("tb_traction_right_pole", I, "either-naming:traction_right",
        RUN("slab", "--set", "traction_right=(0, 1/(t-0.02))"))
    add("tb_body_force_pole", I, "either-naming:body_force", RUN("slab", "--set", "body_force=(0, 1/(y-0.05))"))
    add("tb_point_force_pole", I, "either-naming:point_force", RUN("tp4", "--set", "point_force=(0, 1/(t-0.02))"))
    add("tb_block_traction_pole", I, "either-naming:traction_top",
        RUN("block", "--set", "traction_top=(0, 0, 1/(t-0.002))"))
    add("tb_rod_delta_pole", I, "either-naming:delta", RUN("rod", "--set", "delta=1/(t-0.1)"))
    add("tb_rod_delta_sqrt_neg_t", I, "either-naming:delta", RUN("rod", "--set", "delta=sqrt(-t)"))
    add("tb_rod_delta_complex_pow", I, "either-naming:delta", RUN("rod", "--set", "delta=(-1)**t"))
    add("tb_rod_u0_1_over_x", I, "refuse-naming:u0", RUN("rod", "--set", "u0=1/x"))
    add("tb_tp3_delta_log", I, "either-naming:delta", RUN("tp3", "--set", "delta=log(t)"))
    add("tb_memory_rod_delta_pole", I, "either-naming:delta", RUN("memory_rod", "--set", "delta=1/(t-0.1)"))
    add("tb_memory_slab_traction_pole", I, "either-naming:traction_top",
        RUN("memory_slab", "--set", "traction_top=(0, 1/(t-0.1))"))
    add("tb_memory_kernel_1_over_t", I, "either-naming:kernel",
        RUN("memory_slab", "--set", "kernel=1/t", "--set", "kernel_E=-100", "--set", "prony=[]"))
    add("tb_memory_kernel_pole", I, "either-naming:kernel",
        RUN("memory_slab", "--set", "kernel=exp(-t)/(t-0.05)", "--set", "kernel_E=-100", "--set", "prony=[]"))
    add("tb_memory_kernel_exponentials_pole", I, "either-naming:kernel",
        RUN("memory_slab", "--set", "kernel=1/(t-0.05)", "--set", "kernel_E=-100", "--set", "prony=[]",
            "--set", "kernel_approximation=exponentials"))
    add("tb_width_1e308", I, "either-naming:width", RUN("slab", "--set", "width=1e308"), quick=True)
    add("tb_height_1e308", I, "either-naming:height", RUN("slab", "--set", "height=1e308"))
    add("tb_length_1e308", I, "either-naming:length", RUN("rod", "--set", "length=1e308"))
    add("tb_radius_1e308", I, "either-naming:radius", RUN("hertz", "--set", "radius=1e308"))
    add("tb_h_5e-324", I, "refuse-naming:h", RUN("tp1", "--h", "5e-324"), quick=True)
    add("tb_h_set_5e-324_slab", I, "refuse-naming:h", RUN("slab", "--set", "h=5e-324"))
    add("tb_k_5e-324", I, "refuse-naming:k", RUN("tp1", "--k", "5e-324"))
    add("tb_a1_1e308", I, "either-naming:a1", RUN("slab", "--set", "a1=1e308"), quick=True)
    add("tb_a2_1e308", I, "either-naming:a2", RUN("slab", "--set", "a2=1e308"))
    add("tb_E_1e308", I, "either-naming:E", RUN("slab", "--set", "E=1e308"))
    add("tb_c_nu_1e308", I, "either-naming:c_nu", RUN("tp5", "--set", "c_nu=1e308"))
    add("tb_gamma_nu_1e308", I, "either-naming:gamma_nu", RUN("tp5", "--set", "gamma_nu=1e308"))
    add("tb_L_1e-308", I, "either-naming:L", RUN("tp1", "--set", "L=1e-308"))
    add("tb_b_1e308", I, "either-naming:b", RUN("tp1", "--set", "b=1e308"))
    add("tb_F_1e308", I, "either-naming:F", RUN("memory_slab", "--set", "F=1e308"))
    add("tb_kernel_E_1e308", I, "either-naming:kernel_E", RUN("memory_slab", "--set", "kernel_E=1e308"))
    add("tb_prony_1e308", I, "either-naming:prony", RUN("memory_slab", "--set", "prony=[[-1e308, 0.3, 0.5]]"))
    add("tb_prony_tau_0", I, "refuse-naming:prony", RUN("memory_slab", "--set", "prony=[[-1000, 0.3, 0]]"))
    add("tb_prony_tau_tiny", I, "either-naming:prony", RUN("memory_slab", "--set", "prony=[[-1000, 0.3, 1e-300]]"))
    add("tb_tau_1e308", I, "either-naming:tau", RUN("hertz", "--set", "tau=1e308"))
    add("tb_threads_100000", I, "either-naming:threads", RUN("tp1", "--threads", "100000"), quick=True)
    add("tb_threads_100000_slab", I, "either-naming:threads", RUN("slab", "--threads", "100000"))
    add("tb_nx_1e12", I, "either-naming:nx", RUN("slab", "--set", "nx=1000000000000"))
    add("tb_nx_1e308", I, "refuse-naming:nx", RUN("slab", "--set", "nx=1e308"))
    add("tb_probe_1e308", I, "refuse-naming:probes", RUN("slab", "--set", "probes=[[1e308, 0]]"))
    add("tb_snapshot_1e308", I, "refuse-naming:snapshots", RUN("slab", "--set", "snapshots=[1e308]"))
    add("tb_point_force_at_1e308", I, "either-naming:point_force_at",
        RUN("tp4", "--set", "point_force_at=[[1e308, 1e308]]"))
    add("tb_elastic_tensor_huge", I, "either-naming:elastic_tensor",
        RUN("slab", "--set", "elastic_tensor=[[1e308,0,0],[0,1e308,0],[0,0,1e308]]"))
    add("tb_elastic_tensor_wrong_shape", I, "refuse-naming:elastic_tensor",
        RUN("slab", "--set", "elastic_tensor=[[1,2],[3,4]]"))
    add("tb_elastic_tensor_indefinite", I, "refuse-naming:elastic_tensor",
        RUN("slab", "--set", "elastic_tensor=[[-1,0,0],[0,-1,0],[0,0,-1]]"))
    add("tb_viscous_tensor_nan", I, "refuse-naming:viscous_tensor",
        RUN("slab", "--set", "viscous_tensor=[[nan,0,0],[0,1,0],[0,0,1]]"))
    add("tb_viscous_tensor_ragged", I, "refuse-naming:viscous_tensor",
        RUN("slab", "--set", "viscous_tensor=[[1,0,0],[0,1],[0,0,1]]"))
    add("tb_api_record_times_5", I, "refuse-naming:record_times", code=f"{PY_RUN}, record_times=5)", quick=True)
    add("tb_api_h_array", I, "refuse-naming:h", code='import numpy as np\nworkbench.run("tp1", h=np.array([0.1, 0.2]), '
                                                     'k=0.05, T=0.2, progress=False)', quick=True)
    add("tb_api_study_reference_42", I, "refuse-naming:reference", code=f"{PY_STUDY_NOREF}, reference=42).run(progress=False)",
        quick=True)
    add("tb_api_study_sweep_nonexistent", I, "refuse-naming:nonexistent",
        code=f'{PY_STUDY}, sweep={{"nonexistent": [1]}}).run(progress=False)', quick=True)
    add("tb_api_study_measures_text", I, "refuse-naming:measures",
        code=f'{PY_STUDY}, measures=lambda ds: {{"x": "text"}}).run(progress=False)', quick=True)
    add("tb_api_study_measures_not_callable", I, "refuse-naming:measures",
        code=f'{PY_STUDY}, measures=5).run(progress=False)', quick=True)
    add("tb_api_study_measures_returns_5", I, "refuse-naming:measures",
        code=f'{PY_STUDY}, measures=lambda ds: 5).run(progress=False)')
    add("tb_api_study_measures_list", I, "refuse-naming:measures",
        code=f'{PY_STUDY}, measures=lambda ds: [1, 2]).run(progress=False)')
    add("tb_api_study_measures_nan", I, "either-naming:measures",
        code=f'{PY_STUDY}, measures=lambda ds: {{"x": float("nan")}}).run(progress=False)')
    add("tb_api_write_not_dataset", I, "refuse-naming:re:[Dd]ataset", code='workbench.write("not a dataset", "x.nc")',
        quick=True)
    add("tb_api_write_none", I, "refuse-naming:re:[Dd]ataset", code='workbench.write(None, "x.nc")')
    add("tb_api_write_dict", I, "refuse-naming:re:[Dd]ataset", code='workbench.write({"a": 1}, "x.nc")')
    add("tb_api_write_empty_dataset", I, "either", code='import xarray as xr\nworkbench.write(xr.Dataset(), "x.nc")')
    add("tb_api_write_path_42", I, "refuse", code=f'ds = {PY_RUN})\nworkbench.write(ds, 42)')
    add("tb_api_write_path_empty", I, "refuse", code=f'ds = {PY_RUN})\nworkbench.write(ds, "")')
    add("tb_api_write_path_dir", I, "refuse", code=f'ds = {PY_RUN})\nimport os; os.mkdir("d")\nworkbench.write(ds, "d")')
    add("tb_api_write_proc", I, "refuse", code=f'ds = {PY_RUN})\nworkbench.write(ds, "/proc/x.nc")',
        note="the API raising OSError for an unwritable path counts as a traceback here")
    add("tb_api_load_missing", I, "refuse-naming:missing.nc", code='workbench.load("missing.nc")')
    add("tb_api_load_42", I, "refuse", code="workbench.load(42)")
    add("tb_api_load_text_file", I, "refuse-naming:t.nc", code='open("t.nc", "w").write("hello")\nworkbench.load("t.nc")')
    add("tb_toml_nested_arrays_5000", I, "refuse-naming:deep.toml",
        RUN("deep.toml"), setup=files(**{"deep.toml": SLAB_TOML.replace("[parameters]", "x = " + "[" * 5000 + "]" * 5000
                                                                          + "\n[parameters]")}), quick=True)
    add("tb_toml_nested_tables_5000", I, "refuse-naming:deep.toml",
        RUN("deep.toml"), setup=files(**{"deep.toml": SLAB_TOML.replace("[parameters]", "x = " + "{a = " * 5000 + "1"
                                                                          + "}" * 5000 + "\n[parameters]")}))
    add("tb_toml_nested_in_parameters", I, "refuse-naming:deep.toml",
        RUN("deep.toml"), setup=files(**{"deep.toml": SLAB_TOML + "probes = " + "[" * 3000 + "]" * 3000 + "\n"}))
    add("tb_toml_dotted_keys_5000", I, "refuse-naming:deep.toml",
        RUN("deep.toml"), setup=files(**{"deep.toml": 'scene = "slab"\n' + ".".join(["a"] * 5000) + " = 1\n"}))
    add("tb_toml_show_nested_5000", I, "refuse-naming:deep.toml", ["show", "deep.toml"],
        setup=files(**{"deep.toml": "x = " + "[" * 5000 + "]" * 5000 + "\n"}))
    add("tb_scene_dev_zero", I, "refuse-naming:/dev/zero", ["run", "/dev/zero", "--no-progress"], quick=True,
        note="reads /dev/zero: under the harness's address-space limit a MemoryError, else the machine's memory")
    add("tb_show_dev_zero", I, "refuse-naming:/dev/zero", ["show", "/dev/zero"])
    add("tb_restart_dev_zero", I, "refuse-naming:/dev/zero", ["run", "--restart", "/dev/zero", "--no-progress"])
    add("tb_scene_dev_null", "own", "refuse-naming:null", ["run", "/dev/null", "--no-progress"])
    add("tb_mesh_geometry_dev_zero", I, "refuse-naming:/dev/zero", RUN("body.toml"),
        setup=files(**{"body.toml": mesh_toml(geometry="/dev/zero")}))
    add("tb_output_300_chars", I, "refuse-naming:-o", RUN("tp1", "-o", "o" * 300 + ".nc"), quick=True)
    add("tb_output_300_chars_dir", I, "refuse-naming:-o", RUN("tp1", "-o", "d" * 300 + "/out.nc"))
    add("tb_output_path_5000_chars", I, "refuse-naming:-o", RUN("tp1", "-o", "/".join(["d" * 200] * 25) + "/out.nc"))
    add("tb_plot_300_chars", I, "refuse-naming:--plot", RUN("tp1", "--plot", "p" * 300 + ".png"))
    add("tb_vtk_300_chars", I, "refuse-naming:--vtk", RUN("tp5", "--vtk", "v" * 300))
    add("tb_study_output_300_chars", I, "refuse-naming:-o", STUDY + ["-o", "s" * 300 + ".nc"])
    add("tb_study_output_proc", I, "refuse-naming:/proc", STUDY + ["-o", "/proc/s.nc"], quick=True)
    add("tb_run_output_proc", I, "refuse-naming:/proc", RUN("tp1", "-o", "/proc/out.nc"))
    add("tb_run_output_sys", I, "refuse-naming:/sys", RUN("tp1", "-o", "/sys/out.nc"))
    add("tb_run_plot_proc", I, "refuse-naming:/proc", RUN("tp1", "--plot", "/proc/out.png"))
    add("tb_run_vtk_proc", I, "refuse-naming:/proc", RUN("tp5", "--vtk", "/proc/vtk"))
    add("tb_reproduce_out_proc", I, "refuse-naming:/proc",
        ["reproduce", "tp1", "--h", "0.1", "--k", "0.1", "--no-side", "--out", "/proc/r"])
    add("tb_study_scheduler_unreachable", I, "refuse-naming:re:scheduler|tcp://127\\.0\\.0\\.1:9",
        STUDY + ["--scheduler", "tcp://127.0.0.1:9"], quick=True)
    add("tb_study_scheduler_garbage", I, "refuse-naming:re:scheduler|not-an-address",
        STUDY + ["--scheduler", "not-an-address"])
    add("tb_study_scheduler_empty", I, "refuse-naming:scheduler", STUDY + ["--scheduler", ""])
    add("tb_study_scheduler_bad_port", I, "refuse-naming:re:scheduler|99999",
        STUDY + ["--scheduler", "tcp://127.0.0.1:99999"])
    add("tb_study_scheduler_unresolvable", I, "refuse-naming:re:scheduler|no-such-host",
        STUDY + ["--scheduler", "tcp://no-such-host.invalid:8786"])

    # restart with corrupted archives
    def set_attr(name, value):
        def f(ds):
            ds.attrs[name] = value
            return ds
        return f

    def del_attr(name):
        def f(ds):
            ds.attrs.pop(name, None)
            return ds
        return f

    def state_u_len(n):
        def f(ds):
            import numpy as np

            ds = ds.drop_vars("state_u")
            ds["state_u"] = ("state_u_bad", np.zeros(n))
            return ds
        return f

    def state_u_nan(ds):
        ds["state_u"] = ds["state_u"] * float("nan")
        return ds

    def drop_var(name):
        return lambda ds: ds.drop_vars(name)

    def time_reversed(ds):
        return ds.assign_coords(time=ds.time.values[::-1].copy())

    R = ["run", "--restart", "bad.nc", "--set", "T=1.5", "--no-progress"]
    R_O = R + ["-o", "out.nc"]
    add("tb_restart_bad_state_json", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("state_json", "{not json")), quick=True)
    add("tb_restart_no_scene_attr", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=del_attr("scene")), quick=True)
    add("tb_restart_state_u_wrong_length", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=state_u_len(5)), quick=True)
    add("tb_restart_state_u_longer", I, "refuse-naming:bad.nc", R_O, setup=archive("bad.nc", modify=state_u_len(500)))
    add("tb_restart_state_u_nan", I, "refuse-naming:bad.nc", R_O, setup=archive("bad.nc", modify=state_u_nan))
    add("tb_restart_state_u_missing", I, "refuse-naming:bad.nc", R_O, setup=archive("bad.nc", modify=drop_var("state_u")))
    add("tb_restart_state_json_list", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("state_json", "[]")))
    add("tb_restart_state_json_format_99", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("state_json", '{"format": 99}')))
    add("tb_restart_state_json_empty_obj", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("state_json", "{}")))
    add("tb_restart_state_json_removed", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=del_attr("state_json")))
    add("tb_restart_parameters_json_bad", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("parameters_json", "{oops")))
    add("tb_restart_parameters_json_removed", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=del_attr("parameters_json")))
    add("tb_restart_parameters_json_list", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("parameters_json", "[1, 2]")))
    add("tb_restart_parameters_json_bad_value", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("parameters_json", '{"k": -1}')))
    add("tb_restart_scene_unknown", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("scene", "nonexistent_scene")))
    add("tb_restart_time_reversed", I, "refuse-naming:bad.nc", R_O, setup=archive("bad.nc", modify=time_reversed))
    add("tb_restart_no_time", I, "refuse-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=lambda ds: ds.drop_vars(["u_probe", "u_contact", "beta", "step"]).drop_dims("time")))
    add("tb_restart_status_incomplete", "own", "either-naming:bad.nc", R_O,
        setup=archive("bad.nc", modify=set_attr("status", "incomplete")))
    add("tb_restart_truncated", I, "refuse-naming:bad.nc", R_O,
        setup=archive_bytes("bad.nc", lambda b: b[: len(b) // 2]))
    add("tb_restart_zero_bytes", I, "refuse-naming:bad.nc", R_O, setup=files(**{"bad.nc": b""}))
    add("tb_restart_text_file", I, "refuse-naming:bad.nc", R_O, setup=files(**{"bad.nc": "hello\n"}))
    add("tb_restart_png", I, "refuse-naming:bad.nc", R_O,
        setup=files(**{"bad.nc": b"\x89PNG\r\n\x1a\n" + b"\0" * 100}))
    add("tb_restart_flipped_bytes", I, "refuse-naming:bad.nc", R_O,
        setup=archive_bytes("bad.nc", lambda b: b[:2000] + bytes(x ^ 0xFF for x in b[2000:4000]) + b[4000:]))
    add("tb_restart_directory", "own", "refuse-naming:bad.nc", R_O, setup=mkdirs("bad.nc"))
    add("tb_restart_missing", "own", "refuse-naming:bad.nc", R_O)
    add("tb_restart_fifo", "hang", "refuse-naming:bad.nc", R_O, setup=fifo("bad.nc"))
    add("tb_restart_study_archive", "own", "refuse-naming:bad.nc", R_O,
        setup=lambda wd: shutil.copy(fixture("study.nc"), wd / "bad.nc"))
    add("tb_restart_T_before", "own", "refuse-naming:T", ["run", "--restart", "a.nc", "--set", "T=0.5", "--no-progress"],
        setup=archive("a.nc"))
    add("tb_restart_T_nan", "own", "refuse-naming:T", ["run", "--restart", "a.nc", "--set", "T=nan", "--no-progress"],
        setup=archive("a.nc"))
    add("tb_restart_changed_E", "own", "refuse-naming:gamma_nu",
        ["run", "--restart", "a.nc", "--set", "T=1.5", "--set", "gamma_nu=2", "--no-progress"], setup=archive("a.nc"))
    add("tb_restart_other_scene", "own", "refuse-naming:re:tp2|tp1",
        ["run", "tp2", "--restart", "a.nc", "--set", "T=1.5", "--no-progress"], setup=archive("a.nc"))
    add("tb_restart_valid", "wrongly_refused", "run",
        ["run", "--restart", "a.nc", "--set", "T=1.5", "--no-progress", "-o", "b.nc"], setup=archive("a.nc"),
        check=archive_intact("a.nc"))
    add("tb_restart_valid_with_scene", "wrongly_refused", "run",
        ["run", "tp1", "--restart", "a.nc", "--h", "0.1", "--k", "0.1", "--T", "1.5", "--no-progress", "-o", "b.nc"],
        setup=archive("a.nc"))
    add("tb_restart_valid_memory", "wrongly_refused", "run",
        ["run", "--restart", "m.nc", "--set", "T=0.4", "--no-progress", "-o", "b.nc"],
        setup=archive("m.nc", source="memory_rod.nc"))
    add("tb_restart_valid_slab_plot", "wrongly_refused", "run",
        ["run", "--restart", "s.nc", "--set", "T=0.1", "--no-progress", "-o", "b.nc", "--plot", "b.png"],
        setup=archive("s.nc", source="tp5.nc"))
    add("tb_restart_same_T", "own", "either", ["run", "--restart", "a.nc", "--no-progress", "-o", "b.nc"],
        setup=archive("a.nc"))
    add("tb_restart_empty_path", "own", "refuse-naming:--restart", ["run", "--restart", "", "--no-progress"])
    add("tb_restart_twice", "silently_accepted", "refuse-naming:--restart",
        ["run", "--restart", "a.nc", "--restart", "b.nc", "--set", "T=1.5", "--no-progress"],
        setup=chain(archive("a.nc"), archive("b.nc")))
    add("tb_api_load_corrupt_state", I, "either-naming:bad.nc", code='workbench.load("bad.nc")',
        setup=archive("bad.nc", modify=set_attr("state_json", "{not json")))
    add("tb_api_run_restart_42", I, "refuse-naming:restart", code='workbench.run(restart=42, progress=False)')
    add("tb_api_run_restart_bad_json", I, "refuse-naming:bad.nc", code='workbench.run(restart="bad.nc", T=1.5, '
        'progress=False)', setup=archive("bad.nc", modify=set_attr("state_json", "{not json")))

    # degenerate meshes (gmsh 2.2 files written here, given through a TOML scene)
    def nan_node(nodes, elems):
        nodes[5][0] = "nan"

    def inf_node(nodes, elems):
        nodes[5][1] = "inf"

    def collinear(nodes, elems):
        for v in nodes.values():
            v[1] = 0.0

    def sliver(nodes, elems):  # 4 x 4 grid: node (0.25, 0.25) pushed to within 1e-12 of the bottom (a needle)
        nodes[7][1] = 1e-12

    def crack(nodes, elems):  # a second node at the centre's place, used by half of the triangles
        nodes[99] = list(nodes[5])
        for n, (typ, tag, vs) in enumerate(elems):
            if typ == 2 and n % 2 == 0:
                elems[n] = (typ, tag, [99 if v == 5 else v for v in vs])

    def dup_id(nodes, elems):  # the same node number twice in $Nodes
        items = list(nodes.items())
        items.insert(3, (5, [0.3, 0.7, 0.0]))
        return _NodeList(items), elems

    def unused(nodes, elems):
        nodes[99] = [5.0, 5.0, 0.0]

    def unused_nan(nodes, elems):
        nodes[99] = ["nan", "nan", 0.0]

    def missing_node(nodes, elems):
        typ, tag, vs = elems[-1]
        elems[-1] = (typ, tag, [vs[0], vs[1], 999])

    def clockwise(nodes, elems):
        for n, (typ, tag, vs) in enumerate(elems):
            if typ == 2:
                elems[n] = (typ, tag, vs[::-1])

    def no_triangles(nodes, elems):
        return nodes, [e for e in elems if e[0] != 2]

    def degenerate_triangle(nodes, elems):  # one triangle repeating a node
        elems.append((2, 5, [1, 1, 2]))

    def duplicate_triangle(nodes, elems):
        elems.append(next(e for e in elems if e[0] == 2))

    def below(nodes, elems):
        for v in nodes.values():
            v[1] -= 0.5

    def lifted(nodes, elems):
        for v in nodes.values():
            v[1] += 0.5

    def scale(f):
        def m(nodes, elems):
            for v in nodes.values():
                v[0] *= f
                v[1] *= f
        return m

    def z_nonzero(nodes, elems):
        nodes[5][2] = 0.3

    def quads(nodes, elems):
        elems.append((3, 5, [1, 2, 5, 4]))

    def p2_triangle(nodes, elems):
        elems.append((9, 5, [1, 2, 5, 4, 5, 6]))

    def unnamed_boundary(nodes, elems):
        for n, (typ, tag, vs) in enumerate(elems):
            if typ == 1 and tag == 2:
                elems[n] = (typ, 42, vs)

    add("mesh_nan_coordinate", I, "refuse-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(nan_node)),
        quick=True)
    add("mesh_inf_coordinate", I, "refuse-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(inf_node)))
    add("mesh_all_points_on_a_line", I, "refuse-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(collinear)),
        quick=True)
    add("mesh_sliver", I, "either-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(sliver, nx=4, ny=4)),
        quick=True)
    add("mesh_duplicated_nodes_crack", I, "either-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(crack)),
        quick=True)
    add("mesh_duplicated_node_id", I, "refuse-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(dup_id)))
    add("mesh_unused_node", I, "either-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(unused)), quick=True)
    add("mesh_unused_nan_node", I, "either-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(unused_nan)))
    add("mesh_missing_node_index", I, "refuse-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(missing_node)))
    add("mesh_clockwise_triangles", "own", "either-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(msh2d(clockwise)))
    add("mesh_no_triangles", "own", "refuse-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(no_triangles)))
    add("mesh_degenerate_triangle", I, "refuse-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(msh2d(degenerate_triangle)))
    add("mesh_duplicate_triangle", I, "either-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(msh2d(duplicate_triangle)))
    add("mesh_below_foundation", "own", "refuse-naming:re:below|foundation", RUN("body.toml"),
        setup=mesh_case(msh2d(below)))
    add("mesh_lifted_off_foundation", "own", "either", RUN("body.toml"), setup=mesh_case(msh2d(lifted)))
    add("mesh_scale_1e300", I, "either-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(scale(1e300))))
    add("mesh_scale_1e-300", I, "either-naming:body.msh", RUN("body.toml"), setup=mesh_case(msh2d(scale(1e-300))))
    add("mesh_2d_with_z", "own", "refuse-naming:re:z = 0|plane", RUN("body.toml"), setup=mesh_case(msh2d(z_nonzero)))
    add("mesh_quads", "own", "refuse-naming:re:quad|type", RUN("body.toml"), setup=mesh_case(msh2d(quads)))
    add("mesh_p2_triangles", "own", "refuse-naming:re:triangle6|type", RUN("body.toml"),
        setup=mesh_case(msh2d(p2_triangle)))
    add("mesh_unnamed_boundary", "own", "refuse-naming:bc42", RUN("body.toml"), setup=mesh_case(msh2d(unnamed_boundary)))
    add("mesh_valid_1x1_cell", "unclear", "run", RUN("body.toml"), setup=mesh_case(msh2d(nx=1, ny=1)), quick=True,
        note="a valid mesh of one square (two triangles): the issue saw an unclear error")
    add("mesh_valid_2x2", "wrongly_refused", "run", RUN("body.toml"), setup=mesh_case(msh2d()), quick=True)
    add("mesh_valid_4x2_plot_vtk", "wrongly_refused", "run",
        RUN("body.toml", "-o", "m.nc", "--plot", "m.png", "--vtk", "vtk"), setup=mesh_case(msh2d(nx=4, ny=2)))
    add("mesh_valid_model_B", "wrongly_refused", "run", RUN("body.toml"), setup=mesh_case(msh2d(nx=4, ny=2), model="B"))
    add("mesh_valid_3d", "wrongly_refused", "run", RUN("body.toml"), setup=mesh_case(msh3d(), dim=3))
    add("mesh_valid_3d_model_B", "wrongly_refused", "run", RUN("body.toml"), setup=mesh_case(msh3d(), dim=3, model="B"))
    add("mesh_valid_show", "wrongly_refused", "run", ["show", "body.toml"], setup=mesh_case(msh2d()))
    add("mesh_valid_study", "wrongly_refused", "run",
        ["study", "body.toml", "--k", "0.05", "0.025", "--workers", "0", "--no-progress"], setup=mesh_case(msh2d()))
    add("mesh_2d_given_to_mesh3d", "unclear", "refuse-naming:re:2D|3D|dimension", RUN("body.toml"),
        setup=mesh_case(msh2d(), scene="mesh3d"), quick=True)
    add("mesh_3d_given_to_mesh2d", "unclear", "refuse-naming:re:2D|3D|dimension", RUN("body.toml"),
        setup=mesh_case(msh3d(), dim=3, scene="mesh2d"))
    add("mesh_2d_given_to_memory_mesh3d", "unclear", "refuse-naming:re:2D|3D|dimension", RUN("body.toml"),
        setup=mesh_case(msh2d(), scene="memory_mesh3d"))
    add("mesh_3d_flat", I, "refuse-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(msh3d(lambda n, e: [v.__setitem__(2, 0.0) for v in n.values()] and None), dim=3))
    add("mesh_3d_nan", I, "refuse-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(msh3d(lambda n, e: n[5].__setitem__(0, "nan")), dim=3))
    add("mesh_unreadable_gmsh", "unclear", "refuse-naming:body.msh", RUN("body.toml"),
        setup=mesh_case("this is not a mesh\n\x01\x02 garbage\n"), quick=True)
    add("mesh_gmsh_binary_garbage", "unclear", "refuse-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(bytes(range(256)) * 20))
    add("mesh_gmsh_truncated", "unclear", "refuse-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(msh2d()[:300]))
    add("mesh_gmsh_empty", "unclear", "refuse-naming:body.msh", RUN("body.toml"), setup=mesh_case(""))
    add("mesh_gmsh_wrong_version", "unclear", "refuse-naming:body.msh", RUN("body.toml"),
        setup=mesh_case(msh2d().replace("2.2 0 8", "9.9 0 8")))
    add("mesh_bad_vol", "unclear", "refuse-naming:body.vol", RUN("body.toml"),
        setup=mesh_case("mesh3d\nthis is not a netgen file\n", msh_name="body.vol"), quick=True)
    add("mesh_empty_vol", "unclear", "refuse-naming:body.vol", RUN("body.toml"), setup=mesh_case("", msh_name="body.vol"))
    add("mesh_vol_gz_garbage", "unclear", "refuse-naming:body.vol.gz", RUN("body.toml"),
        setup=mesh_case(b"\x1f\x8b\x08\x00garbage", msh_name="body.vol.gz"))
    add("mesh_fifo", "hang", "refuse-naming:body.msh", RUN("body.toml"),
        setup=chain(fifo("body.msh"), files(**{"body.toml": mesh_toml()})), quick=True)
    add("mesh_symlink_dev_zero", "hang", "refuse-naming:body.msh", RUN("body.toml"),
        setup=chain(symlink("body.msh", "/dev/zero"), files(**{"body.toml": mesh_toml()})))
    add("mesh_is_directory", "own", "refuse-naming:body.msh", RUN("body.toml"),
        setup=chain(mkdirs("body.msh"), files(**{"body.toml": mesh_toml()})))
    add("mesh_missing_file", "own", "refuse-naming:body.msh", RUN("body.toml"),
        setup=files(**{"body.toml": mesh_toml()}))
    add("mesh_unknown_format", "own", "refuse-naming:body.stl", RUN("body.toml"),
        setup=mesh_case("solid x\nendsolid x\n", msh_name="body.stl"))
    add("mesh_geometry_number", "own", "refuse-naming:geometry", RUN("body.toml"),
        setup=files(**{"body.toml": "geometry = 42\n[boundaries]\nbottom = \"contact\"\n"}))
    add("mesh_role_typo", "own", "refuse-naming:contactt", RUN("body.toml"),
        setup=mesh_case(msh2d(), roles=dict(ROLES2D, bottom="contactt")))
    add("mesh_role_missing", "own", "refuse-naming:right", RUN("body.toml"),
        setup=mesh_case(msh2d(), roles={k: v for k, v in ROLES2D.items() if k != "right"}))
    add("mesh_role_unknown_boundary", "own", "refuse-naming:nonexistent", RUN("body.toml"),
        setup=mesh_case(msh2d(), roles=dict(ROLES2D, nonexistent="free")))
    add("mesh_no_contact_role", "own", "refuse-naming:contact", RUN("body.toml"),
        setup=mesh_case(msh2d(), roles=dict(ROLES2D, bottom="free")))
    add("mesh_no_clamped_role", "own", "refuse-naming:clamped", RUN("body.toml"),
        setup=mesh_case(msh2d(), roles=dict(ROLES2D, left="free")))
    add("mesh_role_number", "own", "refuse-naming:bottom", RUN("body.toml"),
        setup=mesh_case(msh2d(), roles=dict(ROLES2D, bottom=5)))
    add("mesh_model_C", "own", "refuse-naming:model", RUN("body.toml"), setup=mesh_case(msh2d(), model="C"))
    add("mesh_h_given", "own", "refuse-naming:h", RUN("body.toml", "--h", "0.1"), setup=mesh_case(msh2d()))
    add("mesh_boundaries_not_table", "own", "refuse-naming:boundaries", RUN("body.toml"),
        setup=mesh_case(msh2d(), toml_text='geometry = "body.msh"\nboundaries = 5\n'))
    add("mesh_traction_wrong_dim", "silently_accepted", "refuse-naming:traction", RUN("body.toml"),
        setup=mesh_case(msh2d(), params={"traction": "(0,)", "k": 0.05, "T": 0.1}))
    add("mesh_traction_3_components_2d", "silently_accepted", "refuse-naming:traction", RUN("body.toml"),
        setup=mesh_case(msh2d(), params={"traction": "(0, 0, -1)", "k": 0.05, "T": 0.1}))
    add("mesh_probe_outside", "own", "refuse-naming:probes", RUN("body.toml"),
        setup=mesh_case(msh2d(), params={"traction": "(0, -t)", "k": 0.05, "T": 0.1, "probes": [[5.0, 5.0]]}))
    add("mesh_changed_after_archive", "own", "refuse-naming:re:mesh|changed|digest",
        ["run", "--restart", "m.nc", "--set", "T=0.2", "--no-progress"],
        setup=lambda wd: _archive_then_change_mesh(wd))

    # ============================================ silently accepted ============================================
    I = "silently_accepted"  # noqa: E741
    add("sa_traction_one_component", I, "refuse-naming:traction_top", RUN("slab", "--set", "traction_top=(0,)"),
        quick=True)
    add("sa_traction_three_components_2d", I, "refuse-naming:traction_top",
        RUN("slab", "--set", "traction_top=(0, 0, 1)"))
    add("sa_traction_empty_tuple", I, "refuse-naming:traction_top", RUN("slab", "--set", "traction_top=()"))
    add("sa_traction_scalar_nonzero", I, "refuse-naming:traction_top", RUN("slab", "--set", "traction_top=1"))
    add("sa_block_traction_two_components", I, "refuse-naming:traction_top", RUN("block", "--set", "traction_top=(0, 1)"))
    add("sa_point_force_one_component", I, "refuse-naming:point_force", RUN("tp4", "--set", "point_force=(1,)"))
    add("sa_body_force_one_component", I, "refuse-naming:body_force", RUN("slab", "--set", "body_force=(0,)"))
    add("sa_memory_traction_one_component", I, "refuse-naming:traction_top",
        RUN("memory_slab", "--set", "traction_top=(0,)"))
    add("sa_rod_delta_vector", I, "refuse-naming:delta", RUN("rod", "--set", "delta=(0, 1)"))
    add("sa_hertz_load_vector", I, "refuse-naming:load", RUN("hertz", "--set", "load=(0, 10*t)"))
    add("sa_two_outputs", I, "refuse-naming:re:-o|--output", RUN("tp1", "-o", "a.nc", "-o", "b.nc"), quick=True)
    add("sa_two_plots", I, "refuse-naming:--plot", RUN("tp1", "--plot", "a.png", "--plot", "b.png"))
    add("sa_two_vtk", I, "refuse-naming:--vtk", RUN("tp5", "--vtk", "v1", "--vtk", "v2"))
    add("sa_h_twice", I, "refuse-naming:re:--h|\\bh\\b", ["run", "tp1", "--h", "0.1", "--h", "0.2", "--k", "0.05", "--T",
                                                        "0.2"])
    add("sa_k_twice", I, "refuse-naming:re:--k|\\bk\\b", ["run", "tp1", "--h", "0.1", "--k", "0.05", "--k", "0.1",
                                                        "--T", "0.2"])
    add("sa_threads_twice", I, "refuse-naming:--threads", RUN("tp1", "--threads", "1", "--threads", "2"))
    add("sa_study_two_outputs", I, "refuse-naming:re:-o|--output", STUDY + ["-o", "a.nc", "-o", "b.nc"])
    add("sa_study_reference_twice", I, "refuse-naming:--reference", STUDY + ["--reference", "finest"])
    add("sa_api_study_grids_empty", I, "refuse-naming:grids",
        code='workbench.Study("tp1", h=0.1, k=[0.1, 0.05], T=0.2, reference="ode", workers=0, grids=[]).run('
             'progress=False)', quick=True)
    add("sa_api_study_grids_empty_dict", I, "refuse-naming:grids",
        code=f'{PY_STUDY}, grids=[{{}}]).run(progress=False)')
    add("sa_api_study_sweep_empty_list", I, "refuse-naming:gamma_nu",
        code=f'{PY_STUDY}, sweep={{"gamma_nu": []}}).run(progress=False)')
    add("sa_api_study_k_empty", I, "refuse-naming:k", code='workbench.Study("tp1", h=0.1, k=[], T=0.2, reference="ode", '
                                                         'workers=0).run(progress=False)')
    add("sa_api_study_sweep_string", I, "refuse-naming:k",
        code='workbench.Study("tp1", h=0.1, sweep={"k": "0.1"}, T=0.2, reference="ode", workers=0).run(progress=False)')
    add("sa_api_study_k_duplicates", I, "either-naming:k",
        code='workbench.Study("tp1", h=0.1, k=[0.1, 0.1], T=0.2, reference="ode", workers=0).run(progress=False)')
    add("sa_api_run_unknown_kw", I, "refuse-naming:nonexistent", code=f"{PY_RUN}, nonexistent=1)")
    add("sa_api_run_progress_text", I, "refuse-naming:progress", code='workbench.run("tp1", h=0.1, k=0.05, T=0.2, progress="no")')
    add("sa_snapshots_after_T", I, "refuse-naming:snapshots", RUN("tp1", "--set", "snapshots=[5]"))
    add("sa_snapshots_negative", I, "refuse-naming:snapshots", RUN("tp1", "--set", "snapshots=[-1]"))
    add("sa_snapshots_nan", I, "refuse-naming:snapshots", RUN("tp1", "--set", "snapshots=[nan]"))
    add("sa_snapshots_nested", I, "refuse-naming:snapshots", RUN("tp1", "--set", "snapshots=[[0.1]]"))
    add("sa_snapshots_text", I, "refuse-naming:snapshots", RUN("tp1", "--set", "snapshots=abc"))
    add("sa_snapshots_unsorted", "own", "either-naming:snapshots", RUN("tp1", "--set", "snapshots=[0.1, 0.05]"))
    add("sa_snapshots_duplicate", "own", "either-naming:snapshots", RUN("tp1", "--set", "snapshots=[0.1, 0.1]"))
    add("sa_probe_outside_slab", I, "refuse-naming:probes", RUN("slab", "--set", "probes=[[5, 5]]"), quick=True)
    add("sa_probe_outside_rod", I, "refuse-naming:probes", RUN("rod", "--set", "probes=[[2]]"))
    add("sa_probe_negative_rod", I, "refuse-naming:probes", RUN("rod", "--set", "probes=[[-0.5]]"))
    add("sa_probe_outside_block", I, "refuse-naming:probes", RUN("block", "--set", "probes=[[0.5, 0.1, 5]]"))
    add("sa_probe_outside_hertz", I, "refuse-naming:probes", RUN("hertz", "--set", "probes=[[5, 5]]"))
    add("sa_probe_outside_memory_slab", I, "refuse-naming:probes", RUN("memory_slab", "--set", "probes=[[5, 5]]"))
    add("sa_probe_wrong_dim_slab", I, "refuse-naming:probes", RUN("slab", "--set", "probes=[[0.5]]"))
    add("sa_probe_3d_on_slab", I, "refuse-naming:probes", RUN("slab", "--set", "probes=[[0.5, 0, 0]]"))
    add("sa_probe_nan", I, "refuse-naming:probes", RUN("slab", "--set", "probes=[[nan, 0]]"))
    add("sa_probe_text", I, "refuse-naming:probes", RUN("slab", "--set", "probes=abc"))
    add("sa_probe_empty_point", I, "refuse-naming:probes", RUN("slab", "--set", "probes=[[]]"))
    add("sa_probes_none", "own", "either-naming:probes", RUN("slab", "--set", "probes=[]"))
    add("sa_point_force_at_outside", I, "refuse-naming:point_force_at", RUN("tp4", "--set", "point_force_at=[[5, 5]]"))
    add("sa_point_force_at_nan", I, "refuse-naming:point_force_at", RUN("tp4", "--set", "point_force_at=[[nan, 0]]"))
    add("sa_u0_mismatch_delta", I, "refuse-naming:u0", RUN("rod", "--set", "u0=-0.5"))
    add("sa_u0_vector_on_slab", I, "either-naming:u0", RUN("slab", "--set", "u0=(0,)"))
    add("sa_order_float", I, "refuse-naming:order", RUN("tp1", "--set", "order=1.5"))
    add("sa_nx_float", I, "refuse-naming:nx", RUN("slab", "--set", "nx=3.7"))
    add("sa_allow_unstable_yes", I, "either-naming:allow_unstable", RUN("tp1", "--set", "allow_unstable=yes"))
    add("sa_contact_2", I, "refuse-naming:contact", RUN("tp1", "--set", "contact=2"))
    add("sa_adhesion_half", I, "refuse-naming:adhesion", RUN("tp1", "--set", "adhesion=0.5"))
    add("sa_bonding_truncation_upper", I, "either-naming:bonding_truncation",
        RUN("tp1", "--set", "bonding_truncation=TENSION"))
    add("sa_scheme_capitalised", I, "either-naming:scheme", RUN("tp1", "--scheme", "Implicit"))
    add("sa_kernel_x", I, "refuse-naming:kernel", RUN("memory_slab", "--set", "kernel=x"))
    add("sa_prony_wrong_tuple", I, "refuse-naming:prony", RUN("memory_slab", "--set", "prony=[[1, 2]]"))
    add("sa_prony_rod_triple", I, "refuse-naming:prony", RUN("memory_rod", "--set", "prony=[[0.5, 0.3, 0.2]]"))
    add("sa_api_times_decreasing", I, "refuse-naming:times", code=f"{PY_RUN}, times=[0, 0.1, 0.05, 0.2])")
    add("sa_api_times_duplicates", I, "refuse-naming:times", code=f"{PY_RUN}, times=[0, 0.1, 0.1, 0.2])")
    add("sa_api_times_not_to_T", I, "refuse-naming:times", code=f"{PY_RUN}, times=[0, 0.1])")
    add("sa_api_times_2d", I, "refuse-naming:times", code=f"{PY_RUN}, times=[[0, 0.1], [0.1, 0.2]])")
    add("sa_api_times_empty", I, "refuse-naming:times", code=f"{PY_RUN}, times=[])")
    add("sa_api_times_text", I, "refuse-naming:times", code=f'{PY_RUN}, times="abc")')
    add("sa_api_record_times_negative", I, "refuse-naming:record_times|record time", code=f"{PY_RUN}, record_times=[-0.1])")
    add("sa_api_record_times_after_T", I, "refuse-naming:record_times|record time", code=f"{PY_RUN}, record_times=[5.0])")
    add("sa_api_record_times_nan", I, "refuse-naming:record_times|record time", code=f'{PY_RUN}, record_times=[float("nan")])')
    add("sa_api_record_times_text", I, "refuse-naming:record_times|record time", code=f'{PY_RUN}, record_times="abc")')
    add("sa_api_limit_negative", I, "refuse-naming:limit", code=f"{PY_RUN}, limit=-1)")
    add("sa_api_limit_nan", I, "refuse-naming:limit", code=f'{PY_RUN}, limit=float("nan"))')
    add("sa_api_limit_zero", I, "refuse-naming:limit", code=f"{PY_RUN}, limit=0)")
    add("sa_api_threads_zero", I, "refuse-naming:threads", code=f"{PY_RUN}, threads=0)")
    add("sa_api_threads_text", I, "refuse-naming:threads", code=f'{PY_RUN}, threads="2")')
    add("sa_api_threads_float", I, "refuse-naming:threads", code=f"{PY_RUN}, threads=2.5)")
    add("sa_api_model_text", I, "refuse-naming:model", code=f'{PY_RUN}, model="A")')
    add("sa_api_checkpoint_42", I, "refuse-naming:checkpoint", code=f"{PY_RUN}, checkpoint_every=2, checkpoint=42)")
    add("sa_api_k_text", I, "refuse-naming:k", code='workbench.run("tp1", h=0.1, k="abc", T=0.2, progress=False)')
    add("sa_api_k_bool", I, "refuse-naming:k", code='workbench.run("tp1", h=0.1, k=True, T=0.2, progress=False)')
    add("sa_api_k_none", I, "either-naming:k", code='workbench.run("tp1", h=0.1, k=None, T=0.2, progress=False)')
    add("sa_api_k_complex", I, "refuse-naming:k", code='workbench.run("tp1", h=0.1, k=0.05+1j, T=0.2, progress=False)')
    add("sa_api_k_list", I, "refuse-naming:k", code='workbench.run("tp1", h=0.1, k=[0.05], T=0.2, progress=False)')
    add("sa_api_scene_42", I, "refuse-naming:42", code="workbench.run(42, progress=False)")
    add("sa_api_scene_none", I, "refuse", code="workbench.run(None, progress=False)")
    add("sa_api_scene_unknown_kw", I, "refuse-naming:nonexistent", code='workbench.scene("tp1", nonexistent=1)')
    add("sa_api_scene_mesh_42", I, "refuse-naming:mesh", code='workbench.scene(mesh=42, boundaries={})')
    add("sa_api_scene_model_C", I, "refuse-naming:model",
        code='workbench.scene(mesh="body.msh", boundaries={}, model="C")', setup=files(**{"body.msh": msh2d()}))
    add("sa_api_scene_boundaries_list", I, "refuse-naming:boundaries",
        code='workbench.scene(mesh="body.msh", boundaries=["bottom"])', setup=files(**{"body.msh": msh2d()}))
    add("sa_api_with_k_negative", I, "refuse-naming:k", code='workbench.scene("tp1").with_(k=-1)')

    # ============================================ hangs ========================================================
    I = "hang"  # noqa: E741
    add("hang_rod_h_1e-7", I, "either-naming:h", ["run", "rod", "--h", "1e-7", "--k", "0.05", "--T", "0.1",
                                                  "--no-progress"], quick=True)
    add("hang_1e8_steps", I, "either-naming:re:\\bT\\b|\\bk\\b", ["run", "tp1", "--h", "0.1", "--set", "T=1e6", "--set",
                                                                  "k=0.01", "--no-progress"], quick=True)
    add("hang_1e9_steps_k", I, "either-naming:re:\\bT\\b|\\bk\\b", ["run", "tp1", "--h", "0.1", "--k", "1e-9",
                                                                    "--no-progress"])
    add("hang_hertz3d_h_contact_1e-4", I, "either-naming:h_contact", RUN("hertz3d", "--set", "h_contact=1e-4"),
        quick=True)
    add("hang_hertz_h_contact_1e-7", I, "either-naming:h_contact", RUN("hertz", "--set", "h_contact=1e-7"), quick=True)
    add("hang_memory_hertz_h_contact_1e-7", I, "either-naming:h_contact",
        RUN("memory_hertz", "--set", "h_contact=1e-7"))
    add("hang_scene_fifo", I, "refuse-naming:scene.toml", ["run", "scene.toml", "--no-progress"],
        setup=fifo("scene.toml"), quick=True)
    add("hang_show_fifo", I, "refuse-naming:scene.toml", ["show", "scene.toml"], setup=fifo("scene.toml"))
    add("hang_study_fifo", I, "refuse-naming:scene.toml", ["study", "scene.toml", "--k", "0.1", "0.05"],
        setup=fifo("scene.toml"))
    add("hang_slab_1e10_cells", I, "either-naming:re:nx|ny", RUN("slab", "--set", "nx=100000", "--set", "ny=100000"))
    add("hang_block_h_1e-3", I, "either-naming:h", RUN("block", "--h", "0.001"))
    add("hang_hertz3d_h_0.005", I, "either-naming:h", RUN("hertz3d", "--h", "0.005"))
    add("hang_memory_rod_1e5_steps_quadrature", I, "either-naming:re:\\bT\\b|\\bk\\b|kernel",
        RUN("memory_rod", "--set", "T=100", "--set", "k=0.001", "--set", "kernel=exp(-t)", "--set", "kernel_E=0.5",
            "--set", "prony=[]"))
    add("hang_adaptive_tiny_tolerance", I, "either-naming:re:rtol|atol|k_min",
        RUN("tp5", "--scheme", "bdf2", "--set", "rtol=1e-12", "--set", "atol=1e-300", "--set", "k_min=1e-300"))
    add("hang_study_many_cases", I, "either", ["study", "tp1", "--h", "0.1", "--k"] + [str(0.1 / (i + 1)) for i in range(60)]
        + ["--set", "T=0.2", "--reference", "ode", "--workers", "0", "--no-progress"],
        note="60 cases of a cheap scene: legitimate work, should finish")
    add("hang_T_1e308", I, "either-naming:re:\\bT\\b", ["run", "tp1", "--h", "0.1", "--set", "T=1e308",
                                                         "--no-progress"])
    add("hang_order_4_block", I, "either", RUN("block", "--order", "4", "--h", "0.1"))

    # ============================================ unclear errors ===============================================
    I = "unclear"  # noqa: E741
    add("un_hertz_tau_0", I, "refuse-naming:tau", RUN("hertz", "--set", "tau=0"), quick=True)
    add("un_hertz3d_tau_0", I, "refuse-naming:tau", RUN("hertz3d", "--set", "tau=0"))
    add("un_hertz_tau_negative", I, "refuse-naming:tau", RUN("hertz", "--set", "tau=-1"))
    add("un_hertz_tau_nan", I, "refuse-naming:tau", RUN("hertz", "--set", "tau=nan"))
    add("un_hertz_tau_1e-300", I, "either-naming:tau", RUN("hertz", "--set", "tau=1e-300"))
    add("un_nu_-0.9999999", I, "either-naming:nu", RUN("slab", "--set", "nu=-0.9999999"), quick=True)
    add("un_nu_-0.9999999_hertz", I, "either-naming:nu", RUN("hertz", "--set", "nu=-0.9999999"))
    add("un_nu_0.4999999_hertz", I, "either-naming:nu", RUN("hertz", "--set", "nu=0.4999999"))
    add("un_nu_0.4999999_memory", I, "either-naming:nu", RUN("memory_slab", "--set", "nu=0.4999999",
                                                             "--set", "plane=strain"))
    add("un_kernel_nu_-0.9999999", I, "either-naming:kernel_nu", RUN("memory_slab", "--set", "kernel_nu=-0.9999999"))
    add("un_a_1e308", I, "either-naming:re:\\ba\\s*=|'a'|\\ba\\b \\(", RUN("tp1", "--set", "a=1e308"), quick=True)
    add("un_a_1e-308", I, "either-naming:re:\\ba\\s*=|'a'|\\ba\\b \\(", RUN("tp1", "--set", "a=1e-308"))
    add("un_output_empty", I, "refuse-naming:re:-o|--output", RUN("tp1", "-o", ""), quick=True)
    add("un_plot_empty", I, "refuse-naming:--plot", RUN("tp1", "--plot", ""))
    add("un_vtk_empty", I, "refuse-naming:--vtk", RUN("tp5", "--vtk", ""))
    add("un_study_output_empty", I, "refuse-naming:re:-o|--output", STUDY + ["-o", ""])
    add("un_reproduce_out_empty", I, "refuse-naming:--out", ["reproduce", "tp1", "--out", ""])
    add("un_scene_empty", I, "refuse-naming:scene", ["run", "", "--no-progress"])
    add("un_output_readonly_dir", I, "refuse-naming:ro/out.nc", RUN("tp1", "-o", "ro/out.nc"), setup=readonly_dir(),
        quick=True)
    add("un_plot_readonly_dir", I, "refuse-naming:ro/out.png", RUN("tp1", "--plot", "ro/out.png"), setup=readonly_dir())
    add("un_study_output_readonly_dir", I, "refuse-naming:ro/s.nc", STUDY + ["-o", "ro/s.nc"], setup=readonly_dir())
    add("un_output_readonly_chmod_as_root", "own", "run", RUN("tp1", "-o", "d/out.nc"),
        setup=lambda wd: ((wd / "d").mkdir(), os.chmod(wd / "d", 0o555)) and None,
        note="root may write into a 0555 folder: the run should simply succeed")
    add("un_output_parent_is_file", I, "refuse-naming:f/out.nc", RUN("tp1", "-o", "f/out.nc"), setup=files(f="x"))
    add("un_output_is_directory", "own", "refuse-naming:d", RUN("tp1", "-o", "d"), setup=mkdirs("d"))
    add("un_api_write_readonly", I, "refuse-naming:ro/x.nc", code=f'ds = {PY_RUN})\nworkbench.write(ds, "ro/x.nc")',
        setup=readonly_dir())

    # ============================================ wrongly refused ==============================================
    I = "wrongly_refused"  # noqa: E741
    s120 = "(0, " + "+".join(["0.001*t"] * 120) + ")"
    add("wr_sum_120_terms", I, "run", RUN("slab", "--set", f"traction_top={s120}"), quick=True)
    add("wr_sum_120_terms_hertz", I, "run", RUN("hertz", "--set", "load=" + "+".join(["0.1*t"] * 120)))
    add("wr_sum_120_terms_delta", I, "run", RUN("rod", "--set", "delta=" + "+".join(["-0.001*t"] * 120)))
    add("wr_sum_500_terms", I, "either-naming:traction_top", RUN("slab", "--set", "traction_top=(0, " + "+".join(["0.001*t"] * 500) + ")"))
    add("wr_sum_2000_terms", I, "either-naming:traction_top",
        RUN("slab", "--set", "traction_top=(0, " + "+".join(["0.0001*t"] * 2000) + ")"))
    add("wr_product_120_factors", I, "run", RUN("slab", "--set", "traction_top=(0, t*" + "*".join(["1.0"] * 120) + ")"))
    add("wr_parens_50_deep", I, "run", RUN("slab", "--set", "traction_top=(0, " + "(" * 50 + "t" + ")" * 50 + ")"))
    add("wr_parens_300_deep", I, "either-naming:traction_top",
        RUN("slab", "--set", "traction_top=(0, " + "(" * 300 + "t" + ")" * 300 + ")"))
    add("wr_nested_functions_30", I, "run", RUN("slab", "--set", "traction_top=(0, " + "sin(" * 30 + "t" + ")" * 30 + ")"))
    add("wr_caret_power", I, "run", RUN("slab", "--set", "traction_top=(0, t^2)"))
    add("wr_ifpos", I, "run", RUN("slab", "--set", "traction_top=(0, 5*t*ifpos(x - 0.5, 1, 0))"))
    add("wr_no_spaces", I, "run", RUN("slab", "--set", "traction_top=(0,-t)"))
    add("wr_many_spaces", I, "run", RUN("slab", "--set", "traction_top=  ( 0 ,   - t )  "))
    add("wr_pi_expression", I, "run", RUN("slab", "--set", "traction_top=(0, sin(pi*t))"))
    add("wr_scientific_option", I, "run", ["run", "tp1", "--h", "1e-1", "--k", "5e-2", "--T", "2e-1", "--no-progress"])
    add("wr_leading_dot", I, "run", RUN("slab", "--set", "nu=.3"))
    add("wr_T_below_k", I, "either-naming:re:\\bk\\b|\\bT\\b", ["run", "tp1", "--h", "0.1", "--k", "0.05", "--T", "0.001", "--no-progress"])
    add("wr_gamma_nu_0", I, "run", RUN("tp1", "--set", "gamma_nu=0"))
    add("wr_c_nu_0", I, "run", RUN("tp5", "--set", "c_nu=0"))
    add("wr_no_contact_no_adhesion", I, "run", RUN("tp5", "--set", "contact=false", "--set", "adhesion=false"))
    add("wr_scheme_implicit", I, "run", RUN("tp5", "--scheme", "implicit"))
    add("wr_scheme_bdf2_adaptive", I, "run", RUN("tp5", "--scheme", "bdf2", "--set", "rtol=1e-3"))
    add("wr_order_4_rod", I, "run", RUN("tp1", "--order", "4"))
    add("wr_order_2_memory_slab", I, "run", RUN("memory_slab", "--order", "2"))
    add("wr_threads_1", I, "run", RUN("tp5", "--threads", "1"))
    add("wr_threads_2", I, "run", RUN("tp5", "--threads", "2"))
    add("wr_probes_interior", I, "run", RUN("slab", "--set", "probes=[[0.5, 0.05]]"))
    add("wr_snapshots_empty", I, "run", RUN("tp1", "--set", "snapshots=[]"))
    add("wr_plane_strain", I, "run", RUN("slab", "--set", "plane=strain"))
    add("wr_memory_trapezoid", I, "run", RUN("memory_slab", "--set", "memory_rule=trapezoid"))
    add("wr_memory_exponentials", I, "run",
        RUN("memory_slab", "--set", "kernel=exp(-2*t)", "--set", "kernel_E=-100", "--set", "prony=[]",
            "--set", "kernel_approximation=exponentials"))
    add("wr_all_outputs", I, "run", RUN("tp5", "-o", "o.nc", "--plot", "o.png", "--vtk", "vtk"), quick=True)
    add("wr_output_unicode_spaces", I, "run", RUN("tp1", "-o", "résumé ü 数据.nc", "--plot", "ü plot.png"))
    add("wr_output_shell_chars", I, "run", RUN("tp1", "-o", "$(touch pwned);x.nc"), check=no_file("pwned"))
    add("wr_output_no_suffix", I, "run", RUN("tp1", "-o", "out"))
    add("wr_output_leading_dash_name", I, "either", RUN("tp1", "-o=-x.nc"))
    add("wr_output_nested_plot_dirs", I, "run", RUN("tp1", "--plot", "p/q/r.png"))
    add("wr_toml_slab_pull", I, "run", ["run", "@REPO@/docs/examples/slab_pull.toml", "--h", "0.2", "--k", "0.01",
                                        "--T", "0.1", "--no-progress"])
    add("wr_toml_rocker", I, "run", ["run", "@REPO@/docs/examples/rocker.toml", "--set", "T=0.05", "--no-progress"])
    add("wr_toml_unicode_description", I, "run", RUN("u.toml"),
        setup=files(**{"u.toml": SLAB_TOML.replace("[parameters]", 'name = "ünïcødé 数据"\ndescription = "✓ ∀x"\n'
                                                    "[parameters]")}))
    add("wr_toml_traction_table", I, "run", RUN("t.toml"),
        setup=files(**{"t.toml": SLAB_TOML + '[traction]\ntop = "(0, -t)"\nright = "(1, 0)"\n'}))
    add("wr_toml_crlf", I, "run", RUN("t.toml"), setup=files(**{"t.toml": SLAB_TOML.replace("\n", "\r\n").encode()}))
    add("wr_toml_bom", I, "either-naming:t.toml", RUN("t.toml"),
        setup=files(**{"t.toml": b"\xef\xbb\xbf" + SLAB_TOML.encode()}))
    add("wr_toml_big_comment", I, "run", RUN("t.toml"),
        setup=files(**{"t.toml": "# " + "x" * 2_000_000 + "\n" + SLAB_TOML}))
    add("wr_toml_int_for_float", I, "run", RUN("t.toml"), setup=files(**{"t.toml": SLAB_TOML + "E = 1000\nnu = 0\n"}))
    add("wr_toml_order_float", I, "either-naming:order", RUN("t.toml"),
        setup=files(**{"t.toml": SLAB_TOML + "order = 1.0\n"}))
    add("wr_toml_file_named_like_scene", I, "run", ["run", "tp1", "--h", "0.1", "--k", "0.05", "--T", "0.2",
                                                    "--no-progress"], setup=files(tp1="garbage = ["))
    add("wr_show_all_scenes", I, "run", ["scenes"])
    for s in ("rod", "slab", "block", "tp1", "tp2", "tp3", "tp4", "tp5", "memory_rod", "memory_slab", "memory_block",
              "hertz", "hertz3d", "memory_hertz", "memory_hertz3d"):
        add(f"wr_show_{s}", I, "run", ["show", s])
    for s in ("tp2", "tp3", "rod", "block", "memory_rod", "memory_block", "hertz3d", "memory_hertz", "memory_hertz3d"):
        add(f"wr_coarse_run_{s}", I, "run", RUN(s, "-o", "out.nc"))
    add("wr_study_valid", I, "run", STUDY + ["-o", "s.nc", "--plot", "s.png", "--pareto", "p.png"], quick=True)
    add("wr_study_workers_2", I, "run", ["study", "tp1", "--h", "0.1", "--k", "0.1", "0.05", "--set", "T=0.2",
                                         "--reference", "ode", "--workers", "2", "--no-progress"])
    add("wr_study_k_over_h", I, "run", ["study", "tp1", "--h", "0.2", "0.1", "--k-over-h", "0.5", "--set", "T=0.2",
                                        "--workers", "0", "--no-progress"])
    add("wr_study_reference_run", I, "run", STUDY[:-5] + ["--reference", "h=0.05,k=0.01", "--workers", "0",
                                                          "--no-progress"])
    add("wr_reproduce_tp1", I, "run", ["reproduce", "tp1", "--h", "0.1", "--k", "0.1", "--no-side", "--out", "r"])
    add("wr_help", I, "run", ["run", "--help"])
    add("wr_api_run_valid", I, "run", code=f"ds = {PY_RUN})\nworkbench.write(ds, 'x.nc')\n"
        "assert workbench.load('x.nc').attrs['status'] == 'complete'")
    add("wr_api_study_valid", I, "run", code=f"st = {PY_STUDY})\nds = st.run('cases', progress=False)\n"
        "print(st.cheapest(1.0))")
    add("wr_api_study_measures_valid", I, "run",
        code=f'{PY_STUDY}, measures=lambda ds: {{"tip": float(ds.u_probe.isel(time=-1).max())}}).run(progress=False)')
    add("wr_api_scene_mesh_object", I, "run",
        code="from netgen.occ import OCCGeometry, Rectangle, X, Y\nface = Rectangle(1.0, 0.2).Face()\n"
             "face.edges.Min(Y).name, face.edges.Min(X).name, face.edges.Max(Y).name = 'bottom', 'left', 'top'\n"
             "sc = workbench.scene(mesh=OCCGeometry(face, dim=2), h=0.1, traction='(0, -t)', T=0.1, k=0.05, "
             "boundaries={'bottom': 'contact', 'left': 'clamped', 'top': 'traction', 'default': 'free'})\n"
             "workbench.run(sc, progress=False)")

    # ============================================ own: CLI types, names, values ================================
    I = "own"  # noqa: E741
    cli_bad = [
        ("h_abc", ["--h", "abc"], "refuse-naming:--h"), ("k_minus_1", ["--k", "-1"], "refuse-naming:re:--k|\\bk\\b"),
        ("order_0", ["--order", "0"], "refuse-naming:order"), ("order_9", ["--order", "9"], "refuse-naming:order"),
        ("order_1.5", ["--order", "1.5"], "refuse-naming:--order"), ("order_minus", ["--order", "-1"],
                                                                     "refuse-naming:order"),
        ("h_empty", ["--h", ""], "refuse-naming:--h"), ("h_nan", ["--h", "nan"], "refuse-naming:re:--h|\\bh\\b"),
        ("h_inf", ["--h", "inf"], "refuse-naming:re:--h|\\bh\\b"), ("h_zero", ["--h", "0"], "refuse-naming:re:--h|\\bh\\b"),
        ("h_minus_zero", ["--h", "-0"], "refuse-naming:re:--h|\\bh\\b"),
        ("h_negative", ["--h", "-0.1"], "refuse-naming:re:--h|\\bh\\b"),
        ("h_huge", ["--h", "1e308"], "either-naming:re:--h|\\bh\\b"),
        ("h_hex", ["--h", "0x1p-3"], "refuse-naming:--h"),
        ("k_zero", ["--k", "0"], "refuse-naming:re:--k|\\bk\\b"), ("k_nan", ["--k", "nan"], "refuse-naming:re:--k|\\bk\\b"),
        ("k_inf", ["--k", "inf"], "refuse-naming:re:--k|\\bk\\b"),
        ("T_negative", ["--T", "-1"], "refuse-naming:re:--T|\\bT\\b"), ("T_zero", ["--T", "0"], "refuse-naming:re:--T|\\bT\\b"),
        ("T_nan", ["--T", "nan"], "refuse-naming:re:--T|\\bT\\b"), ("T_inf", ["--T", "inf"], "refuse-naming:re:--T|\\bT\\b"),
        ("threads_0", ["--threads", "0"], "refuse-naming:--threads"),
        ("threads_negative", ["--threads", "-5"], "refuse-naming:--threads"),
        ("threads_abc", ["--threads", "abc"], "refuse-naming:--threads"),
        ("scheme_nonsense", ["--scheme", "nonsense"], "refuse-naming:re:scheme|nonsense"),
        ("scheme_empty", ["--scheme", ""], "refuse-naming:scheme"),
        ("scheme_vi_on_model_A", ["--scheme", "vi"], "refuse-naming:re:scheme|vi"),
        ("set_no_equals", ["--set", "gamma_nu"], "refuse-naming:gamma_nu"),
        ("set_empty_name", ["--set", "=5"], "refuse-naming:re:--set|parameter ''"),
        ("set_empty", ["--set", ""], "refuse-naming:--set"),
        ("set_empty_value", ["--set", "gamma_nu="], "refuse-naming:gamma_nu"),
        ("set_double_equals", ["--set", "gamma_nu==1"], "refuse-naming:gamma_nu"),
        ("set_unknown", ["--set", "foo=1"], "refuse-naming:foo"),
        ("set_typo", ["--set", "gama_nu=1"], "refuse-naming:gama_nu"),
        ("set_unicode_name", ["--set", "γ=1"], "refuse-naming:γ"),
        ("set_twice", ["--set", "gamma_nu=1", "--set", "gamma_nu=2"], "refuse-naming:gamma_nu"),
        ("set_and_option", ["--set", "k=0.01", "--k", "0.02"], "refuse-naming:re:\\bk\\b"),
        ("set_shell_subst", ["--set", "gamma_nu=$(reboot)"], "refuse-naming:gamma_nu"),
        ("set_semicolon", ["--set", "gamma_nu=0.3; rm -rf ~"], "refuse-naming:gamma_nu"),
        ("set_backticks", ["--set", "gamma_nu=`ls`"], "refuse-naming:gamma_nu"),
        ("set_huge_int", ["--set", "gamma_nu=" + "9" * 100000], "either-naming:gamma_nu"),
        ("set_huge_scheme", ["--set", "scheme=" + "x" * 100000], "refuse-naming:scheme"),
        ("set_arabic_digit", ["--set", "gamma_nu=٣"], "either-naming:gamma_nu"),
        ("set_fullwidth_digit", ["--set", "gamma_nu=１"], "either-naming:gamma_nu"),
        ("set_underscore_number", ["--set", "gamma_nu=1_000"], "either-naming:gamma_nu"),
        ("set_expression_for_number", ["--set", "gamma_nu=1/3"], "either-naming:gamma_nu"),
        ("set_list_for_number", ["--set", "gamma_nu=[1, 2]"], "refuse-naming:gamma_nu"),
        ("set_bool_for_number", ["--set", "gamma_nu=true"], "refuse-naming:gamma_nu"),
        ("set_number_for_bool", ["--set", "contact=1"], "either-naming:contact"),
        ("set_text_for_bool", ["--set", "adhesion=maybe"], "refuse-naming:adhesion"),
        ("set_json_dict", ["--set", 'gamma_nu={"a": 1}'], "refuse-naming:gamma_nu"),
        ("set_complex_literal", ["--set", "gamma_nu=1j"], "refuse-naming:gamma_nu"),
        ("extra_positional", ["extra"], "refuse-naming:extra"),
        ("unknown_option", ["--bogus"], "refuse-naming:--bogus"),
        ("option_prefix_ambiguous", ["--no"], "either-naming:--no"),
    ]
    for name, extra, expect in cli_bad:
        add(f"cli_{name}", I, expect, RUN("tp1", *extra), quick=name in ("h_abc", "k_minus_1", "order_0", "order_9"))
    add("cli_scheme_explicit_on_model_B", I, "refuse-naming:re:scheme|explicit", RUN("memory_slab", "--scheme",
                                                                                     "explicit"))
    add("cli_order_3_memory", I, "refuse-naming:order", RUN("memory_slab", "--order", "3"))
    add("cli_order_2_memory_block", I, "refuse-naming:order", RUN("memory_block", "--order", "2"))
    add("cli_no_command", I, "refuse", [])
    add("cli_unknown_command", I, "refuse-naming:bogus", ["bogus"])
    add("cli_scenes_extra_arg", I, "refuse-naming:extra", ["scenes", "extra"])
    add("cli_run_no_scene", I, "refuse-naming:scene", ["run"])
    add("cli_show_no_scene", I, "refuse-naming:scene", ["show"])
    add("cli_study_no_values", I, "refuse-naming:--k", ["study", "tp1", "--k"])
    add("cli_reproduce_unknown", I, "refuse-naming:tp9", ["reproduce", "tp9"])
    add("cli_reproduce_h_abc", I, "refuse-naming:--h", ["reproduce", "tp1", "--h", "abc"])
    add("cli_reproduce_h_negative", I, "refuse-naming:re:--h|\\bh\\b", ["reproduce", "tp1", "--h", "-1", "--no-side",
                                                                        "--out", "r"])
    add("cli_reproduce_set_unknown", I, "refuse-naming:foo", ["reproduce", "tp1", "--set", "foo=1", "--out", "r"])
    for sc, expect in (("tp6", "refuse-naming:tp6"), ("TP1", "refuse-naming:TP1"), ("tp1 ", "refuse-naming:tp1"),
                       ("ťp1", "refuse-naming:ťp1"), ("x" * 100000, "refuse-naming:scene"),
                       ("$(rm -rf /)", "refuse-naming:re:rm -rf|scene"), ("tp1; ls", "refuse-naming:tp1; ls"),
                       ("../../etc/passwd", "refuse-naming:passwd"), ("/", "refuse-naming:re:'/'|directory"),
                       (".", "refuse-naming:re:'\\.'|directory|scene"), ("-", "refuse-naming:re:'-'|scene"),
                       ("/etc/hostname", "refuse-naming:hostname"), ("nonexistent.toml", "refuse-naming:nonexistent.toml"),
                       ("mesh2d", "refuse-naming:mesh"), ("memory_mesh3d", "refuse-naming:mesh")):
        tag = {"/": "root_dir", ".": "dot", "-": "dash"}.get(sc) or re.sub(r"[^A-Za-z0-9]+", "_", sc).strip("_")[:20]
        add(f"scene_{tag}_{len(sc)}", I, expect, ["run", sc, "--no-progress"], quick=sc == "tp6",
            check=no_file("pwned") if "rm" in sc else None)
    for sc in ("tp6", "x" * 10000, "/dev/null"):
        add(f"show_scene_{re.sub(r'[^A-Za-z0-9]+', '_', sc)[:12]}_{len(sc)}", I, "refuse", ["show", sc])

    # expressions: unknown functions, code, syntax
    exprs = [
        ("import", '(0, __import__("os").system("touch pwned"))'), ("subclasses", "(0, ().__class__.__bases__[0])"),
        ("eval", "(0, eval('1'))"), ("lambda", "(0, (lambda: 1)())"), ("comprehension", "(0, [t for t in (1,)][0])"),
        ("open", "(0, open('/etc/passwd'))"), ("attribute", "(0, t.real)"), ("ternary", "(0, t if t else 0)"),
        ("comparison", "(0, t > 0)"), ("boolean", "(0, t and 1)"), ("sin_two_args", "(0, sin(t, 1))"),
        ("sin_no_args", "(0, sin())"), ("ifpos_two_args", "(0, ifpos(t, 1))"), ("unknown_function", "(0, foo(t))"),
        ("upper_T", "(0, T)"), ("z_on_2d", "(0, z)"), ("dangling_op", "(0, 1 +)"), ("unbalanced", "(0, ((t)"),
        ("string", "(0, 'abc')"), ("float_overflow_literal", "(0, 1e999)"), ("hex", "(0, 0x10)"),
        ("complex_literal", "(0, 1j)"), ("true", "(0, True)"), ("none", "(0, None)"), ("ellipsis", "(0, ...)"),
        ("matmul", "(0, t @ t)"), ("floordiv", "(0, t // 2)"), ("modulo", "(0, t % 2)"), ("shift", "(0, 1 << 2)"),
        ("invert", "(0, ~1)"), ("not", "(0, not t)"), ("empty", ""), ("whitespace", "   "), ("superscript", "(0, t²)"),
        ("unicode_minus", "(0, −t)"), ("fullwidth", "(0, ｓｉｎ(t))"), ("walrus", "(0, (a := 1))"),
        ("starred", "(0, *t)"), ("keyword_arg", "(0, sin(x=t))"), ("subscript", "(0, (1, 2)[0])"),
        ("set_literal", "{0, t}"), ("dict_literal", "{0: t}"), ("list_vector", "[0, t]"), ("nested_tuple", "((0, t), 1)"),
        ("semicolon", "(0, t); (1, 1)"), ("newline", "(0,\nt)"), ("comment", "(0, t) # c"), ("fstring", "(0, f'{t}')"),
        ("yield", "(0, (yield))"), ("await", "(0, await t)"), ("pi_call", "(0, pi())"), ("x_call", "(0, x(1))"),
        ("huge_100k", "(0, " + "+".join(["t"] * 33000) + ")"), ("deep_unary_minus", "(0, " + "-" * 5000 + "t)"),
        ("deep_power_tower", "(0, " + "**".join(["1"] * 3000) + ")"), ("nul_like", "(0, t\\x00)"),
        ("backslash", "(0, t\\\n)"), ("tab", "(0,\tt)"),
    ]
    for name, text in exprs:
        expect = "either-naming:traction_top" if name in ("comment", "newline", "tab", "huge_100k", "list_vector", "hex",
                                                     "fullwidth", "backslash") \
            else "refuse-naming:traction_top"
        add(f"expr_{name}", I, expect, RUN("slab", "--set", f"traction_top={text}"),
            check=no_file("pwned") if "pwned" in text else None, quick=name in ("import", "unknown_function"))
    add("expr_api_nul_byte", I, "refuse-naming:traction_top",
        code='workbench.run("slab", h=0.1, k=0.01, T=0.05, progress=False, traction_top="(0, t\\x00)")')
    add("expr_api_1MB", I, "either-naming:traction_top",
        code='workbench.run("slab", h=0.1, k=0.01, T=0.05, progress=False, traction_top="(0, " + "+".join(["t"] * 330000)'
             ' + ")")')
    add("expr_api_tuple_not_text", I, "either-naming:traction_top",
        code='workbench.run("slab", h=0.1, k=0.01, T=0.05, progress=False, traction_top=(0, 1))')
    add("expr_api_callable", I, "refuse-naming:traction_top",
        code='workbench.run("slab", h=0.1, k=0.01, T=0.05, progress=False, traction_top=lambda t: (0, t))')
    add("expr_delta_x", I, "refuse-naming:delta", RUN("rod", "--set", "delta=x"))
    add("expr_u0_t", I, "refuse-naming:u0", RUN("rod", "--set", "u0=t"))
    add("expr_rod_y", I, "refuse-naming:delta", RUN("rod", "--set", "delta=y"))
    add("expr_kernel_x", I, "refuse-naming:kernel", RUN("memory_rod", "--set", "kernel=x"))
    add("expr_point_force_x", I, "refuse-naming:point_force", RUN("tp4", "--set", "point_force=(0, x)"))
    add("expr_load_x", I, "refuse-naming:load", RUN("hertz", "--set", "load=x"))

    # NaN / inf / negative / zero for every numeric parameter
    numeric = {
        "tp5": ["width", "height", "nx", "ny", "T", "k", "order", "h", "rtol", "atol", "k_min", "k_max", "E", "nu", "a1",
                "a2", "c_nu", "m_nu", "gap", "gamma_nu", "eps_a", "L", "beta0", "gamma_p", "q_p", "c_tau",
                "checkpoint_every"],
        "tp1": ["length", "a", "b"],
        "tp3": ["delta_amp", "omega"],
        "memory_slab": ["F", "c", "kernel_E", "kernel_nu", "kernel_tol"],
        "memory_rod": ["F", "c", "kernel_E"],
        "hertz": ["radius", "h_contact", "contact_zone"],
        "block": ["depth", "nz"],
    }
    positive = {"width", "height", "T", "k", "h", "atol", "k_min", "E", "a2", "L", "beta0", "length", "a", "b", "radius",
                "depth", "kernel_tol", "omega"}
    nonneg = {"nx", "ny", "nz", "rtol", "k_max", "a1", "c_nu", "gap", "gamma_nu", "eps_a", "gamma_p", "c_tau",
              "checkpoint_every", "F", "c", "h_contact", "contact_zone"}
    ranged = {"order": "0", "m_nu": "0.5", "q_p": "0.5", "nu": "0.5", "kernel_nu": "-1", "rtol": "0.6",
              "beta0": "1.5", "kernel_tol": "1", "contact_zone": "2"}
    for scene_name, params in numeric.items():
        for p in params:
            word = "re:\\ba\\s*=|'a'|\\ba\\b \\(" if p == "a" else p
            for v in ("nan", "inf") + (("-inf",) if p in ("kernel_E", "nu", "E", "k") else ()):
                add(f"val_{scene_name}_{p}_{v}", I, f"refuse-naming:{word}", RUN(scene_name, "--set", f"{p}={v}"),
                    quick=(scene_name, p, v) in (("tp5", "E", "nan"), ("tp5", "k", "inf")))
            if p in positive or p in nonneg:
                add(f"val_{scene_name}_{p}_negative", I, f"refuse-naming:{word}", RUN(scene_name, "--set", f"{p}=-1"))
            if p in positive:
                add(f"val_{scene_name}_{p}_zero", I, f"refuse-naming:{word}", RUN(scene_name, "--set", f"{p}=0"))
            if p in ranged:
                add(f"val_{scene_name}_{p}_out_of_range", I, f"refuse-naming:{word}",
                    RUN(scene_name, "--set", f"{p}={ranged[p]}"))
            add(f"val_{scene_name}_{p}_text", I, f"refuse-naming:{word}", RUN(scene_name, "--set", f"{p}=abc"))
    add("val_nu_-1_exact", I, "refuse-naming:nu", RUN("slab", "--set", "nu=-1"))
    add("val_tau_inf", I, "refuse-naming:tau", RUN("hertz", "--set", "tau=inf"))
    add("val_m_nu_10_c_nu_1e308", I, "either-naming:re:c_nu|m_nu", RUN("tp5", "--set", "m_nu=10", "--set", "c_nu=1e308"))
    add("val_beta0_tiny", I, "either-naming:beta0", RUN("tp1", "--set", "beta0=5e-324"))
    add("val_k_max_below_k", I, "either-naming:k_max", RUN("tp5", "--scheme", "bdf2", "--set", "rtol=1e-3",
                                                          "--set", "k_max=1e-6"))
    add("val_k_min_above_k", I, "either-naming:k_min", RUN("tp5", "--scheme", "bdf2", "--set", "rtol=1e-3",
                                                          "--set", "k_min=1"))
    add("val_explicit_k_too_large", I, "refuse-naming:k", RUN("tp5", "--k", "0.05", "--set", "c_nu=1e4"))
    add("val_allow_unstable_diverges", I, "either", RUN("tp5", "--k", "0.05", "--set", "c_nu=1e6", "--set",
                                                        "allow_unstable=true", "-o", "div.nc"),
        note="a run that diverges must keep its data, marked incomplete (exit 3)")
    add("val_diverge_blowup", I, "either", RUN("slab", "--set", "traction_top=(0, exp(200*t))", "--set",
                                               "allow_unstable=true", "-o", "div.nc", "--plot", "div.png"))

    # TOML scene files (built-in scenes)
    tomls = [
        ("syntax_error", 'scene = "slab"\n[parameters\n', "refuse-naming:t.toml"),
        ("unknown_key", 'scene = "slab"\nfoo = 1\n', "refuse-naming:foo"),
        ("no_scene", "[parameters]\nk = 0.01\n", "refuse-naming:scene"),
        ("scene_number", "scene = 42\n", "refuse-naming:scene"),
        ("scene_unknown", 'scene = "slabb"\n', "refuse-naming:slabb"),
        ("scene_self_reference", 'scene = "t.toml"\n', "refuse-naming:t.toml"),
        ("parameters_not_table", 'scene = "slab"\nparameters = 5\n', "refuse-naming:parameters"),
        ("traction_unknown_side", SLAB_TOML + '[traction]\nleft = "(0, 1)"\n', "refuse-naming:left"),
        ("traction_twice", SLAB_TOML + 'traction_top = "(0, 1)"\n[traction]\ntop = "(0, 2)"\n',
         "refuse-naming:traction_top"),
        ("name_number", 'scene = "slab"\nname = 42\n', "refuse-naming:name"),
        ("datetime_T", SLAB_TOML.replace("T = 0.05", "T = 1979-05-27"), "refuse-naming:re:\\bT\\b"),
        ("inf_k", SLAB_TOML.replace("k = 0.01", "k = inf"), "refuse-naming:re:\\bk\\b"),
        ("nan_k", SLAB_TOML.replace("k = 0.01", "k = nan"), "refuse-naming:re:\\bk\\b"),
        ("string_h", SLAB_TOML.replace("h = 0.1", 'h = "0.1"'), "either-naming:re:\\bh\\b"),
        ("ragged_probes", SLAB_TOML + "probes = [[0.5, 0.0], [1.0]]\n", "refuse-naming:probes"),
        ("snapshots_text", SLAB_TOML + 'snapshots = "abc"\n', "refuse-naming:snapshots"),
        ("traction_number", SLAB_TOML + "traction_top = 5\n", "either-naming:traction_top"),
        ("traction_array", SLAB_TOML + "traction_top = [0, 1]\n", "either-naming:traction_top"),
        ("empty_file", "", "refuse-naming:scene"),
        ("latin1_bytes", b'scene = "slab"\nname = "caf\xe9"\n', "refuse-naming:t.toml"),
        ("nul_bytes", b'scene = "slab"\n\x00\x00\n', "refuse-naming:t.toml"),
        ("huge_probes_array", SLAB_TOML + "probes = [" + ", ".join(["[0.5, 0.0]"] * 20000) + "]\n",
         "either-naming:probes"),
        ("huge_key", 'scene = "slab"\n' + "k" * 100000 + " = 1\n", "refuse"),
        ("boundaries_without_geometry", 'scene = "slab"\n[boundaries]\nbottom = "contact"\n',
         "refuse-naming:boundaries"),
        ("mesh_param_on_slab", SLAB_TOML + 'mesh = "x.msh"\n', "refuse-naming:mesh"),
        ("model_B_on_slab", 'scene = "slab"\nmodel = "B"\n', "refuse-naming:model"),
        ("duplicate_key", SLAB_TOML + "k = 0.02\n", "refuse-naming:t.toml"),
    ]
    for name, text, expect in tomls:
        add(f"toml_{name}", I, expect, RUN("t.toml"), setup=files(**{"t.toml": text}),
            quick=name in ("syntax_error",))
    add("toml_directory", I, "refuse-naming:t.toml", RUN("t.toml"), setup=mkdirs("t.toml"))
    add("toml_symlink_loop", I, "refuse-naming:t.toml", RUN("t.toml"), setup=symlink("t.toml", "t.toml"))
    add("toml_no_read_permission_root", I, "run", RUN("t.toml"),
        setup=chain(files(**{"t.toml": SLAB_TOML}), lambda wd: os.chmod(wd / "t.toml", 0)),
        note="root reads a 0000 file: should run")

    # study misuse (CLI)
    study_bad = [
        ("k_negative", ["--k", "0.1", "-0.1"], "refuse-naming:re:\\bk\\b|-0.1"),
        ("k_nan", ["--k", "nan", "0.1"], "refuse-naming:re:\\bk\\b|nan"),
        ("h_zero", ["--h", "0", "0.1"], "refuse-naming:re:\\bh\\b"),
        ("reference_bogus", ["--reference", "bogus"], "refuse-naming:--reference"),
        ("reference_h_abc", ["--reference", "h=abc"], "refuse-naming:--reference"),
        ("reference_unknown_key", ["--reference", "foo=1"], "refuse-naming:foo"),
        ("reference_h_negative", ["--reference", "h=-1,k=0.01"], "refuse-naming:re:\\bh\\b|reference"),
        ("compare_0", ["--compare", "0"], "refuse-naming:re:compare|n_compare"),
        ("compare_negative", ["--compare", "-1"], "refuse-naming:re:compare|n_compare"),
        ("compare_huge", ["--compare", "100000"], "either-naming:re:compare|n_compare"),
        ("workers_negative", ["--workers", "-1"], "refuse-naming:workers"),
        ("workers_huge", ["--workers", "100000"], "either-naming:workers"),
        ("k_over_h_zero", ["--k-over-h", "0"], "refuse-naming:k_over_h|--k-over-h"),
        ("k_over_h_nan", ["--k-over-h", "nan"], "refuse-naming:k_over_h|--k-over-h"),
        ("order_0", ["--order", "0"], "refuse-naming:order"),
        ("scheme_nonsense", ["--scheme", "nonsense"], "refuse-naming:nonsense"),
        ("checkpoint_every", ["--set", "checkpoint_every=1"], "refuse-naming:checkpoint_every"),
        ("set_k_twice", ["--set", "k=0.1"], "refuse-naming:re:\\bk\\b"),
        ("set_unknown", ["--set", "foo=1"], "refuse-naming:foo"),
    ]
    for name, extra, expect in study_bad:
        if name == "k_over_h_zero" or name == "k_over_h_nan":
            expect = "refuse-naming:re:k_over_h|--k-over-h"
        base = ["study", "tp1", "--h", "0.1", "--k", "0.1", "0.05", "--set", "T=0.2", "--reference", "ode",
                "--workers", "0", "--no-progress"]
        if extra[0] in ("--k", "--h", "--reference", "--k-over-h"):
            drop = {"--k": ("--k", 3), "--h": ("--h", 2), "--reference": ("--reference", 2),
                    "--k-over-h": ("--k", 3)}[extra[0]]
            i = base.index(drop[0])
            base = base[:i] + base[i + drop[1]:]
        add(f"study_{name}", I, expect, base + extra)
    # (a rod has an exact reference, the default's first choice: one case of it is a measurement; a scene without
    # one has nothing to compare a single case with)
    add("study_single_case_rod", I, "run", ["study", "tp1", "--h", "0.1", "--k", "0.1", "--set", "T=0.2", "--workers",
                                             "0", "--no-progress"])
    add("study_single_case_finest", I, "refuse-naming:re:case|reference",
        ["study", "tp5", "--h", "0.1", "--k", "0.01", "--set", "T=0.02", "--workers", "0", "--no-progress"])
    add("study_unknown_scene", I, "refuse-naming:tp6", ["study", "tp6", "--k", "0.1", "0.05"])
    add("study_reference_exact_on_slab", I, "refuse-naming:re:exact|ode|rod",
        ["study", "tp5", "--h", "0.1", "--k", "0.01", "0.005", "--set", "T=0.05", "--reference", "exact", "--workers",
         "0", "--no-progress"])
    add("study_rerun_resumes", I, "run", STUDY + ["-o", "s.nc"],
        setup=lambda wd: subprocess.run(WORKBENCH + STUDY + ["-o", "s.nc"], cwd=wd, env=CHILD_ENV, capture_output=True,
                                        timeout=300) and None)
    add("study_cases_dir_is_file", I, "refuse-naming:s.nc.cases", STUDY + ["-o", "s.nc"],
        setup=files(**{"s.nc.cases": "x"}))

    # study misuse (API)
    api = [
        ("reference_bogus", f'{PY_STUDY_NOREF}, reference="bogus").run(progress=False)',
         "refuse-naming:reference"),
        ("reference_dict_negative", f'{PY_STUDY_NOREF}, reference={{"h": -1}}).run('
                                    f'progress=False)', "refuse-naming:re:\\bh\\b"),
        ("reference_dict_unknown", f'{PY_STUDY_NOREF}, reference={{"nonexistent": 1}})'
                                   f'.run(progress=False)', "refuse-naming:nonexistent"),
        ("reference_lambda", f'{PY_STUDY_NOREF}, reference=lambda: 1).run(progress=False)',
         "refuse-naming:reference"),
        ("reference_none_single", 'workbench.Study("tp1", h=0.1, k=0.1, T=0.2, reference=None, workers=0).run('
                                  'progress=False)', "run"),
        ("sweep_list", f'{PY_STUDY}, sweep=[("gamma_nu", [1])]).run(progress=False)', "refuse-naming:sweep"),
        ("sweep_nan", f'{PY_STUDY}, sweep={{"gamma_nu": [float("nan")]}}).run(progress=False)',
         "refuse-naming:gamma_nu"),
        ("sweep_text_value", f'{PY_STUDY}, sweep={{"gamma_nu": ["abc"]}}).run(progress=False)',
         "refuse-naming:gamma_nu"),
        ("sweep_scheme_bogus", f'{PY_STUDY}, sweep={{"scheme": ["bogus"]}}).run(progress=False)',
         "refuse-naming:re:scheme|bogus"),
        ("sweep_order_float", 'workbench.Study("tp1", h=0.1, k=0.1, order=[1.5], T=0.2, reference="ode", workers=0)'
                              '.run(progress=False)', "refuse-naming:order"),
        ("sweep_scalar", f'{PY_STUDY}, sweep={{"gamma_nu": 0.5}}).run(progress=False)', "either-naming:gamma_nu"),
        ("sweep_twice", f'{PY_STUDY}, sweep={{"k": [0.1]}}).run(progress=False)', "refuse-naming:re:\\bk\\b"),
        ("grids_scalar", f'{PY_STUDY}, grids=[{{"gamma_nu": 0.5}}]).run(progress=False)', "either-naming:gamma_nu"),
        ("grids_unknown", f'{PY_STUDY}, grids=[{{"nonexistent": [1]}}]).run(progress=False)',
         "refuse-naming:nonexistent"),
        ("grids_text", f'{PY_STUDY}, grids="abc").run(progress=False)', "refuse-naming:grids"),
        ("grids_ints", f'{PY_STUDY}, grids=[5]).run(progress=False)', "refuse-naming:grids"),
        ("scene_42", 'workbench.Study(42, k=[0.1, 0.05]).run(progress=False)', "refuse-naming:42"),
        ("scene_none", 'workbench.Study(None, k=[0.1, 0.05]).run(progress=False)', "refuse"),
        ("couple_not_callable", f'{PY_STUDY}, couple={{"gamma_nu": 5}}).run(progress=False)', "refuse-naming:couple"),
        ("couple_returns_text", f'{PY_STUDY}, couple={{"gamma_nu": lambda c: "abc"}}).run(progress=False)',
         "refuse-naming:gamma_nu"),
        ("couple_raises", f'{PY_STUDY}, couple={{"gamma_nu": lambda c: c["nonexistent"]}}).run(progress=False)',
         "refuse-naming:re:couple|gamma_nu"),
        ("couple_negative_k", 'workbench.Study("tp1", h=[0.2, 0.1], T=0.2, reference="ode", workers=0, '
                              'couple={"k": lambda c: -1.0}).run(progress=False)', "refuse-naming:re:\\bk\\b"),
        ("k_over_h_negative", 'workbench.Study("tp1", h=[0.2, 0.1], k_over_h=-1, T=0.2, workers=0).run(progress=False)',
         "refuse-naming:k_over_h"),
        ("n_compare_0", f'{PY_STUDY}, n_compare=0).run(progress=False)', "refuse-naming:n_compare"),
        ("workers_float", f'{PY_STUDY[:-len(", workers=0")]}, workers=1.5).run(progress=False)', "refuse-naming:workers"),
        ("client_42", f'{PY_STUDY[:-len(", workers=0")]}, client=42).run(progress=False)', "refuse-naming:client"),
        ("run_archive_42", f'{PY_STUDY}).run(42, progress=False)', "refuse-naming:archive"),
        ("run_archive_proc", f'{PY_STUDY}).run("/proc/cases", progress=False)', "refuse-naming:/proc"),
        ("run_archive_chardev", f'{PY_STUDY}).run("dev", progress=False)', "refuse-naming:dev"),
        ("assert_order_bogus_norm", f'st = {PY_STUDY})\nst.run(progress=False)\nst.assert_order(1.0, norm="bogus")',
         "refuse-naming:bogus"),
        ("assert_order_text", f'st = {PY_STUDY})\nst.run(progress=False)\nst.assert_order("abc")',
         "refuse-naming:re:expected|abc"),
        ("cheapest_nan", f'st = {PY_STUDY})\nst.run(progress=False)\nprint(st.cheapest(float("nan")))',
         "either-naming:tolerance"),
        ("cheapest_before_run", f'st = {PY_STUDY})\nprint(st.cheapest(0.1))', "refuse-naming:run"),
        ("cheapest_unknown_error", f'st = {PY_STUDY})\nst.run(progress=False)\nprint(st.cheapest(0.1, error="bogus"))',
         "refuse-naming:bogus"),
        ("measures_raises", f'{PY_STUDY}, measures=lambda ds: 1/0).run(progress=False)', "refuse-naming:measures"),
        ("checkpoint_every", f'{PY_STUDY}, checkpoint_every=1).run(progress=False)', "refuse-naming:checkpoint_every"),
    ]
    for name, snippet, expect in api:
        add(f"api_study_{name}", I, expect, code=snippet, setup=chardev("dev") if "chardev" in name else None,
            check=still_chardev("dev") if "chardev" in name else None)

    # misc: environment and streams
    add("env_cache_unwritable", I, "run", code=(
        "from netgen.occ import OCCGeometry, Rectangle, X, Y\nface = Rectangle(1.0, 0.2).Face()\n"
        "face.edges.Min(Y).name, face.edges.Min(X).name, face.edges.Max(Y).name = 'bottom', 'left', 'top'\n"
        "sc = workbench.scene(mesh=OCCGeometry(face, dim=2), h=0.1, traction='(0, -t)', T=0.1, k=0.05, "
        "boundaries={'bottom': 'contact', 'left': 'clamped', 'top': 'traction', 'default': 'free'})\n"
        "workbench.run(sc, progress=False)"), env={"WORKBENCH_CACHE": "/proc/cache"},
        note="the mesh cache folder cannot be written: should fall back or say so")
    add("env_tmpdir_missing", I, "keep-data", RUN("tp1", "-o", "full/out.nc"), setup=full_disk(),
        env={"TMPDIR": "@WD@/no/such/dir"})
    add("env_mplbackend_bogus", I, "either-naming:re:MPLBACKEND|backend", RUN("tp1", "--plot", "p.png"),
        env={"MPLBACKEND": "bogus_backend"})
    add("env_home_unset", I, "run", RUN("tp1", "-o", "out.nc"), env={"HOME": None})


class _NodeList(dict):
    """Nodes kept as a list of (id, xyz) pairs, so that an id can appear twice in the file."""

    def __init__(self, items):
        super().__init__()
        self._items = list(items)

    def items(self):
        return list(self._items)

    def __len__(self):
        return len(self._items)

    def values(self):
        return [v for _, v in self._items]


def _archive_then_change_mesh(wd: Path):
    (wd / "body.msh").write_text(msh2d())
    (wd / "body.toml").write_text(mesh_toml())
    r = subprocess.run(WORKBENCH + ["run", "body.toml", "--no-progress", "-o", "m.nc"], cwd=wd, env=CHILD_ENV,
                       capture_output=True, text=True, timeout=300)
    if r.returncode != 0:
        raise Skip(f"could not make the mesh archive: {r.stderr.strip()[-200:]}")
    (wd / "body.msh").write_text(msh2d(_centre_moved))


def _centre_moved(nodes, elems):
    nodes[5][1] = 0.25


# ----------------------------------------------------------------------------------------------------------------
# Running and classifying
# ----------------------------------------------------------------------------------------------------------------
WORKBENCH: list = []
PY_WRAPPER = textwrap.dedent('''
    import os, sys, warnings
    def _show(message, category, filename, lineno, file=None, line=None):
        print("warning: " + " ".join(str(message).split()), file=sys.stderr)
    warnings.showwarning = _show
    import workbench
    WD = os.getcwd()
    try:
        exec(compile(SNIPPET, "<input>", "exec"), {"workbench": workbench, "WD": WD, "__name__": "__main__"})
    except workbench.ParameterError as _e:
        print("error: " + " ".join(str(_e).split()), file=sys.stderr)
        sys.exit(2)
    except workbench.Diverged as _e:
        print("error: " + " ".join(str(_e).split()), file=sys.stderr)
        sys.exit(3)
''')


def _limits(mem_bytes):
    def f():
        if mem_bytes:
            try:
                resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
            except (ValueError, OSError):
                pass
        try:
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        except (ValueError, OSError):
            pass
    return f


def _subst(text, wd):
    return str(text).replace("@WD@", str(wd)).replace("@REPO@", str(REPO))


def _read(path: Path, limit=200_000) -> str:
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError:
        return ""
    if len(data) > limit:
        data = data[: limit // 2] + b"\n[...]\n" + data[-limit // 2:]
    return data.decode("utf-8", "replace")


def _naming_ok(spec: str, line: str) -> bool:
    for alt in spec.split("|") if not spec.startswith("re:") else [spec]:
        if alt.startswith("re:"):
            if re.search(alt[3:], line):
                return True
            continue
        if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", alt):
            if re.search(r"(?<![A-Za-z0-9_])" + re.escape(alt) + r"(?![A-Za-z0-9_])", line):
                return True
        elif alt in line:
            return True
    return False


def classify(inp: Input, rc, timed_out, stderr, wall, data_reason, data_class, flags):
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    non_warning = [ln for ln in lines if not ln.startswith("warning:")]
    error_line = non_warning[0] if non_warning else ""
    one_error = len(non_warning) == 1 and error_line.startswith("error:")
    tb = "Traceback (most recent call last)" in stderr or (rc is not None and rc not in (0, 2, 3, 4))
    expect = inp.expect
    kind, _, words = expect.partition("-naming:")
    if timed_out:
        return "hang"
    if data_reason and data_class == "data_lost":
        if tb:
            flags.append("traceback")
        return "data_lost"
    if tb:
        return "traceback"
    if data_reason:
        return data_class
    if rc == 0:
        return "silently_accepted" if kind == "refuse" else "ran"
    if rc == 3:
        flags.append("diverged")
        if kind == "refuse":
            flags.append("accepted_then_diverged")
        return "ran"
    if rc == 4:
        flags.append("exit4")
        return "write_failed" if one_error else "messy_error"
    # rc == 2
    if not one_error:
        return "messy_error"
    if kind == "run":
        out = "wrongly_refused"
    elif words and not _naming_ok(words, error_line):
        out = "unclear"
    else:
        out = "clean_error"
    if wall > SLOW_ERROR:
        flags.append("slow_error")
    return out


def run_one(inp: Input, base: Path, timeout: float, mem_bytes: int, keep: bool) -> dict:
    rec = dict(id=inp.id, issue=inp.issue, kind=inp.kind, command=inp.command(4000), expect=inp.expect, outcome=None,
               flags=[], exit=None, wall=None, stderr_first="", stderr_error="", stderr_last="", stderr_tail="",
               stdout_tail="", data_check=None, note=inp.note)
    wd = Path(tempfile.mkdtemp(prefix=re.sub(r"[^A-Za-z0-9_.-]", "_", inp.id)[:60] + "-", dir=base))
    cleanup = None
    try:
        (wd / "tmp").mkdir()
        try:
            if inp.setup is not None:
                cleanup = inp.setup(wd)
        except Skip as s:
            rec.update(outcome="skipped", note=(inp.note + " " if inp.note else "") + f"skipped: {s}")
            return rec
        except Exception as err:
            rec.update(outcome="harness_error", note=f"setup failed: {type(err).__name__}: {err}",
                       stderr_tail=traceback.format_exc()[-2000:])
            return rec
        env = dict(CHILD_ENV)
        env["TMPDIR"] = str(wd / "tmp")
        for k, v in inp.env.items():
            if v is None:
                env.pop(k, None)
            else:
                env[k] = _subst(v, wd)
        if inp.args is not None:
            cmd = WORKBENCH + [_subst(a, wd) for a in inp.args]
        else:
            cmd = [sys.executable, "-c", f"SNIPPET = {inp.code!r}\n" + PY_WRAPPER]
        out_path, err_path = base / f".{wd.name}.stdout", base / f".{wd.name}.stderr"
        timed_out = False
        with open(out_path, "wb") as so, open(err_path, "wb") as se:
            t0 = time.monotonic()
            try:
                p = subprocess.Popen(cmd, cwd=wd, env=env, stdin=subprocess.DEVNULL, stdout=so, stderr=se,
                                     start_new_session=True, preexec_fn=_limits(mem_bytes))
            except OSError as err:
                rec.update(outcome="skipped", note=f"cannot start the process: {err}")
                return rec
            try:
                rc = p.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                timed_out = True
                rc = None
            wall = time.monotonic() - t0
            try:
                os.killpg(p.pid, signal.SIGKILL)  # the process group this input started (and only that)
            except (ProcessLookupError, PermissionError):
                pass
            if timed_out:
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    pass
        stdout, stderr = _read(out_path), _read(err_path)
        for f in (out_path, err_path):
            f.unlink(missing_ok=True)
        # a copy "kept in the temporary folder" outside the work folder (TMPDIR unusable) is checked, then removed
        stray = [Path(k) for k in re.findall(r"kept in (/\S+?\.nc)\b", stderr)
                 if not str(k).startswith(str(wd)) and Path(k).name.startswith("workbench-kept-")]
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        errors = [ln for ln in lines if not ln.startswith("warning:")]
        rec["stderr_error"] = (errors[0] if errors else "")[:600]
        rec.update(exit=rc, wall=round(wall, 3), stderr_first=lines[0][:600] if lines else "",
                   stderr_last=lines[-1][:600] if lines else "", stderr_tail=stderr[-3000:], stdout_tail=stdout[-800:])
        data_reason, data_class, flags = None, "data_lost", []
        try:
            if not timed_out:
                data_reason, flags = generic_checks(inp, wd, rc, stderr)
            r = inp.check(wd, rec) if inp.check is not None else None
            if r:
                cls, why = r if isinstance(r, tuple) else ("data_lost", r)
                if timed_out:
                    if cls == "data_lost":
                        flags.append("data_lost_too")
                        data_reason = why
                elif data_reason is None:  # (a loss found by the generic checks outranks the input's own verdict)
                    data_reason, data_class = why, cls
        except Exception as err:
            rec["note"] = (rec["note"] + " " if rec["note"] else "") + f"check failed: {type(err).__name__}: {err}"
        if timed_out:
            data_reason = None if "data_lost_too" not in flags else data_reason
        for k in stray:
            try:
                k.unlink()
            except OSError:
                pass
        rec["data_check"] = data_reason
        rec["outcome"] = classify(inp, rc, timed_out, stderr, wall, data_reason, data_class, flags)
        rec["flags"] = flags
        return rec
    except Exception as err:  # the harness must never fall over on an odd outcome
        rec.update(outcome="harness_error", note=f"{type(err).__name__}: {err}", stderr_tail=traceback.format_exc()[-2000:])
        return rec
    finally:
        if cleanup is not None:
            _quiet(cleanup)
        if not keep:
            _rmtree(wd)


def _rmtree(path: Path):
    def onerror(func, p, exc):
        try:
            os.chmod(os.path.dirname(p), 0o755)
            os.chmod(p, 0o755)
            func(p)
        except OSError:
            pass
    # never descend into a mount that is still there
    for dirpath, dirnames, _ in os.walk(path):
        for d in list(dirnames):
            full = os.path.join(dirpath, d)
            if os.path.ismount(full):
                subprocess.run(["umount", "-l", full], capture_output=True)
    shutil.rmtree(path, onerror=onerror)


# ----------------------------------------------------------------------------------------------------------------
# Reports
# ----------------------------------------------------------------------------------------------------------------
OUTCOMES = ["clean_error", "ran", "write_failed", "skipped", "traceback", "hang", "data_lost", "silently_accepted",
            "unclear", "wrongly_refused", "messy_error", "harness_error"]
ISSUES = ["data_lost", "traceback", "silently_accepted", "hang", "unclear", "wrongly_refused", "own"]


def _md(text, n=300):
    text = " ".join(str(text).split())
    if len(text) > n:
        text = text[: n - 3] + "..."
    return text.replace("|", "\\|").replace("`", "'")


def summary(records, meta) -> str:
    counts = {o: 0 for o in OUTCOMES}
    for r in records:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    slow = [r for r in records if "slow_error" in r["flags"]]
    lines = [f"# Hostile inputs: {meta['tag'] or 'results'}", "",
             f"{len(records)} inputs ({meta['inputs_cli']} command line, {meta['inputs_py']} Python API), run "
             f"{meta['started']} - {meta['finished']} ({meta['wall_minutes']:.1f} min) on commit {meta['commit']} "
             f"(package: {meta['package']}), timeout {meta['timeout']:g} s per input, address-space limit "
             f"{meta['mem_limit_gb']:g} GB, {meta['jobs']} job(s). Made by `python studies/hostile.py "
             f"{meta['argv']}`; classes: see the module docstring of studies/hostile.py.", "",
             "## Outcomes", "", "| outcome | inputs |", "|---|---|"]
    lines += [f"| {o} | {c} |" for o, c in counts.items() if c or o in OUTCOMES[:10]]
    errors = [r for r in records if r["outcome"] in ("clean_error", "unclear", "wrongly_refused")]
    lines += ["", f"slow_error (informational): {len(slow)} of {len(errors)} clean refusals took more than "
              f"{SLOW_ERROR} s wall as a whole process"
              + (f" (median {sorted(r['wall'] for r in errors)[len(errors) // 2]:.2f} s)" if errors else "") + ".", ""]
    lines += ["## Per issue class", "", "| issue class | inputs | " + " | ".join(OUTCOMES) + " |",
              "|---|---|" + "---|" * len(OUTCOMES)]
    for issue in ISSUES:
        rs = [r for r in records if r["issue"] == issue]
        lines.append(f"| {issue} | {len(rs)} | " + " | ".join(str(sum(r['outcome'] == o for r in rs)) or "0"
                                                           for o in OUTCOMES) + " |")
    flags = {}
    for r in records:
        for f in r["flags"]:
            flags[f] = flags.get(f, 0) + 1
    if flags:
        lines += ["", "Flags: " + ", ".join(f"{k} {v}" for k, v in sorted(flags.items()))]
    lines += ["", "## Inputs that are not clean", "",
              "Every input whose outcome is not clean_error, ran or skipped (write_failed included: exit 4 is "
              "right only for a disk that fills up during the run). For a traceback the exception line is given too.",
              ""]
    order = {o: i for i, o in enumerate(["data_lost", "traceback", "hang", "silently_accepted", "unclear",
                                         "wrongly_refused", "messy_error", "write_failed", "harness_error"])}
    bad = sorted((r for r in records if r["outcome"] not in CLEAN), key=lambda r: (order.get(r["outcome"], 99), r["id"]))
    for o in order:
        rs = [r for r in bad if r["outcome"] == o]
        if not rs:
            continue
        lines += [f"### {o} ({len(rs)})", "", "| id | issue | expect | exit | wall s | command | stderr: first line "
                  "(warning lines skipped) |",
                  "|---|---|---|---|---|---|---|"]
        for r in rs:
            err = r.get("stderr_error") or r["stderr_first"]
            if r["outcome"] == "traceback" or "traceback" in r["flags"]:
                err = f"{err} ... {r['stderr_last']}" if err != r["stderr_last"] else err
            if r["data_check"]:
                err = f"[{r['data_check']}] {err}"
            if r["outcome"] == "hang":
                err = f"[killed after {r['wall']:.0f} s] {err}"
            lines.append(f"| {r['id']} | {r['issue']} | {_md(r['expect'], 60)} | {r['exit']} | {r['wall']} | "
                         f"`{_md(r['command'], 220)}` | {_md(err, 400)} |")
        lines.append("")
    skipped = [r for r in records if r["outcome"] == "skipped"]
    if skipped:
        lines += ["### skipped", ""] + [f"* {r['id']}: {_md(r['note'], 300)}" for r in skipped] + [""]
    return "\n".join(lines) + "\n"


def _git(*args):
    try:
        return subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True, timeout=30).stdout.strip()
    except Exception:
        return ""


def main(argv=None):
    global WORKBENCH, FIXTURE_DIR, CHILD_ENV
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="a subset of about 60 inputs covering every class")
    ap.add_argument("--only", metavar="PATTERN", help="only the inputs whose id matches this regular expression")
    ap.add_argument("--jobs", type=int, default=1, help="inputs run at once (default 1)")
    ap.add_argument("--timeout", type=float, default=90.0, help="wall seconds per input (default 90)")
    ap.add_argument("--mem-limit", type=float, default=6.0, help="address-space limit per input, GB (default 6; 0: none)")
    ap.add_argument("--tag", default="", help="file suffix: results_TAG.json, summary_TAG.md")
    ap.add_argument("--out", default=str(REPO / "data" / "hostile"), help="output folder (default data/hostile)")
    ap.add_argument("--code", metavar="REV", help="test the package as committed at this git revision (git archive)")
    ap.add_argument("--package", metavar="DIR", help="a folder holding workbench/ to test (put first on PYTHONPATH)")
    ap.add_argument("--keep", action="store_true", help="keep the work folders")
    ap.add_argument("--list", action="store_true", help="list the inputs and exit")
    args = ap.parse_args(argv)

    build_inputs()
    selected = [i for i in INPUTS if (not args.quick or i.quick) and (not args.only or re.search(args.only, i.id))]
    if args.list:
        for i in selected:
            print(f"{i.id:48s} {i.issue:18s} {i.expect:36s} {i.command(160)}")
        print(f"{len(selected)} of {len(INPUTS)} inputs ({sum(i.quick for i in INPUTS)} in --quick)")
        return 0

    base = Path(tempfile.mkdtemp(prefix="hostile-"))
    package = None
    commit = _git("rev-parse", "--short", "HEAD")
    if args.code:
        package = base / "package"
        package.mkdir()
        arch = subprocess.run(["git", "-C", str(REPO), "archive", args.code, "workbench"], capture_output=True)
        if arch.returncode != 0:
            print(f"error: git archive {args.code}: {arch.stderr.decode().strip()}", file=sys.stderr)
            return 2
        subprocess.run(["tar", "-x", "-C", str(package)], input=arch.stdout, check=True)
        commit = _git("rev-parse", "--short", args.code)
    elif args.package:
        package = Path(args.package).resolve()
    CHILD_ENV = dict(os.environ)
    CHILD_ENV["MPLBACKEND"] = "Agg"
    CHILD_ENV.pop("PYTHONSTARTUP", None)
    if package is not None:
        CHILD_ENV["PYTHONPATH"] = str(package) + (os.pathsep + CHILD_ENV["PYTHONPATH"] if CHILD_ENV.get("PYTHONPATH")
                                                  else "")
    exe = Path(sys.executable).with_name("workbench")
    WORKBENCH = [str(exe)] if exe.exists() else [sys.executable, "-m", "workbench.cli"]
    FIXTURE_DIR = base / "fixtures"
    FIXTURE_DIR.mkdir()
    where = subprocess.run([sys.executable, "-c", "import workbench; print(workbench.__file__)"], env=CHILD_ENV,
                           cwd=base, capture_output=True, text=True).stdout.strip()
    dirty = bool(_git("status", "--porcelain", "workbench")) and package is None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    suffix = f"_{args.tag}" if args.tag else ""
    mem = int(args.mem_limit * 1024 ** 3) if args.mem_limit > 0 else 0
    started = datetime.datetime.now()
    print(f"{len(selected)} inputs, package {where}" + (" (working tree with uncommitted changes)" if dirty else "")
          + f", work folders in {base}", flush=True)
    records = []
    t0 = time.monotonic()
    try:
        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            futures = {pool.submit(run_one, i, base, args.timeout, mem, args.keep): i for i in selected}
            done = 0
            for fut in concurrent.futures.as_completed(futures):
                inp = futures[fut]
                try:
                    rec = fut.result()
                except Exception as err:  # (run_one catches everything; belt and braces)
                    rec = dict(id=inp.id, issue=inp.issue, kind=inp.kind, command=inp.command(4000), expect=inp.expect,
                               outcome="harness_error", flags=[], exit=None, wall=None, stderr_first="",
                               stderr_last="", stderr_tail="", stdout_tail="", data_check=None, note=repr(err))
                records.append(rec)
                done += 1
                print(f"[{done}/{len(selected)}] {rec['outcome']:17s} {rec['id']} ({rec['wall']} s) "
                      f"{_md(rec['stderr_first'], 120)}", flush=True)
    finally:
        index = {i.id: n for n, i in enumerate(INPUTS)}
        records.sort(key=lambda r: index.get(r["id"], 0))
        meta = dict(tag=args.tag, started=started.isoformat(timespec="seconds"),
                    finished=datetime.datetime.now().isoformat(timespec="seconds"),
                    wall_minutes=(time.monotonic() - t0) / 60, commit=commit + (" + uncommitted changes" if dirty else ""),
                    package=where, timeout=args.timeout, mem_limit_gb=args.mem_limit, jobs=args.jobs,
                    argv=" ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:])),
                    inputs=len(records), inputs_cli=sum(r["kind"] == "cli" for r in records),
                    inputs_py=sum(r["kind"] == "py" for r in records),
                    counts={o: sum(r["outcome"] == o for r in records) for o in OUTCOMES},
                    slow_error=sum("slow_error" in r["flags"] for r in records))
        (out / f"results{suffix}.json").write_text(json.dumps({"meta": meta, "results": records}, indent=1,
                                                              ensure_ascii=False))
        (out / f"summary{suffix}.md").write_text(summary(records, meta))
        if not args.keep:
            _rmtree(base)
    print(f"wrote {out / f'results{suffix}.json'} and {out / f'summary{suffix}.md'}: " +
          ", ".join(f"{o} {c}" for o, c in meta["counts"].items() if c))
    return 0


if __name__ == "__main__":
    sys.exit(main())
