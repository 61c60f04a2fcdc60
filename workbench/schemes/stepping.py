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

import collections
import math
import sys

import numpy as np

from ..discrete.world import SERIAL, stop_requested, stopped_by
from ..errors import Diverged, Interrupted


def time_grid(T: float, k: float, times=None, sync=()) -> np.ndarray:
    """Grid 0 = t_0 < ... < t_N = T with steps <= k containing the ``sync`` times, or a checked user grid.

    The grid is the uniform one of N = ceil(T / k) equal steps. A sync time (a snapshot or a
    requested record) is a point of the grid, exactly: one that the uniform grid meets within
    round-off (0.3 = 3 x 0.1 to 1e-9 T) replaces that point, any other splits the step that
    holds it in two; the steps around it do not move. So the grid of a run to T1, where T1 is a
    point of the uniform grid to T2 > T1, is the start of the grid to T2 (with the same sync
    times up to T1): a run continued from T1 to T2 takes the steps of the run straight to T2
    (:mod:`workbench.running.restart`). A user grid ``times`` must end at T and contain every
    sync time (to round-off); otherwise ValueError, as for a sync time outside [0, T]: a
    requested time is never dropped or moved.

    Examples
    --------
    >>> time_grid(1.0, 0.25).tolist()
    [0.0, 0.25, 0.5, 0.75, 1.0]
    >>> [round(float(t), 6) for t in time_grid(1.0, 0.4, sync=(0.5,))]  # three steps of 1/3, the second split at 0.5
    [0.0, 0.333333, 0.5, 0.666667, 1.0]
    >>> float(time_grid(1.0, 0.1, sync=(0.3,))[3])  # not 0.30000000000000004
    0.3
    """
    tol = 1e-9 * T  # (relative: a run of T = 1e-9 s is no coarser in time than one of 1 s)
    sync = sorted({float(s) for s in sync})
    outside = [s for s in sync if not -tol <= s <= T + tol]
    if outside:
        raise ValueError(f"record time {outside[0]:g} is outside the run, 0 <= t <= T = {T:g}")
    if times is not None:
        grid = np.array(times, dtype=float)
        if grid.ndim != 1 or grid.size < 2 or not np.all(np.isfinite(grid)):
            raise ValueError("times: give at least two finite times")
        if grid[0] != 0.0 or np.any(np.diff(grid) <= 0):
            raise ValueError("times: the grid must start at 0 and increase strictly")
        if np.min(np.diff(grid)) <= tol:  # (times that close are one time wherever times are matched)
            raise ValueError(f"times: a step of {np.min(np.diff(grid)):.3g} s is below the times told apart, "
                             f"1e-9 T = {tol:.3g} s")
        if abs(grid[-1] - T) > tol:
            raise ValueError(f"times: the grid ends at {grid[-1]:g}, not at T = {T:g}; end it at T or set T")
        off = [s for s in sync if np.min(np.abs(grid - s)) > tol]
        if off:
            raise ValueError(f"times: the snapshot or record time {off[0]:g} is not on the given grid; add it to "
                             "times (or leave times out: the grid is then made to contain it)")
        return _land(grid, sync, tol)
    n = max(1, math.ceil(T / k - 1e-9))
    grid = np.linspace(0.0, T, n + 1)
    inside = [s for s in sync if tol < s < T - tol]
    grid = _land(grid, inside, tol)
    off = [s for s in inside if np.min(np.abs(grid - s)) > tol]
    return np.sort(np.concatenate([grid, off])) if off else grid


def _land(grid, sync, tol):
    """The grid with each of the ``sync`` times (each within ``tol`` of a point) in place of that point."""
    for s in sync:
        i = int(np.argmin(np.abs(grid - s)))
        if abs(grid[i] - s) <= tol and 0 < i < len(grid) - 1:
            grid[i] = s
    return grid


