"""The scheme protocols: a stepper, its optional error control, and the observer that records.

A time scheme is three small things, each a protocol with its defaults here:

:class:`Scheme`, the **stepper**, advances one :class:`~workbench.discrete.discretisation.Discretisation`
(which holds the state u, v and, for Model A, beta) from one time to the next. The time loop
(:func:`workbench.schemes.stepping.march`) calls, in this order:

``__init__(disc)``
    Factor and prepare what is constant (per step size where it depends on k).
``preflight(k_max) -> dict``
    Checks before any step, with the largest step of the run: may raise
    :class:`~workbench.errors.ParameterError` (e.g. the explicit scheme's
    :class:`~workbench.errors.StepTooLarge`). Returns attributes to record
    (``k_crit``, ``bonding_resolved``, ...). Warnings it has to give come after all
    its checks (:meth:`Scheme.warnings`), so a refused run prints only its error.
``used() -> dict``
    Attributes known only once the run has stepped, recorded with preflight's when the archive is made (Model A's
    implicit schemes factor their operator at the first step of each size: ``linear_solver``).
``start(t0)``
    The state at t0: Model A's u0 is given (nothing to do); Model B's quasistatic
    u(0) is the solution of the inequality at t0. Then ``accept(t0)``.
``step(t_prev, t_next)``
    Advance the state; any step size (the loop asks a step controller). Raises
    :class:`~workbench.errors.Diverged` / :class:`~workbench.errors.NewtonFailed`
    when it cannot.
``accept(t)``
    The step to t is kept: it joins the history of accepted states (the last
    :attr:`Scheme.keep`), which multistep schemes, predictors, error estimates and
    event detection read.
``state(restart=False) -> dict`` / ``restore(state)``
    The full state (u, v, beta, the history, and whatever the scheme keeps: memory
    histories, active sets), as copies; restoring it makes the scheme bitwise what it
    was (a rejected adaptive step is redone from it; a restart continues from it).
    ``restart=True`` adds what only a new process needs (``cache``: which step sizes
    the cached factorisations were built from, :meth:`Scheme._cache_state`). What the
    scheme keeps beyond u, v, beta and the history is its own (``extra``): it says
    where those arrays live (:attr:`Scheme.distributed_layout`) and what they are
    (:attr:`Scheme.state_variables`), so restarts archive them without knowing them.
``diagnostics() -> dict``
    Scalars of the last step (or of ``start``), recorded by name (units in
    :data:`workbench.output.results.VARIABLES`).
``observer(disc) -> Observer``
    What the recorder reads at a time (below), for the scheme's state in ``disc``.

:class:`ErrorControlled`, the **error control** (a scheme that takes error-controlled steps
inherits it; the loop calls it only when ``rtol > 0``):

``local_error(rtol, atol) -> float``
    The scaled local error of the step just taken (<= 1: acceptable), from the
    difference to a predictor of the scheme's order; ``None`` when the history is
    too short to tell.
``event(state) -> (theta or None, crossed)``
    Where in the step just taken (0 < theta <= 1 of its length) the first event
    happened: a kink crossed (the laws say where theirs are:
    :meth:`workbench.physics.contact.ContactTerm.kinks`,
    :meth:`workbench.physics.bonding.BondingLaw.kinks`) by :data:`EVENT_FRACTION` of the
    contact boundary, measured against ``state`` (the state at the step's start), None
    without one; and ``crossed``, the largest share of the boundary whose laws switched
    inside the step (0 for a scheme whose estimate does not see kinks).
``admissible_step(k) -> float``
    The step (<= k) an error-controlled run takes instead of k: k itself, or for BDF2
    the step whose a0 lies on its grid (so that factorisations are met again).

:class:`Observer`, the **observer**, is what a run records of the state at a time (the
runner hands the recorder to the loop as a callback, :class:`workbench.output.results.Recorder`):

``diagnostics()``, ``node_values(t) -> dict``
    The step's scalars; arrays per contact node (the contact pressure; Model B's state).
``node_weights()``, ``contact_points()``, ``point_values(t) -> dict``
    Each vertex's share of the side for those pressures; other contact points with
    unknowns (Model B on P2: the facet midpoints, coordinates and weights) and arrays
    per point.
``stress_parts() -> [(tensor, dof vector), ...]``
    sigma at the current state as a sum of linear tensors applied to the strains of
    dof vectors (Model A: A eps(v) + G eps(u); Model B: A eps(u) + the memory). The
    recorder takes their P0 projection through the discretisation's strain operator.

A run on several MPI processes records rank 0's serial view of the body: its observer is
the scheme's observer of that view (``scheme.observer(view)``).

Registration is one line in :data:`workbench.input.numerics.SCHEMES` (name -> model, module,
class, what it can do); the scene's allowed values of ``scheme`` and each model's schemes
come from it.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from ..discrete.world import SERIAL


class Scheme:
    """The stepper (module docs) with its defaults."""

    name = ""
    order = 1
    chatter_watch = False
    #: Take the steps by the scheme's first-order formula (a multistep scheme: backward Euler) while set; the first
    #: step's Richardson check sets it for its two halves (:func:`workbench.schemes.stepping._halved`).
    first_order = False
    #: How many accepted states the history holds (enough for a quadratic predictor).
    keep = 4
    #: The arrays of :meth:`_extra_state` by what they live on, "dof" or "point" (a contact quadrature point's), for a
    #: state gathered from several MPI processes into the serial order.
    distributed_layout: dict = {}
    #: (units, long_name) of the arrays of :meth:`_extra_state`, for the restart archive ('' units: the scheme's own,
    #: said in the name).
    state_variables: dict = {}

    def __init__(self, disc):
        self.d = disc
        self.k_last = 0.0
        self.history = []  # accepted (t, u, beta), oldest first
        self.u_scale = 0.0  # the largest |u| accepted so far (the scale of rtol)

    def preflight(self, k_max: float) -> dict:
        return {}

    def warnings(self) -> list:
        """Messages (text) the run should warn about, issued by the loop after every preflight check passed."""
        return []

    def used(self) -> dict:
        """Attributes to record that the run's steps decided (module docs)."""
        return {}

    def start(self, t0: float) -> None:
        return None

    def step(self, t_prev: float, t_next: float) -> None:
        raise NotImplementedError

    def diagnostics(self) -> dict:
        return {}

    def observer(self, disc=None) -> "Observer":
        """What a run records of this scheme's state in ``disc`` (default: its own discretisation)."""
        raise NotImplementedError

    # -- the accepted history, the full state ------------------------------------------------------------
    def _beta(self):
        d = self.d
        return None if d.beta is None else d.beta.vec.FV().NumPy()[d.beta_dofs]

    def accept(self, t: float) -> None:
        if not self.keep:  # (a scheme without error control or multistep formula keeps no history)
            return
        beta = self._beta()
        u = self.d.u.vec.FV().NumPy()
        self.history.append((float(t), u.copy(), None if beta is None else beta.copy()))
        del self.history[: -self.keep]
        self.u_scale = max(self.u_scale, self.d.world.max(float(np.abs(u).max(initial=0.0))))

    def state(self, restart: bool = False) -> dict:
        """The full state as copies (module docs); ``restart``: with the cache's make-up (a new process)."""
        d = self.d
        beta = self._beta()
        out = {"u": d.u.vec.FV().NumPy().copy(), "v": d.v.vec.FV().NumPy().copy(),
               "beta": None if beta is None else beta.copy(), "k_last": self.k_last, "u_scale": self.u_scale,
               "history": [(t, u.copy(), None if b is None else b.copy()) for t, u, b in self.history],
               "extra": self._extra_state()}
        if restart:
            out["cache"] = self._cache_state()
        return out

    def restore(self, state: dict) -> None:
        d = self.d
        d.u.vec.FV().NumPy()[:] = state["u"]
        d.v.vec.FV().NumPy()[:] = state["v"]
        if state["beta"] is not None:
            d.beta.vec.FV().NumPy()[d.beta_dofs] = state["beta"]
        self.k_last, self.u_scale = state["k_last"], state["u_scale"]
        self.history = [(t, u.copy(), None if b is None else b.copy()) for t, u, b in state["history"]]
        self._restore_extra(state["extra"])
        if "cache" in state:  # (a rollback within the run keeps the factorisations it has)
            self._restore_cache(state["cache"])

    def settle(self, t: float) -> None:
        """After a state was carried onto a finer mesh at ``t`` (:func:`workbench.running.follow.carry`): solve again
        there what the finer mesh would have had at t (default: nothing, the carried state is taken as it is)."""
        return None

    def _extra_state(self) -> dict:
        """What else the scheme keeps between steps (copies)."""
        return {}

    def _restore_extra(self, extra: dict) -> None:
        return None

    def _cache_state(self) -> list:
        """The numbers that rebuild the scheme's cached operators exactly as they are (empty: nothing cached, or a
        cache whose entries depend on their keys alone)."""
        return []

    def _restore_cache(self, cache: list) -> None:
        return None


