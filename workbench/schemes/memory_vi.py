"""Model B's fully discrete scheme: one elliptic variational inequality per step (``scheme = "vi"``).

Per step n: find u_n in K_h = {v : v_nu <= g at the contact vertices} with

    (A eps(u_n), eps(v - u_n)) + (M_n, eps(v - u_n)) + j_h(v) - j_h(u_n) >= (f_n, v - u_n)

where M_n approximates int_0^{t_n} B(t_n - s) eps(u(s)) ds by one of two rules
(``memory_rule``):

* ``rectangle`` (default, first order): M_n = sum_{j<n} (t_{j+1} - t_j) B(t_n - t_j) eps(u_j);
* ``trapezoid`` (second order): u taken piecewise linear in time. A Prony term
  C exp(-t/tau) is then integrated exactly: with x = k/tau, the history
  H_n = e^{-x} H_{n-1} + tau ((1 - e^{-x})/x - e^{-x}) u_{n-1} + tau (1 - (1 - e^{-x})/x) u_n;
  a general kernel b(t) C by the product trapezoid rule,
  sum_j (k_j / 2) [b(t_n - t_j) u_j + b(t_n - t_{j+1}) u_{j+1}]. The part that multiplies
  u_n (tau (1 - (1 - e^{-x})/x) C, resp. (k/2) b(0) C) joins the operator of step n, so
  A + that is factored (and condensed) once per step size.

Prony kernels cost O(number of terms) per step; a general kernel O(n), unless it is
approximated by a sum of exponentials (``kernel_approximation = "exponentials"``,
:meth:`workbench.physics.memory.GeneralKernel.exponential_sum`), which then runs as a
Prony series. j_h(v) = sum_i w_i psi(v_nu,i) is the layer functional with lumped
boundary quadrature (w_i = int phi_i da), at the contact vertices (P1) or, on P2 in
2D, at the vertices and facet midpoints with Simpson's weights (s = B u there, the
condensed system B K^-1 B^T). On a curved contact side the law acts on s - g0, the
initial gap g0 taken off. u(0) solves the inequality at t = 0 (no memory yet).

The memory rules are objects (:mod:`.memory_rules`), and so are the contact points with their
active set (:mod:`.contact_nodes`); this scheme puts them together.

Solver (``contact_solver``): the elastic matrix K_A (with the trapezoid rule:
K_A plus the current step's memory part) is factored once. ``condensed``: it is
condensed onto the contact vertices' normal dofs (S0 = (K_A^-1)_CC, one back-substitution per
contact point and operator); ``coupled``: S0 is never formed, each state's system is solved by
conjugate gradients on the active points, one back-substitution per iteration
(:mod:`.coupled_contact`; for thousands of contact points, 3D); ``auto`` picks by the cost of each
(:meth:`workbench.input.numerics.Numerics.coupled_contact`). Condensed, a step costs one back-substitution for the
contact-free displacement z,
a primal-dual active-set iteration on the contact nodes (states separated /
stuck / compliant / rigid, :mod:`workbench.physics.unilateral`; each iteration
one small dense solve, exact once the states are right, warm-started from the
previous step's states), and one back-substitution to recover u. Recorded per
step: iterations, state counts, the complementarity residual
max |s - prox(s + rho lam / w)| and the number of linear solves.

Where the factor keeps the contact vertices' normal dofs last (MKL PARDISO, condensed, P1, one process:
:class:`workbench.discrete.solvers.SplitSolve`), the two back-substitutions of a step become one solve in two
parts: the forward part gives the condensed load there, hence z at the contact dofs; the active set runs; the
backward part gives u from the contact dofs' values. The condensed stiffness comes out of that same factorization.
Where ``auto`` took the coupled solver on a curved 3D side, the same is done on the points of smallest gap first,
the others checked from the whole u (:mod:`.candidates`); a step where one of those others touches is the coupled
solver's.

Local error (:meth:`MemoryVI.local_error`): u_n solves the inequality at t_n exactly for its memory term, so the
step's local error is that of the memory integral over [t_{n-1}, t_n] (an embedded pair, not a predictor: u of a
quasistatic problem kinks where a contact node changes state, and a predictor read that kink as an error that no
step is short enough to remove - measured: memory_slab stopped at k = 5e-9 s). dM is, per kernel term C b(s), C
applied to

* rectangle: the trapezoid rule minus the rectangle rule, (k/2) (b(0) u_n - b(k) u_{n-1}) (Prony: the exact
  integral of the linear interpolant minus k e^-x u_{n-1});
* trapezoid: its own leading error -(k^3/12) g'', g(s) = b(t_n - s) u(s) by divided differences of u_n, u_{n-1},
  u_{n-2} (Prony: the kernel is integrated exactly, only u's curvature counts: -(k^3/12) ((1 - e^-x)/x) u'').

(:meth:`workbench.schemes.memory_rules.MemoryRule.error_terms`.) K^-1 (the factored operator of the step, contact
left out) turns the force dM into a displacement.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..discrete import solvers
from ..discrete.condensation import CondensedSystem, SchurOperator
from ..input.numerics import COUPLED_FROM_SCHUR
from ..physics import unilateral
from .base import ErrorControlled, Observer, Scheme, first_event
from .candidates import Candidates
from .contact_nodes import ContactNodes
from .coupled_contact import CoupledActiveSet, condensed_up_to
from .memory_rules import rule_for
from .step_operators import SharedFactor, StepOperator, StepOperators


@dataclass
class MemoryOperator(StepOperator):
    """Model B's step operator: with the condensed solver's dense contact stiffness ``S_inv`` (built on demand where
    the coupled solver falls back to it), the active set's scale ``rho`` and the coupled solver's ``schur``."""

    S_inv: object = None
    rho: object = None
    schur: object = None


class MemoryVI(ErrorControlled, Scheme):
    """One variational inequality per step, memory by recursion or quadrature, left rectangle or trapezoid."""

    name = "vi"
    cache_size = 4  # (factored operators kept, by their weights; fewer where large: solvers.factors_kept)
    #: The memory's histories are dof vectors (each rank its part); the contact points' states and forces are held
    #: in the serial order where the contact problem is solved ("root").
    distributed_layout = {"histories": "dof", "stored": "dof", "states": "root", "lam": "root"}
    state_variables = {
        "histories": ("m s", "restart state: memory histories H_i = int e^(-(t-s)/tau_i) u(s) ds (vi), dof vectors"),
        "times": ("s", "restart state: times of the stored steps (vi, general kernel)"),
        "stored": ("m", "restart state: stored displacement dofs u_j (vi, general kernel)"),
        "states": ("1", "restart state: contact node states (vi): 0 separated, 1 stuck, 2 compliant, 3 rigid"),
        "lam": ("N", "restart state: contact node forces (vi; per unit thickness in 2D, N/m)"),
    }

    def __init__(self, d):
        super().__init__(d)
        self.trapezoid = d.numerics.memory_rule == "trapezoid"
        self.order = 2 if self.trapezoid else 1
        # the contact points live on the view of the body that solves the contact problem (on several processes
        # rank 0's serial view, the other ranks serving its back-substitutions: self.exchange)
        self.exchange = x = d.exchange()
        self.nodes = ContactNodes(x.view) if x.solves else None
        self.size = x.share(self.nodes.size if x.solves else 0)
        self.vertices_only = x.share(self.nodes.B is None if x.solves else None)  # (P1: s is u at the normal dofs)
        x.bind(self.nodes.C if x.solves else ())
        self.method = d.step_solver()
        self.cache_size = solvers.factors_kept(d.dim, d.ndof_global, self.method, self.cache_size)
        self.coupled = None
        limit = condensed_up_to(d.ndof, self.method) if self.vertices_only and d.dim == 3 else COUPLED_FROM_SCHUR
        if d.numerics.coupled_contact(self.size, self.method, solvers.forms_schur(self.method), limit):
            self.coupled = CoupledActiveSet(self.nodes, self.method, d.ndof, d.numerics.contact_tol) \
                if x.solves else True
        # (auto's coupled solver on a curved side: first the condensed one on the points of smallest gap)
        self.candidates = Candidates.of(self.nodes, self.method) if self.coupled is not None and x.solves else None
        self.memory = rule_for(d, self.trapezoid)  # (None without memory)
        self._balance = None  # f - memory of the last equilibrium (only for the reaction of pinned contact nodes)
        # (the run's own operator, its step's: none under error control with the trapezoid, which changes each step)
        own = None if d.numerics.adaptive and any(self._weights_of(1.0)) else self._weights_of(d.numerics.k)
        own = None if own is None else StepOperators.key(own)
        self.shared = SharedFactor.of_memory(d, self.method, self.trapezoid)  # (C_i = f_i A: one factor of K_A)
        self.operators = StepOperators(self.cache_size, own, self.candidates, self.shared is not None)
        self._use(0.0)
        self.z = np.zeros(d.ndof)
        self.rhs = d.u.vec.CreateVector()
        self.rhs_np = self.rhs.FV().NumPy()
        self.tmp, self.work = d.u.vec.CreateVector(), d.u.vec.CreateVector()  # (the clamp's lift, M times it)
        self.u_prev = d.u.vec.FV().NumPy().copy()
        self.diag = {}

    def used(self) -> dict:
        return Candidates.attrs(self.candidates)

    def preflight(self, k_max: float) -> dict:
        """Records how a general kernel was approximated by exponentials (its terms and error bound)."""
        fit = self.d.model.memory.fit if self.d.model.memory is not None else None
        used = {"contact_solver_used": "coupled" if self.coupled is not None else "condensed",
                "linear_solver": self.solver.name} | Candidates.planned(len(self.candidates.P) if self.candidates else 0)
        return used if fit is None else used | {"kernel_terms": fit["terms"], "kernel_fit_error": fit["error"]}

    # -- the operator of a step -------------------------------------------------------------------------------
    def _weights_of(self, k: float) -> tuple:
        """The weights w_i of u_n in the memory terms of a step of length k (all 0 but for the trapezoid rule)."""
        return tuple(self.memory.implicit_weights(k)) if self.memory is not None else ()

    def _use(self, k: float) -> None:
        """K_A + sum_i w_i K_Ci for a step of length k, factored once per weights (:class:`StepOperators`)."""
        weights = self._weights_of(k)
        if not self.operators.holds(weights):
            self._op = self.M = self.solver = self.S_inv = self.schur = self.split = self.kept = None  # (freed)
        op = self._op = self.operators.get(weights, self._build)
        self.M, self.solver, self.S_inv, self.rho, self.schur = op.M, op.solver, op.S_inv, op.rho, op.schur
        self.split, self.kept, self._weights = op.split, op.kept, list(weights)

    def _build(self, weights: tuple, keep: bool) -> MemoryOperator:
        """K_A + sum_i w_i K_Ci factored, with its condensed system or the coupled solver's operator; the
        factorization keeps the contact candidates where ``keep``."""
        d, x, nodes = self.d, self.exchange, self.nodes
        M = self.memory.operator(weights) if self.memory is not None else d.elastic.mat
        solver = d.step_factor(M) if self.shared is None else self.shared.solver(weights)
        schur = S_inv = rho = None
        if self.coupled is not None:
            diagonal = x.diagonal(M)
            schur = SchurOperator(x.proxy(solver), x.view.ndof, nodes.C, nodes.sign, diagonal, nodes.B, True) \
                if x.solves else None
        else:
            S_inv = x.run(lambda: _condensed(x, nodes, solver), solver)
        if x.solves:
            # z = s + rho lam / S_ii-scaled: the prox scale from the body's own stiffness. A large factor predicts the
            # states from the contact force (measured: factor 1 cycles on memory_slab, 10 and 100 settle)
            stiffness = schur.stiffness if schur is not None else np.diag(S_inv)
            rho = 100.0 / stiffness if nodes.size else np.zeros(0)
        split = solver.split(nodes.C) if S_inv is not None and x.solves and self.vertices_only else None
        kept = self.candidates.operator(solver) if keep else None
        return MemoryOperator(M, solver, split=split, kept=kept, S_inv=S_inv, rho=rho, schur=schur)

    def _condensed_fallback(self):
        """(S_inv, rho) of the current operator for the condensed solver, built once (the coupled solve's fallback)."""
        op = self._op
        self.S_inv = op.S_inv = op.S_inv if op.S_inv is not None else _condensed(self.exchange, self.nodes, self.solver)
        return self.S_inv, 100.0 / np.diag(self.S_inv)  # (the condensed solver's own scale; the coupled one keeps its)

    # -- steps ----------------------------------------------------------------------------------------------------
    def start(self, t0: float) -> None:
        """u(t0) is the solution of the inequality at t0 (no memory yet): quasistatic, there is no u0."""
        self._use(0.0)
        self._equilibrium(t0, np.zeros(self.d.ndof))

    def step(self, t_prev: float, t_next: float) -> None:
        d = self.d
        k = t_next - t_prev
        u = d.u.vec.FV().NumPy()
        self.u_prev[:] = u
        self._use(k)
        memory = np.zeros(d.ndof)
        if self.memory is not None:
            self.memory.advance(t_prev, t_next, u, memory, self._weights)
        self._equilibrium(t_next, memory)
        if self.memory is not None:
            self.memory.finish(u)
        d.v.vec.FV().NumPy()[:] = (u - self.u_prev) / k
        self.k_last = k

    def _equilibrium(self, time: float, memory: np.ndarray) -> None:
        """u = the solution of the inequality at ``time`` with the memory vector K_C H given."""
        d, x = self.d, self.exchange
        u = d.u.vec.FV().NumPy()
        d.load_vector(time, self.rhs)
        self.rhs_np -= memory
        if d.geometry.pins_contact:  # (on every process of a distributed body: the reaction is summed over them)
            self._balance = self.rhs_np.copy()
        if d.moves_clamp:  # u = delta(t_n) at x = 0
            d.lift(time, self.tmp.FV().NumPy())
            self.work.data = self.M * self.tmp
            self.rhs_np -= self.work.FV().NumPy()
        if self.size and (self.split or self.kept) is not None and self._split_equilibrium(u, time):
            return
        self.solver.solve(self.rhs_np, self.z)
        if d.moves_clamp:
            self.z[d.dirichlet_dofs] = d.dirichlet_value(time)
        if self.size:
            z, start = x.gather(self.z), x.gather(u)
            found = x.run(lambda: self._contact(z, time, start), self.solver)
            out = np.zeros(d.ndof)
            self.solver.solve(x.spread(found[0] if x.solves else None), out)
            u[:] = self.z - out
            if self.vertices_only:  # the constrained values exactly (removes round-off above g)
                x.put(u, found[1] if x.solves else None)
        else:
            u[:] = self.z
        u_view = x.gather(u)
        if x.solves:
            linear = self.coupled.linear_iterations if self.coupled is not None else None
            self.diag = self.nodes.record(u_view, found[2] if self.size else None, self.rho, linear)

    def _split_equilibrium(self, u: np.ndarray, time: float) -> bool:
        """:meth:`_equilibrium` by one solve in two parts around the contact dofs or the candidates (module docs;
        serial, P1); False where a point beyond the candidates met the foundation (the coupled solver's step then)."""
        d, C = self.d, self.nodes.C
        if self.kept is not None:
            iterations = self.candidates.equilibrium(self.kept, self.rhs_np, u, time)
            if iterations is None:
                return False
            solves = 0
        else:
            self.z[:] = 0.0
            self.z[C] = self.split.free_displacement(self.rhs_np)  # (the contact problem reads z at C only)
            _, fixed, (iterations, solves) = self._contact(self.z, time, u)
            self.split.expand(fixed[C], u)  # (u on the Dirichlet dofs: 0, or the clamp's value set below)
        if d.moves_clamp:
            u[d.dirichlet_dofs] = d.dirichlet_value(time)
        linear = 0 if self.coupled is not None else None  # (the coupled solver's CG: not used by these steps)
        self.diag = self.nodes.record(u, (iterations, solves - 1), self.rho, linear)  # (-1: one solve for z and u)
        return True

    def _contact(self, z: np.ndarray, time: float, start: np.ndarray):
        """Where the contact problem is solved, from the contact-free displacement ``z`` and the step's start ``start``
        (vectors of the view; the start only for the fallback of a cycling active set): (the
        contact forces as a dof vector of the view, the view's u at the contact dofs where the constraint fixes it
        (else ``z`` there, kept), (the active-set iterations, the back-substitutions))."""
        nodes, solves = self.nodes, 0
        if self.coupled is not None:
            before = self.schur.applications
            s, lam, iterations = self.coupled.solve(self.schur, self.rho, nodes.distance(z), time,
                                                    self._condensed_fallback, start)
            # (linear_solves adds the iterations: each back-substitution of the solve counted once)
            solves = self.schur.applications - before - iterations
        else:
            s, lam, iterations = nodes.solve(self.S_inv, self.rho, nodes.distance(z), time, start)
        if nodes.g0 is not None:  # (the layer's law acts on the distance to the foundation)
            s = s + nodes.g0
        fixed = None
        if nodes.B is None:
            fixed = np.zeros_like(z)
            fixed[nodes.C] = nodes.sign * s
        return nodes.force(lam, len(z)), fixed, (iterations, solves)

    def diagnostics(self) -> dict:
        return dict(self.diag)

    # -- error control, events, state -------------------------------------------------------------------------------
    def local_error(self, rtol, atol, order=None):
        """The memory rule's error over the last step, through the step's operator: max |K^-1 dM| / (atol + rtol U)
        (module docs, "Local error"); 0 without memory (exact in time), None while the history is too short."""
        d = self.d
        if self.memory is None:
            return 0.0
        if len(self.history) < (2 if self.trapezoid else 1):
            return None
        u, du = d.u.vec.FV().NumPy(), np.zeros(d.ndof)
        self.solver.solve(self.memory.error_force(self.k_last, self.history, u), du)
        world = d.world
        return float(world.max(np.abs(du).max(initial=0.0)) / (atol + rtol * max(self.u_scale,
                                                                                 world.max(np.abs(u).max(initial=0.0)))))

    def event(self, start: dict):
        """Where to land on a state change; the crossed share is 0: the estimate (a pair of memory rules) does
        not see the kinks of u."""
        nodes, x = self.nodes, self.exchange
        if not self.size:
            return None, 0.0
        before, after = x.gather(start["u"]), x.gather(self.d.u.vec.FV().NumPy())  # (where the contact points are)
        theta = first_event(nodes.kinks(before, start["extra"]["lam"]), nodes.kinks(after, nodes.lam)) \
            if x.solves else None
        return x.share(theta), 0.0

    def settle(self, t: float) -> None:
        """u_n solved again at t on the finer mesh with the memory carried onto it (rectangle rule: its memory at t_n
        holds no u_n). The next step's estimate reads u_n: the coarse mesh's, it charged the step with the jump onto
        the finer mesh, which the memory integrates over the step, and no step size removed it (k cut to k_min)."""
        if self.trapezoid or not self.history or self.history[-1][0] != t:
            return
        self._equilibrium(t, self.memory.held() if self.memory is not None else np.zeros(self.d.ndof))
        self.history[-1] = (t, self.d.u.vec.FV().NumPy().copy(), None)

    def _extra_state(self) -> dict:
        memory = self.memory.state() if self.memory is not None else {"histories": []}
        nodes = self.nodes.state() if self.nodes is not None else {}  # (held where the contact problem is solved)
        return memory | nodes | {"diag": dict(self.diag)}

    def _restore_extra(self, extra: dict) -> None:
        if self.memory is not None:
            self.memory.restore(extra)
        if self.nodes is not None:
            self.nodes.restore(extra)
        self.diag = dict(extra["diag"])

    def observer(self, disc=None) -> "MemoryObserver":
        return MemoryObserver(self, disc or self.d)


def _condensed(exchange, nodes, solver):
    """The dense contact stiffness S^-1 = (B K^-1 B^T)^-1, one back-substitution per contact point."""
    return CondensedSystem(exchange.proxy(solver), exchange.view.ndof, nodes.C, B=nodes.B).S0_inv  # (P1: sign^2 = 1)


class MemoryObserver(Observer):
    """What a run records of Model B: the contact pressure and state at the contact points, sigma = A eps(u) + M."""

    def node_values(self, t: float | None = None) -> dict:
        """Per contact node: the contact pressure lam / w and the state (clamped vertices: NaN / -1)."""
        d, s = self.d, self.scheme
        nodes = s.nodes
        n = len(d.node_dofs)
        pressure, state = np.full(n, np.nan), np.full(n, -1, dtype=np.int64)
        m = nodes.n_vertex_points  # (P2: the first m contact points are the vertices)
        pressure[nodes.active_nodes] = nodes.lam[:m] / nodes.w[:m]
        state[nodes.active_nodes] = nodes.states[:m]
        pinned = d.pinned_nodes
        if pinned.size and (s._balance is not None or self.gathered_record is not None):
            # a vertex held where the contact holds it: its contact force is the support's reaction,
            # R = (M u - (f - memory)) at its normal dof, pushing the body out of the foundation
            dofs = d.normal_dofs[pinned]
            whole = self.gathered_record[0] if self.gathered_record is not None else self.record_vectors(t)[0]
            residual = whole[dofs]
            if nodes.B is not None:  # P2: the forces of the adjacent facet midpoints act on the held vertex's dof too
                residual = residual + (nodes.B.T @ nodes.lam)[dofs]
            reaction = -nodes.sign * residual
            pressure[pinned] = reaction / nodes.vertex_weights[pinned]
            layer = nodes.layer
            state[pinned] = unilateral.STUCK if layer.g > 0 or layer.F > 0 else unilateral.RIGID
        out = {"contact_pressure": pressure, "contact_state": state}
        if nodes.B is None:  # (P2: the facet midpoints carry most of the force; their own pressures are recorded)
            out["contact_pressure_recovered"] = d.pressure_recovery(pressure, nodes.vertex_weights)
        return out

    def record_vectors(self, t: float) -> list:
        """On a body that holds contact vertices: M u - (f - memory) of the last equilibrium, whose value at a held
        vertex is the support's reaction (less the contact forces of P2's midpoints)."""
        s = self.scheme
        if s._balance is None:
            return []
        s.work.data = s.M * self.d.u.vec
        return [s.work.FV().NumPy() - s._balance]

    def node_weights(self) -> np.ndarray:
        """Each contact vertex's share of the side as the pressures use it (P2: Simpson's, 1/6 of each facet)."""
        return self.scheme.nodes.vertex_weights

    def contact_points(self) -> dict:
        """P2: the facet midpoints, the other contact points (coordinates and their Simpson weight, 2/3 of the
        facet), so that the archive's pressures close the force balance with those of the vertices."""
        nodes = self.scheme.nodes
        if nodes.B is None:
            return {}
        m = nodes.n_vertex_points
        out = {f"midpoint_{c}": nodes.midpoints[:, i] for i, c in enumerate("xyz"[: self.d.dim])}
        return out | {"midpoint_weight": nodes.w[m:]}

    def point_values(self, t: float | None = None) -> dict:
        """P2: the contact pressure lam / w and the state at the facet midpoints."""
        nodes = self.scheme.nodes
        if nodes.B is None:
            return {}
        m = nodes.n_vertex_points
        return {"contact_pressure_midpoint": nodes.lam[m:] / nodes.w[m:],
                "contact_state_midpoint": nodes.states[m:]}

    def stress_parts(self) -> list:
        """sigma_n = A eps(u_n) + M_n (M_n from the memory histories)."""
        memory = self.scheme.memory
        parts = memory.stress_parts() if memory else []
        if self.gathered is not None:  # (the serial view of a distributed body: the histories gathered)
            parts = [(C, H) for (C, _), H in zip(parts, self.gathered)]
        return [(self.d.model.elastic, self.d.u.vec.FV().NumPy())] + parts

    def snapshot_vectors(self) -> list:
        memory = self.scheme.memory
        return [H for _, H in memory.stress_parts()] if memory else []
