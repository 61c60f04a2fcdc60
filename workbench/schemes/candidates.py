"""Model B's condensed solver on the contact points a curved body reaches first (``contact_solver = "auto"``).

A body whose gap to the foundation grows away from where it first touches (the Hertz indenters, a curved body from a
mesh file) comes into contact at the points of smallest initial gap first. :class:`Candidates` keeps those points P
last in the step's factorization: the factor then gives their condensed stiffness (PARDISO's Schur complement) and
solves in two parts around them, and a step is the condensed solver's: the free displacement at P from the first
part, the inequality solved densely on P with the other points Q held apart, and u everywhere from the second part,
one solve's work in all. That u is the whole body's, so the assumption is checked exactly: where no point of Q then
meets the foundation, the forces found on P (and none on Q) solve the whole inequality. Where one does, the step is
solved again by the coupled solver (one more back-substitution for the free displacement, warm started from the
forces found on P), and the candidates are given up for the run.

Measured on the hemisphere from rest to the full load in 4 steps (docs/schemes.md, "The candidate points"): at 47k
dofs, with 5186 contact vertices and 1182 in contact at the end, the 1590 candidates cost the factorization about
0.6 s more, and the run then took 5 solves in two parts and 29 dense active-set iterations, against 76
back-substitutions (54 of them conjugate gradient iterations) and the half-space model's dense work: 4.89 s against
6.48 s in one run of each (16 steps: 5.81 s against 14.85 s). Where the zone outgrows the candidates (the hemisphere
at 106k and 193k dofs, in its last steps) their factorization's extra cost is paid for fewer cheap steps: 4 steps
took 11 % less and 10 % more time than the coupled solver alone, 16 steps 50 % and 26 % less.

>>> import numpy as np
>>> Candidates.choose(np.array([0.3, 0.0, 0.1, 0.1, 0.2]), 3).tolist()  # the smallest gaps, ties kept together
[1, 2, 3]
>>> Candidates.choose(np.array([0.3, 0.0, 0.1, 0.1, 0.2]), 2).tolist()  # (0.1 twice: only the first fits)
[1]
>>> Candidates.choose(np.zeros(5), 3) is None  # a flat side: the gaps do not tell which points touch first
True
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as la

from ..physics.unilateral import SEPARATED
from .halfspace import dense_points


class Candidates:
    """The contact points P of smallest initial gap, solved on densely, and the rest Q checked (module docs).

    Parameters
    ----------
    nodes : ContactNodes
        The contact vertices (P1), with their initial gaps ``g0``.
    P : array of int
        The candidates, positions among ``nodes``.
    """

    def __init__(self, nodes, P: np.ndarray):
        self.nodes, self.P = nodes, np.asarray(P)
        self.Q = np.setdiff1d(np.arange(nodes.size), self.P)
        #: Whether a point of Q met the foundation: the candidates are given up for the run.
        self.missed = False
        #: Whether a factorization kept them (a solver that cannot, banded or iterative, leaves the coupled solver).
        self.kept = False

    @staticmethod
    def choose(g0, most: int):
        """The points of the ``most`` smallest gaps g0, without splitting a set of equal gaps (so no point left out
        lies nearer than one kept), sorted; None where that leaves none or takes every point."""
        if g0 is None or not 0 < most < len(g0):
            return None
        order = np.argsort(g0, kind="stable")
        first_out = g0[order[most]]
        P = np.sort(order[:most][g0[order[:most]] < first_out])
        return P if P.size else None

    @classmethod
    def of(cls, nodes, method: str):
        """The candidates of ``nodes`` (3D contact vertices, ``contact_solver = "auto"``) for a factor ``method`` (at
        most :meth:`most`), or None where their gaps do not rank them (module docs)."""
        d = nodes.d
        if d.dim != 3 or nodes.B is not None or d.numerics.contact_solver != "auto":
            return None
        P = cls.choose(nodes.g0, cls.most(d.ndof, method))
        return None if P is None else cls(nodes, P)

    #: The candidates' dense work against the factor's: as many points as a dense Cholesky factor of this many
    #: back-substitutions' cost (:func:`~workbench.schemes.halfspace.dense_points`).
    backsubs = 1.0

    @classmethod
    def most(cls, ndof: int, method: str) -> int:
        """The most candidates for a factor ``method`` of ``ndof`` dofs. Keeping them last costs the factorization
        more than their dense block's flops: measured on the hemisphere at 47k dofs (1.13 s without), 1.33, 1.47,
        1.70 and 2.34 s for 500, 1000, 1500 and 2500 points.

        >>> [Candidates.most(n, "pardiso") for n in (11_865, 46_938, 193_464)]
        [863, 1590, 2985]
        """
        return dense_points(ndof, method, cls.backsubs)

    @staticmethod
    def attrs(candidates) -> dict:
        """The run's attributes: how many candidates its steps solved on (0: none), and whether the contact zone
        outgrew them (1: the coupled solver took over)."""
        if candidates is None or not candidates.kept:
            return {"contact_candidates": 0, "contact_candidates_missed": 0}
        return {"contact_candidates": int(candidates.P.size), "contact_candidates_missed": int(candidates.missed)}

    def operator(self, solver):
        """(the candidates' condensed stiffness, the solve in parts around them, the active set's scale rho) from
        ``solver``'s factorization, which keeps them last (asked before any solve), or None where it cannot."""
        if self.missed:
            return None
        found = solver.kept(self.nodes.C[self.P])
        if found is None:
            return None
        stiffness, split = found
        self.kept = True
        compliance = inverse(stiffness)  # (the active set's systems on the forces: ContactNodes)
        return stiffness, split, 100.0 / np.diag(stiffness), compliance  # (rho: the condensed solver's)

    def equilibrium(self, operator, rhs: np.ndarray, u: np.ndarray, time: float):
        """u (in place) for the load ``rhs`` with the inequality solved on the candidates; the active-set iterations,
        or None where a point of Q meets the foundation (then ``missed``, and the nodes' states and forces are those
        found, as the coupled solver's start)."""
        if self.missed:
            return None
        stiffness, split, rho, compliance = operator
        nodes, P, Q = self.nodes, self.P, self.Q
        sub = nodes.subset(P)
        sub.compliance = compliance
        u_C = split.free_displacement(rhs)  # (u at C[P] with nothing acting there)
        free = nodes.sign * u_C - (sub.g0 if sub.g0 is not None else 0.0)
        s, lam, iterations = sub.solve(stiffness, rho, free, time, u)
        if sub.g0 is not None:
            s = s + sub.g0
        split.expand(nodes.sign * s, u)
        states, forces = np.full(nodes.size, SEPARATED), np.zeros(nodes.size)
        states[P], forces[P] = sub.states, sub.lam
        # Q's own states under no force: separated wherever it does not reach the foundation (state_of at lam = 0)
        states[Q] = nodes.layer.state_of(nodes.distance(u)[Q], np.ones(Q.size) * nodes.w[Q])
        nodes.states, nodes.lam = states, forces
        if np.any(states[Q] != SEPARATED):
            self.missed = True
            return None
        return iterations


def inverse(A: np.ndarray) -> np.ndarray:
    """The inverse of the symmetric positive definite A from its Cholesky factor (LAPACK's potri: a third of the
    work of solving with the identity; at 1590 points 0.12 s against 0.45 s).

    >>> inverse(np.array([[2.0, 1.0], [1.0, 2.0]])).round(6).tolist()
    [[0.666667, -0.333333], [-0.333333, 0.666667]]
    """
    potrf, potri = la.get_lapack_funcs(("potrf", "potri"), (A,))
    factor, info = potrf(A, lower=True, clean=False, overwrite_a=False)
    if info == 0:
        factor, info = potri(factor, lower=True, overwrite_c=True)
    if info != 0:
        raise la.LinAlgError(f"the candidates' condensed stiffness is not positive definite (LAPACK info {info})")
    n, block = len(factor), 256  # (the upper triangle from the lower one, a band of rows at a time: no n x n temporary)
    for i in range(0, n, block):
        factor[i:i + block, i + block:] = factor[i + block:, i:i + block].T
        diagonal = factor[i:i + block, i:i + block]
        upper = np.triu_indices(len(diagonal), 1)
        diagonal[upper] = diagonal.T[upper]
    return factor
