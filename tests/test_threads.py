"""Thread pools (the random 3-10x stalls of the new-user defects issue): every BLAS pool that NGSolve, NumPy and SciPy
load runs one thread while workbench computes; the timing itself is measured by studies/bench_stalls.py."""
import os
import subprocess
import sys

import pytest


@pytest.mark.slow
def test_import_leaves_the_process_alone_and_a_run_gives_the_pools_back():
    """`import workbench` in a user's fresh process, before NumPy, sets no thread variable; a run holds every BLAS
    pool at one thread and leaves them as the user had them (here: 2 threads each)."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")} | {"OPENBLAS_NUM_THREADS": "2"}
    code = ("import os, workbench\n"
            "print(sorted(k for k in os.environ if k.endswith('_NUM_THREADS') and k != 'OPENBLAS_NUM_THREADS'))\n"
            "import numpy, scipy.linalg, ngsolve\n"
            "from threadpoolctl import threadpool_info\n"
            "most = lambda: max(p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas')\n"
            "before = most()\n"
            "workbench.run('tp1', h=0.1, k=0.1, progress=False)\n"
            "print(before, most())\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    variables, counts = p.stdout.splitlines()
    assert variables == "[]", p.stdout
    assert counts == "2 2", p.stdout


def test_blas_pools_start_single_threaded_in_a_workbench_process(tmp_path):
    """The `workbench` command (a process of its own, :func:`workbench.running.threads.lean_process`): every OpenBLAS the run
    loads (NumPy's, SciPy's, NGSolve's) starts with one thread, with no thread variables in the environment."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    code = ("import atexit, sys\n"
            "def report():\n"
            "    from threadpoolctl import threadpool_info\n"
            "    pools = [p for p in threadpool_info() if p['user_api'] == 'blas']\n"
            "    print('POOLS', len(pools), max(p['num_threads'] for p in pools))\n"
            "atexit.register(report)\n"
            "sys.argv = ['workbench', 'run', 'tp1', '--h', '0.1', '--k', '0.1', '--no-progress']\n"
            "from workbench.cli import console\n"
            "sys.exit(console())\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300,
                       cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    n, most = map(int, p.stdout.split("POOLS")[1].split())
    assert n >= 1 and most == 1, p.stdout


def test_a_run_holds_blas_at_one_thread_where_numpy_came_first(monkeypatch):
    """A process where NumPy started its pools first (a notebook): inside the time loop every BLAS pool is held at
    one thread, and restored after."""
    from threadpoolctl import threadpool_info, threadpool_limits

    import workbench
    from workbench.running import runner

    seen = []
    march, build = runner.march, runner.parallel.discretise

    def most():
        return max(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas")

    def spy(*a, **kw):
        seen.append(most())
        return march(*a, **kw)

    def spy_build(*a, **kw):  # the setup (factorisations) too
        seen.append(most())
        return build(*a, **kw)

    monkeypatch.setattr(runner, "march", spy)
    monkeypatch.setattr(runner.parallel, "discretise", spy_build)
    with threadpool_limits(limits=2, user_api="blas"):
        workbench.run("tp1", h=0.1, k=0.1, progress=False)
        after = max(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas")
    assert seen == [1, 1] and after == 2
