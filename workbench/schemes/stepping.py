"""The time loop shared by all schemes: a step controller, recording by time, progress, blow-up detection.

The loop asks a step controller for the next time, steps the scheme there, watches
for blow-up and records by time (what the recorder wants at that time), so that the
step size may change from step to step without touching the schemes.

:class:`FixedSteps` is today's controller: the uniform grid of steps <= k over
[0, T] that contains every snapshot time exactly (where a requested time is not on
the uniform grid, each stretch between consecutive such times is divided into equal
steps <= k, so that a snapshot is a solution at that time, never a moved or
interpolated one).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import Diverged


def time_grid(T: float, k: float, times=None, sync=()) -> np.ndarray:
    """Grid 0 = t_0 < ... < t_N = T with steps <= k containing the ``sync`` times, or a checked user grid.

    Examples
    --------
    >>> time_grid(1.0, 0.25).tolist()
    [0.0, 0.25, 0.5, 0.75, 1.0]
    >>> time_grid(1.0, 0.4, sync=(0.5,)).tolist()
    [0.0, 0.25, 0.5, 0.75, 1.0]
    """
    if times is not None:
        grid = np.asarray(times, dtype=float)
        if grid.ndim != 1 or grid.size < 2 or not np.all(np.isfinite(grid)):
            raise ValueError("times: give at least two finite times")
        if grid[0] != 0.0 or np.any(np.diff(grid) <= 0):
            raise ValueError("times: the grid must start at 0 and increase strictly")
        return grid
    n = max(1, math.ceil(T / k - 1e-9))
    grid = np.linspace(0.0, T, n + 1)
    tol = 1e-9 * max(1.0, T)
    inside = sorted({float(s) for s in sync if tol < s < T - tol})
    if all(np.min(np.abs(grid - s)) <= tol for s in inside):
        return grid
    marks = [0.0] + inside + [float(T)]
    parts = [np.linspace(a, b, max(1, math.ceil((b - a) / k - 1e-9)) + 1)[:-1] for a, b in zip(marks, marks[1:])]
    return np.concatenate(parts + [np.array([float(T)])])


class FixedSteps:
    """Steps on a fixed grid (:func:`time_grid`)."""

    def __init__(self, grid):
        self.grid = np.asarray(grid, dtype=float)
        self.index = 0

    @property
    def t0(self) -> float:
        return float(self.grid[0])

    @property
    def T(self) -> float:
        return float(self.grid[-1])

    @property
    def k_max(self) -> float:
        return float(np.max(np.diff(self.grid)))

    @property
    def n_steps(self) -> int:
        return len(self.grid) - 1

    def done(self) -> bool:
        return self.index >= len(self.grid) - 1

    def next(self) -> tuple[float, float]:
        """(t_prev, t_next) of the next step."""
        self.index += 1
        return float(self.grid[self.index - 1]), float(self.grid[self.index])


class OscillationWatch:
    """Detects the explicit scheme's instability: a velocity that flips direction every step.

    A resolved solution cannot reverse its velocity at every step for
    ``window`` steps in a row; an unstable mode of forward Euler does, and does
    not decay. Watched on the whole velocity and, separately, on the normal
    velocity of the contact nodes (where the boundary springs' unstable modes
    live, hidden in the whole vector by the smooth bending motion). Keeps the
    previous velocities in preallocated buffers (no copies per step).
    """

    def __init__(self, v: np.ndarray, parts, window: int = 12, noise: float = 1e-8):
        self.v, self.parts, self.window, self.noise = v, parts, window, noise
        self.prev = [np.empty(v.size if p is None else len(p)) for p in parts]
        self.have = [False] * len(parts)
        self.count = [0] * len(parts)
        self.norms = [[] for _ in parts]
        self.peak = [0.0] * len(parts)
        self.prev_norm = [0.0] * len(parts)

    def flipped(self) -> bool:
        hit = False
        for i, part in enumerate(self.parts):
            cur = self.v if part is None else self.v[part]
            nv = float(np.linalg.norm(cur))
            self.peak[i] = max(self.peak[i], nv)
            # velocities at round-off level (a run at rest) carry no sign information
            significant = nv > self.noise * self.peak[i]
            alternating = (self.have[i] and significant
                           and float(cur @ self.prev[i]) < -0.5 * nv * self.prev_norm[i])
            self.count[i] = self.count[i] + 1 if alternating else 0
            self.norms[i] = (self.norms[i] + [nv])[-(self.window + 1):]
            self.prev[i][:] = cur
            self.prev_norm[i] = nv
            self.have[i] = True
            hit |= self.count[i] >= self.window and self.norms[i][-1] >= 0.95 * self.norms[i][0]
        return hit


class ChatterWatch:
    """Detects contact chatter: contact nodes switching between penetration and separation every few steps.

    The explicit scheme's unstable contact mode need not alternate every step:
    a penetrating node is kicked far out, pulled back over a few steps,
    penetrates again. A resolved run switches a node's contact state only when
    the load drives it; ``max_switches`` switches within ``window`` steps (a
    period of 5 steps or less) means the step cannot be trusted.
    """

    def __init__(self, u_nu, window: int = 20, max_switches: int = 8, significant: float = 1e-2):
        self.u_nu, self.window, self.max_switches = u_nu, window, max_switches
        self.significant = significant
        self.history = []
        self.prev = None

    def chattering(self) -> bool:
        u = self.u_nu()
        # a switch counts only where the node is clearly on either side: a node hovering at u_nu ~ 0
        # (near the clamp, or a decaying oscillation of a stable step) is not chatter
        big = np.abs(u) > self.significant * (np.abs(u).max() + 1e-300)
        state = np.where(big, np.sign(u), 0.0)
        if self.prev is not None:
            self.history.append((state * self.prev) < 0)
            self.history = self.history[-self.window:]
        self.prev = np.where(state != 0, state, self.prev if self.prev is not None else 0.0)
        if len(self.history) < self.window:
            return False
        return bool(np.max(np.sum(self.history, axis=0)) >= self.max_switches)


def march(disc, scheme, steps, recorder, *, progress=None, limit=None):
    """Advance ``scheme`` with the step controller ``steps``, recording what ``recorder`` wants at each time.

    Stops with :class:`~workbench.errors.Diverged` at the first step whose
    displacement is not finite or exceeds ``limit`` anywhere (the state is then
    meaningless for a small-strain model), whose velocity has alternated in sign
    for 12 steps without decaying (:class:`OscillationWatch`), or (schemes that
    ask for it: the explicit one) whose contact nodes chatter
    (:class:`ChatterWatch`); the recorder keeps what was computed before.
    """
    from tqdm.auto import tqdm

    u_np = disc.u.vec.FV().NumPy()
    bound = limit or math.inf
    t = steps.t0
    scheme.start(t)
    recorder.record(t, scheme)
    watch = OscillationWatch(disc.v.vec.FV().NumPy(), [None] + ([disc.normal_dofs] if disc.dim > 1 else []))
    chatter = ChatterWatch(lambda: disc.normal_displacement(u_np)) if scheme.chatter_watch else None
    bar = tqdm(total=steps.n_steps, disable=None if progress is None else not progress, unit="step",
               mininterval=0.5, leave=False, desc=disc.scene.name)
    n = 0
    try:
        while not steps.done():
            t_prev, t = steps.next()
            n += 1
            scheme.step(t_prev, t)
            norm = float(np.abs(u_np).max())
            oscillating = watch.flipped()
            chattering = chatter is not None and chatter.chattering()
            if not math.isfinite(norm) or norm > bound or oscillating or chattering:
                if not math.isfinite(norm):
                    what = "non-finite values"
                elif oscillating:
                    what = (f"a sign-alternating oscillation of the velocity, not decaying over {watch.window} steps "
                            "(the scheme is unstable at this step size)")
                elif chattering:
                    what = (f"contact chatter: a contact node switched between penetration and separation "
                            f"{chatter.max_switches} or more times within {chatter.window} steps (the explicit "
                            "scheme is unstable at this step size, or the step is far too long for the load)")
                else:
                    what = f"a displacement of {norm:.3g} m, beyond the bound {limit:.3g} m (10 x the body)"
                raise Diverged(f"{disc.scene.name}: {what} at step {n} (t = {t:.6g} s) "
                               f"with the {scheme.name} scheme, k = {t - t_prev:.3g} s", step=n, time=t)
            recorder.record(t, scheme, final=steps.done())
            bar.update()
    finally:
        bar.close()
