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

Solver, with no parameter to tune: the elastic matrix K_A (with the trapezoid rule:
K_A plus the current step's memory part) is factored once and condensed onto the
contact vertices' normal dofs (S0 = (K_A^-1)_CC, once per operator); a step costs one back-substitution for the contact-free displacement z,
a primal-dual active-set iteration on the contact nodes (states separated /
stuck / compliant / rigid, :mod:`workbench.physics.unilateral`; each iteration
one small dense solve, exact once the states are right, warm-started from the
previous step's states), and one back-substitution to recover u. Recorded per
step: iterations, state counts, the complementarity residual
max |s - prox(s + rho lam / w)| and the number of linear solves.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np

from .. import solvers
from ..condensation import CondensedSystem
from ..errors import NewtonFailed
from ..physics import unilateral
from .base import Scheme, first_event


class MemoryVI(Scheme):
    """One variational inequality per step, memory by recursion or quadrature, left rectangle or trapezoid (module docs)."""

    name = "vi"
    max_iterations = 50
    cache_size = 4

    def __init__(self, d):
        super().__init__(d)
        self.layer = d.model.layer
        self.trapezoid = d.scene["memory_rule"] == "trapezoid"
        self.order = 2 if self.trapezoid else 1
        free = np.array(d.fes.FreeDofs(), dtype=bool)
        normal = d.normal_dofs
        self.active_nodes = np.nonzero(free[normal])[0]  # a clamped contact vertex is not an unknown
        self.C = normal[self.active_nodes]
        self.sign = d.geometry.normal_sign  # u_nu = sign * u_C
        self.w = d.contact_weights[self.active_nodes]
        # a curved contact side: the layer's law acts on u_nu - g0 (the initial gap at the node; None: flat)
        self.g0 = d.geometry.gap0(d.node_xyz[self.active_nodes])
        self.vertex_weights = d.contact_weights  # each contact vertex's share of the side (P2: Simpson's)
        self.B = None  # P2: s = B u at the contact points (the vertices, then the facet midpoints)
        if d.scene["order"] == 2:
            self._quadratic_points()
        self.pinned = d.pinned_nodes
        self._balance = None  # f - memory of the last equilibrium (only for the reaction of pinned contact nodes)
        self._operators = OrderedDict()
        self.scales = d.memory_scale or [1.0] * len(d.memory)  # (before _use: the step operator needs them)
        self._use(0.0)
        self.states = np.full(self.w.size, unilateral.SEPARATED)
        self.lam = np.zeros(self.w.size)
        self.z = np.zeros(d.ndof)
        self.rhs = d.u.vec.CreateVector()
        self.rhs_np = self.rhs.FV().NumPy()
        self.tmp = d.u.vec.CreateVector()
        self.work = d.u.vec.CreateVector()  # matvec results (allocated once, not per step)
        self.u_prev = d.u.vec.FV().NumPy().copy()
        # memory: Prony histories H_i (dof vectors) or the stored u_j for a general kernel
        n = d.ndof
        self.histories = [np.zeros(n) for _ in d.memory] if d.memory_kind == "prony" else []
        groups = OrderedDict()  # terms sharing one stiffness: sum_i s_i H_i first, then one matvec
        for i, (K, _, _) in enumerate(d.memory):
            groups.setdefault(id(K), (K, []))[1].append(i)
        self.groups = list(groups.values())
        self.combined = np.zeros(n)
        self.stored = np.empty((64, n)) if d.memory_kind == "kernel" else None
        self.times = [0.0]
        self.diag = {}
        self._pending = None

    def _quadratic_points(self) -> None:
        """P2 (2D): the constraint and the layer's law at the contact vertices and the facet midpoints (the nodes of
        P2), lumped by Simpson's rule (a vertex: 1/6 of each adjacent facet, a midpoint: 2/3 of its facet).
        s = B u, B the normal trace at those points (NGSolve's P2 edge functions are hierarchical, so a midpoint's
        u_nu involves its edge dof as well as the two vertices)."""
        import scipy.sparse as sp

        from ..boundary import ContactSide

        d = self.d
        mid = ContactSide(d.fes, d.contact_name, d.geometry, rule=0)  # one point per facet: its midpoint
        facet_len = mid.weights  # (one point per facet, in point order)
        length = np.zeros(len(facet_len))
        length[mid.element] = facet_len  # in facet order
        index = {int(v): i for i, v in enumerate(d.vertex_numbers)}
        w_v = np.zeros(len(d.node_dofs))
        for j, el in enumerate(d.mesh.Boundaries(d.contact_name).Elements()):
            for v in el.vertices:
                w_v[index[v.nr]] += length[j] / 6.0
        rows_v = sp.csr_matrix((np.full(self.active_nodes.size, self.sign), (np.arange(self.active_nodes.size),
                                                                           self.C)), shape=(self.active_nodes.size,
                                                                                            d.ndof))
        self.B = sp.vstack([rows_v, mid.T_nu]).tocsr()
        self.w = np.concatenate([w_v[self.active_nodes], 2.0 * facet_len / 3.0])
        self.vertex_weights = w_v
        corners = [[d.mesh[v].point for v in el.vertices] for el in d.mesh.Boundaries(d.contact_name).Elements()]
        self.midpoints = np.asarray([np.mean(c, axis=0) for c in corners])[mid.element]  # (in point order)
        self.n_vertex_points = self.active_nodes.size
        if self.g0 is not None:
            self.g0 = np.concatenate([self.g0, mid.gap0])
        self.C = np.unique(self.B.indices)  # the dofs the contact points see (for the recovery only)

    def _s(self, u):
        """u_nu at the contact points."""
        return self.sign * u[self.C] if self.B is None else self.B @ u

    def local_error(self, rtol, atol, order=None):
        """The memory rule's error over the last step, through the step's operator: max |K^-1 dM| / (atol + rtol U).

        u_n solves the inequality at t_n exactly for its memory term, so the step's local error is that of
        the memory integral over [t_{n-1}, t_n] (an embedded pair, not a predictor: u of a quasistatic
        problem kinks where a contact node changes state, and a predictor read that kink as an error that no
        step is short enough to remove - measured: memory_slab stopped at k = 5e-9 s). dM is, per kernel
        term C b(s), C applied to

        * rectangle: the trapezoid rule minus the rectangle rule, (k/2) (b(0) u_n - b(k) u_{n-1}) (Prony:
          the exact integral of the linear interpolant minus k e^-x u_{n-1});
        * trapezoid: its own leading error -(k^3/12) g'', g(s) = b(t_n - s) u(s) by divided differences
          of u_n, u_{n-1}, u_{n-2} (Prony: the kernel is integrated exactly, only u's curvature counts:
          -(k^3/12) ((1 - e^-x)/x) u'').

        K^-1 (the factored operator of the step, contact left out) turns the force dM into a displacement.
        Without memory the scheme is exact in time: 0. None while the history is too short.
        """
        d = self.d
        if not d.memory:
            return 0.0
        need = 2 if self.trapezoid else 1
        if len(self.history) < need:
            return None
        u = d.u.vec.FV().NumPy()
        t1, u1 = self.history[-1][0], self.history[-1][1]
        k = self.k_last
        force, deltas = np.zeros(d.ndof), []
        if self.trapezoid:
            t2, u2 = self.history[-2][0], self.history[-2][1]
            kp = t1 - t2
            curvature = 2.0 * (u / (k * (k + kp)) - u1 / (k * kp) + u2 / (kp * (k + kp)))
        for K, _, kernel in d.memory:
            if d.memory_kind == "prony":
                x = k / kernel
                mean = -np.expm1(-x) / x
                if self.trapezoid:
                    delta = (-k ** 3 / 12.0 * mean) * curvature
                else:
                    delta = (kernel * (mean - np.exp(-x)) - k * np.exp(-x)) * u1 + kernel * (1.0 - mean) * u
            else:
                b = lambda s: float(kernel(t=s))  # noqa: E731
                if self.trapezoid:
                    g = 2.0 * (b(0.0) * u / (k * (k + kp)) - b(k) * u1 / (k * kp) + b(k + kp) * u2 / (kp * (k + kp)))
                    delta = (-k ** 3 / 12.0) * g
                else:
                    delta = 0.5 * k * (b(0.0) * u - b(k) * u1)
            deltas.append(delta)
        self._apply_memory(deltas, force)
        force[d.dirichlet_dofs] = 0.0
        du = np.zeros(d.ndof)
        self.solver.solve(force, du)
        return float(np.abs(du).max() / (atol + rtol * max(self.u_scale, np.abs(u).max())))

    def preflight(self, k_max: float) -> dict:
        """Records how a general kernel was approximated by exponentials (its terms and error bound)."""
        memory = self.d.model.memory
        fit = memory.fit if memory is not None else None
        return {} if fit is None else {"kernel_terms": fit["terms"], "kernel_fit_error": fit["error"]}

    # -- the operator of a step -------------------------------------------------------------------------------
    def _implicit_weights(self, k: float) -> list:
        """Per memory stiffness, the weight of u_n in the step's memory term (0 for the rectangle rule)."""
        d = self.d
        if not self.trapezoid or k == 0.0 or not d.memory:
            return [0.0] * len(d.memory)
        if d.memory_kind == "prony":
            out = []
            for _, _, tau in d.memory:
                x = k / tau
                out.append(tau * (1.0 - (-np.expm1(-x)) / x))
            return out
        return [0.5 * k * float(d.model.memory.shape(t=0.0))]

    def _use(self, k: float) -> None:
        """Factor (and condense) K_A + sum_i w_i K_Ci for this step (cached by the weights)."""
        d = self.d
        weights = self._implicit_weights(k)
        key = tuple(weights)
        if key not in self._operators:
            M = d.elastic.mat
            if any(weights):
                M = d.elastic.mat.CreateMatrix()
                vec = M.AsVector()
                vec.data = d.elastic.mat.AsVector()
                for wi, si, (K, _, _) in zip(weights, self.scales, d.memory):
                    vec.data += (wi * si) * K.mat.AsVector()
            solver = solvers.factor(M, d.fes.FreeDofs(), d.u.vec, d.scene["solver"])
            S_inv = CondensedSystem(solver, d.ndof, self.C, B=self.B).S0_inv  # (P1: sign^2 = 1, the same in s)
            # z = s + rho lam / S_ii-scaled: the prox scaling comes from the body's own stiffness. A large factor
            # predicts the states from the contact force (measured: factor 1 cycles on memory_slab, 10 and 100 settle)
            self._operators[key] = (M, solver, S_inv, 100.0 / np.diag(S_inv) if self.w.size else np.zeros(0))
            while len(self._operators) > self.cache_size:
                self._operators.popitem(last=False)
        else:
            self._operators.move_to_end(key)
        self.M, self.solver, self.S_inv, self.rho = self._operators[key]
        self._weights = weights

    # -- memory -------------------------------------------------------------------------------------------------
    def _memory_vector(self, t_prev, t_next, out_np):
        """out = sum_i K_Ci H~_i: the histories advanced to t_next without their u_n part (uses u_{n-1} = u)."""
        d = self.d
        u_prev = d.u.vec.FV().NumPy()
        k = t_next - t_prev
        out_np[:] = 0.0
        self._pending = []
        if d.memory_kind == "prony":
            for H, (K, _, tau) in zip(self.histories, d.memory):
                x = k / tau
                decay = np.exp(-x)
                if self.trapezoid:  # exact for u linear on the step
                    H *= decay
                    H += (tau * ((-np.expm1(-x)) / x - decay)) * u_prev
                else:
                    H += k * u_prev
                    H *= decay
            self._apply_memory(self.histories, out_np)
        elif d.memory_kind == "kernel":
            K = d.memory[0][0]
            n = len(self.times) - 1  # u_0 ... u_{n} stored after this append
            if n >= self.stored.shape[0]:  # grow the history buffer by doubling
                grown = np.empty((2 * self.stored.shape[0], self.stored.shape[1]))
                grown[:n] = self.stored[:n]
                self.stored = grown
            self.stored[n] = u_prev
            self.times.append(t_next)
            t = np.asarray(self.times)
            weights = d.model.memory.weights(t, self.trapezoid)
            H = weights @ self.stored[: n + 1]  # O(n) work: the whole history
            self.histories = [H]
            self._add_matvec(K, H, out_np)

    def _finish_memory(self) -> None:
        """The u_n part of the trapezoid rule joins the histories once u_n is known."""
        u = self.d.u.vec.FV().NumPy()
        for H, w in zip(self.histories, self._weights):
            if w:
                H += w * u

    def _apply_memory(self, vectors, out_np):
        """out += sum_i s_i K_i vectors[i], one matvec per distinct stiffness (a fitted kernel's 32 terms: one)."""
        for K, members in self.groups:
            if len(members) == 1 and self.scales[members[0]] == 1.0:
                self._add_matvec(K, vectors[members[0]], out_np)
                continue
            self.combined[:] = 0.0
            for i in members:
                self.combined += self.scales[i] * vectors[i]
            self._add_matvec(K, self.combined, out_np)

    def _add_matvec(self, K, H, out_np):
        self.tmp.FV().NumPy()[:] = H
        self.work.data = K.mat * self.tmp
        out_np += self.work.FV().NumPy()

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
        if d.memory:
            self._memory_vector(t_prev, t_next, memory)
        self._equilibrium(t_next, memory)
        self._finish_memory()
        d.v.vec.FV().NumPy()[:] = (u - self.u_prev) / k
        self.k_last = k

    def _equilibrium(self, time: float, memory: np.ndarray) -> None:
        """u = the solution of the inequality at ``time`` with the memory vector K_C H given."""
        d = self.d
        u = d.u.vec.FV().NumPy()
        d.load_vector(time, self.rhs)
        self.rhs_np -= memory
        if self.pinned.size:
            self._balance = self.rhs_np.copy()
        if d.moves_clamp:  # u = delta(t_n) at x = 0
            d.lift(time, self.tmp.FV().NumPy())
            self.work.data = self.M * self.tmp
            self.rhs_np -= self.work.FV().NumPy()
        self.solver.solve(self.rhs_np, self.z)
        if d.moves_clamp:
            self.z[d.dirichlet_dofs] = d.dirichlet_value(time)
        solves = 1
        if self.w.size:
            s_free = self._s(self.z)
            if self.g0 is not None:  # the layer's law in the distance to the foundation
                s_free = s_free - self.g0
            s, lam, iterations = self._active_set(s_free, time)
            if self.g0 is not None:
                s = s + self.g0
            if self.B is None:
                force = np.zeros(d.ndof)
                force[self.C] = self.sign * lam  # contact forces on the body, in dof direction: -(outward) ...
            else:
                force = self.B.T @ lam
            out = np.zeros(d.ndof)
            self.solver.solve(force, out)
            solves += 1
            u[:] = self.z - out
            if self.B is None:
                u[self.C] = self.sign * s  # the constrained values exactly (removes round-off above g)
            self.lam = lam
        else:
            u[:] = self.z
            iterations = 0
        counts = np.bincount(self.states, minlength=4)
        self.diag = {
            "iterations": iterations, "linear_solves": solves + iterations,
            "n_separated": int(counts[0]), "n_stuck": int(counts[1]), "n_compliant": int(counts[2]),
            "n_rigid": int(counts[3]),
            "complementarity": self.layer.complementarity(self._distance(u), self.lam, self.w, self.rho * self.w)
            if self.w.size else 0.0,
        }

    def _distance(self, u):
        """s - g0: the contact nodes' normal displacement less their initial gap (what the layer's law acts on)."""
        s = self._s(u)
        return s - self.g0 if self.g0 is not None else s

    # -- state, events ----------------------------------------------------------------------------------------------
    def _extra_state(self) -> dict:
        n = len(self.times)
        return {"histories": [H.copy() for H in self.histories], "times": list(self.times),
                "stored": None if self.stored is None else self.stored[:n].copy(), "states": self.states.copy(),
                "lam": self.lam.copy(), "diag": dict(self.diag)}

    def _restore_extra(self, extra: dict) -> None:
        self.histories = [H.copy() for H in extra["histories"]]
        self.times = list(extra["times"])
        if extra["stored"] is not None:
            n = len(self.times)
            if self.stored.shape[0] < n:
                self.stored = np.empty((max(64, 2 * n), self.stored.shape[1]))
            self.stored[:n] = extra["stored"]
        self.states, self.lam, self.diag = extra["states"].copy(), extra["lam"].copy(), dict(extra["diag"])

    def switching(self, u, lam) -> list:
        """Zeros where a contact node changes state, weighted by the node's boundary measure: s = u_nu
        (separation), s - g (the rigid limit) and lam / w - F (the layer's yield limit, between stuck and
        compliant)."""
        s = self._distance(u)
        return [(s, self.w), (s - self.layer.g, self.w), (lam / self.w - self.layer.F, self.w)]

    def event(self, start: dict):
        """Where to land on a state change; the crossed share is 0: the estimate (a pair of memory rules) does
        not see the kinks of u."""
        if not self.w.size:
            return None, 0.0
        return first_event(self.switching(start["u"], start["extra"]["lam"]),
                           self.switching(self.d.u.vec.FV().NumPy(), self.lam)), 0.0

    def _active_set(self, s_free, time):
        """Primal-dual active set on the contact nodes, from the previous step's states.

        PDAS is exact once the states are right but may cycle when the condensed
        stiffness is not an M-matrix; on a cycle the states are re-seeded by
        projected Gauss-Seidel on the (convex) condensed energy, which converges
        from anywhere, and PDAS finishes exactly.
        """
        layer = self.layer
        rho_t = self.rho * self.w  # rho in traction units: z = s + rho_t * lam / w
        states = self.states.copy()
        total = 0
        for attempt in range(2):
            seen = set()
            for _ in range(self.max_iterations):
                total += 1
                s, lam = layer.solve_states(self.S_inv, s_free, self.w, states)
                new = layer.state_of(s + rho_t * lam / self.w, rho_t)
                if np.array_equal(new, states):
                    self.states = states
                    return s, lam, total
                key = new.tobytes()
                if key in seen:
                    break
                seen.add(key)
                states = new
            if attempt == 0:
                states = self._gauss_seidel_states(s_free)
        raise NewtonFailed(f"{self.d.scene.name}: the contact active-set iteration did not settle ({total} iterations) at "
                           f"t = {time:.6g} s; try a smaller k", time=time)

    def _gauss_seidel_states(self, s_free, sweeps=2000, tol=1e-13):
        """States of the condensed energy's minimiser by projected Gauss-Seidel (exact coordinate minimisation)."""
        S, w = self.S_inv, self.w
        b = S @ s_free
        diag = np.diag(S)
        rho = w / diag  # coordinate i: minimise (S_ii / 2) s^2 - y S_ii s + w psi(s) over s <= g -> prox
        layer = self.layer
        s = np.minimum(self._distance(self.d.u.vec.FV().NumPy()), layer.g)
        for _ in range(sweeps):
            change = 0.0
            for i in range(len(s)):
                y = (b[i] - S[i] @ s + diag[i] * s[i]) / diag[i]
                new = float(layer.prox(y, rho[i]))
                change = max(change, abs(new - s[i]))
                s[i] = new
            if change <= tol * (1.0 + np.abs(s).max()):
                break
        lam = S @ (s_free - s)
        return layer.state_of(s + self.rho * lam, self.rho * w)

    def diagnostics(self) -> dict:
        return dict(self.diag)

    def node_values(self, t: float | None = None) -> dict:
        """Per contact node: the contact pressure lam / w and the state (clamped vertices: NaN / -1)."""
        d = self.d
        n = len(d.node_dofs)
        pressure, state = np.full(n, np.nan), np.full(n, -1, dtype=np.int64)
        m = self.active_nodes.size  # (P2: the first m contact points are the vertices)
        pressure[self.active_nodes] = self.lam[:m] / self.w[:m]
        state[self.active_nodes] = self.states[:m]
        if self.pinned.size and self._balance is not None:
            # a vertex held where the contact holds it: its contact force is the support's reaction,
            # R = (M u - (f - memory)) at its normal dof, pushing the body out of the foundation
            self.work.data = self.M * d.u.vec
            dofs = d.normal_dofs[self.pinned]
            residual = self.work.FV().NumPy()[dofs] - self._balance[dofs]
            if self.B is not None:  # P2: the forces of the adjacent facet midpoints act on the held vertex's dof too
                residual = residual + (self.B.T @ self.lam)[dofs]
            reaction = -self.sign * residual
            weights = self.vertex_weights[self.pinned]
            pressure[self.pinned] = reaction / weights
            state[self.pinned] = unilateral.STUCK if self.layer.g > 0 or self.layer.F > 0 else unilateral.RIGID
        return {"contact_pressure": pressure, "contact_state": state}

    def node_weights(self) -> np.ndarray:
        """Each contact vertex's share of the side as the pressures use it (P2: Simpson's, 1/6 of each facet)."""
        return self.vertex_weights

    def contact_points(self) -> dict:
        """P2: the facet midpoints, the other contact points (coordinates and their Simpson weight, 2/3 of the
        facet), so that the archive's pressures close the force balance with those of the vertices."""
        if self.B is None:
            return {}
        d, m = self.d, self.n_vertex_points
        out = {f"midpoint_{c}": self.midpoints[:, i] for i, c in enumerate("xyz"[: d.dim])}
        return out | {"midpoint_weight": self.w[m:]}

    def point_values(self, t: float | None = None) -> dict:
        """P2: the contact pressure lam / w and the state at the facet midpoints."""
        if self.B is None:
            return {}
        m = self.n_vertex_points
        return {"contact_pressure_midpoint": self.lam[m:] / self.w[m:], "contact_state_midpoint": self.states[m:]}

    def stress_parts(self) -> list:
        """sigma_n = A eps(u_n) + M_n (M_n from the memory histories)."""
        d = self.d
        return [(d.model.elastic, d.u.vec.FV().NumPy())] + [(C, H) for H, (_, C, _) in zip(self.histories, d.memory)]
