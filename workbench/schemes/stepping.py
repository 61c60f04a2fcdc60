"""The time loop shared by all schemes: grid, recording, progress, blow-up detection."""
from __future__ import annotations

import math

import numpy as np

from ..errors import Diverged


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


class OscillationWatch:
    """Detects the explicit scheme's instability: a velocity that flips direction every step.

    A resolved solution cannot reverse its velocity at every step for
    ``window`` steps in a row; an unstable mode of forward Euler does, and does
    not decay. Watched on the whole velocity and, separately, on the normal
    velocity of the contact nodes (where the boundary springs' unstable modes
    live, hidden in the whole vector by the smooth bending motion).
    """

    def __init__(self, v: np.ndarray, parts, window: int = 12, noise: float = 1e-8):
        self.v, self.parts, self.window, self.noise = v, parts, window, noise
        self.prev = [None] * len(parts)
        self.count = [0] * len(parts)
        self.norms = [[] for _ in parts]
        self.peak = [0.0] * len(parts)

    def flipped(self) -> bool:
        hit = False
        for i, part in enumerate(self.parts):
            cur = self.v[part] if part is not None else self.v.copy()
            prev = self.prev[i]
            nv = float(np.linalg.norm(cur))
            self.peak[i] = max(self.peak[i], nv)
            # velocities at round-off level (a run at rest) carry no sign information
            significant = nv > self.noise * self.peak[i]
            alternating = (prev is not None and significant
                           and float(cur @ prev) < -0.5 * nv * np.linalg.norm(prev))
            self.count[i] = self.count[i] + 1 if alternating else 0
            self.norms[i] = (self.norms[i] + [nv])[-(self.window + 1):]
            self.prev[i] = cur
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


def march(disc, scheme, times, recorder, *, progress=None, limit=None):
    """Advance ``scheme`` over ``times``, recording as ``recorder`` asks.

    Stops with :class:`Diverged` at the first step whose displacement is not
    finite or exceeds ``limit`` anywhere (the state is then meaningless for a
    small-strain model), whose velocity has alternated in sign for 12 steps
    without decaying (:class:`OscillationWatch`), or (schemes that ask for it:
    the explicit one) whose contact nodes chatter (:class:`ChatterWatch`); the
    recorder keeps what was computed before.
    """
    from tqdm.auto import tqdm

    u_np = disc.u.vec.FV().NumPy()
    bound = limit or math.inf
    nodes = getattr(scheme, "node_values", None)
    start = getattr(scheme, "start", None)
    if start is not None:
        start(times[0])
    if recorder.wants(0):
        recorder.record(0, node_values=nodes() if nodes else None, **scheme.diagnostics(initial=True))
    if recorder.wants_snapshot(0):
        recorder.snapshot(0, scheme.stress())
    n_steps = len(times) - 1
    normal = disc.node_dofs[:, -1] if disc.dim > 1 else None
    watch = OscillationWatch(disc.v.vec.FV().NumPy(), [None] + ([normal] if normal is not None else []))
    chatter = ChatterWatch(lambda: disc.normal_displacement(u_np)) if getattr(scheme, "watch_chatter", False) else None
    bar = tqdm(total=n_steps, disable=None if progress is None else not progress, unit="step",
               mininterval=0.5, leave=False, desc=disc.scene.name)
    try:
        for n in range(1, n_steps + 1):
            scheme.step(times[n - 1], times[n])
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
                raise Diverged(f"{disc.scene.name}: {what} at step {n} (t = {times[n]:.6g} s) "
                               f"with the {scheme.name} scheme, k = {times[n] - times[n - 1]:.3g} s",
                               step=n, time=times[n])
            if recorder.wants(n):
                recorder.record(n, node_values=nodes() if nodes else None, **scheme.diagnostics())
            if recorder.wants_snapshot(n):
                recorder.snapshot(n, scheme.stress())
            bar.update()
    finally:
        bar.close()
