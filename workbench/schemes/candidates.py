"""Model B's condensed solver on the contact points a curved body reaches first (``contact_solver = "auto"``).

A body whose gap to the foundation grows away from where it first touches (the Hertz indenters, a curved body from a
mesh file) comes into contact at the points of smallest initial gap first. :class:`Candidates` keeps those points P
last in the step's factorization: the factor then gives their condensed stiffness (PARDISO's Schur complement) and
solves in two parts around them, and a step is the condensed solver's: the free displacement at P from the first
part, the inequality solved densely on P with the other points Q held apart, and u everywhere from the second part,
one solve's work in all. That u is the whole body's, so the assumption is checked exactly: where no point of Q then
meets the foundation, the forces found on P (and none on Q) solve the whole inequality. Where one does, the
factorization is made again keeping every point, where the condensed solver affords them all and their dense work
costs less than the coupled solver's steps left, and the step solved on them; else the step is solved again by the
coupled solver (one more back-substitution for the free displacement, warm started from the forces found on P), and
the candidates are given up for the run.

Measured on the hemisphere from rest to the full load in 4 steps (docs/schemes.md, "The candidate points"): at 47k
dofs, with 5186 contact vertices and 1182 in contact at the end, the 1590 candidates cost the factorization about
0.6 s more, and the run then took 5 solves in two parts and 29 dense active-set iterations, against 76
back-substitutions (54 of them conjugate gradient iterations) and the half-space model's dense work: 4.89 s against
6.48 s in one run of each. At 106k and 193k dofs the zone outgrows those 4 steps' candidates in the last steps, and
their factorization's extra cost is paid for fewer cheap steps: 11 % less and 10 % more time than the coupled solver
alone. A run of more steps affords more candidates (:meth:`Candidates.most`): in 16 steps they hold at all three
sizes, the runs take 0.59, 0.56 and 0.41 of the coupled solver's time, and a step's cost grows with slope 1.18
against the dofs (1.50 for the coupled solver).

>>> import numpy as np
>>> Candidates.choose(np.array([0.3, 0.0, 0.1, 0.1, 0.2]), 3).tolist()  # the smallest gaps, ties kept together
[1, 2, 3]
>>> Candidates.choose(np.array([0.3, 0.0, 0.1, 0.1, 0.2]), 2).tolist()  # (0.1 twice: only the first fits)
[1]
>>> Candidates.choose(np.zeros(5), 3) is None  # a flat side: the gaps do not tell which points touch first
True
>>> Candidates.choose(np.zeros(5), 5).tolist()  # (unless every point fits)
[0, 1, 2, 3, 4]
"""
from __future__ import annotations

