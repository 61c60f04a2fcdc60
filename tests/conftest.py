import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

#: Set in the processes that mpiexec starts for a ``parallel`` test: there the test body runs on every rank.
CHILD = "WORKBENCH_TEST_MPI_CHILD"


def pytest_configure(config):
    """The suite keeps its meshes out of the user's home (~/.cache/workbench): in a folder of its own, also for the
    subprocesses it starts (they inherit the variable)."""
    if not os.environ.get("WORKBENCH_CACHE"):
        import tempfile

        os.environ["WORKBENCH_CACHE"] = tempfile.mkdtemp(prefix="workbench-test-cache-")


def observed_order(sizes, errors):
    """Least-squares slope of log(error) against log(size)."""
    return float(np.polyfit(np.log(sizes), np.log(errors), 1)[0])


@pytest.fixture
def order_of():
    return observed_order


def pytest_generate_tests(metafunc):
    """``@pytest.mark.parallel(nprocs=[1, 2, 3])`` with an ``nprocs`` argument: one test per process count (Firedrake's
    way: the same body runs serially and under mpiexec)."""
    mark = metafunc.definition.get_closest_marker("parallel")
    if mark is not None and "nprocs" in metafunc.fixturenames:
        counts = mark.kwargs.get("nprocs", [1, 2])
        if os.environ.get(CHILD):  # (the child runs the one count it was started for)
            counts = [int(os.environ[CHILD])]
        metafunc.parametrize("nprocs", counts, ids=[f"np{n}" for n in counts])


def pytest_collection_modifyitems(items):
    for item in items:  # a parallel test on several processes starts MPI processes
        if item.get_closest_marker("parallel") and getattr(item, "callspec", None) \
                and item.callspec.params.get("nprocs", 1) > 1:
            item.add_marker(pytest.mark.mpi)


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem):
    """A parallel test for n > 1 processes: run this very test in ``mpiexec -n n python -m pytest`` (every rank runs its
    body; it passes when every rank passes)."""
    if not pyfuncitem.get_closest_marker("parallel") or os.environ.get(CHILD):
        return None
    n = pyfuncitem.callspec.params.get("nprocs", 1)
    if n <= 1:
        return None
    launcher = Path(sys.executable).parent / "mpiexec"
    launcher = str(launcher) if launcher.exists() else shutil.which("mpiexec")
    if launcher is None:
        pytest.skip("no mpiexec (pip install mpich)")
    from workbench.discrete.world import alone

    env = alone() | {CHILD: str(n)}
    cmd = [launcher, "-n", str(n), sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-p", "no:cacheprovider",
           "--rootdir", str(pyfuncitem.config.rootpath), pyfuncitem.nodeid]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=pyfuncitem.config.rootpath, timeout=1800)
    assert p.returncode == 0, f"{pyfuncitem.nodeid} on {n} processes:\n{p.stdout[-4000:]}\n{p.stderr[-3000:]}"
    return True
