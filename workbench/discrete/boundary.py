"""The contact side at its quadrature points: trace operators assembled once, then NumPy in the time loop.

The contact boundary Gamma_3 does not move in a small-strain model, so everything
the contact terms need can be prepared once: the quadrature points of the rule
NGSolve itself uses for the boundary functional (order 2 p for P_p elements), their
weights w_q (with the facet's measure), and sparse trace matrices T with
(T u)_q = u_nu(x_q) (and the tangential components). Then

    j(beta, u, .) = T_nu^T (w * p_nu(T_nu u, beta_q)) + sum_c T_c^T (w * p_tau,c(T_tau u, beta_q))

is two sparse products and a vectorised law per step, with no form assembly, and
the Jacobian of the implicit schemes is T^T diag(w p') T. The bonding rate P_B is
evaluated with the one-point (midpoint) rule, as NGSolve integrates a form with
piecewise-constant test functions, on a second, one-point side.

Examples
--------
>>> import workbench
>>> from workbench.discrete import discretisation
>>> d = discretisation.build(workbench.scene("slab", h=0.1))
>>> d.side.points, d.rate_side.points, round(float(d.side.weights.sum()), 12)  # 10 facets x 2 Gauss points; length 1
(20, 10, 1.0)
"""
from __future__ import annotations

from functools import cached_property

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp


class ContactSide:
    """Quadrature points on the contact boundary ``name`` of ``fes`` and the traces of its dofs there.

    Parameters
    ----------
    fes : ngsolve.FESpace
        The displacement space (H1 in 1D, VectorH1 otherwise).
    name : str
        The contact boundary.
    geometry : workbench.input.geometry.Geometry
        Says which component is normal (and its sign) and which are tangential.
    rule : int
        Order of NGSolve's integration-rule space (its rule has order 2 ``rule``); ``rule = order``
        reproduces the rule NGSolve uses for a boundary linear form of that order; 0 is the midpoint rule.

    Attributes
    ----------
    weights : ndarray (points,)
    T_nu : scipy.sparse.csr_matrix (points, ndof)
        u_nu at the points (positive: penetration).
    T_tau : list of csr_matrix
        The tangential components at the points (empty in 1D).
    element : ndarray (points,)
        Index of each point's facet among the contact facets (their order: :attr:`facets`).
    facets : list of int
        The contact boundary elements, in facet order.
    """

    def __init__(self, fes, name: str, geometry, rule: int):
        mesh = fes.mesh
        self.dim = geometry.dim
        self.geometry = geometry
        region = mesh.Boundaries(name)
        self.facets = [el.nr for el in region.Elements()]
        if self.dim == 1:  # the rod's contact side is the point x = length: one point, weight 1
            dof = _point_dof(fes, mesh, name)
            self.weights = np.ones(1)
            self.T_nu = sp.csr_matrix(([geometry.normal_sign], ([0], [dof])), shape=(1, fes.ndof))
            self.T_tau = []
            self._transposes()
            self.element = np.zeros(1, dtype=np.int64)
            self.gap0 = None
            return
        irs = ngs.comp.IntegrationRuleSpaceSurface(mesh, order=rule, definedon=region)
        rules = irs.GetIntegrationRules()
        v = irs.TestFunction()
        wlf = ngs.LinearForm(irs)
        wlf += v * ngs.ds(name, intrules=rules)
        wlf.Assemble()
        w = wlf.vec.FV().NumPy().copy()
        points = np.nonzero(w)[0]
        # each point's facet: the rule-space dofs of each contact boundary element
        owner = np.full(irs.ndof, -1)
        for i, e in enumerate(self.facets):
            owner[np.asarray(irs.GetDofNrs(ngs.ElementId(ngs.BND, e)))] = i
        u = fes.TrialFunction()
        traces = []
        for c in range(self.dim):
            form = ngs.BilinearForm(trialspace=fes, testspace=irs)
            form += u[c] * v * ngs.ds(name, intrules=rules)
            form.Assemble()
            rows, cols, vals = form.mat.local_mat.COO()  # (several MPI processes: this rank's facets)
            M = sp.csr_matrix((np.asarray(vals), (np.asarray(rows), np.asarray(cols))), shape=(irs.ndof, fes.ndof))
            traces.append((sp.diags(1.0 / w[points]) @ M[points]).tocsr())  # M = diag(w) T
        self.weights = w[points]
        self.element = owner[points]
        self._rule_space = (irs, rules, name, points)
        self.gap0 = None  # the initial gap at the points of a curved contact side (None: flat, on the foundation)
        if geometry.curved:
            self.gap0 = geometry.gap0(self.xyz)
        self.T_nu = (geometry.normal_sign * traces[geometry.normal_axis]).tocsr()
        self.T_tau = [traces[a] for a in geometry.facet_axes]
        self._transposes()

    @cached_property
    def xyz(self) -> np.ndarray:
        """The points' coordinates, shape (points, dim) (int x phi_q da / w_q over the rule space)."""
        irs, rules, name, points = self._rule_space
        v, xyz = irs.TestFunction(), []
        for c in (ngs.x, ngs.y, ngs.z)[: self.dim]:
            lf = ngs.LinearForm(irs)
            lf += c * v * ngs.ds(name, intrules=rules)
            lf.Assemble()
            xyz.append(lf.vec.FV().NumPy()[points] / self.weights)
        return np.stack(xyz, axis=1).reshape(len(points), self.dim)

    def _transposes(self):
        """T^T as CSR, made once: ``T.T`` builds a new matrix at every call (65 us a step at 5k dofs, measured)."""
        self.T_nu_t = self.T_nu.T.tocsr()
        self.T_tau_t = [T.T.tocsr() for T in self.T_tau]

    @property
    def points(self) -> int:
        return len(self.weights)

    def u_nu(self, u: np.ndarray) -> np.ndarray:
        return self.T_nu @ u

    def u_tau(self, u: np.ndarray) -> np.ndarray:
        """Tangential displacement at the points, shape (points, d-1)."""
        return np.stack([T @ u for T in self.T_tau], axis=-1)

    def integrate(self, p_nu, p_tau=None) -> np.ndarray:
        """The dof vector of int p_nu w_nu + p_tau . w_tau da (either may be None)."""
        out = np.zeros(self.T_nu.shape[1])
        if p_nu is not None:
            out += self.T_nu_t @ (self.weights * p_nu)
        if p_tau is not None:
            for c, Tt in enumerate(self.T_tau_t):
                out += Tt @ (self.weights * p_tau[:, c])
        return out

    def restricted(self, dofs: np.ndarray, points=None) -> "RestrictedSide":
        """The same traces on the columns ``dofs`` only (the contact unknowns of the condensed systems), at the
        quadrature points ``points`` only where given (their traces then all within ``dofs``)."""
        return RestrictedSide(self, dofs, points)


