"""Thread pools (the random 3-10x stalls of the new-user defects issue): every BLAS pool that NGSolve, NumPy and SciPy
load runs one thread while workbench computes; the timing itself is measured by studies/bench_stalls.py."""
import os
import subprocess
import sys


def test_blas_pools_start_single_threaded_in_a_fresh_process():
    """`import workbench` before NumPy: every OpenBLAS the run loads (NumPy's, SciPy's, NGSolve's) starts with one
    thread, with no thread variables in the environment."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    code = ("import workbench, numpy, scipy.linalg, ngsolve\n"
            "workbench.run('tp1', h=0.1, k=0.1, progress=False)\n"
            "from threadpoolctl import threadpool_info\n"
            "pools = [p for p in threadpool_info() if p['user_api'] == 'blas']\n"
            "print(len(pools), max(p['num_threads'] for p in pools))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    n, most = map(int, p.stdout.split())
    assert n >= 1 and most == 1, p.stdout


def test_a_run_holds_blas_at_one_thread_where_numpy_came_first(monkeypatch):
    """A process where NumPy started its pools first (a notebook): inside the time loop every BLAS pool is held at
    one thread, and restored after."""
    from threadpoolctl import threadpool_info, threadpool_limits

    import workbench
    from workbench import runner

    seen = []
    march, build = runner.march, runner.discretisation.build

    def most():
        return max(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas")

    def spy(*a, **kw):
        seen.append(most())
        return march(*a, **kw)

    def spy_build(*a, **kw):  # the setup (factorisations) too
        seen.append(most())
        return build(*a, **kw)

    monkeypatch.setattr(runner, "march", spy)
    monkeypatch.setattr(runner.discretisation, "build", spy_build)
    with threadpool_limits(limits=2, user_api="blas"):
        workbench.run("tp1", h=0.1, k=0.1, progress=False)
        after = max(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas")
    assert seen == [1, 1] and after == 2
