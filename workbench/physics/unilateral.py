"""The foundation of Model B: a compliant layer of thickness g over a rigid one (nodal form).

With psi(r) = F r_+ + (c/2) r_+^2, the contact condition at a contact node with
normal displacement s (positive = penetration) and nodal contact force lam
(positive = pushing the body out) is lam in w d(psi + I_(-inf, g])(s), w the
node's share of the contact side (lumped boundary quadrature). Four states:

    separated  s < 0        lam = 0
    stuck      s = 0        0 <= lam <= w F        (below the layer's yield limit)
    compliant  0 < s < g    lam = w (F + c s)
    rigid      s = g        lam >= w (F + c g)

Equivalently s = prox(s + rho lam / w) for any rho > 0 with the piecewise
linear map of docs/models.md; its branches are the states, which makes a primal-dual
active set (semismooth Newton) iteration exact once the states are right.

Examples
--------
>>> prox(np.array([-1.0, 0.05, 0.5, 5.0]), rho=0.1, F=1.0, c=1.0, g=1.0).tolist()
[-1.0, 0.0, 0.36363636363636365, 1.0]
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve

SEPARATED, STUCK, COMPLIANT, RIGID = 0, 1, 2, 3


class Layer:
    """The compliant layer psi(r) = F r_+ + (c/2) r_+^2 over the rigid foundation at u_nu = g, with its nodal law.

    Examples
    --------
    >>> Layer(F=1.0, c=1.0, g=1.0).prox(np.array([0.5]), rho=0.1).round(6).tolist()
    [0.363636]
    """

    def __init__(self, F: float, c: float, g: float):
        self.F, self.c, self.g = float(F), float(c), float(g)

    def prox(self, z, rho):
        return prox(z, rho, self.F, self.c, self.g)

    def state_of(self, z, rho):
        return state_of(z, rho, self.F, self.c, self.g)

    def solve_states(self, S_inv, s_free, w, states):
        return solve_states(S_inv, s_free, w, self.F, self.c, self.g, states)

    def complementarity(self, s, lam, w, rho):
        return complementarity(s, lam, w, rho, self.F, self.c, self.g)


def prox(z, rho, F, c, g):
    """prox of rho (psi + I_(-inf, g]): z (z <= 0); 0 (0 < z <= rho F); (z - rho F)/(1 + rho c) capped at g."""
    z = np.asarray(z, dtype=float)
    comp = np.minimum((z - rho * F) / (1.0 + rho * c), g)
    return np.where(z <= 0, z, np.where(z <= rho * F, 0.0, comp))


def state_of(z, rho, F, c, g):
    """The branch of prox at z: SEPARATED, STUCK, COMPLIANT or RIGID."""
    z = np.asarray(z, dtype=float)
    edge = rho * F + (1.0 + rho * c) * g
    return np.where(z <= 0, SEPARATED, np.where(z <= rho * F, STUCK, np.where(z < edge, COMPLIANT, RIGID)))


def solve_states(S_inv, s_free, w, F, c, g, states):
    """Solve the condensed linear system for the given states.

    The body's response is lam = S_inv (s_free - s) (S_inv: the contact
    stiffness seen by the contact nodes; s_free: where they would be without
    contact). Each node adds the equation of its state. Returns (s, lam).
    Only the nodes whose position is unknown (separated, compliant) are solved for, by a Cholesky factor: their
    block of S_inv plus the compliant nodes' w c is symmetric positive definite.
    """
    fix = (states == STUCK) | (states == RIGID)
    sep = states == SEPARATED
    comp = states[~fix] == COMPLIANT
    s = np.where(states == RIGID, g, 0.0)  # stuck / rigid: s_i = 0 / g
    free = np.flatnonzero(~fix)
    if free.size:
        # separated: lam_i = 0  ->  (S_inv s)_i = (S_inv s_free)_i
        # compliant: lam_i = w (F + c s_i)  ->  (S_inv s)_i + w c s_i = (S_inv s_free)_i - w F
        A, at = S_inv[np.ix_(free, free)], np.flatnonzero(comp)  # (a copy)
        A[at, at] += w[free][comp] * c
        b = S_inv[free] @ s_free - S_inv[np.ix_(free, np.flatnonzero(fix))] @ s[fix]
        b[comp] -= w[free][comp] * F
        s[free] = cho_solve(cho_factor(A, check_finite=False), b, check_finite=False)
    lam = S_inv @ (s_free - s)
    lam[sep] = 0.0  # exactly zero by its equation; remove round-off
    return s, lam


def complementarity(s, lam, w, rho, F, c, g):
    """max |s - prox(s + rho lam / w)| (0 exactly at a solution)."""
    return float(np.max(np.abs(s - prox(s + rho * lam / w, rho, F, c, g)))) if len(s) else 0.0
