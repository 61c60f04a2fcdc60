"""The contact problem of an implicit step on a body distributed over MPI processes: solved on rank 0's serial view.

The contact unknowns are few (the contact dofs D: n^(1/2) of n dofs in 2D, n^(2/3) in 3D) and their solvers (the
condensed and coupled semismooth Newton, Model B's active sets) are sequential iterations on them. So rank 0 runs
them unchanged on its serial view of the body (:class:`workbench.parallel.order.Shell`), and every product with
K^-1 they ask for is a collective solve of the distributed operator: rank 0 broadcasts the right-hand side on D,
every rank puts its part in (a shared dof on its owner alone: right-hand sides are distributed), the ranks solve
together, and the result on D is gathered back to rank 0 by the owners. Meanwhile ranks 1 ... N-1 wait in
:meth:`DistributedExchange.run` for the next right-hand side, until rank 0 says the contact solve is over and sends
its result. A contact solve therefore costs what it costs on one process, plus one broadcast and one gather of |D|
numbers a back-substitution.
"""
from __future__ import annotations

import numpy as np

from ..discrete.exchange import Exchange
from .algebra import cumulate, owned
from .order import Order


class DistributedExchange(Exchange):
    """The contact dofs D between the ranks' parts of a body and rank 0's serial view (module docs)."""

    def __init__(self, d):
        self.d, self.w, self.shell = d, d.world, d.shell
        self.solves = self.w.root
        self.view = self.shell.disc if self.w.root else None
        self.comm = self.w.comm

    def bind(self, dofs) -> "DistributedExchange":
        d, shell = self.d, self.shell
        self.dofs = np.asarray(self.w.bcast(np.unique(np.asarray(dofs, dtype=np.int64)) if self.solves else None))
        serial = shell.dofs.index  # (the serial number of each of shell.local_dofs)
        on = np.isin(serial, self.dofs)
        self.local = shell.local_dofs[on]
        self.position = np.searchsorted(self.dofs, serial[on])
        self.mine = owned(d.fes)[self.local]
        self.order = Order(self.comm, self.position, send=self.mine, size=self.dofs.size, what="contact dof")
        return self

    def _full(self, values):
        """A vector of the view with ``values`` on D (rank 0), else None."""
        if values is None:
            return None
        out = np.zeros(self.view.ndof)
        out[self.dofs] = values
        return out

    def gather(self, vector: np.ndarray):
        return self._full(self.order.gather(np.asarray(vector)[self.local]))

    def _on_d(self, vector):
        """The values on D of rank 0's ``vector``, on every rank."""
        return self.w.bcast(np.asarray(vector)[self.dofs] if self.solves else None)

    def _rhs(self, values: np.ndarray) -> np.ndarray:
        out = np.zeros(self.d.ndof)
        out[self.local[self.mine]] = values[self.position[self.mine]]
        return out

    def spread(self, vector) -> np.ndarray:
        return self._rhs(self._on_d(vector))

    def put(self, vector: np.ndarray, values) -> None:
        vector[self.local] = self._on_d(values)[self.position]

    def share(self, obj):
        return self.w.bcast(obj)

    def run(self, solve, solver):
        if not self.solves:
            while True:  # (serve rank 0's back-substitutions until it says the contact solve is over)
                values = self.comm.bcast(None, root=0)
                if values is None:
                    break
                self._solve(solver, values)
            failed = self.comm.bcast(None, root=0)
            if failed is not None:
                raise failed
            return None
        try:
            result, failed = solve(), None
        except Exception as err:  # (every rank raises it: one alone would leave the others waiting)
            result, failed = None, err
        self.comm.bcast(None, root=0)
        self.comm.bcast(failed, root=0)
        if failed is not None:
            raise failed
        return result

    def _solve(self, solver, values: np.ndarray):
        """Every rank's part of the collective solve with the right-hand side ``values`` on D: the solution on D,
        gathered on rank 0."""
        out = np.zeros(self.d.ndof)
        solver.solve(self._rhs(values), out)
        return self.order.gather(out[self.local])

    def proxy(self, solver):
        return _Proxy(self, solver) if self.solves else None

    def diagonal(self, mat) -> np.ndarray:
        from ..discrete import solvers

        local = solvers.to_scipy(mat.local_mat).diagonal()
        return self.gather(cumulate(self.d.u.vec.CreateVector(), local))

    def sync_beta(self) -> None:
        d, view = self.d, self.view
        if d.beta is None:
            return
        beta = self.shell.facets.gather(d.beta.vec.FV().NumPy()[d.beta_dofs])
        if view is not None:
            view.beta.vec.FV().NumPy()[view.beta_dofs] = beta


class _Proxy:
    """On rank 0: the distributed solver of a step's operator on vectors of the view, right on D (the other ranks
    serve in :meth:`DistributedExchange.run`)."""

    def __init__(self, exchange: DistributedExchange, solver):
        self.exchange, self.solver = exchange, solver
        self.name, self.warm_start, self.iterative = solver.name, solver.warm_start, solver.iterative

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        x = self.exchange
        values = np.ascontiguousarray(rhs[x.dofs])
        x.comm.bcast(values, root=0)
        out[:] = x._full(x._solve(self.solver, values))

    def solve_many(self, R: np.ndarray) -> np.ndarray:
        out = np.zeros_like(R)
        for j in range(R.shape[1]):
            self.solve(R[:, j], out[:, j])
        return out

    def approximate_compliance(self, C: np.ndarray):
        return None  # (the distributed solvers form none)

    def condensed_stiffness(self, C: np.ndarray, B=None):
        """None: a distributed body's matrix is nowhere whole, so the condensed stiffness is made by solves."""
        return None
