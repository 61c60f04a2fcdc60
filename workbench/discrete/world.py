"""Where a run's data lives: the processes that hold it, and the reductions its decisions take over them.

Every discretisation carries its world (``disc.world``). On one process it is :data:`SERIAL`, whose reductions
return their arguments; a body distributed over several MPI processes carries a
:class:`workbench.parallel.World`, with the same methods reduced over the ranks. The time loop, the step limit and
the schemes call these methods and never ask which world they have.

This module holds no MPI code: it also says, from the environment alone, whether an MPI launcher started this
process among others (:func:`launched`), and gives a worker process an environment without the launcher's
variables (:func:`alone`).

Examples
--------
>>> SERIAL.max(2.0), SERIAL.any(False), SERIAL.root
(2.0, False, True)
"""
from __future__ import annotations

import contextlib
import os

#: The environment variables through which MPI launchers (MPICH's hydra and Intel MPI, Open MPI, MVAPICH) tell a
#: process how many were started.
SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "MV2_COMM_WORLD_SIZE")


class Serial:
    """One process: every reduction returns its argument."""

    parallel = False
    rank, size, root = 0, 1, True

    @staticmethod
    def any(flag) -> bool:
        return bool(flag)

    @staticmethod
    def max(value) -> float:
        return value

    @staticmethod
    def sum(value) -> float:
        return value

    @staticmethod
    def bcast(obj):
        return obj

    @staticmethod
    def allgather(obj) -> list:
        """Every process's ``obj``, in rank order, on every process."""
        return [obj]


SERIAL = Serial()


def launched(environment=None) -> int:
    """How many processes an MPI launcher started this one among (1 without a launcher)."""
    environment = os.environ if environment is None else environment
    return max(int(environment.get(name) or 1) for name in SIZE_VARIABLES)


def alone(environment=None) -> dict:
    """A copy of the environment (default: this process's) without an MPI launcher's variables: a process started
    from it runs alone (a study's worker), or under a launcher of its own."""
    environment = os.environ if environment is None else environment
    return {key: value for key, value in environment.items() if not key.startswith(("PMI_", "OMPI_", "MV2_", "PMIX_"))}


#: The signals that stop a run on the command line and keep its steps, where the system has them: Ctrl-C (SIGINT),
#: SIGTERM (``kill``, a scheduler's time limit), SIGHUP (the terminal closed: an ssh session dropped), SIGXCPU (a CPU
#: time limit: ``ulimit -t``, a scheduler's soft limit) and SIGUSR1/2 (a scheduler's warning before its limit, e.g.
#: Slurm's ``--signal``). All but the first two ended the process at once, every step lost (an outside pass).
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP", "SIGXCPU", "SIGUSR1", "SIGUSR2")


def stop_signals() -> list:
    """:data:`STOP_SIGNALS` this system has, as numbers."""
    import signal

    return [signal.Signals[name] for name in STOP_SIGNALS if name in signal.Signals.__members__]


def stopped_by(signum: int) -> str:
    """What a stop signal did, for a message: "interrupted" (Ctrl-C) or "terminated (SIGHUP)".

    >>> stopped_by(2), stopped_by(15)
    ('interrupted', 'terminated (SIGTERM)')
    """
    import signal

    return "interrupted" if signum == signal.SIGINT else f"terminated ({signal.Signals(signum).name})"


#: The signal (one of :func:`stop_signals`) that asked the processes of a distributed run to stop, 0 for none
#: (:func:`request_stop`).
_STOP = [0]


def request_stop(signum: int) -> None:
    """Ask a run on several MPI processes to stop after its current step (the command line's signal handler there):
    every rank reads the request together at the end of each step (:func:`stop_requested`), so all stop after the
    same step and the steps recorded are gathered and written, as a diverged run's are. A signal that raised at once
    left the ranks in different places, with nothing to gather: an interrupted run wrote nothing, and on two
    processes hung (an outside pass, December 2026)."""
    _STOP[0] = int(signum)


def stop_requested() -> int:
    """The signal a stop was asked for with (:func:`request_stop`), 0 for none."""
    return _STOP[0]


#: The command line's hold on the last run finished in this process (:func:`keep_finished`).
_FINISHED = {"keep": False, "runs": []}


def keep_finished(keep: bool = True) -> list:
    """From now on (``keep``; False: no longer), the result of the run that finishes in this process
    (:func:`finished`) is kept in the list returned, emptied here: the command line's own, so that a stop signal in
    the instants between the run's end and its archive being written (its Dataset on its way back through the
    calls) does not lose a complete run. A Python session keeps its result itself, and nothing is held for it."""
    _FINISHED["keep"] = keep
    _FINISHED["runs"].clear()  # (a command run before in the same process, a test's: not this one's)
    return _FINISHED["runs"]


def finished(ds, failure=None) -> None:
    """A run's final Dataset (a run on one mesh, or an adaptive run's merged result: not the run on each of its
    meshes), made while the stop signals were held (:func:`keep_finished`), with the failure that stopped it (a
    Diverged, raised with it; None: complete). A diverged run's, unwinding to the command, was lost to a signal too."""
    if _FINISHED["keep"] and ds is not None:
        _FINISHED["runs"][:] = [(ds, failure)]


@contextlib.contextmanager
def signals_held(drop: bool = False):
    """The stop signals (:func:`stop_signals`) held inside (the main thread's): delivered when the block ends, or dropped
    (``drop``: the run has stopped already, and what it computed is being kept). A Ctrl-C inside a netCDF write (a
    checkpoint) left xarray's lock taken, and the final archive's write hung on it; a second Ctrl-C while an interrupted
    run's records became a Dataset lost them (found by an outside pass)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came = []
    held = {s: signal.getsignal(s) for s in stop_signals()}
    for s in held:
        signal.signal(s, signal.SIG_IGN if drop else (lambda signum, frame: came.append(signum)))
    try:
        yield
    finally:
        for s, handler in held.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        for signum in came[:1]:
            signal.raise_signal(signum)