class FixedSteps:
    """Steps on a fixed grid (:func:`time_grid`): every step is accepted."""

    adaptive = False

    def __init__(self, grid, given: bool = False):
        self.grid = np.asarray(grid, dtype=float)
        self.index = 0
        #: A grid of the user's (``times=``): kept in the restart state, where nothing else says it.
        self.given = given

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
        return float(self.grid[self.index]), float(self.grid[self.index + 1])

    def accepted(self, err=None) -> None:
        self.index += 1

    @property
    def t(self) -> float:
        """The time reached (the end of the last step taken)."""
        return float(self.grid[self.index])

    @property
    def taken(self) -> int:
        """Steps taken so far (a restarted run counts those before the restart too)."""
        return self.index

    def state(self) -> dict:
        """What a restart needs to go on with the same grid: the index reached, and its time (to check the grid); a
        grid of the user's itself (a continuation takes it from the archive)."""
        own = {"grid": self.grid.copy()} if self.given else {}
        return {"kind": "fixed", "index": self.index, "time": self.t} | own

    def restore(self, state: dict) -> None:
        self.index = int(state["index"])


class StepTooSmall(Diverged):
    """Error control asked for a step below k_min."""


class AdaptiveSteps:
    """Error-controlled steps: k from the scaled local error (PI control), rejection, landing on kinks and sync times.

    After each step the loop reports the scheme's scaled local error (relative to
    atol + rtol U, U the largest |u| of the run so far,
    :meth:`workbench.schemes.base.Scheme.local_error`) and where in the step a kink was
    crossed (``theta``). The error is judged **per unit of elapsed time**:
    err = local error x (t_n - t0) / k, so that the local errors up to any time t add up to
    about rtol U(t) when u grows from rest like a power of t (the sum of rtol U(s) ds / s),
    and to rtol U ln(t / k_1) at worst (a solution that starts large and stays). The
    achieved global error is then about proportional to the tolerance. Per unit step
    (x (T - t0) / k) cannot start from rest: relative to a u ~ t^2 it asks for k ~ rtol t^2 / T
    (measured on the slab of issue 11: steps of 1e-8 s at t = 1e-3 s); per step (x 1) the
    global error grows only like tol^(p/(p+1)). A step is

    * **rejected** when err > 1 (next try: k * max(0.2, 0.9 err^(-1/p))), when the
      nonlinear solve failed (k / 4), or when a kink lies inside it more than k_min from
      its end (next try: the step that ends at the kink, theta k, so that no kink is
      stepped over blindly);
    * **accepted** otherwise, and the next step is k * 0.9 err^(-0.5/p) (err_prev / err)^(0.2/p)
      (a PI controller; measured on tp1 against the exact solution: 0-2 rejections per run and an
      achieved error of 0.25-0.4 times the tolerance for both schemes, where the gains 0.7 and 0.4
      rejected every third backward-Euler step), at most twice longer (BDF2's variable-step
      formula is zero-stable only for step ratios below 1 + sqrt 2), and kept as it is when it
      could grow by less than 1.5 (:attr:`hold`).

    Steps are rounded down to k0 2^(j/4) (so that schemes which factor a matrix per step
    size meet the same few sizes again: they keep a small cache), shortened further where the
    scheme asks (``admissible``: BDF2's operator depends on the step ratio too, so it snaps its
    a0 to a grid instead), shortened to land on the
    ``sync`` times (snapshots, requested records) and on T (halved when within 2 k of them, so
    that no sliver of a step is left before them), for BDF2 at most twice the last step (also
    after landing on an event), and kept within [k_min, k_max];
    when error control needs a step below k_min the run stops (:class:`StepTooSmall`).
    """

    adaptive = True
    #: PI gains (as multiples of 1/p), the safety factor and the largest growth of the step per step.
    alpha, beta, safety, max_growth = 0.5, 0.2, 0.9, 2.0  # measured on tp1: few rejections, error ~ 0.3 tol
    #: A step that could grow by less than this factor is kept: each new step size costs a factorisation
    #: (BDF2: each new ratio too). Measured on the slab of issue 11 (rtol 1e-2): 184 factorisations in 210
    #: steps without.
    hold = 1.5

    def __init__(self, T, k0, *, rtol, atol, k_min, k_max, order, sync=(), t0=0.0, admissible=None, kinks=(),
                 loads=()):
        self.t, self.T, self.k = float(t0), float(T), float(min(k0, k_max))
        self.tol = 1e-12 * T
        # (a step below ~1e-10 T cannot be told from round-off in t: k_min = 1e-300 would divide by t - t_prev = 0)
        self.k_floor = 100 * self.tol
        self.k0, self.rtol, self.atol, self.k_min, self.k_max = float(k0), rtol, atol, max(k_min, self.k_floor), k_max
        self.order = order
        self.growth = self.max_growth
        #: The loads' kinks (``Expression.kinks``): landed on like the sync times, and the steps after each charged to
        #: it as to a kink of the whole boundary (:meth:`per_unit_step`). A ramp held from t = 0.3 stopped backward
        #: Euler at k_min there at every rtol: the step across it was judged per unit time, which grows as k falls.
        self.kinks = sorted(float(s) for s in kinks if t0 + self.tol < s < T - self.tol)
        #: The loads as functions of t (arrays, the same on every process), with their largest size over [0, T]: a
        #: step must resolve them (:meth:`load_error`).
        self.loads = [(f, max(float(np.abs(f(t)).max(initial=0.0)) for t in np.linspace(0.0, T, 201)))
                      for f in loads]
        self.sync = sorted(set(float(s) for s in sync if t0 + self.tol < s < T - self.tol) | set(self.kinks))
        self.err_prev = None
        self.accepted_steps = self.rejected_steps = 0
        self._t0 = float(t0)
        self._proposed = None
        self._resume = None
        self._k_last = None
        self._k_request = None  # the step asked for, when the scheme shortened it (admissible)
        #: the shares of the boundary that switched law in the last ``order`` accepted steps (newest last): a
        #: predictor through a kink is first order for the ``order`` steps after it (:meth:`per_unit_step`)
        self._kinked = [0.0] * order
        #: k -> the step the scheme would rather take (<= k; BDF2: one whose a0 is on its grid)
        self.admissible = admissible or (lambda k: k)

    @property
    def t0(self) -> float:
        return self._t0

    @property
    def n_steps(self):
        return None

    def done(self) -> bool:
        return self.t >= self.T - self.tol

    @property
    def taken(self) -> int:
        """Accepted steps so far (a restarted run counts those before the restart too)."""
        return self.accepted_steps

    #: What the controller carries from step to step (the rest is set by the constructor from the scene): a restart
    #: that restores these takes the steps the uninterrupted run takes.
    _STATE = ("t", "k", "err_prev", "accepted_steps", "rejected_steps", "growth", "_proposed", "_resume", "_k_last",
              "_k_request", "_kinked")

    def state(self) -> dict:
        return {"kind": "adaptive"} | {name.lstrip("_"): getattr(self, name) for name in self._STATE}

    def restore(self, state: dict) -> None:
        for name in self._STATE:
            key = name.lstrip("_")
            if key == "kinked" and key not in state:  # (a checkpoint from before the kink memory: no kink pending)
                continue
            setattr(self, name, state[key])

    def _quantize(self, k):
        j = math.floor(4 * math.log2(k / self.k0) + 1e-9)
        return self.k0 * 2.0 ** (j / 4)

    def next(self) -> tuple[float, float]:
        k = min(self.k, self.k_max)
        if self.order >= 2 and self._k_last:  # variable-step BDF2 is zero-stable for step ratios < 1 + sqrt 2
            k = min(k, self.max_growth * self._k_last)
        target = next((s for s in self.sync if s > self.t + self.tol), self.T)
        d = target - self.t
        # land on the next sync time (or T) without a sliver before it: one step if it is within k,
        # two equal ones if within 2 k
        self._k_request = None
        if d <= k * (1 + 1e-9):
            end = target
        elif d <= 2 * k:
            end = self.t + d / 2
        else:  # a free step: the scheme may shorten it to one whose operator it has factored already
            k_free = self.admissible(k)
            if self.k_min <= k_free < k:
                # the next step is chosen from k, not from the shortened step: shortening and rounding down
                # again would ratchet the step down
                k, self._k_request = k_free, k
            end = self.t + k
        self._proposed = end
        return self.t, end

    def per_unit_step(self, err, crossed=0.0):
        """The scheme's local error estimate per unit of elapsed time (see the class docs), or, in a step inside
        which a share ``crossed`` of the boundary switched law, err / crossed if that is smaller.

        A kink inside a step makes a local error of first order, k |jump of u'|, that no shorter step
        removes per unit time (the estimate x t / k does not fall with k) - yet it is made once, not at every
        step. Charged instead against its share of the tolerance (the sum of the shares over the run is the
        number of times the boundary switches, about 1 for a front that sweeps it), the kink errors add up to
        about rtol U, and the steps while a front sweeps are limited by the size of the jump, k <~ rtol U /
        |jump| (measured on the slab of issue 11, h = 0.05, BDF2 at rtol 1e-3: 607 steps, 477 of them
        < 1e-3 s for t in (0.7, 0.9), without this rule).

        The ``order`` steps after a kink are charged to it too: their predictor (and BDF2's own formula) is drawn
        through the kink, so their estimates are first order in the same jump (on the slab of
        ``studies/time_stepping.py``, BDF2 at rtol 1e-3: two rejections after nearly every kink, 316 of 481 steps
        for t > 0.6 s and steps down to 1.4e-4 s; charged to the kink, 112 steps, the tip error at T 1.9e-4 both
        ways).
        """
        if err is None:
            return None
        crossed = max(crossed, *self._kinked) if self._kinked else crossed
        unit = err * (self._proposed - self._t0) / (self._proposed - self.t)
        return min(unit, err / crossed) if crossed > 0 else unit

    def accepted(self, err) -> None:
        p = self.order
        k = self._proposed - self.t
        self.t = self._proposed
        self._k_last = k
        self.accepted_steps += 1
        if self._resume is not None:  # a step that landed on an event: go on with the step from before the event
            self.k, self._resume = self._resume, None
            return
        if err is None:  # no estimate yet (the first steps): keep the step
            return
        err = max(err, 1e-10)
        factor = self.safety * err ** (-self.alpha / p)
        if self.err_prev is not None:
            factor *= (self.err_prev / err) ** (self.beta / p)
        self.err_prev = err
        factor = min(self.growth, max(0.2, factor))
        if 1.0 <= factor < self.hold:  # keep the step (and the factored matrix) unless it can grow clearly
            factor = 1.0
        basis = self._k_request or k
        self.k = self._quantize(min(self.k_max, max(self.k_min, basis * factor)))

    def rejected(self, err=None, theta=None, failed=False) -> None:
        """Shorten the step after a rejection (see the class docs); StepTooSmall below k_min."""
        k = self._proposed - self.t
        self.rejected_steps += 1
        if theta is not None:
            new = max(theta * k, self.k_min)
        elif failed:
            new = k / 4
        else:
            new = k * max(0.2, 0.9 * err ** (-1.0 / self.order))
        if new < self.k_min * (1 - 1e-9) or (new <= self.k_min and k <= self.k_min * (1 + 1e-9)):
            why = "the nonlinear solve failed" if failed else f"the scaled local error is {err:.3g}"
            floor = self.k_min == self.k_floor
            raise StepTooSmall(f"error control needs a step below k_min = {self.k_min:.3g} s"
                               f"{' (the smallest step time resolves here)' if floor else ''} at t = {self.t:.6g} s "
                               f"({why} with k = {k:.3g} s, and it asks for {new:.3g} s next): loosen rtol/atol, "
                               f"{'' if floor else 'lower k_min, '}or check the scene", time=self.t)
        self.k = new if theta is not None else self._quantize(new)

    #: The loads' interpolation error a step may leave, in rtol (:meth:`load_error`): a bound for steps that no
    #: estimate shortens, not the accuracy's driver (at 1, a rod driven by 0.3 sin(2 pi t) under BDF2 came out at
    #: 0.28 rtol in 195 steps at rtol 1e-3, where the estimate gives 0.82 in 166).
    load_share = 10.0

    def load_error(self) -> float:
        """How far the step's straight line between its ends misses the loads inside it, at its quarter points, over
        rtol times each load's largest size (and atol): at most 1 where the step resolves them. A body that follows
        a load exactly (a free rod's rigid motion) has no error estimate to shorten its steps, and an event check
        along that line misses a contact that begins and ends inside the step: a rod moved by 0.03 sin(20 pi t) kept
        an error of 6.5e-3 from rtol = 1e-3 to 1e-5."""
        t0, t1 = self.t, self._proposed
        worst = 0.0
        for f, size in self.loads:
            a, b = f(t0), f(t1)
            for s in (0.25, 0.5, 0.75):
                miss = float(np.abs(f(t0 + s * (t1 - t0)) - ((1 - s) * a + s * b)).max(initial=0.0))
                worst = max(worst, miss / (self.atol + self.load_share * self.rtol * size) if size > 0 else 0.0)
        return worst

    def judge(self, err, theta, crossed=0.0) -> bool:
        """Whether the step just taken is accepted (``err``: the scheme's scaled local error, ``theta``: where
        to land on an event, ``crossed``: see :meth:`per_unit_step`); updates the controller either way."""
        err = self.per_unit_step(err, crossed)
        if self.loads and err is not None:
            err = max(err, self.load_error() ** (self.order / 2.0))  # (in the scheme's order: the controller's)
        k = self._proposed - self.t
        if theta is not None and theta * k > self.k_min and (1 - theta) * k > self.k_min:
            if self._resume is None:  # the step to go on with after landing: what the error asked for
                ok = err is None or err <= 1.0
                self._resume = self._quantize(k if ok else k * max(0.2, 0.9 * err ** (-1.0 / self.order)))
            self.rejected(theta=theta)
            return False
        if err is not None and err > 1.0:
            self.rejected(err=err)
            return False
        self.accepted(err)
        if self._kinked:
            on_kink = any(abs(self.t - s) <= self.tol for s in self.kinks)
            self._kinked = self._kinked[1:] + [1.0 if on_kink else float(crossed)]
        return True


