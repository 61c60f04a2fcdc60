"""The README and docs work as written: every Python block and every `workbench` command line runs as pasted.

Each ```python block of README.md and docs/*.md runs in a fresh interpreter, and each line of a ```console block
that starts with ``workbench `` runs as a command, in a scratch folder where docs/, studies/, data/ and
README.md are reachable by the same relative paths (so written outputs land in the scratch folder's out/).
A block's claims are its own assertions (e.g. the README's ``assert_order``): a block that raises fails here.
The README's test command is the one CI runs.
"""
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from workbench.discrete.world import alone

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.S | re.M)


def blocks(kind):
    out = []
    for page in PAGES:
        for i, m in enumerate(FENCE.finditer(page.read_text())):
            if m.group(1) == kind:
                out.append(pytest.param(m.group(2), id=f"{page.relative_to(ROOT)}#{i}"))
    return out


def commands():
    out = []
    for param in blocks("console"):
        (text,) = param.values
        for line in text.splitlines():
            line = line.strip()
            if line.startswith("$ "):
                line = line[2:]
            if line.startswith(("workbench ", "mpiexec ")):
                out.append(pytest.param(line, id=f"{param.id}: {line[:60]}"))
    return out


@pytest.fixture
def scratch(tmp_path):
    for name in ("docs", "studies", "data", "README.md"):
        os.symlink(ROOT / name, tmp_path / name)
    (tmp_path / "out").mkdir()
    return tmp_path


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    line = next(li.strip() for li in readme.splitlines() if "pytest" in li and "pip install" in li)
    assert line in ci


def test_there_are_snippets():
    assert len(blocks("python")) >= 3 and len(commands()) >= 8


@pytest.mark.slow
@pytest.mark.parametrize("code", blocks("python"))
def test_python_block_runs(code, scratch):
    env = dict(os.environ, MPLBACKEND="Agg")  # a script's backend (no display here); notebooks are tested inline
    p = subprocess.run([sys.executable, "-c", code], cwd=scratch, capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, f"{code}\n--- stderr:\n{p.stderr[-3000:]}"


@pytest.mark.slow
@pytest.mark.parametrize("line", [pytest.param(c, marks=pytest.mark.mpi) if "mpiexec" in c else c for c in commands()])
def test_command_runs(line, scratch):
    """`workbench ...` as this interpreter's module; `mpiexec -n N workbench ...` with the MPI launcher installed beside
    it (the test extra's mpich)."""
    words = shlex.split(line)
    start = words.index("workbench")
    launcher = []
    if start:
        found = Path(sys.executable).parent / words[0]
        launcher = [str(found) if found.exists() else words[0], *words[1:start]]
    env = alone()
    p = subprocess.run([*launcher, sys.executable, "-m", "workbench.cli", *words[start + 1:]], cwd=scratch,
                       capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, f"$ {line}\n--- stdout:\n{p.stdout[-2000:]}\n--- stderr:\n{p.stderr[-3000:]}"
    assert "Traceback" not in p.stderr


def test_readme_scene_file_is_the_example_file():
    """The README shows docs/examples/slab_pull.toml (and says so): its TOML block is that file, byte for byte."""
    (block,) = [m.group(2) for m in FENCE.finditer((ROOT / "README.md").read_text()) if m.group(1) == "toml"]
    assert block == (ROOT / "docs" / "examples" / "slab_pull.toml").read_text()


def test_no_reference_to_a_file_outside_the_repository():
    """The docstrings and notes referred to a model statement outside the repository (in a shared folder beside it,
    by its name in capitals); they refer to docs/ instead."""
    outside = re.compile(r"\b" + "SP" + r"EC\b|\.\./shared|shared/" + "SP")
    files = [ROOT / "README.md"] + [p for d in ("workbench", "studies", "docs", "tests") for p in (ROOT / d).rglob("*")
                                    if p.suffix in (".py", ".md", ".toml", ".txt")]
    hits = [f"{p.relative_to(ROOT)}:{i}" for p in files for i, line in enumerate(p.read_text().splitlines(), 1)
            if outside.search(line)]
    assert not hits, hits
