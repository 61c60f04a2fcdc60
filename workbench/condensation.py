"""The contact problem condensed onto the contact-boundary dofs.

The volume operator of an implicit step, M = K_A / k + K_G, is constant; only
the boundary functional j acts on the contact dofs C. With S0 = (M^{-1})_CC
(the discrete Steklov–Poincaré inverse, computed once per k by |C| solves with
the once-factored M), the step's nonlinear system reduces exactly to

    S0^{-1} (u_C - z_C) + f(u_C) = 0,        z = M^{-1} r,

where f(u_C) = j(beta, u, .) restricted to C. A semismooth Newton iteration on
this |C|-dimensional SPD system needs no volume refactorisation; the volume
field is recovered with one more solve, u = z - M^{-1} P f(u_C).

The boundary functional and its Jacobian are evaluated by an NGSolve form on a
surface space holding only the contact-boundary dofs (``Apply`` and
``AssembleLinearization``; the ``IfPos`` truncations linearise exactly).
"""
from __future__ import annotations

import ngsolve as ngs
import numpy as np
import scipy.linalg as la

from .physics import contact


def _nodes_of_boundary(mesh, name):
    """NodeIds (vertices, edges, faces) of the boundary elements called ``name``."""
    nodes = []
    region = mesh.Boundaries(name)
    seen = set()
    for el in region.Elements():
        for kind, items in ((ngs.VERTEX, el.vertices), (ngs.EDGE, el.edges), (ngs.FACE, el.faces)):
            for item in items:
                key = (kind, item.nr)
                if key not in seen:
                    seen.add(key)
                    nodes.append(ngs.NodeId(kind, item.nr))
    return nodes


class ContactOperator:
    """f(u_C) = j(beta, u, .)|_C and its Jacobian, on the contact dofs of the components that j touches.

    Parameters
    ----------
    d : Discretisation
    """

    def __init__(self, d):
        self.d = d
        scene, mesh, dim, order = d.scene, d.mesh, d.dim, d.scene["order"]
        name = d.contact_name
        region = mesh.Boundaries(name)
        if dim == 1:
            surf = ngs.H1(mesh, order=1, definedon=region)
        else:
            surf = ngs.VectorH1(mesh, order=order, definedon=region)
        surf = ngs.Compress(surf)
        # components j acts on: the normal one (flat contact side), all of them with the glue
        comps = list(range(dim)) if "glue" in scene.terms else [dim - 1]
        vol_dofs, surf_dofs = [], []
        for node in _nodes_of_boundary(mesh, name):
            vd = list(d.fes.GetDofNrs(node))
            sd = list(surf.GetDofNrs(node))
            if dim == 1:
                vd, sd = vd[:1], sd[:1]
            n_scalar = len(vd) // dim if dim > 1 else len(vd)
            for c in comps:
                # both spaces store component blocks contiguously: the c-th block of the node's dofs
                vd_c = vd[c * n_scalar:(c + 1) * n_scalar] if dim > 1 else vd
                sd_c = sd[c * n_scalar:(c + 1) * n_scalar] if dim > 1 else sd
                vol_dofs += vd_c
                surf_dofs += sd_c
        self.C = np.asarray(vol_dofs)
        self.S = np.asarray(surf_dofs)
        free = np.array(d.fes.FreeDofs(), dtype=bool)
        keep = free[self.C]  # a clamped contact vertex (x = 0) is not an unknown
        self.C, self.S = self.C[keep], self.S[keep]
        self.space = surf
        self.u = ngs.GridFunction(surf)
        trial, test = surf.TnT()
        self.form = ngs.BilinearForm(surf)
        integrand = contact.boundary_integrand(scene.terms, scene, trial, d.beta, test)
        self.form += integrand.Compile() * ngs.ds(name)
        self.res = self.u.vec.CreateVector()
        self.size = self.C.size
        self._flat = None

    def set(self, u_C: np.ndarray) -> None:
        arr = self.u.vec.FV().NumPy()
        arr[:] = 0.0
        arr[self.S] = u_C

    def force(self, u_C: np.ndarray) -> np.ndarray:
        """f(u_C): the contact nodal forces (as they enter the residual) on C."""
        self.set(u_C)
        self.form.Apply(self.u.vec, self.res)
        return self.res.FV().NumPy()[self.S].copy()

    def jacobian(self, u_C: np.ndarray) -> np.ndarray:
        """df/du_C as a dense |C| x |C| matrix (semismooth: the active branch of each IfPos)."""
        self.set(u_C)
        self.form.AssembleLinearization(self.u.vec)
        rows, cols, vals = self.form.mat.COO()
        if self._flat is None:  # the sparsity pattern is fixed: map it into the dense C x C block once
            where = np.full(self.space.ndof, -1)
            where[self.S] = np.arange(self.size)
            r, c = where[np.asarray(rows)], where[np.asarray(cols)]
            self._keep = (r >= 0) & (c >= 0)
            self._flat = r[self._keep] * self.size + c[self._keep]
        J = np.bincount(self._flat, weights=np.asarray(vals)[self._keep], minlength=self.size * self.size)
        return J.reshape(self.size, self.size)


class CondensedSystem:
    """S0^{-1} = ((M^{-1})_CC)^{-1} for one matrix M (one step size), built with the factored M."""

    def __init__(self, solver, ndof: int, C: np.ndarray, chunk: int = 256):
        m = C.size
        S0 = np.empty((m, m))
        rhs = np.zeros(ndof)
        out = np.zeros(ndof)
        if hasattr(solver, "solve_many"):
            for start in range(0, m, chunk):
                cols = C[start:start + chunk]
                R = np.zeros((ndof, cols.size))
                R[cols, np.arange(cols.size)] = 1.0
                S0[:, start:start + cols.size] = solver.solve_many(R)[C]
        else:
            for j, c in enumerate(C):
                rhs[:] = 0.0
                rhs[c] = 1.0
                solver.solve(rhs, out)
                S0[:, j] = out[C]
        S0 = 0.5 * (S0 + S0.T)
        self.S0_inv = la.cho_solve(la.cho_factor(S0), np.eye(m)) if m else S0
        self.S0_inv = 0.5 * (self.S0_inv + self.S0_inv.T)
        self.S0_abs = np.abs(self.S0_inv)