class OscillationWatch:
    """Detects the explicit scheme's instability: a velocity that flips direction every step.

    A resolved solution cannot reverse its velocity at every step for
    ``window`` steps in a row; an unstable mode of forward Euler does, and does
    not decay. Watched on the whole velocity and, separately, on the normal
    velocity of the contact nodes (where the boundary springs' unstable modes
    live, hidden in the whole vector by the smooth bending motion). Keeps the
    previous velocities in preallocated buffers (no copies per step).
    """

    def __init__(self, v: np.ndarray, parts, window: int = 12, noise: float = 1e-8, world=None, owned=None):
        self.v, self.parts, self.window, self.noise = v, parts, window, noise
        # (several MPI processes: the products are summed over the ranks, each shared dof counted by its owner)
        self.world = world or SERIAL
        self.owned = None if owned is None else [owned if p is None else owned[p] for p in parts]
        self.prev = [np.empty(v.size if p is None else len(p)) for p in parts]
        self.have = [False] * len(parts)
        self.count = [0] * len(parts)
        self.norms = [collections.deque(maxlen=window + 1) for _ in parts]
        self.peak = [0.0] * len(parts)
        self.prev_norm = [0.0] * len(parts)

    #: Velocities below this share of the largest displacement so far per step are round-off too, whatever their
    #: own peak: a body that never moved has a peak of round-off (a rod held at rest by Signorini contact, with
    #: changes of 8e-16 in u, was stopped as unstable at t = 0.75 s by the peak-relative test alone).
    round_off = 1e-10

    def flipped(self, floor: float = 0.0) -> bool:
        """Whether a velocity has alternated for ``window`` steps without decaying; ``floor``: the velocity below which
        it is round-off (:attr:`round_off` x the largest |u| so far / k, from :class:`_Guard`)."""
        hit = False
        for i, part in enumerate(self.parts):
            cur = self.v if part is None else self.v[part]
            if self.owned is None:
                nv, along = float(np.linalg.norm(cur)), float(cur @ self.prev[i]) if self.have[i] else 0.0
            else:
                mine = self.owned[i]
                nv = np.sqrt(self.world.sum(cur[mine] @ cur[mine]))
                along = self.world.sum(cur[mine] @ self.prev[i][mine]) if self.have[i] else 0.0
            self.peak[i] = max(self.peak[i], nv)
            # velocities at round-off level (a run at rest) carry no sign information
            significant = nv > max(self.noise * self.peak[i], floor)
            alternating = self.have[i] and significant and along < -0.5 * nv * self.prev_norm[i]
            self.count[i] = self.count[i] + 1 if alternating else 0
            self.norms[i].append(nv)  # (a deque of the last window + 1 norms)
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

    def __init__(self, u_nu, window: int = 20, max_switches: int = 8, significant: float = 1e-2, world=None):
        self.u_nu, self.window, self.max_switches = u_nu, window, max_switches
        self.significant = significant
        self.world = world or SERIAL  # (several MPI processes: each watches its nodes, the largest |u_nu| is everyone's)
        self.history = collections.deque()  # the switches of the last `window` steps
        self.counts = None  # their sum per node, kept as the window moves (not summed again every step)
        self.prev = None

    def chattering(self) -> bool:
        u = self.u_nu()
        # a switch counts only where the node is clearly on either side: a node hovering at u_nu ~ 0
        # (near the clamp, or a decaying oscillation of a stable step) is not chatter
        big = np.abs(u) > self.significant * (self.world.max(np.abs(u).max(initial=0.0)) + 1e-300)
        state = np.where(big, np.sign(u), 0.0)
        if self.prev is not None:
            switched = (state * self.prev) < 0
            if self.counts is None:
                self.counts = np.zeros(switched.size, dtype=np.int64)
            self.counts += switched
            self.history.append(switched)
            if len(self.history) > self.window:
                self.counts -= self.history.popleft()
        self.prev = np.where(state != 0, state, self.prev if self.prev is not None else 0.0)
        if len(self.history) < self.window:
            return False
        return self.world.any(self.counts.max(initial=0) >= self.max_switches)


