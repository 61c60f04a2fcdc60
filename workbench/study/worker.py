"""A study worker: ``python -c "$START" PARENT_PID`` (:data:`workbench.study.execute.START`: a process of its own
that runs scenes only, which starts its BLAS pools with one thread and skips dask before anything imports xarray:
:func:`workbench.running.threads.lean_process`).

Reads tasks (pickled argument tuples of :func:`workbench.study.execute.run_case`)
from standard input, answers each with ``("ok", Dataset)`` or ``("error",
traceback)`` on its own copy of standard output, and exits at end of input or
when its parent dies (:func:`workbench.running.threads.die_with_parent`, the program's first
call, before anything heavy is imported). Whatever the run prints goes to standard error, so it
cannot corrupt the channel.
"""
from __future__ import annotations

import os
import sys
import traceback


def main() -> None:
    import warnings

    channel = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # prints inside a run go to stderr, never into the channel
    warnings.showwarning = _one_line
    stdin = sys.stdin.buffer
    from .execute import read_frame, run_case, write_frame

    while True:
        try:
            args = read_frame(stdin)
        except EOFError:
            return
        try:
            reply = ("ok", run_case(*args))
        except BaseException:  # any failure goes back to the parent, which reports it with the case
            reply = ("error", traceback.format_exc())
        write_frame(channel, reply)


def _one_line(message, category, filename, lineno, file=None, line=None) -> None:
    """A case's warning as the command line shows one, ``warning: ...`` on one line (Python's own gave the file, the
    line number and the source line, once per case: found by an outside pass)."""
    try:
        print("warning: " + " ".join(str(message).split()), file=sys.stderr)
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    main()
