"""Model B's contact points and the primal-dual active set that solves the condensed inequality on them.

The unilateral constraint and the compliant layer's law act at the contact points with unknowns: the contact
vertices (P1) or, on P2 in 2D, the vertices and the facet midpoints (the nodes of P2), lumped by the weights
w_i = int phi_i da (Simpson's on P2). With s = u_nu at the points (s = B u; P1: the normal dofs) and the condensed
stiffness S0^-1 = (B K^-1 B^T)^-1, a step solves, for the points' forces lam, the nodal law of the layer
(:mod:`workbench.physics.unilateral`) in the states separated / stuck / compliant / rigid.

:meth:`ContactNodes.solve` is a primal-dual active set on the states, from the previous step's: exact once the
states are right, one small dense solve an iteration; it may cycle when the condensed stiffness is not an
M-matrix, and then the states are re-seeded by projected Gauss-Seidel on the (convex) condensed energy, which
converges from anywhere.

Examples
--------
>>> import workbench
>>> from workbench.discrete import discretisation
>>> nodes = ContactNodes(discretisation.build(workbench.scene("memory_slab", h=0.25)))
>>> nodes.size, round(float(nodes.w.sum()), 12)  # the free contact vertices and their share of the side
(8, 1.875)
"""
from __future__ import annotations

import copy

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from ..discrete.solvers import inverse
from ..errors import NewtonFailed
from ..physics import unilateral
from .halfspace import state_system


def scales_from(scales: tuple, last: float) -> tuple:
    """The prediction's scales in the order to try them: from ``last`` (the one that settled last time) where it is
    still among them, the rest after it.

    >>> scales_from((1.0, 0.01, 100.0), 0.01)
    (0.01, 100.0, 1.0)
    """
    first = scales.index(last) if last in scales else 0
    return scales[first:] + scales[:first]