def march(disc, scheme, steps, observe, *, progress=None, limit=None, limit_origin="the given limit", resume=False,
          after_step=None):
    """Advance ``scheme`` with the step controller ``steps``, handing each accepted state's time to ``observe``.

    ``observe(t, final=False, control=None)`` is the output callback (the runner's recorder:
    :meth:`workbench.output.results.Recorder.record`; ``control``: an adaptive run's step size and error estimate). With an
    adaptive controller every step is judged (scaled local error, kinks inside it) and a rejected step is redone
    from the exact state before it (:meth:`~workbench.schemes.base.Scheme.state` / ``restore``). Stops with
    :class:`~workbench.errors.Diverged` at the first accepted step that :class:`_Guard` finds diverged; what was
    observed before is kept. ``limit_origin`` says in the message where the limit came from.

    With ``resume`` the scheme, controller and observer hold a restored state (a restart, :mod:`workbench.running.restart`):
    the loop goes on from it, without ``start`` and the first record. ``after_step(t, n)`` is called after each
    accepted step is observed, ``n`` counting the steps from the run's start (the runner writes its checkpoints
    there).
    """
    if resume:
        t = steps.t
    else:
        t = steps.t0
        scheme.start(t)
        scheme.accept(t)
        observe(t, control=_control(steps, None, None))
    # a restarted run watches afresh: the watchers only stop a run (they never change its state), so the restart
    # delays the detection of an instability that began before it by at most their windows (12 and 20 steps)
    guard = _Guard(disc, scheme, limit, limit_origin)
    n = steps.taken
    bar = progress_bar(progress if disc.world.root else False, total=steps.n_steps, initial=n, unit="step",
                       mininterval=0.5, leave=False, desc=disc.scene.name)
    try:
        while not steps.done():
            t_prev, t = steps.next()
            err = _advance(scheme, steps, t_prev, t)
            if err is _REJECTED:
                continue
            scheme.accept(t)
            n += 1
            guard.check(n, t_prev, t)
            observe(t, final=steps.done(), control=_control(steps, t - t_prev, err))
            if after_step is not None:
                after_step(t, n)
            bar.update()
            guard.stop_if_asked()
    finally:
        bar.close()


