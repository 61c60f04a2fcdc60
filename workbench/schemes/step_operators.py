"""The step operators of the implicit schemes, factored once per key and cached: a0 K_A + K_G per a0 for Model A
(:class:`~workbench.schemes.implicit_euler.ImplicitEuler` and BDF2), K_A + sum_i w_i K_Ci per tuple of the memory
terms' weights w for Model B (:class:`~workbench.schemes.memory_vi.MemoryVI`: one operator, K_A, unless the memory
rule is the trapezoid).

A run of fixed steps k mostly meets one operator, its own: a0 of a step k after steps of k (1/k for backward Euler,
3/(2k) for BDF2). It meets others too, each for a step or two: a landing on a snapshot off the grid, BDF2's first
step (backward Euler) and the step after each change of size. Two choices follow from that.

* Where the cache holds fewer operators than the run meets (large factors: ``solvers.factors_kept``), the run's own
  is dropped last, so a landing does not cost it a factorization again. BDF2 on the hemisphere at 106k dofs holds
  two and meets five; its own was factored three times before.
* The contact candidates (:mod:`~workbench.schemes.facet_candidates`) are kept in the own operator's factorization
  at once. Keeping them costs a factorization about twice a plain one, and their compliance's inverse. Another
  operator's steps are the coupled solver's on a plain factor until it has served :attr:`StepOperators.RENT_STEPS`;
  its factorization is then made again keeping them. The rule is the ski rental's: an operator that serves a landing
  or two stays plain, and one that keeps serving costs at most about twice the better choice.

Where every operator is a multiple of one matrix (a body with A = tau G, :class:`SharedFactor`), both choices fall
away: one factorization, keeping the candidates, serves every operator.
"""
from __future__ import annotations

from collections import Counter, OrderedDict
from dataclasses import dataclass

import numpy as np

from ..discrete import solvers
from .base import make_room


@dataclass
class StepOperator:
    """One factored operator: the matrix ``M`` (None where a shared factor serves it and nothing else needs it), its
    ``solver``, the contact solver ``newton`` on it, the solve in parts around the contact dofs (``split``, the
    condensed solver's), and the candidates' operator (``kept``, None where the factorization does not keep them)."""

    M: object
    solver: object
    newton: object = None
    split: object = None
    kept: list | None = None
    #: The a0 it was built from (:meth:`StepOperators.state`; Model B: the tuple of weights).
    a0: float | tuple = 0.0


class StepOperators:
    """The factored operators of one run, one per key of a0 (:meth:`key`), at most ``size`` of them: the least
    recently used dropped first, the run's own (``own``, its key; None under error control, where no step size
    stands out) last. :meth:`get`'s ``build(a0, keep)`` makes a :class:`StepOperator`, keeping the contact
    ``candidates`` where ``keep`` (None: the run has none). It is given to each call, not held: the scheme holds its
    operators, and their holding its method back would make a cycle, which only the garbage collector frees, with
    every factor in it (a session's next run then peaked with the last one's factors alive: 1219 MB against 873 MB
    for ``memory_hertz3d`` at 47k dofs after a factorization of the study's).

    The a0 each entry was built from is restart state (:meth:`state`). An entry serves every a0 of its key, so it is
    the operator of the a0 that first met the key (fixed steps of the uniform grid differ in the last bits); a
    restored one is that a0 alone until it is used, then built from it.

    >>> built = []
    >>> build = lambda a0, keep: built.append(a0) or StepOperator(a0, None)  # (M: a0 itself, to read back)
    >>> ops = StepOperators(2, StepOperators.key(50.0), None)
    >>> [ops.get(a0, build).M for a0 in (50.0, 100.0, 200.0, 50.0)], ops.state(), built
    ([50.0, 100.0, 200.0, 50.0], [200.0, 50.0], [50.0, 100.0, 200.0])
    """

    #: The step of an operator other than the run's own at which its factorization is made again keeping the
    #: candidates; its steps before are the coupled solver's. A step on the candidates saves a coupled step's
    #: back-substitutions; keeping them costs a factorization about twice a plain one and the compliance's inverse.
    #: On ``hertz3d`` the two balance after about 11 steps at 47k dofs and 12 at 106k (docs/schemes.md).
    RENT_STEPS = 10

    def __init__(self, size: int, own, candidates, shared: bool = False):
        self.size, self.own, self.candidates = size, own, candidates
        #: Whether the operators share one factor (:class:`SharedFactor`): each keeps the candidates then, at no
        #: factorization's cost.
        self.shared = shared
        self._entries = OrderedDict()
        self._rented = Counter()  # (steps of each operator on the coupled solver while the candidates are not kept)

    @staticmethod
    def key(a0: float | tuple) -> float | tuple:
        """``a0`` (or each number of a tuple) to 11 digits: a0 snapped to a grid by BDF2, and the steps of a uniform
        grid (t_n - t_(n-1) differs in the last bits), come back equal only to round-off.

        >>> StepOperators.key((0.024187090179797810, 0.0)) == StepOperators.key((0.024187090179797865, 0.0))
        True
        """
        if isinstance(a0, tuple):
            return tuple(float(f"{w:.11g}") for w in a0)
        return float(f"{a0:.11g}")

    def holds(self, a0: float) -> bool:
        """Whether the operator of ``a0`` is factored (else :meth:`get` factors it, and may drop another)."""
        return isinstance(self._entries.get(self.key(a0)), StepOperator)

    def get(self, a0: float, build) -> StepOperator:
        """The operator of ``a0`` for one more step, made by ``build`` where it is not held (a step of an operator
        that does not keep the candidates counts toward :attr:`RENT_STEPS`)."""
        key = self.key(a0)
        entry = self._entries.get(key)
        if not isinstance(entry, StepOperator):
            make_room(self._entries, self.size, key, keep=self.own)
            built_from = a0 if entry is None else entry
            self._entries[key] = build(built_from, self._keeps(key))
            self._entries[key].a0 = built_from
        self._entries.move_to_end(key)
        operator = self._entries[key]
        if operator.kept is None and self.candidates is not None and not self.candidates.missed:
            self._rent(key, operator)
        return operator

    def _keeps(self, key: float) -> bool:
        return self.candidates is not None and (self.shared or key == self.own
                                                or self._rented[key] >= self.RENT_STEPS)

    def _rent(self, key: float, operator: StepOperator) -> None:
        """One more step of ``operator`` on the coupled solver; at :attr:`RENT_STEPS`, its factorization is made
        again keeping the candidates, for this step and the rest."""
        self._rented[key] += 1
        if self._rented[key] == self.RENT_STEPS:  # (once: a factor that cannot keep them stays as it is)
            operator.kept = self.candidates.operator(operator.solver, again=True)

    def state(self) -> list:
        """The a0 each held operator was built from, least recently used first."""
        return [entry.a0 if isinstance(entry, StepOperator) else entry for entry in self._entries.values()]

    def restore(self, a0s: list) -> None:
        self._entries = OrderedDict((self.key(a0), float(a0)) for a0 in a0s)


