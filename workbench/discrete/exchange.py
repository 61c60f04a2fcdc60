"""Where the contact problem of an implicit step is solved, and how its unknowns get there and back.

The contact solvers (:mod:`workbench.discrete.condensation`, :mod:`workbench.schemes.contact_nodes`,
:mod:`workbench.schemes.coupled_contact`) work on the contact dofs D of the whole body, in its dof order, on a
discretisation that holds the contact side: the *view*. Their products with K^-1 are back-substitutions whose
right-hand sides live on D and whose results are read on D.

An :class:`Exchange` carries the values on D between the body and the view. On one process (this class) the body is
the view and every method hands its argument through. On several MPI processes
(:class:`workbench.parallel.contact.DistributedExchange`) rank 0's serial view of the body solves the contact
problem while the other ranks serve its back-substitutions, and the values on D are gathered to rank 0 and sent back
out. The schemes call these methods and never ask which they have.

Examples
--------
>>> import numpy as np, workbench
>>> from workbench.discrete import discretisation
>>> d = discretisation.build(workbench.scene("tp4", h=0.25))
>>> x = d.exchange().bind(np.array([3, 5]))
>>> u = np.arange(d.ndof, dtype=float)
>>> x.solves, x.view is d, x.gather(u) is u, x.run(lambda: 7, solver=None)
(True, True, True, 7)
"""
from __future__ import annotations

import numpy as np


class Exchange:
    """The contact dofs D of a body on one process: the body is the view, and every value is where it is needed."""

    #: Whether this process runs the contact solver (it holds the view).
    solves = True

    def __init__(self, d):
        self.d = self.view = d
        self.dofs = np.zeros(0, dtype=np.int64)

    def bind(self, dofs) -> "Exchange":
        """Exchange the values on ``dofs`` (the view's dof numbers, known where the contact solver runs); returns
        self."""
        self.dofs = np.asarray(dofs, dtype=np.int64)
        return self

    def gather(self, vector: np.ndarray):
        """A dof vector of the body as a vector of the view, right on D (where the solver runs; None elsewhere)."""
        return vector

    def spread(self, vector) -> np.ndarray:
        """A right-hand side on D from where the solver runs (a vector of the view) as the body's right-hand side
        (each process its part of the sum)."""
        return vector

    def put(self, vector: np.ndarray, values) -> None:
        """``vector`` (the body's) takes ``values`` (a vector of the view, where the solver runs) on D."""
        if vector is not values:
            vector[self.dofs] = values[self.dofs]

    def share(self, obj):
        """``obj`` from where the solver runs, on every process."""
        return obj

    def run(self, solve, solver):
        """``solve()`` where the contact solver runs, and its result there (None elsewhere); the other processes
        meanwhile serve the back-substitutions of ``solver`` that ``proxy(solver)`` asks for, and raise what
        ``solve()`` raised."""
        return solve()

    def proxy(self, solver):
        """``solver`` as the contact solver sees it: on vectors of the view, right on D."""
        return solver

    def diagonal(self, mat) -> np.ndarray:
        """The diagonal of an assembled matrix of the body, as a vector of the view (right on D)."""
        from .condensation import matrix_diagonal

        return matrix_diagonal(mat)

    _diagonals = None  # (K_A's and K_G's, as operator_diagonal gathered them)

    def operator_diagonal(self, a0: float):
        """The diagonal of Model A's step operator a0 K_A + K_G, as a vector of the view (None where the contact
        problem is not solved), from K_A's and K_G's, gathered once (:meth:`diagonal` of each operator took 28 ms at
        47k dofs, 57 times in an error-controlled run)."""
        if self._diagonals is None:
            self._diagonals = tuple(self.diagonal(m) for m in (self.d.viscous.mat, self.d.elastic.mat))
        viscous, elastic = self._diagonals
        return None if viscous is None else a0 * viscous + elastic

    def sync_beta(self) -> None:
        """The view's bonding field takes the body's (it is the body's here)."""
        return None