#: What :func:`_advance` returns for a step the controller rejected.
_REJECTED = object()


def _advance(scheme, steps, t_prev: float, t: float):
    """Take the step; with an adaptive controller judge it (redone from the state before it when rejected). The
    scaled error per unit of elapsed time (None: not estimated), or :data:`_REJECTED`."""
    if not steps.adaptive:
        scheme.step(t_prev, t)
        steps.accepted()
        return None
    from ..errors import NewtonFailed

    before = scheme.state()
    try:
        scheme.step(t_prev, t)
    except NewtonFailed:
        scheme.restore(before)
        steps.rejected(failed=True)
        return _REJECTED
    err = scheme.local_error(steps.rtol, steps.atol)
    if err is None:  # (the first steps: too few accepted states for the scheme's own estimate)
        try:
            err = _halved(scheme, before, t_prev, t, steps.rtol, steps.atol)
        except NewtonFailed:
            scheme.restore(before)
            steps.rejected(failed=True)
            return _REJECTED
    theta, crossed = scheme.event(before)
    judged = steps.per_unit_step(err, crossed)
    if not steps.judge(err, theta, crossed):
        scheme.restore(before)
        return _REJECTED
    return judged


def _halved(scheme, before: dict, t_prev: float, t: float, rtol: float, atol: float) -> float:
    """The scaled local error of a step that the scheme cannot estimate yet (its first: no history for a predictor),
    by Richardson: the same step again as two halves from the state ``before``. For a step of order p the whole
    step's error is about (whole - halves) 2^p / (2^p - 1); p = 1 (every scheme's first step is backward Euler or
    as accurate). Both halves are taken by the first-order formula (``scheme.first_order``), as the whole step is:
    the estimate is then Richardson's for one formula, and the two halves share one matrix (a multistep second
    half met a third one, so each try of a first step factored three). The scheme is left in the whole step's
    state. Costs two more solves, for the first step(s) only: without it the first step went unchecked, and a
    large first step made an error no later step could remove (issue 23: a rod at rtol 1e-5 with k = 0.01 ended
    34 x rtol off, all of it from its first step)."""
    whole = scheme.state()
    u, beta = whole["u"], whole["beta"]
    mid = t_prev + 0.5 * (t - t_prev)
    scheme.restore(before)
    scheme.first_order = True
    try:
        scheme.step(t_prev, mid)
        scheme.accept(mid)
        scheme.step(mid, t)
    finally:
        scheme.first_order = False
    err = 2.0 * scheme.scaled_difference(u, beta, rtol, atol)
    scheme.restore(whole)
    return err