class ContactNodes:
    """The contact points of Model B on one discretisation, their weights and initial gaps, and the active set."""

    max_iterations = 50
    #: The scales of rho tried in turn, from the one that last settled, before projected Gauss-Seidel, and the
    #: iterations without a new low in the states changed after which a scale is given up (as the coupled solver's,
    #: :class:`~workbench.schemes.coupled_contact.CoupledActiveSet`). Measured: a compliant layer on the hemisphere
    #: (gap 0.002, F = 5, c = 1e4, h_contact = 0.01) wandered for all 50 iterations of each step at rho and went to
    #: Gauss-Seidel (82.7 s of the 88.9 s run); at rho / 100 it settles.
    rho_scales, stall = (1.0, 0.01, 100.0), 10
    #: The points' compliance, S_inv's inverse, where the caller has it (:class:`~workbench.schemes.candidates.
    #: Candidates`); else it is formed from the S_inv given, the first time the forces' system is the smaller
    #: (:meth:`_state_solution`), and kept with it.
    compliance = None
    _inverse = (None, None)

    def __init__(self, d):
        self.d, self.layer = d, d.model.layer
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
        self.midpoints = None
        self.n_vertex_points = self.active_nodes.size
        if d.numerics.order == 2:
            self._quadratic_points()
        self.states = np.full(self.w.size, unilateral.SEPARATED)
        self.lam = np.zeros(self.w.size)
        self._scale = self.rho_scales[0]

    @property
    def size(self) -> int:
        return self.w.size

    def subset(self, P: np.ndarray) -> "ContactNodes":
        """These contact vertices restricted to the points P (P1), with their states and forces: a copy whose arrays
        are P's (:class:`~workbench.schemes.candidates.Candidates` solves on it)."""
        sub = copy.copy(self)
        sub.active_nodes, sub.C, sub.w = self.active_nodes[P], self.C[P], self.w[P]
        sub.g0 = None if self.g0 is None else self.g0[P]
        sub.n_vertex_points = P.size
        sub.states, sub.lam = self.states[P].copy(), self.lam[P].copy()
        return sub

    def _quadratic_points(self) -> None:
        """P2 (2D): the constraint and the layer's law at the contact vertices and the facet midpoints (the nodes of
        P2), lumped by Simpson's rule (a vertex: 1/6 of each adjacent facet, a midpoint: 2/3 of its facet).
        s = B u, B the normal trace at those points (NGSolve's P2 edge functions are hierarchical, so a midpoint's
        u_nu involves its edge dof as well as the two vertices)."""
        from ..discrete.boundary import ContactSide

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
        m = self.active_nodes.size
        rows_v = sp.csr_matrix((np.full(m, self.sign), (np.arange(m), self.C)), shape=(m, d.ndof))
        self.B = sp.vstack([rows_v, mid.T_nu]).tocsr()
        self.w = np.concatenate([w_v[self.active_nodes], 2.0 * facet_len / 3.0])
        self.vertex_weights = w_v
        corners = [[d.mesh[v].point for v in el.vertices] for el in d.mesh.Boundaries(d.contact_name).Elements()]
        self.midpoints = np.asarray([np.mean(c, axis=0) for c in corners])[mid.element]  # (in point order)
        if self.g0 is not None:
            self.g0 = np.concatenate([self.g0, mid.gap0])
        self.C = np.unique(self.B.indices)  # the dofs the contact points see (for the recovery only)

    def positions(self) -> np.ndarray:
        """The contact points' coordinates (the vertices, then on P2 the facet midpoints)."""
        vertices = self.d.node_xyz[self.active_nodes]
        return vertices if self.midpoints is None else np.vstack([vertices, self.midpoints[:, : vertices.shape[1]]])

    def s(self, u: np.ndarray) -> np.ndarray:
        """u_nu at the contact points."""
        return self.sign * u[self.C] if self.B is None else self.B @ u

    def distance(self, u: np.ndarray) -> np.ndarray:
        """s - g0: the points' normal displacement less their initial gap (what the layer's law acts on)."""
        s = self.s(u)
        return s - self.g0 if self.g0 is not None else s

    def force(self, lam: np.ndarray, ndof: int) -> np.ndarray:
        """The dof vector of the points' forces on the body, in the dofs' directions."""
        if self.B is not None:
            return self.B.T @ lam
        force = np.zeros(ndof)
        force[self.C] = self.sign * lam  # contact forces on the body, in dof direction: -(outward) ...
        return force

    def solve(self, S_inv, rho, s_free: np.ndarray, time: float, u=None):
        """(s, lam, iterations) of the condensed inequality for the contact-free displacement ``s_free`` at the points
        (its distance, g0 taken off), by the primal-dual active set from the previous step's states (module docs).
        ``u``: the displacement the step starts from (a dof vector; default: the discretisation's), where projected
        Gauss-Seidel starts should the states cycle."""
        total = 0
        for scale in scales_from(self.rho_scales, self._scale):
            found, total = self._active_set(S_inv, scale * rho, s_free, self.states.copy(), total)
            if found is not None:
                self._scale = scale
                return found
        states = self._gauss_seidel_states(S_inv, rho, s_free, u)
        found, total = self._active_set(S_inv, rho, s_free, states, total)
        if found is not None:
            return found
        raise NewtonFailed(f"{self.d.scene.name}: the contact active-set iteration did not settle ({total} iterations) "
                           f"at t = {time:.6g} s; try a smaller k", time=time)

    def _active_set(self, S_inv, rho, s_free, states, total):
        """((s, lam, iterations) or None should the states cycle or stall, iterations so far): the primal-dual active
        set from ``states``."""
        layer, seen = self.layer, set()
        rho_t = rho * self.w  # rho in traction units: z = s + rho_t * lam / w
        fewest, since = np.inf, 0  # (the fewest states changed in an iteration so far, and iterations since)
        for _ in range(self.max_iterations):
            total += 1
            s, lam = self._state_solution(S_inv, s_free, states)
            new = layer.state_of(s + rho_t * lam / self.w, rho_t)
            if np.array_equal(new, states):
                self.states, self.lam = states, lam
                return (s, lam, total), total
            changed = np.count_nonzero(new != states)
            fewest, since = (changed, 0) if changed < fewest else (fewest, since + 1)
            key = new.tobytes()
            if key in seen or since >= self.stall:
                break
            seen.add(key)
            states = new
        return None, total

    def _state_solution(self, S_inv, s_free, states):
        """(s, lam) for fixed ``states``: by the points whose position is unknown (the separated and compliant ones)
        and S_inv, or by the points whose force is unknown and the compliance, whichever are fewer. Where few points
        touch, the forces' system is the smaller (the hemisphere's 1590 candidates at 47k dofs: 463 forces against 1127
        positions at the first load step). The compliance is S_inv inverted once (:func:`inverse`; kept while S_inv
        is the same object: an operator's)."""
        layer = self.layer
        unknown, rhs, D, lam = state_system(layer, self.w, states, s_free)
        U = np.flatnonzero(unknown)
        S = None
        if U.size < np.count_nonzero((states == unilateral.SEPARATED) | (states == unilateral.COMPLIANT)):
            S = self.compliance if self.compliance is not None else self._compliance_of(S_inv)
        if S is not None:
            if U.size:
                A = S[np.ix_(U, U)]
                A[np.diag_indices_from(A)] += D[U]
                known = rhs[U] - S[U] @ lam if lam.any() else rhs[U]  # (lam: the forces known, c = 0)
                lam[U] = la.cho_solve(la.cho_factor(A, overwrite_a=True, check_finite=False), known,
                                      check_finite=False)
            s = s_free - S @ lam
            s[states == unilateral.STUCK] = 0.0  # (exactly, as the positions' system has them)
            s[states == unilateral.RIGID] = layer.g
            return s, lam
        return layer.solve_states(S_inv, s_free, self.w, states)

    def _compliance_of(self, S_inv):
        """S_inv's inverse, formed once for the S_inv object given (None should it not be positive definite to
        round-off: the positions' system then, as before)."""
        if self._inverse[0] is not S_inv:
            try:
                self._inverse = (S_inv, inverse(S_inv))
            except la.LinAlgError:
                self._inverse = (S_inv, None)
        return self._inverse[1]

    def _gauss_seidel_states(self, S, rho_diag, s_free, u=None, sweeps=2000, tol=1e-13):
        """States of the condensed energy's minimiser by projected Gauss-Seidel (exact coordinate minimisation)."""
        w = self.w
        b = S @ s_free
        diag = S.diagonal()
        rho = w / diag  # coordinate i: minimise (S_ii / 2) s^2 - y S_ii s + w psi(s) over s <= g -> prox
        layer = self.layer
        s = np.minimum(self.distance(self.d.u.vec.FV().NumPy() if u is None else u), layer.g)
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
        return layer.state_of(s + rho_diag * lam, rho_diag * w)

    def record(self, u: np.ndarray, counted, rho, linear_iterations=None) -> dict:
        """A step's record: ``u`` the body's displacement (where the contact problem is solved), ``counted`` the
        contact solve's iterations and back-substitutions besides them (None without contact points),
        ``linear_iterations`` the coupled solver's conjugate gradient iterations (None: not recorded)."""
        iterations, solves = counted or (0, 0)
        counts = np.bincount(self.states, minlength=4)
        out = {  # (the back-substitutions: z, the contact solve's, and u from the contact forces)
            "iterations": iterations, "linear_solves": 1 + (solves + iterations + 1 if counted else 0),
            "n_separated": int(counts[0]), "n_stuck": int(counts[1]), "n_compliant": int(counts[2]),
            "n_rigid": int(counts[3]), "complementarity": self.complementarity(u, rho),
        }
        if linear_iterations is not None:
            out["linear_iterations"] = linear_iterations
        return out

    def kinks(self, u: np.ndarray, lam: np.ndarray) -> list:
        """Zeros where a contact point changes state, weighted by its share of the side: s = u_nu (separation),
        s - g (the rigid limit) and lam / w - F (the layer's yield limit, between stuck and compliant)."""
        s = self.distance(u)
        return [(s, self.w), (s - self.layer.g, self.w), (lam / self.w - self.layer.F, self.w)]

    def complementarity(self, u: np.ndarray, rho) -> float:
        """max |s - prox(s + rho lam / w)| at the points: 0 at a solution of the inequality."""
        return self.layer.complementarity(self.distance(u), self.lam, self.w, rho * self.w) if self.size else 0.0

    def state(self) -> dict:
        return {"states": self.states.copy(), "lam": self.lam.copy()}

    def restore(self, extra: dict) -> None:
        self.states, self.lam = extra["states"].copy(), extra["lam"].copy()

