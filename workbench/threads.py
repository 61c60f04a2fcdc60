"""Thread pools: one BLAS thread while workbench computes, NGSolve's TaskManager only when asked.

NGSolve's wheel, NumPy and SciPy each load their own OpenBLAS, each with a pool of
threads; next to NGSolve's own task manager they oversubscribe a small machine
(measured: one whole-process run in six to eight took 3-9x longer on two idle
cores, the time spent in a banded Cholesky of 1458 unknowns). Every solve in
workbench is either a sparse factorisation, a back-substitution or a small dense
solve, none of which gains from BLAS threads at these sizes. Two measures:

* ``import workbench`` before NumPy starts every OpenBLAS with one thread (the
  environment variables, unless set): the only measure that removed the stalls
  (measured with another process busy on the second core: setup 0.4-0.5 s in 8 of 8
  runs, against 0.7-11.7 s without);
* a run holds every loaded BLAS pool at one thread while it computes
  (threadpoolctl) and restores them after, for processes where NumPy came first
  (it lowers the threads but does not stop pools already started).

Examples
--------
>>> from threadpoolctl import threadpool_info
>>> with blas_single_threaded():
...     all(p["num_threads"] == 1 for p in threadpool_info() if p["user_api"] == "blas")
True
"""
from __future__ import annotations

import contextlib

#: Set by :func:`workbench._lean_process` in a process of its own whose BLAS pools all started with one thread.
POOLS_STARTED_SINGLE = False


@contextlib.contextmanager
def blas_single_threaded():
    """Hold every BLAS pool (NumPy's, SciPy's, NGSolve's OpenBLAS) at one thread inside the block.

    The libraries a run uses are loaded first: threadpoolctl limits only the pools loaded when the
    block starts, and one loaded later (in a process where NumPy came before workbench) would run
    with as many threads as cores.
    """
    if POOLS_STARTED_SINGLE:  # (a process of its own whose pools all started with one thread)
        yield
        return
    import ngsolve  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


class task_manager:
    """NGSolve's TaskManager with ``n`` threads inside the block, or nothing for n in (None, 1)."""

    def __init__(self, n: int | None):
        self.n, self.tm = n, None

    def __enter__(self):
        if self.n and self.n > 1:
            import ngsolve as ngs

            ngs.SetNumThreads(int(self.n))
            self.tm = ngs.TaskManager()
            self.tm.__enter__()
        return self

    def __exit__(self, *exc):
        if self.tm is not None:
            self.tm.__exit__(*exc)