class _Guard:
    """What stops a run as diverged after an accepted step: a displacement (max over dofs) that is not finite or
    exceeds ``limit`` anywhere (the state is then meaningless for a small-strain model), a velocity that has
    alternated in sign for 12 steps without decaying (:class:`OscillationWatch`), or (schemes that ask for it: the
    explicit one) contact nodes that chatter (:class:`ChatterWatch`). Every decision is reduced over the processes
    that hold the body (``disc.world``)."""

    def __init__(self, disc, scheme, limit, limit_origin):
        self.disc, self.scheme, self.origin = disc, scheme, limit_origin
        self.limit = limit
        self.bound = limit or math.inf
        self.u = u = disc.u.vec.FV().NumPy()
        self.largest = 0.0  # (the largest |u| so far: the scale of a velocity's round-off)
        self.world = disc.world
        self.watch = OscillationWatch(disc.v.vec.FV().NumPy(), [None] + ([disc.normal_dofs] if disc.dim > 1 else []),
                                      world=self.world, owned=disc.owned())
        self.chatter = ChatterWatch(lambda: disc.normal_displacement(u), world=self.world) \
            if scheme.chatter_watch else None

    def stop_if_asked(self) -> None:
        """On several processes, a signal asks every rank to stop after the step just recorded, together
        (:func:`workbench.discrete.world.request_stop`): Interrupted on all of them."""
        if self.world.parallel:
            signum = int(self.world.max(stop_requested()))
            if signum:
                raise Interrupted(stopped_by(signum), signal=signum,
                                  together=True)

    def check(self, n: int, t_prev: float, t: float) -> None:
        norm = self.world.max(np.abs(self.u).max(initial=0.0))
        self.largest = max(self.largest, norm) if math.isfinite(norm) else self.largest
        oscillating = self.watch.flipped(self.watch.round_off * self.largest / (t - t_prev))
        chattering = self.chatter is not None and self.chatter.chattering()
        if math.isfinite(norm) and norm <= self.bound and not oscillating and not chattering:
            return
        if not math.isfinite(norm):
            what = "non-finite values"
        elif oscillating:
            what = (f"a sign-alternating oscillation of the velocity, not decaying over {self.watch.window} steps "
                    "(the scheme is unstable at this step size)")
        elif chattering:
            what = (f"contact chatter: a contact node switched between penetration and separation "
                    f"{self.chatter.max_switches} or more times within {self.chatter.window} steps (the explicit "
                    "scheme is unstable at this step size, or the step is far too long for the load)")
        else:
            what = f"a displacement of {norm:.3g} m, beyond the bound {self.limit:.3g} m ({self.origin})"
        raise Diverged(f"{self.disc.scene.name}: {what} at step {n} (t = {t:.6g} s) "
                       f"with the {self.scheme.name} scheme, k = {t - t_prev:.3g} s", step=n, time=t)


