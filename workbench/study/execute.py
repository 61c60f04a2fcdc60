"""Where a study's cases run: in this process, in worker subprocesses, or on a dask.distributed cluster.

Every backend yields ``(case, Dataset)`` as cases finish, in any order.

The local workers are :mod:`workbench.study.worker` subprocesses talking
through pipes (length-prefixed pickles), not a ``multiprocessing`` pool: a
spawned pool re-imports the caller's ``__main__``, so a study in a plain script
without a main guard, on standard input or in some notebook set-ups died with
``BrokenProcessPool``; these workers import only workbench. A worker exits when
its parent dies (``PR_SET_PDEATHSIG`` on Linux, and a watchdog on the parent's
pid elsewhere), so a killed study leaves nothing running. Workers are reused
across cases (the NGSolve import is paid once per worker); each case's peak
resident memory is measured in its own worker.
"""
from __future__ import annotations

import os
import pickle
import selectors
import struct
import subprocess
import sys
import warnings

_HEADER = struct.Struct(">Q")
#: A worker's whole program (:mod:`workbench.study.worker`; ``python -m workbench.study.worker`` would import
#: ``workbench.study``, so xarray, first).
START = ("import sys; from workbench.running import threads; threads.die_with_parent(int(sys.argv[1])); "
         "threads.lean_process(); from workbench.study.worker import main; main()")


def run_case(scene, case_values, record_times, snapshots, extra_attrs, extend=None):
    """Run one case (in whatever process this is).

    A diverged case returns its partial Dataset (``status = "incomplete"``); a case the explicit scheme
    refuses (k above its predicted k_crit) returns an empty Dataset with ``status = "refused"``: in a
    sweep these are results, not errors. With ``extend`` (a plan of :func:`.cases.extension`) the case
    continues the archived run of a shorter T, and keeps the fields at its own snapshot times only.
    """
    import xarray as xr

    from ..errors import Diverged, StepTooLarge
    from ..running.runner import run

    _peak_memory_reset()  # workers are reused: the peak must be this case's
    restart = None
    if extend is not None:
        snapshots, record_times, restart = extend["snapshots"], extend["record_times"], extend["restart"]
    sc = scene.with_(snapshots=tuple(snapshots), **case_values)
    try:
        with warnings.catch_warnings():
            if extend is not None:  # (the study states that extended cases equal straight runs to round-off)
                warnings.filterwarnings("ignore", message=r".*differ from those of the grid.*by round-off")
            ds = run(sc, progress=False, record_times=record_times, restart=restart)
        if extend is not None:
            ds = _keep_snapshots(ds, extend["keep"])
            ds.attrs["case_extended_from_T"] = extend["T"]
    except Diverged as err:
        ds = err.dataset
    except StepTooLarge as err:
        ds = xr.Dataset(attrs={"scene": sc.name, "status": "refused", "failure": str(err), "failure_type":
                               type(err).__name__, "ndof": -1, "nsteps": -1, "wall_time": 0.0, "cpu_time": 0.0,
                               "setup_time": 0.0})
    ds.attrs["memory_peak_mb"] = _peak_memory_mb()
    ds.attrs.update(extra_attrs)
    return ds


def _keep_snapshots(ds, times):
    """``ds`` with the field snapshots at ``times`` only (to round-off)."""
    import numpy as np

    if "snapshot_time" not in ds.coords:
        return ds
    t = ds.snapshot_time.values
    keep = [i for i in range(t.size) if np.min(np.abs(np.asarray(times) - t[i])) <= 1e-9 * max(1.0, abs(t[i]))]
    return ds.isel(snapshot=keep)


def _peak_memory_reset() -> bool:
    """Reset the process's peak resident memory (Linux: write 5 to /proc/self/clear_refs)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _peak_memory_mb() -> float:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def write_frame(stream, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def read_frame(stream):
    """The next pickled object on ``stream``; EOFError when the other side is gone."""
    head = _read_exact(stream, _HEADER.size)
    return pickle.loads(_read_exact(stream, _HEADER.unpack(head)[0]))


def _read_exact(stream, n):
    chunks, got = [], 0
    while got < n:
        chunk = stream.read(n - got)
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


class WorkerFailed(RuntimeError):
    """A case raised an unexpected error in a worker, or the worker died (killed, out of memory)."""


def in_process(tasks):
    """Run the tasks here, one after another (no isolation: the memory peak is cumulative)."""
    for case, args in tasks:
        yield case, run_case(*args)


def subprocesses(tasks, n_workers: int):
    """Run the tasks on ``n_workers`` worker subprocesses (see the module docs)."""
    tasks = list(tasks)
    if not tasks:
        return
    n = max(1, min(n_workers, len(tasks)))
    from ..discrete.world import alone
    from ..running.threads import single_threaded

    env = single_threaded(alone())  # (a case each, alone)
    workers = [subprocess.Popen([sys.executable, "-c", START, str(os.getpid())],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env) for _ in range(n)]
    sel = selectors.DefaultSelector()
    busy = {}
    pending = list(reversed(tasks))
    try:
        for w in workers:
            sel.register(w.stdout, selectors.EVENT_READ, w)
            _give(w, pending, busy)
        while busy:
            for key, _ in sel.select():
                w = key.data
                case = busy.pop(w)
                try:
                    status, payload = read_frame(w.stdout)
                except EOFError:
                    code = w.wait()
                    raise WorkerFailed(f"the worker running case {case.key} died (exit code {code}; out of memory or "
                                       "killed?)") from None
                if status != "ok":
                    raise WorkerFailed(f"case {case.key} failed in a worker:\n{payload}")
                yield case, payload
                _give(w, pending, busy)
    finally:
        for w in workers:
            try:
                w.stdin.close()
            except OSError:
                pass
        for w in workers:
            try:
                w.wait(timeout=5)
            except subprocess.TimeoutExpired:
                w.kill()
                w.wait()


def _give(worker, pending, busy):
    if pending:
        case, args = pending.pop()
        write_frame(worker.stdin, args)
        busy[worker] = case


def on_cluster(tasks, client):
    """Run the tasks on a dask.distributed cluster (a Client or a scheduler address)."""
    from distributed import Client
    from distributed import as_completed as dask_completed

    if isinstance(client, str):
        try:
            client = Client(client, timeout=10)
        except (OSError, ValueError, TypeError) as err:  # (unreachable, a malformed address, a wrong port)
            from ..errors import ParameterError

            raise ParameterError(f"--scheduler {client!r}: no dask.distributed scheduler answers there "
                                 f"({type(err).__name__}: {str(err).splitlines()[0][:80] if str(err) else ''})") \
                from None
    futures = {client.submit(run_case, *args, pure=False): case for case, args in tasks}
    for fut in dask_completed(futures):
        yield futures[fut], fut.result()
