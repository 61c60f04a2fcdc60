"""Thread pools and processes of workbench's own: one BLAS thread while workbench computes, NGSolve's TaskManager
only when asked, a worker that dies with its parent.

NGSolve's wheel, NumPy and SciPy each load their own OpenBLAS, each with a pool of
threads; next to NGSolve's own task manager they oversubscribe a small machine
(measured: one whole-process run in six to eight took 3-9x longer on two idle
cores, the time spent in a banded Cholesky of 1458 unknowns). Every solve in
workbench is either a sparse factorisation, a back-substitution or a small dense
solve, none of which gains from BLAS threads at these sizes. Two measures:

* a process of workbench's own (the ``workbench`` command, a study's worker) starts
  every OpenBLAS with one thread (:func:`lean_process`, before NumPy loads: the
  environment variables, unless set): the only measure that removed the stalls
  (measured with another process busy on the second core: setup 0.4-0.5 s in 8 of 8
  runs, against 0.7-11.7 s without);
* a run in a user's process (a script, a notebook) holds every loaded BLAS pool at one
  thread while it computes (threadpoolctl) and gives the user's settings back after;
  ``import workbench`` itself changes nothing in the process.

Examples
--------
>>> from threadpoolctl import threadpool_info
>>> with blas_single_threaded():
...     all(p["num_threads"] == 1 for p in threadpool_info() if p["user_api"] == "blas")
True
"""
from __future__ import annotations

import contextlib
import os
import sys

#: The environment variables by which the BLAS libraries (OpenBLAS, OpenMP, MKL) size their pools when they load.
BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: Set by :func:`lean_process` in a process of its own whose BLAS pools all started with one thread.
POOLS_STARTED_SINGLE = False


def single_threaded(environment: dict) -> dict:
    """A copy of ``environment`` in which every BLAS pool starts with one thread (a worker process's)."""
    return dict(environment) | {name: "1" for name in BLAS_VARIABLES}


def die_with_parent(parent: int) -> None:
    """A worker process of workbench's own exits when its parent (pid ``parent``) dies: Linux's PR_SET_PDEATHSIG (the
    kernel kills it with the parent), and a watchdog thread on the parent's pid elsewhere. Called first thing, before
    the heavy imports (NumPy, NGSolve, xarray: seconds on a loaded machine, during which a killed parent's worker
    would otherwise live on)."""
    import threading
    import time

    try:  # Linux: the kernel sends SIGKILL when the parent thread exits
        import ctypes
        import signal

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)

    def watch():
        while True:
            time.sleep(1.0)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def lean_process() -> None:
    """For a process started to run scenes only (``workbench run``, a study's worker), first thing, where no user code
    runs before the run: skip what such a process does not need (measured on ``workbench run tp5``, 1.7 s in all).

    * Every BLAS pool starts with one thread (the environment variables, unless set, before NumPy, SciPy or NGSolve
      load); then the runs skip threadpoolctl's library scan (40 ms, :func:`blas_single_threaded`).
    * dask counts as absent. With dask installed, xarray imports dask.array when it builds a Dataset and
      dask.distributed when it writes one (looking for chunked arrays and a scheduler's lock): 0.35 s, for a
      process whose arrays are all NumPy. Python's own rule (``sys.modules[name] is None``: the import raises
      ImportError) takes xarray down its no-dask path.

    Not for a session (a notebook may want dask, or set its own BLAS threads, later).
    """
    global POOLS_STARTED_SINGLE
    if not {"numpy", "scipy", "ngsolve"} & set(sys.modules):
        for name in BLAS_VARIABLES:
            os.environ.setdefault(name, "1")
        POOLS_STARTED_SINGLE = all(os.environ[name] == "1" for name in BLAS_VARIABLES)
    for name in ("dask", "distributed"):
        sys.modules.setdefault(name, None)


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
