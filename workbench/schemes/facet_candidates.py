"""Model A's implicit steps on the part of a curved contact side it reaches first (``contact_solver = "auto"``).

The counterpart of :mod:`workbench.schemes.candidates` for a normal compliance (``scheme = "implicit"`` or
``"bdf2"``). A curved body (the Hertz hemisphere, a body from a mesh file) comes into contact where its initial gap
is smallest, and the zone grows outward through the side's facets in that order. The compliance acts at the side's
quadrature points, each on the dofs of its facet, so the candidates are facets: those of smallest gap, as many as
their dofs P fit :meth:`~workbench.schemes.candidates.Candidates.most`, and every other point whose traces lie within
P. The step's factorization keeps P last (PARDISO's Schur complement: their condensed stiffness, and solves in two
parts around them), and a step is then

* the free displacement at P from the first part of one solve;
* the coupled solver's semismooth Newton (:class:`~workbench.discrete.condensation.CoupledNewton`, the same
  iteration as on the whole side) on P's points alone, its products with the compliance dense
  (:class:`~workbench.discrete.condensation.DenseSchur`) instead of one back-substitution each;
* u everywhere from the second part.

That u is the whole body's, so the assumption is checked exactly: where the compliance is zero at every other point
Q of the side, the forces found on P solve the whole step. Where it is not, and dense work on every contact dof is
affordable (as many as twice the condensed solver's rule for Model B, :meth:`of`), P becomes every contact dof, the
factorization is made again keeping them, and the step is solved on them (a cylinder segment on its side from a mesh
file, 59k dofs, 2238 of 2973 contact vertices in contact: 18.5 s against 33.8 s for the coupled solver alone, and
46.1 s when it took over after the miss). Else the step is solved again on the whole side by the coupled solver,
and the candidates are given up for the run.

Not for a glue or a friction (their forces act on the whole bonded side, not where it touches), a flat side (every
gap equal: nothing tells the points apart), a moving clamp, several processes, or a solver that cannot keep dofs
last (the banded and iterative ones).

Model A's step operator a0 K_A + K_G changes with the step. Where A = tau G (the Hertz scenes), every operator is a
multiple of K_G, and K_G's one factorization, keeping the candidates, serves them all
(:class:`~workbench.schemes.step_operators.SharedFactor`): every step is the candidates', under error control too.
Where A is no multiple of G, each operator has its own factorization, and one that keeps the candidates costs
about twice a plain one. Under error control, which factors often, they then stay out: measured on the hemisphere
at 47k dofs with BDF2 at rtol = 1e-3 before the factor was shared (389 solves, 67 factorizations), 230 s with the
candidates against 228 s without (the factorizations 154 against 78 s, the rest 76 against 149 s), a tie.

For the same reason a run of fixed steps with a factor per operator keeps them in the factorization of its own
operator, the a0 of a step k after steps of k (:mod:`workbench.schemes.step_operators`). Its other operators (a
landing on a snapshot off the grid, BDF2's first step and the step after each change of size) serve a step or two
each, and those steps are the coupled solver's on a plain factor, until one of them has served
``StepOperators.RENT_STEPS`` steps; its factorization is then made again keeping the candidates. On ``hertz3d`` with
BDF2 (five operators, 52 steps), before its operators shared one factor, that took the run from 46.6 to 37.1 s at
47k dofs and, with the own operator dropped last from a cache of two, from 264.7 to 137.3 s at 106k
(docs/schemes.md, "The candidates kept for the run's own operator").

Measured with fixed steps on the hemisphere (``hertz3d`` at its defaults, 52 steps of backward Euler;
``python studies/model_a_candidates.py``, docs/schemes.md, "Model A's implicit steps on candidate facets"), one
factorization of K_G serving both of the run's operators: at 47k dofs 19.5 s against 53.9 s for the coupled solver on
the whole side, at 106k 54.9 s against 156.9 s, at 193k (where the zone outgrows the candidates in the last steps)
219.4 s against 364.2 s; equal to 5e-10. With a factorization per operator (061b3ac) the same study gave 23.2 s
against 49.0 s, 74.6 s against 140.0 s and 420 s against 487 s.
"""
from __future__ import annotations

import numpy as np

from ..discrete.condensation import CoupledNewton, DenseSchur
from ..physics.ops import NP
from .candidates import Candidates
from .halfspace import dense_points