class ErrorControlled:
    """The error control (module docs): local error estimates from a predictor of the scheme's order, events, the
    admissible step. A mixin for a :class:`Scheme` (it reads the scheme's accepted history)."""

    def predictor(self, t: float, order: int | None = None):
        """(u, beta) at t extrapolated from the last ``order + 1`` accepted states (None if there are fewer)."""
        p = order or self.order
        if len(self.history) < p + 1:
            return None
        pts = self.history[-(p + 1):]
        times = [s[0] for s in pts]
        weights = []
        for i, ti in enumerate(times):  # Lagrange weights at t
            w = 1.0
            for j, tj in enumerate(times):
                if j != i:
                    w *= (t - tj) / (ti - tj)
            weights.append(w)
        u = sum(w * s[1] for w, s in zip(weights, pts))
        beta = None if pts[0][2] is None else sum(w * s[2] for w, s in zip(weights, pts))
        return u, beta

    def error_constant(self, t: float, order: int = 1) -> float:
        """C = l / P, the scheme's local error l over the predictor's error P for the current step sizes (Taylor
        expansions, exact for smooth solutions), so that l = C / (1 + C) (u_n - predictor). Order 1 (backward
        Euler): l = k^2/2 u'', P = k (k + k_prev)/2 u''."""
        if order != 1:
            raise NotImplementedError(f"{self.name}: no error constant of order {order}")
        t1, t0 = self.history[-1][0], self.history[-2][0]
        return (t - t1) / (t - t0)

    def local_error(self, rtol: float, atol: float, order: int | None = None):
        """The scaled local error: the maximum over the free dofs of |C (u - u_pred)| / (atol + rtol U), and the
        root mean square over the contact boundary (by measure) of |C (beta - beta_pred)| / rtol when beta is
        modelled, the larger of the two; <= 1 is acceptable.

        U is the largest |u| of the run so far (this step's included): relative to the current |u| alone, a
        displacement passing through 0 (an oscillating load) would ask for arbitrarily small steps there. The
        maximum for u, since the error users measure is where u is largest (a root mean square over the dofs
        let the tip error of the slab of issue 11 reach 15 x rtol); the root mean square for beta, since a
        debonding front sweeping the boundary kinks beta at one facet after the other and in the maximum each
        kink asked for short steps (on that slab: 3e-3 s steps for t > 0.7 s where the fixed step 0.01 s is
        1e-4 accurate)."""
        order = order or self.order
        t = self.history[-1][0] + self.k_last
        pred = self.predictor(t, order)
        if pred is None:
            return None
        c = self.error_constant(t, order)
        c = abs(c / (1.0 + c))  # u_n - predictor = l + P = (1 + C) P
        response = self.prescribed_response(pred[0])
        return c * self.scaled_difference(pred[0] if response is None else pred[0] + response, pred[1], rtol, atol)

    def prescribed_response(self, u_pred: np.ndarray):
        """What the predictor ``u_pred`` misses of the prescribed displacement, spread over the body as the step's
        operator spreads it (a dof vector), or None where nothing is prescribed to move. That part of u is
        algebraic: the step meets the prescribed values at its end exactly, whatever their curvature, and its
        error test leaves it out (as DAE codes leave out their algebraic variables)."""
        return None

    def scaled_difference(self, u_other, beta_other, rtol: float, atol: float) -> float:
        """The norm of error control (:meth:`local_error`) of the current state minus another (u, beta)."""
        u, world = self.d.u.vec.FV().NumPy(), self.d.world
        free = self._free
        e = (u[free] - u_other[free]) if free is not None else (u - u_other)
        err = world.max(np.abs(e).max(initial=0.0)) / (atol + rtol * max(self.u_scale,
                                                                            world.max(np.abs(u).max(initial=0.0))))
        beta = self._beta()
        if beta is not None:  # beta is of order 1: relative to rtol
            w = self.d.rate_side.weights
            eb = np.zeros(len(beta))
            eb[self.d.rate_side.element] = w  # facet measures in facet order
            err = max(err, np.sqrt(world.sum(np.sum(eb * (beta - beta_other) ** 2)) / world.sum(np.sum(eb))) / rtol)
        return float(err)

    @cached_property
    def _free(self):
        """The dofs whose values the scheme computes (not the prescribed ones: their predictor mismatch is no error)."""
        d = self.d
        mask = np.ones(d.ndof, dtype=bool)
        mask[np.asarray(d.dirichlet_dofs, dtype=np.int64)] = False
        return np.flatnonzero(mask)

    def admissible_step(self, k: float) -> float:
        """The step (<= k) an error-controlled run should take instead of k: k itself unless the scheme's operator
        depends on more than k (BDF2)."""
        return k

    def event(self, start: dict):
        """(theta, crossed): where in the last step to land on a kink (None: nowhere) and the largest share of
        the boundary whose laws switched inside it (0: none; a kink makes a predictor-based estimate first order
        there, see :meth:`workbench.schemes.stepping.AdaptiveSteps.per_unit_step`)."""
        return None, 0.0


