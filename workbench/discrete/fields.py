"""What a run records of whole fields, as operators on the dof vector taken once: the probe values, the cell means
of the strain (the P0 stress is linear in them; P1 bodies compute them from the cells' geometry at each call and
store no operator), the field at the edge midpoints (order >= 2).

Examples
--------
>>> import numpy as np, workbench
>>> from workbench.discrete import discretisation
>>> d = discretisation.build(workbench.scene("tp5", h=0.1))
>>> d.fields.probe_values().shape, d.fields.cell_strains(d.u.vec.FV().NumPy()).shape
((5, 2), (20, 3))
"""
from __future__ import annotations

from functools import cached_property

import ngsolve as ngs
import numpy as np

from ..physics import kelvin_voigt


def mesh_cells(mesh, dim):
    """Vertex indices (0-based) of every cell of an NGSolve mesh, shape (cell, dim + 1)."""
    ngm = mesh.ngmesh
    elems = {1: ngm.Elements1D, 2: ngm.Elements2D, 3: ngm.Elements3D}[dim]().NumPy()
    return np.array(elems["nodes"][:, : dim + 1], dtype=np.int64) - 1


def p1_gradients(X: np.ndarray) -> np.ndarray:
    """The gradients of the barycentric coordinates of simplices with vertices ``X`` (cell, vertex, x), shape (cell,
    x_b, vertex k): with J = [x_1 - x_0, ..., x_d - x_0] (rows), grad lambda_i is column i of J^-1 (i >= 1) and
    grad lambda_0 = -sum of them."""
    inverse = np.linalg.inv(X[:, 1:, :] - X[:, :1, :])  # (cell, b, i): d lambda_i / d x_b, i = 1..d
    return np.concatenate([-inverse.sum(axis=2, keepdims=True), inverse], axis=2)


def p1_strains(U: np.ndarray, cells: np.ndarray, gradients: np.ndarray) -> np.ndarray:
    """The strain per cell (cell, component in :data:`workbench.physics.kelvin_voigt.COMPONENTS` order) of the P1
    field with vertex values ``U`` (component, vertex), from :func:`p1_gradients`."""
    # d u_a / d x_b per cell: (cell, a, vertex k) @ (cell, k, b), batched (2x faster than the einsum, measured)
    G = np.matmul(U[:, cells].transpose(1, 0, 2), gradients.transpose(0, 2, 1))
    return np.stack([0.5 * (G[:, i, j] + G[:, j, i]) for i, j in kelvin_voigt.COMPONENTS[len(U)]], axis=1)