class _NoBar:
    def update(self, n=1):
        pass

    def close(self):
        pass


class _BarThatMayLoseItsTerminal:
    """A bar whose terminal may go away during the run (an ssh session dropped, a log on a full disk): a write that
    fails ends the bar, not the run (it lost every step, found by an outside pass)."""

    def __init__(self, bar):
        self.bar = bar

    def update(self, n=1):
        self._call("update", n)

    def close(self):
        self._call("close")

    def _call(self, name, *args):
        if self.bar is None:
            return
        try:
            (self.bar.update if name == "update" else self.bar.close)(*args)
        except (OSError, ValueError, UnicodeError):
            self.bar = None


def progress_bar(progress, **options):
    """tqdm's bar when one is shown (``progress``, or None: on a terminal), else a stand-in: tqdm's import (30 ms,
    with its monitor thread) is not paid by runs that show none."""
    if sys.stderr is None or not (sys.stderr.isatty() if progress is None else progress):  # (None: started closed)
        return _NoBar()
    import importlib.util

    if importlib.util.find_spec("ipywidgets") is None:  # (tqdm.auto warned "IProgress not found" in every notebook
        from tqdm.std import tqdm  # without ipywidgets, which is no dependency: the text bar it falls back to)
    else:
        from tqdm.auto import tqdm
    try:
        return _BarThatMayLoseItsTerminal(tqdm(**options))
    except (OSError, ValueError, UnicodeError):
        return _NoBar()


def _control(steps, k, err) -> dict:
    """What an adaptive run records per step: the step size and the scaled local error estimate."""
    if not steps.adaptive:
        return {}
    return {"step_size": np.nan if k is None else float(k), "error_estimate": np.nan if err is None else float(err)}