class Observer:
    """What a run records of a scheme's state in a discretisation (module docs), with its defaults."""

    def __init__(self, scheme, disc):
        self.scheme, self.d = scheme, disc

    def diagnostics(self) -> dict:
        return self.scheme.diagnostics()

    def node_values(self, t: float | None = None) -> dict:
        """Per contact vertex, what the run records at time t (e.g. the contact pressure)."""
        return {}

    def node_weights(self) -> np.ndarray:
        """Each contact vertex's share of the side, by which its recorded pressure becomes a force."""
        return self.d.node_weights

    def contact_points(self) -> dict:
        """Coordinates (``midpoint_x``, ...) and weights (``midpoint_weight``) of contact points other than the
        vertices at which the scheme has unknowns (Model B on P2: the facet midpoints); empty by default."""
        return {}

    def point_values(self, t: float | None = None) -> dict:
        """Per point of :meth:`contact_points`, what the run records at time t."""
        return {}

    def stress_parts(self) -> list:
        raise NotImplementedError

    #: The vectors of :meth:`snapshot_vectors` (``gathered``) and of :meth:`record_vectors` (``gathered_record``) in
    #: the order of the whole body, where a run on several MPI processes records its serial view (None: this
    #: observer's own discretisation holds them).
    gathered = gathered_record = None

    def record_vectors(self, t: float) -> list:
        """Dof vectors that :meth:`node_values` reads at a record besides the state (each process its part of the
        sum; gathered for the serial view of a distributed body, where no matrices are); none by default."""
        return []

    def snapshot_vectors(self) -> list:
        """The dof vectors besides u and v that :meth:`stress_parts` reads (gathered for the serial view of a body
        distributed over several MPI processes); none by default."""
        return []


