"""The time loop shared by all schemes: grid, recording, progress, blow-up detection."""
from __future__ import annotations

import math

import numpy as np


class Diverged(RuntimeError):
    """A run stopped because its state became non-finite or unbounded.

    ``dataset`` holds everything computed up to the failing step, with
    ``status = "incomplete"`` and the message in ``failure``.
    """

    def __init__(self, message, step=None, time=None, dataset=None):
        super().__init__(message)
        self.step, self.time, self.dataset = step, time, dataset


def time_grid(T: float, k: float, times=None) -> np.ndarray:
    """Uniform grid 0 = t_0 < ... < t_N = T with steps T/N <= k, or a checked user grid."""
    if times is not None:
        grid = np.asarray(times, dtype=float)
        if grid.ndim != 1 or grid.size < 2 or not np.all(np.isfinite(grid)):
            raise ValueError("times: give at least two finite times")
        if grid[0] != 0.0 or np.any(np.diff(grid) <= 0):
            raise ValueError("times: the grid must start at 0 and increase strictly")
        return grid
    n = max(1, math.ceil(T / k - 1e-9))
    return np.linspace(0.0, T, n + 1)


def march(disc, scheme, times, recorder, *, progress=None, limit=None):
    """Advance ``scheme`` over ``times``, recording as ``recorder`` asks.

    Stops with :class:`Diverged` at the first step whose displacement is not
    finite or whose RMS exceeds ``limit`` (the state is then meaningless for a
    small-strain model); the recorder keeps what was computed before.
    """
    from tqdm.auto import tqdm

    uvec = disc.u.vec
    bound = (limit or math.inf) * math.sqrt(disc.ndof)
    if recorder.wants(0):
        recorder.record(0, **scheme.diagnostics(initial=True))
    if recorder.wants_snapshot(0):
        recorder.snapshot(0, scheme.stress())
    n_steps = len(times) - 1
    bar = tqdm(total=n_steps, disable=None if progress is None else not progress, unit="step",
               mininterval=0.5, leave=False, desc=disc.scene.name)
    try:
        for n in range(1, n_steps + 1):
            scheme.step(times[n - 1], times[n])
            norm = uvec.Norm()
            if not math.isfinite(norm) or norm > bound:
                what = "non-finite values" if not math.isfinite(norm) else \
                    f"displacement RMS {norm / math.sqrt(disc.ndof):.3g} m beyond the bound {limit:.3g} m"
                raise Diverged(f"{disc.scene.name}: {what} at step {n} (t = {times[n]:.6g} s) "
                               f"with the {scheme.name} scheme, k = {times[n] - times[n - 1]:.3g} s",
                               step=n, time=times[n])
            if recorder.wants(n):
                recorder.record(n, **scheme.diagnostics())
            if recorder.wants_snapshot(n):
                recorder.snapshot(n, scheme.stress())
            bar.update()
    finally:
        bar.close()