class SharedFactor:
    """One factor of a matrix K for step operators that are all multiples of it, c K, each solved by K's solve scaled
    (:class:`solvers.Scaled`):

    * Model A, a Kelvin-Voigt body with A = tau G: a0 K_A + K_G = (a0 tau + 1) K_G (:meth:`of`);
    * Model B with the trapezoid rule and relaxation tensors C_i = f_i A: K_A + sum_i w_i K_Ci = (1 + sum_i w_i f_i)
      K_A (:meth:`of_memory`).

    The operators a run meets (BDF2's start, the landings, one per step size under error control) then cost one
    factorization. What that factorization gives about the contact dofs is scaled as well: the condensed solver's
    stiffness and solve in parts, and the contact candidates' (a factorization that keeps them last, made once:
    every operator keeps them then, also under error control). Not for an iterative solver or several processes.

    >>> import workbench
    >>> from workbench.discrete import discretisation
    >>> from workbench.schemes.implicit_euler import ImplicitEuler
    >>> d = discretisation.build(workbench.scene("hertz3d", h_contact=0.05, contact_solver="coupled"))
    >>> ImplicitEuler(d).shared.solver(50.0).c  # (A = tau G, tau = 0.05: a0 = 50 is 3.5 K_G)
    3.5
    """

    def __init__(self, d, matrix, scale):
        self.d, self.matrix, self.scale, self.factor = d, matrix, scale, None
        self.found = {}  # (what K's factorization gave about the contact dofs: solvers.Scaled)

    @staticmethod
    def _affords(d, method: str) -> bool:
        return d.world.size == 1 and method not in ("cg", "mixed")

    @classmethod
    def of(cls, d, method: str):
        """The shared factor of an implicit Model A scheme on ``d`` with the linear solver ``method`` (K_G; the key of
        an operator is its a0), or None where A is not a multiple of G, the solver is iterative or the run has
        several processes."""
        tau = d.model.viscous.multiple_of(d.model.elastic)
        if tau is None or not cls._affords(d, method):
            return None
        return cls(d, d.elastic.mat, lambda a0: a0 * tau + 1.0)

    @classmethod
    def of_memory(cls, d, method: str, trapezoid: bool):
        """The shared factor of Model B's ``trapezoid`` rule on ``d`` (K_A; the key of an operator is its tuple of
        the memory terms' weights w_i), or None where a relaxation tensor is not a multiple of A (or as :meth:`of`).
        The rectangle rule's operator is K_A alone."""
        factors = [C.multiple_of(d.model.elastic) for _, C, _ in d.memory] if d.memory else [None]
        if not trapezoid or None in factors or not cls._affords(d, method):
            return None
        return cls(d, d.elastic.mat, lambda weights: 1.0 + float(np.dot(weights, factors)))

    def solver(self, key) -> solvers.Scaled:
        """The solver of the operator of ``key`` (K factored at the first call that needs it)."""
        if self.factor is None:
            self.factor = self.d.step_factor(self.matrix)
        return solvers.Scaled(self.factor, self.scale(key), self.found)