#: An event (a kink the step must land on) is the switching of this fraction of a group's weight (of the contact
#: boundary, by measure) within one step. Landing on every single quadrature point is futile where a front sweeps the
#: boundary (measured on the slab of issue 11: 489 landings on crossings 1e-7 s apart, 2854 steps where fixed BDF2 is
#: 1e-4 accurate in 100); one point that is the whole boundary (a rod) or a whole boundary switching at once is landed on.
EVENT_FRACTION = 0.25
#: A switching function this small against its group's largest value is on its kink (round-off): Model B's stuck
#: contact points sit at s = 1e-21 ... 1e-19 of either sign after a condensed solve, and each such flip was read as a
#: kink crossed (measured: memory_slab at rtol 1e-3 landed on 268 of them, 2176 steps and 270 rejected, against
#: 1854 and 2 with the coupled solver, whose values there are exactly 0).
KINK_NOISE = 1e-12


def make_room(cache, size: int, key=None, keep=None) -> None:
    """Drops the least recently used entries of the OrderedDict ``cache`` (not ``key``'s) until a new entry, or
    ``key``'s, fits ``size``; ``keep``'s last, where it is the only one left to drop. The schemes call it *before*
    they factor an operator they do not hold, and drop their own references to the last one: factors of a gigabyte
    each, two at once, doubled the peak (BDF2 on the P2 block at 271k dofs: 5.67 GB, 3.36 GB now).

    >>> from collections import OrderedDict
    >>> cache = OrderedDict.fromkeys("abc")
    >>> make_room(cache, 2, "d", keep="a"); list(cache)
    ['a']
    >>> make_room(cache, 1, "d", keep="a"); list(cache)
    []
    """
    while len(cache) - (key in cache) >= size:
        spare = [k for k in cache if k != key]
        del cache[next((k for k in spare if k != keep), spare[0])]


