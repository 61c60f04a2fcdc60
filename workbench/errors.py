"""The exceptions a user meets, in one bottom-level module (every layer may raise them).

* :class:`ParameterError` — bad input (a value out of range, an unknown name, an
  impossible combination); raised before any work, the message names the
  parameter and what is allowed. The command line turns it into one line and exit code 2.
* :class:`StepTooLarge` — the explicit scheme's step exceeds its predicted stability limit.
* :class:`Diverged` — a run stopped because its state became non-finite, unbounded
  or oscillating; ``dataset`` holds what was computed, marked incomplete (exit code 3).
* :class:`NewtonFailed` — an implicit step's nonlinear iteration did not converge.
* :class:`StepLimitExceeded` — the explicit scheme's state reached springs whose stability
  limit is below its step; stopped like :class:`Diverged`, with what was computed.
* :class:`NotWritten` — a file of a computed result could not be written; it carries the result.
* :class:`Unwritable` — an output path that cannot be written: a ParameterError and an OSError.
* :class:`Interrupted` — a run stopped by Ctrl-C or SIGTERM; it carries what was computed.
"""
from __future__ import annotations


class ParameterError(ValueError):
    """A bad parameter value or name; the message names the parameter and the allowed range."""


class Unwritable(ParameterError, OSError):
    """An output path that cannot be written (a folder where a file is meant, a parent that is a file, no permission):
    a bad parameter when checked before the run, and an :class:`OSError` like any failed write when the path changed
    during the run (a folder removed, a file made in its place), so that what was computed is kept elsewhere."""


class StepTooLarge(ParameterError):
    """k exceeds the explicit scheme's predicted stability limit."""


class Diverged(RuntimeError):
    """A run stopped because its state became non-finite or unbounded.

    ``dataset`` holds everything computed up to the failing step, with
    ``status = "incomplete"`` and the message in ``failure``.
    """

    def __init__(self, message, step=None, time=None, dataset=None):
        super().__init__(message)
        self.step, self.time, self.dataset = step, time, dataset


class NewtonFailed(Diverged):
    """The nonlinear iteration of an implicit step (semismooth Newton, active set) did not converge."""


class StepLimitExceeded(Diverged):
    """The explicit scheme's step exceeds the stability limit of the springs that act in the state the run has
    reached (they were not acting when it started); ``dataset`` holds the steps before, marked incomplete."""


class Interrupted(KeyboardInterrupt):
    """A run stopped from outside: Ctrl-C (SIGINT), or SIGTERM on the command line (a batch scheduler's time limit).
    ``dataset`` holds the steps recorded before, marked incomplete (no state to go on from: the step under way may
    have been left half done; ``checkpoint_every`` keeps one); ``signal`` is the signal's number; ``together``: raised
    on every process of a distributed run after the same step (:func:`workbench.discrete.world.request_stop`)."""

    def __init__(self, message="interrupted", dataset=None, signal: int = 2, together: bool = False):
        super().__init__(message)
        self.dataset, self.signal, self.together = dataset, signal, together


class NotWritten(OSError):
    """A result was computed but a file of it could not be written (a full disk, a folder gone); ``dataset`` holds the
    result, so a caller can keep it elsewhere."""

    def __init__(self, err: OSError, dataset=None):
        super().__init__(err.errno, err.strerror or str(err), err.filename)
        self.dataset = dataset