class FieldOperators:
    """The field operators of one discretisation ``d`` (module docs)."""

    def __init__(self, d):
        self.d = d

    @cached_property
    def probe_operator(self):
        """P with P u = u at the probe points, (probe, component) flattened: a point value is linear in the dofs of
        the cell that holds the point, so P is taken once through their unit vectors (a record then costs one small
        product: NGSolve's point evaluation cost 34 us a record at two probes, measured on tp5)."""
        import scipy.sparse as sp

        points = self.d.probe_points
        cells = {int(nr) for nr in np.atleast_1d(points["nr"])}
        dofs = sorted({j for nr in cells for j in self.d.fes.GetDofNrs(ngs.ElementId(ngs.VOL, nr)) if j >= 0})
        unit = ngs.GridFunction(self.d.fes)
        e = unit.vec.FV().NumPy()
        columns = []
        for j in dofs:
            e[:] = 0.0
            e[j] = 1.0
            columns.append(np.asarray(unit(points), dtype=float).ravel())
        P = np.stack(columns, axis=1)
        rows, cols = np.nonzero(P)
        return sp.csr_matrix((P[rows, cols], (rows, np.asarray(dofs)[cols])), shape=(P.shape[0], self.d.ndof))

    def probe_values(self) -> np.ndarray:
        """u at the probe points, shape (probe, component)."""
        return (self.probe_operator @ self.d.u.vec.FV().NumPy()).reshape(len(self.d.scene["probes"]), self.d.dim)

    @property
    def _p1(self) -> bool:
        """Whether the strain is constant per cell and taken from the cells' geometry (P1 vectors on straight
        simplices, 2D and 3D)."""
        d = self.d
        return d.dim > 1 and d.scene["order"] == 1 and d.ndof == d.dim * len(d.vertex_xyz)

    @cached_property
    def strain_operator(self):
        """E with (E u)[cell, c] = the mean over the cell of the strain component c (COMPONENTS order): the P0
        projection of eps(u), assembled once by NGSolve's mixed forms (any order, the rod; P1 bodies take the strain
        from the cells' geometry instead, :meth:`cell_strains`)."""
        return self._assembled_strains()

    @cached_property
    def _p1_gradients(self) -> np.ndarray:
        """The gradients of the barycentric coordinates per cell, shape (cell, x_b, vertex k): on a cell with vertices
        x_0..x_d and J = [x_1 - x_0, ..., x_d - x_0] (rows), grad lambda_i is column i of J^-1 (i >= 1) and
        grad lambda_0 = -sum of them."""
        d = self.d
        return p1_gradients(d.vertex_xyz[self.cells][:, :, :d.dim])

    def _p1_strains(self, u: np.ndarray) -> np.ndarray:
        """The P1 strain per cell, (cell, component), from the cells' vertex values and :attr:`_p1_gradients`; the
        displacement dof of vertex v, component a, is a * (vertices) + v (VectorH1). Nothing of the size of an
        operator is stored: on the block at 78k dofs, 0.11 s for the gradients once and 0.03-0.04 s a call, where the
        sparse operator took 0.5 s to make and 0.004 s a call, and 0.6 GB of the run's peak at 267k dofs (measured)."""
        d = self.d
        return p1_strains(np.asarray(u).reshape(d.dim, len(d.vertex_xyz)), self.cells, self._p1_gradients)

    def _assembled_strains(self):
        """The strain operator by NGSolve's mixed forms (any order, the rod)."""
        import scipy.sparse as sp

        q = ngs.L2(self.d.mesh, order=0)
        vol = ngs.LinearForm(q.TestFunction() * ngs.dx).Assemble().vec.FV().NumPy().copy()
        u, p = self.d.fes.TrialFunction(), q.TestFunction()
        eps = kelvin_voigt.strain(u, self.d.dim)
        blocks = []
        for i, j in kelvin_voigt.COMPONENTS[self.d.dim]:
            form = ngs.BilinearForm(trialspace=self.d.fes, testspace=q)
            form += (eps if self.d.dim == 1 else eps[i, j]) * p * ngs.dx
            form.Assemble()
            rows, cols, vals = form.mat.COO()
            M = sp.csr_matrix((np.asarray(vals), (np.asarray(rows), np.asarray(cols))), shape=(q.ndof, self.d.ndof))
            blocks.append(sp.diags(1.0 / vol) @ M)
        return [b.tocsr() for b in blocks]

    @cached_property
    def cells(self) -> np.ndarray:
        """The vertices (0-based) of every cell, shape (cell, dim + 1)."""
        return mesh_cells(self.d.mesh, self.d.dim)

    @cached_property
    def edges(self):
        """(edge vertex pairs, their midpoints as mesh points): where a field of order >= 2 is recorded beside the
        vertices, so that its quadratic part survives in the archive (and in VTK)."""
        from itertools import combinations

        cells = self.cells
        pairs = np.sort(np.concatenate([cells[:, [a, b]] for a, b in combinations(range(self.d.dim + 1), 2)]), axis=1)
        pairs = np.unique(pairs, axis=0)
        mid = self.d.vertex_xyz[pairs].mean(axis=1)
        return pairs, self.d.mesh(*[mid[:, i] for i in range(self.d.dim)])

    def edge_values(self) -> np.ndarray:
        """u at the edge midpoints, shape (edge, component)."""
        pairs, points = self.edges
        return np.asarray(self.d.u(points)).reshape(len(pairs), self.d.dim)

    def cell_strains(self, u: np.ndarray) -> np.ndarray:
        """Cell means of eps(u) for a dof vector: shape (cell, component)."""
        if self._p1:
            return self._p1_strains(u)
        return np.stack([E @ u for E in self.strain_operator], axis=1)