def _settled(before: np.ndarray, after: np.ndarray, world) -> tuple:
    """``before``, ``after`` with the values within :data:`KINK_NOISE` of the group's largest set to 0."""
    scale = world.max(max(np.abs(before).max(initial=0.0), np.abs(after).max(initial=0.0)))
    noise = KINK_NOISE * scale
    return np.where(np.abs(before) <= noise, 0.0, before), np.where(np.abs(after) <= noise, 0.0, after)


def first_crossing(before: np.ndarray, after: np.ndarray, weights=None, fraction: float = 0.0, world=SERIAL):
    """The smallest theta in (0, 1] at which linear paths from ``before`` to ``after`` cross zero (None: none).

    Entries that start at 0 (on the kink already; within :data:`KINK_NOISE` of the group's largest value) do not
    count. With ``weights``,
    the theta at which the crossings (taken in order) first add up to ``fraction`` of the
    total weight (None when they never do). On several processes (``world``) each holds some of the entries:
    the crossings of all are gathered on every process, so all take the same theta.

    >>> first_crossing(np.array([1.0, -2.0, 3.0]), np.array([-1.0, -1.0, 1.0]))
    0.5
    >>> first_crossing(np.array([1.0, 1.0]), np.array([-1.0, -3.0]), np.array([3.0, 1.0]), 0.5)  # 1/4 of it at 0.25
    0.5
    """
    before, after = _settled(before, after, world)
    return _first_settled(before, after, _crossed(before, after), weights, fraction, world)


def _crossed(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Where settled switching functions changed sign, or reached their kink from off it."""
    return (before * after < 0) | ((after == 0) & (before != 0))


def _first_settled(before, after, crossed, weights, fraction, world):
    """:func:`first_crossing` of settled values whose crossings ``crossed`` are known."""
    if not world.any(crossed.any()):
        return None
    b, a = before[crossed], after[crossed]
    theta = np.concatenate(world.allgather(b / (b - a)))
    if weights is None:
        return float(np.min(theta))
    w = np.concatenate(world.allgather(np.asarray(weights)[crossed]))
    order = np.argsort(theta, kind="stable")
    reached = np.cumsum(w[order]) >= fraction * world.sum(np.sum(weights)) * (1 - 1e-12)
    return float(theta[order][np.argmax(reached)]) if reached.any() else None


def first_event(before, after, world=SERIAL):
    """The earliest event over groups of switching functions: lists of (values, weights) at the step's start and end
    (on several processes, ``world``: each process's part of every group)."""
    thetas = [first_crossing(b, a, w, EVENT_FRACTION, world) for (b, w), (a, _) in zip(before, after)]
    thetas = [x for x in thetas if x is not None]
    return min(thetas) if thetas else None


def events(before, after, world=SERIAL) -> tuple:
    """(:func:`first_event`, :func:`crossed_fraction`) of the same groups, each group's values settled and its
    crossings found once for both (an implicit step on a 2D slab asks for both: 12 settlings a step took 7 % of it).

    >>> events([(np.array([1.0, 1.0, 1.0, 1.0]), np.ones(4))], [(np.array([-1.0, 1.0, 1.0, 1.0]), None)])
    (0.5, 0.25)
    """
    thetas, fraction = [], 0.0
    for (b, w), (a, _) in zip(before, after):
        b, a = _settled(b, a, world)
        crossed = _crossed(b, a)
        theta = _first_settled(b, a, crossed, w, EVENT_FRACTION, world)
        if theta is not None:
            thetas.append(theta)
        fraction = max(fraction, _fraction(crossed, w, world))
    return (min(thetas) if thetas else None), fraction


def _fraction(crossed: np.ndarray, weights, world) -> float:
    """The share of the weights where a group's functions crossed (0 where the group weighs nothing)."""
    total = world.sum(float(np.sum(weights)))
    return world.sum(float(np.sum(weights[crossed]))) / total if total > 0 else 0.0


def crossed_fraction(before, after, world=SERIAL) -> float:
    """The largest share (by weight) of one group of switching functions that changed sign over the step (0: none;
    on several processes, ``world``: each process's part of every group).

    >>> crossed_fraction([(np.array([1.0, 1.0, 1.0, 1.0]), np.ones(4))], [(np.array([-1.0, 1.0, 1.0, 1.0]), None)])
    0.25
    """
    return events(before, after, world)[1]