#: The most points x dofs for which a :class:`RestrictedSide` also keeps its traces dense (a 2D side: tens of each).
#: There SciPy's sparse products cost more in their overhead than in their work: measured on the debonding slab of
#: tests/test_time_stepping.py (P2, 410 dofs, 60 points x 80 dofs), backward Euler at rtol = 1e-2 (1616 steps and
#: 70 rejected) took 10.2 s against 14.7 s with the sparse traces, u equal to 8e-13.
DENSE_TRACES = 40_000


class RestrictedSide:
    """A :class:`ContactSide` acting on a sub-vector u_C (the dofs that carry a trace on the contact side), at some
    of its points (``points``, positions among the side's; None: all). Small ones (:data:`DENSE_TRACES`) compute
    with dense copies of their traces."""

    def __init__(self, side: ContactSide, dofs: np.ndarray, points=None):
        self.side, self.dofs, self.points = side, np.asarray(dofs), points
        rows = slice(None) if points is None else np.asarray(points)
        self.weights, self.element = side.weights[rows], side.element[rows]
        self.gap0 = side.gap0[rows] if side.gap0 is not None else None
        self.T_nu = side.T_nu[rows][:, self.dofs].tocsr()
        self.T_tau = [T[rows][:, self.dofs].tocsr() for T in side.T_tau]
        self.T_nu_t, self.T_tau_t = self.T_nu.T.tocsr(), [T.T.tocsr() for T in self.T_tau]
        small = self.T_nu.shape[0] * self.T_nu.shape[1] <= DENSE_TRACES
        self._dense = (self.T_nu.toarray(), [T.toarray() for T in self.T_tau]) if small else None

    @property
    def xyz(self) -> np.ndarray:
        """The coordinates of its points."""
        return self.side.xyz if self.points is None else self.side.xyz[self.points]

    def _traces(self):
        return (self.T_nu, self.T_tau) if self._dense is None else self._dense

    def u_nu(self, u_C):
        return self._traces()[0] @ u_C

    def u_tau(self, u_C):
        return np.stack([T @ u_C for T in self._traces()[1]], axis=-1)

    def integrate(self, p_nu, p_tau=None):
        if self._dense is None:
            out = self.T_nu_t @ (self.weights * p_nu) if p_nu is not None else np.zeros(len(self.dofs))
            tangential = self.T_tau_t
        else:
            out = (self.weights * p_nu) @ self._dense[0] if p_nu is not None else np.zeros(len(self.dofs))
            tangential = [T.T for T in self._dense[1]]
        if p_tau is not None:
            for c, Tt in enumerate(tangential):
                out = out + Tt @ (self.weights * p_tau[:, c])
        return out

    def jacobian(self, slope_nu, slope_tau=None, dense: bool = True):
        """T_nu^T diag(w slope_nu) T_nu (+ the tangential blocks) as a |C| x |C| matrix, dense or sparse (CSR)."""
        if dense and self._dense is not None:
            T_nu, T_tau = self._dense
            J = T_nu.T @ ((self.weights * slope_nu)[:, None] * T_nu)
            if slope_tau is not None:
                for a, Ta in enumerate(T_tau):
                    for b, Tb in enumerate(T_tau):
                        J += Ta.T @ ((self.weights * slope_tau[:, a, b])[:, None] * Tb)
            return J
        J = (self.T_nu.T @ sp.diags(self.weights * slope_nu) @ self.T_nu)
        if slope_tau is not None:
            for a, Ta in enumerate(self.T_tau):
                for b, Tb in enumerate(self.T_tau):
                    J = J + Ta.T @ sp.diags(self.weights * slope_tau[:, a, b]) @ Tb
        return J.toarray() if dense else J.tocsr()


def _point_dof(fes, mesh, name):
    """The dof of the vertex of the point boundary ``name`` (1D)."""
    for el in mesh.Boundaries(name).Elements():
        return fes.GetDofNrs(el)[0]
    raise ValueError(f"no boundary called {name!r}")


def contact_dofs(fes, side: ContactSide, tangential: bool) -> np.ndarray:
    """The free dofs that have a trace on the contact side: the normal component's, and all of them with
    ``tangential`` (a law acting on u_tau); a clamped vertex on the side is not an unknown."""
    free = np.array(fes.FreeDofs(), dtype=bool)
    T = side.T_nu if not tangential else sp.vstack([side.T_nu] + side.T_tau)
    used = np.unique(T.tocoo().col[T.tocoo().data != 0])
    return used[free[used]]