class FacetCandidates:
    """The contact dofs of the facets of smallest initial gap, solved on with a dense compliance, and the other
    quadrature points checked (module docs).

    Parameters
    ----------
    op : ContactOperator
        The whole side's.
    cols : array of int
        The candidates P, positions among ``op.C``.
    points : array of int
        The side's quadrature points whose traces lie within P; the others are checked after each step.
    """

    def __init__(self, op, cols: np.ndarray, points: np.ndarray, whole: bool = False):
        self.op = op
        self._choose(cols, points)
        #: Whether every contact dof is affordable, should the zone outgrow P (:meth:`of`).
        self.whole = whole
        #: Whether the compliance acted beyond P where every dof was not affordable: the coupled solver on the whole
        #: side from then on.
        self.missed = False
        #: The most dofs a factorization kept (0: none, the solver cannot).
        self.kept = 0

    def _choose(self, cols: np.ndarray, points: np.ndarray) -> None:
        """P = op.C[cols] and its points; the others Q, whose compliance each step checks."""
        op = self.op
        self.C, self.sub = op.C[cols], op.subset(cols, points)
        others = np.setdiff1d(np.arange(op.side.T_nu.shape[0]), points)
        side = op.d.side  # (the traces on the whole dof vector)
        self.T_Q = side.T_nu[others].tocsr() if others.size else None
        self.gap_Q = side.gap0[others] if others.size else None

    @classmethod
    def of(cls, d, op, method: str, coupled: bool, shared: bool = False):
        """The candidates of the contact operator ``op`` where ``auto`` took the coupled solver (``coupled``) on a
        curved 3D side with a normal compliance alone, for a factor ``method`` (as many dofs as
        :meth:`Candidates.most` for the run's steps T / k; ``whole`` where the side's dofs are at most twice
        ``dense_points(ndof, method, 3)``); else None. Under error control only where the step operators share one
        factor (``shared``, :class:`~workbench.schemes.step_operators.SharedFactor`): Model A's step operator
        changes with the step, and a factorization of its own that keeps the candidates costs about twice a plain
        one, for the few steps each then serves (module docs)."""
        n = d.numerics
        if (not coupled or op is None or d.dim != 3 or op.tangential or d.beta is not None or d.moves_clamp
                or n.contact_solver != "auto" or op.side.gap0 is None or (n.adaptive and not shared)):
            return None
        steps = np.inf if n.adaptive else n.T / n.k  # (error control takes many steps, as a rule: the upper bound)
        chosen = cls.choose(op.side.T_nu, op.side.element, op.side.gap0, Candidates.most(d.ndof, method, steps))
        # (every dof where the dense work on them is what the condensed solver's rule affords Model B: twice it)
        return None if chosen is None else cls(op, *chosen, whole=op.size <= 2 * dense_points(d.ndof, method, 3.0))

    @staticmethod
    def choose(T, element: np.ndarray, gap: np.ndarray, most: int):
        """(cols, points): the columns of ``T`` (the points' traces on the contact dofs) on the facets of smallest
        gap (a facet's: its points' least ``gap``; ``element``: each point's facet), as many as fit in ``most``
        without splitting a set of facets of equal gap, and every point whose traces lie within them; every column
        and point where all fit; None where none does.

        >>> import scipy.sparse as sp
        >>> T = sp.csr_matrix(np.array([[1, 1, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1.0]]))  # three facets on a line
        >>> [a.tolist() for a in FacetCandidates.choose(T, np.arange(3), np.array([0.2, 0.0, 0.1]), 3)]
        [[1, 2, 3], [1, 2]]
        >>> FacetCandidates.choose(T, np.arange(3), np.zeros(3), 3) is None  # (equal gaps: all or none)
        True
        """
        facets = int(element.max()) + 1
        facet_gap = np.full(facets, np.inf)
        np.minimum.at(facet_gap, element, gap)
        order = np.argsort(facet_gap, kind="stable")
        rank = np.empty(facets, dtype=np.int64)
        rank[order] = np.arange(facets)
        T = T.tocoo()
        on = T.data != 0
        rows, cols = T.row[on], T.col[on]
        first = np.full(T.shape[1], facets)  # (the rank of the first facet, in gap order, that reaches a column)
        np.minimum.at(first, cols, rank[element[rows]])
        within = np.cumsum(np.bincount(first[first < facets], minlength=facets))  # columns of the first r + 1 facets
        if within[-1] <= most:
            return np.arange(T.shape[1]), np.arange(T.shape[0])
        r = int(np.searchsorted(within, most, side="right")) - 1
        if r < 0:
            return None
        taken = facet_gap < facet_gap[order[r + 1]]
        if not taken.any():
            return None
        inside = np.zeros(T.shape[1], dtype=bool)
        inside[cols[taken[element[rows]]]] = True
        beyond = np.bincount(rows, weights=~inside[cols], minlength=T.shape[0])
        return np.nonzero(inside)[0], np.nonzero(beyond == 0)[0]

    def operator(self, solver, again: bool = False):
        """[the solve in parts around P, the Newton iteration on P, ``solver``] from ``solver``'s factorization,
        which keeps P last (asked before any solve, or ``again``: the factorization made anew); None where it
        cannot. A list: :meth:`step` renews it in place where P has grown since."""
        if self.missed:
            return None
        found = solver.kept(self.C, again)
        if found is None:
            return None
        stiffness, compliance, split = found
        self.kept = max(self.kept, self.C.size)
        schur = DenseSchur(stiffness, compliance)  # (also the springs' exact preconditioner, in the half-space's place)
        return [split, CoupledNewton(schur, self.sub, halfspace=schur), solver]

    def step(self, operator, rhs: np.ndarray, u: np.ndarray, guess, time: float, label: str = ""):
        """du of the step M du + j(u + du, .) = ``rhs`` solved on P from ``guess(C)`` (u at the dofs C), or None
        where the compliance then acts beyond P and every dof is not affordable (``missed``; where it is, P becomes
        every contact dof, the operator's factorization is made again keeping them, and the step is solved on
        them)."""
        if operator[1].op is not self.sub:  # (made for the candidates before they grew to every dof)
            operator[:] = self.operator(operator[2], again=True) or [None, None, None]
            if operator[0] is None:
                self.missed = True
                return None
        split, newton, _ = operator
        newton.iterations = newton.linear_iterations = 0
        z_C, u_C = u[self.C] + newton.schur.compliance @ split.condensed_load(rhs), guess(self.C)
        newton.solve(u_C, z_C, time, label)
        du = np.zeros_like(u)
        split.expand(u_C - u[self.C], du)
        if self.T_Q is None or not np.any(self.op.contact.normal(NP, self.T_Q @ (u + du), None, self.gap_Q)):
            return du
        if self.whole:
            self._choose(np.arange(self.op.size), np.arange(self.op.side.T_nu.shape[0]))
            return self.step(operator, rhs, u, guess, time, label)
        self.missed = True
        return None