import numpy as np

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

    def __init__(self, nodes, P: np.ndarray, whole: float = 0.0):
        self.nodes, self.P = nodes, np.asarray(P)
        #: What every point's dense work costs, in back-substitutions, where the condensed solver affords them all
        #: should the zone outgrow the candidates (:meth:`of`); 0 where it does not (:meth:`_grows`).
        self.whole = whole
        #: Whether a point of Q met the foundation where every point was not affordable: the coupled solver takes
        #: over for the run.
        self.missed = False
        #: The most candidates a factorization kept (0: none; a solver that cannot, banded or iterative, leaves the
        #: coupled solver).
        self.kept = 0

    @staticmethod
    def choose(g0, most: int):
        """The points of the ``most`` smallest gaps g0, without splitting a set of equal gaps (so no point left out
        lies nearer than one kept), sorted (every point where ``most`` allows, none checked then); None where that
        leaves none."""
        if g0 is None or most < 1 or len(g0) == 0:
            return None
        if most >= len(g0):
            return np.arange(len(g0))
        order = np.argsort(g0, kind="stable")
        first_out = g0[order[most]]
        P = np.sort(order[:most][g0[order[:most]] < first_out])
        return P if P.size else None

    @classmethod
    def of(cls, nodes, method: str):
        """The candidates of ``nodes`` (3D contact vertices, ``contact_solver = "auto"``) for a factor ``method`` (at
        most :meth:`most` for the run's steps T / k, many under error control), or None where their gaps do not
        rank them (module docs)."""
        d = nodes.d
        if d.dim != 3 or nodes.B is not None or d.numerics.contact_solver != "auto":
            return None
        n = d.numerics
        steps = np.inf if n.adaptive else n.T / n.k  # (error control takes many steps, as a rule: the upper bound)
        P = cls.choose(nodes.g0, cls.most(d.ndof, method, steps))
        # (every point, with the smaller of its two systems (ContactNodes._state_solution), costs the condensed solver
        # at most an eighth of the dense work of condensed_up_to's rule: twice its points)
        whole = cls.growth * (nodes.size / dense_points(d.ndof, method, 1.0)) ** 3 \
            if nodes.size <= 2 * dense_points(d.ndof, method, 3.0) else 0.0
        return None if P is None else cls(nodes, P, whole)

    #: A coupled step's back-substitutions, and the dense work of every point (the factorization keeping them, their
    #: compliance, the active set on them) in their dense Cholesky factor's (:meth:`_grows`).
    coupled_step, growth = 20.0, 8.0

    def _grows(self, time: float) -> bool:
        """Whether the zone that outgrew the candidates at ``time`` is solved on every point from then: where the
        condensed solver affords them (``whole``) and their dense work costs less than the coupled solver's steps
        left. Measured on the hemisphere at 106k dofs (6410 points, 2286 candidates, outgrown in the last of 4
        steps): every point took the run to 25.0 s, against 14.6 s for the coupled solver alone; their dense work
        was about 170 back-substitutions, 8 times their Cholesky factor's 22."""
        if not self.whole:
            return False
        n = self.nodes.d.numerics
        left = np.inf if n.adaptive else max(1.0, (n.T - time) / n.k + 1.0)
        return self.whole <= self.coupled_step * left

    #: As many candidates as a dense Cholesky factor of this many back-substitutions' cost
    #: (:func:`~workbench.schemes.halfspace.dense_points`) per this many steps, within these bounds (:meth:`most`).
    backsubs, steps_per_backsub = (1.0, 4.0), 4.0

    @classmethod
    def most(cls, ndof: int, method: str, steps: float) -> int:
        """The most candidates for a factor ``method`` of ``ndof`` dofs and a run of about ``steps`` steps. Keeping
        them last costs the factorization more than their dense block's flops (measured on the hemisphere at 47k
        dofs, 1.13 s without, 1.33, 1.47, 1.70 and 2.34 s for 500, 1000, 1500 and 2500 points), once; a step they
        hold costs a solve and dense work, where the coupled solver's takes about 20 back-substitutions. So a run of
        more steps affords more of them, and more of them hold a larger zone: from one back-substitution's worth at
        4 steps to four at 16 and more (docs/schemes.md, "The candidate points").

        >>> [Candidates.most(n, "pardiso", 4) for n in (11_865, 46_938, 193_464)]
        [863, 1590, 2985]
        >>> Candidates.most(193_464, "pardiso", 16)
        4738
        """
        least, largest = cls.backsubs
        return dense_points(ndof, method, float(np.clip(steps / cls.steps_per_backsub, least, largest)))

    @staticmethod
    def planned(count: int) -> dict:
        """The preflight record: how many candidates (points, or dofs on facets) the steps try first, where any."""
        return {"contact_candidates_planned": int(count)} if count else {}

    @staticmethod
    def attrs(candidates) -> dict:
        """The run's attributes: how many candidates its steps solved on (0: none), and whether the contact zone
        outgrew them (1: the coupled solver took over)."""
        if candidates is None or not candidates.kept:
            return {"contact_candidates": 0, "contact_candidates_missed": 0}
        return {"contact_candidates": candidates.kept, "contact_candidates_missed": int(candidates.missed)}

    def operator(self, solver, again: bool = False):
        """The candidates' operator from ``solver``'s factorization, which keeps them last (asked before any solve,
        or ``again``: the factorization made anew): [the points P, their condensed stiffness, the solve in parts
        around them, the active set's scale rho, their compliance, the solver]; or None where it cannot. A list: it
        grows in place (:meth:`equilibrium`)."""
        if self.missed:
            return None
        return self._keep(solver, self.P, again)

    def _keep(self, solver, P, again: bool = False):
        found = solver.kept(self.nodes.C[P], again)
        if found is None:
            return None
        stiffness, compliance, split = found  # (the compliance: the active set's systems on the forces, ContactNodes)
        self.kept = max(self.kept, P.size)
        return [P, stiffness, split, 100.0 / stiffness.diagonal(), compliance, solver]  # (rho: the condensed solver's)

    def equilibrium(self, operator, rhs: np.ndarray, u: np.ndarray, time: float):
        """u (in place) for the load ``rhs`` with the inequality solved on the candidates; the active-set iterations,
        or None where a point of Q meets the foundation and the condensed solver does not afford every point (then
        ``missed``, and the nodes' states and forces are those found, as the coupled solver's start). Where it does,
        the operator's factorization is made again keeping every point, and the step solved on them."""
        if self.missed:
            return None
        if not operator[2].holds():  # (its factor, shared, made again keeping every point for another operator)
            grown = self._keep(operator[5], np.arange(self.nodes.size), again=True)
            if grown is None:
                self.missed = True
                return None
            operator[:] = grown
        P, stiffness, split, rho, compliance, solver = operator
        nodes, Q = self.nodes, np.setdiff1d(np.arange(self.nodes.size), P)
        sub = nodes.subset(P)
        sub.compliance = compliance
        u_C = compliance @ split.condensed_load(rhs)  # (u at C[P] with nothing acting there)
        free = nodes.sign * u_C - (sub.g0 if sub.g0 is not None else 0.0)
        s, lam, iterations = sub.solve(stiffness, rho, free, time, u)
        if sub.g0 is not None:
            s = s + sub.g0
        split.expand(nodes.sign * s, u)
        states, forces = np.full(nodes.size, SEPARATED), np.zeros(nodes.size)
        states[P], forces[P] = sub.states, sub.lam
        # Q's own states under no force: separated wherever it does not reach the foundation (state_of at lam = 0)
        states[Q] = nodes.layer.state_of(nodes.distance(u)[Q], nodes.w[Q])
        nodes.states, nodes.lam = states, forces
        if not np.any(states[Q] != SEPARATED):
            return iterations
        grown = self._keep(solver, np.arange(nodes.size), again=True) if self._grows(time) else None
        if grown is not None:  # (every point then: no check left, and the step again from its start)
            operator[:] = grown
            return self.equilibrium(operator, rhs, u, time)
        self.missed = True
        return None

