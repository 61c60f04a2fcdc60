"""The contact problem condensed onto the contact-boundary dofs, and its semismooth Newton solver.

The volume operator of an implicit step, M (Model A's backward Euler:
K_A / k + K_G), is constant; only the boundary functional j acts on the contact
dofs C. With S0 = (M^{-1})_CC (the discrete Steklov–Poincaré inverse, computed once
per M by |C| solves with the once-factored M), the step's nonlinear system reduces
exactly to

    g(u_C) = S0^{-1} (u_C - z_C) + f(u_C) = 0,        z = M^{-1} r,

where f(u_C) = j(beta, u, .) restricted to C (:class:`ContactOperator`). A
semismooth Newton iteration on this |C|-dimensional SPD system
(:class:`CondensedNewton`) needs no volume refactorisation; the volume field is
recovered with one more solve, u = z - M^{-1} P f(u_C).

Forming S0 costs |C| solves and a dense |C| x |C| factor: a wall in 3D, where |C| grows like n^(2/3).
With ``contact_solver = 'coupled'`` S0 is only applied, one back-substitution a product
(:class:`SchurOperator`), and the same Newton iteration runs on the contact force with its directions by
conjugate gradients preconditioned by S0 (:class:`CoupledNewton`; Model B's active set:
:mod:`workbench.schemes.coupled_contact`).

Examples
--------
>>> import workbench
>>> from workbench.discrete import discretisation
>>> d = discretisation.build(workbench.scene("slab", h=0.1, c_tau=1.0))
>>> op = ContactOperator(d)
>>> op.size  # 10 free contact vertices, both components (the glue acts tangentially)
20
"""
from __future__ import annotations

import copy

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import NewtonFailed
from ..physics.ops import NP
from .boundary import contact_dofs
from .solvers import Multiple, inverse
from .springs import SpringsFactor

#: The residual a semismooth Newton takes as round-off, per unit of the absolute terms it sums (a few hundred
#: products of doubles, each good to eps).
ROUNDOFF = 64 * np.finfo(float).eps


class ContactOperator:
    """f(u_C) = j(beta, u, .)|_C and its Jacobian on the contact dofs C of the components the terms act on.

    The bonding field is read from the discretisation each call (the schemes update it in place).
    """

    def __init__(self, d):
        self.d = d
        self.contact = d.model.contact
        self.C = contact_dofs(d.fes, d.side, self.contact.tangential)
        self.side = d.side.restricted(self.C)
        self.size = self.C.size
        self.tangential = self.contact.tangential and bool(self.side.T_tau)

    def _beta(self):
        d = self.d
        if d.beta is None:
            return None
        return d.beta.vec.FV().NumPy()[d.beta_dofs][self.side.element]

    def force(self, u_C: np.ndarray) -> np.ndarray:
        """f(u_C): the contact nodal forces (as they enter the residual) on C."""
        beta = self._beta()
        p = self.contact.normal(NP, self.side.u_nu(u_C), beta, self.side.gap0)
        q = self.contact.tangential_traction(NP, self.side.u_tau(u_C), beta) if self.tangential else None
        return self.side.integrate(p, q)

    def _slopes(self, u_C: np.ndarray):
        beta = self._beta()
        slope = self.contact.normal_slope(self.side.u_nu(u_C), beta, self.side.gap0)
        return slope, self.contact.tangential_slope(self.side.u_tau(u_C), beta) if self.tangential else None

    def jacobian(self, u_C: np.ndarray, dense: bool = True):
        """df/du_C as a |C| x |C| matrix, dense or sparse (semismooth: the active branch of each kink)."""
        return self.side.jacobian(*self._slopes(u_C), dense=dense)

    def dof_points(self):
        """Each contact dof as a point of the side, (positions, areas): the area its share of the side, sum_q w_q
        |phi(x_q)|, the position the mean of the quadrature points weighted by it (the half-space preconditioner of
        :class:`CoupledNewton`)."""
        side = self.side
        T = abs(side.T_nu)
        area = T.T @ side.weights
        return (T.T @ (side.weights[:, None] * side.xyz)) / np.maximum(area, 1e-300)[:, None], area

    def subset(self, cols: np.ndarray, points: np.ndarray) -> "ContactOperator":
        """The operator on the dofs C[cols] and the side's quadrature points ``points`` alone (their traces within
        those dofs): the contact problem of part of the side, the rest held apart
        (:mod:`workbench.schemes.facet_candidates`)."""
        sub = copy.copy(self)
        sub.C = self.C[cols]
        sub.side, sub.size = self.d.side.restricted(sub.C, points), sub.C.size
        return sub


class CondensedSystem:
    """S0^{-1} = ((M^{-1})_CC)^{-1} for one matrix M, built with the factored M; with a trace matrix B (rows: the
    contact points) instead of the dofs C, S0 = B M^{-1} B^T."""

    def __init__(self, solver, ndof: int, C: np.ndarray, chunk: int = 256, B=None):
        S0_inv = solver.condensed_stiffness(C, B)  # (inside one factorization, where the solver can)
        if S0_inv is None:
            S0_inv = self._by_solves(solver, ndof, C, chunk, B)
        self.S0_inv = 0.5 * (S0_inv + S0_inv.T)
        self.S0_abs = np.abs(self.S0_inv)

    @staticmethod
    def _by_solves(solver, ndof: int, C: np.ndarray, chunk: int, B):
        """S0^{-1} from S0 = (M^{-1})_CC or B M^{-1} B^T, formed one back-substitution per contact unknown."""
        m = C.size if B is None else B.shape[0]
        S0 = np.empty((m, m))
        for start in range(0, m, chunk):
            if B is None:
                cols = C[start:start + chunk]
                R = np.zeros((ndof, cols.size))
                R[cols, np.arange(cols.size)] = 1.0
                S0[:, start:start + cols.size] = solver.solve_many(R)[C]
            else:
                R = B[start:start + chunk].T.toarray()
                S0[:, start:start + R.shape[1]] = B @ solver.solve_many(R)
        S0 = 0.5 * (S0 + S0.T)
        return inverse(S0) if m else S0


class SchurOperator:
    """S = B K^{-1} B^T on the contact points, applied with one back-substitution of the factored K and never formed
    (the coupled contact solve: its cost grows like a back-substitution, not like the number of contact points).

    B is the signed selection of the contact vertices' normal dofs (P1: ``C``, ``sign``) or a trace matrix (rows: the
    points). ``stiffness`` approximates the diagonal of S^{-1} (the stiffness a point feels) by 1 / (B^2 diag(K)^-1):
    the Jacobi preconditioner of the conjugate gradients on S and the scale of the active-set prediction.
    ``applications`` counts the back-substitutions.

    >>> import numpy as np, scipy.sparse as sp
    >>> from workbench.discrete.solvers import BandedCholesky
    >>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()
    >>> op = SchurOperator(BandedCholesky(K, np.arange(1, 5)), 5, np.array([4]), 1.0, diagonal=K.diagonal())
    >>> round(float(op.apply(np.array([1.0]))[0]), 12), op.stiffness.tolist()  # (K^-1)_44 on dofs 1..4: 4/5
    (0.8, [2.0])
    """

    def __init__(self, solver, ndof: int, C: np.ndarray, sign: float = 1.0, diagonal=None, B=None,
                 approximate: bool = False):
        self.solver, self.ndof, self.C, self.sign, self.B = solver, ndof, C, sign, B
        # ``approximate``: S itself, approximately and densely, where the solver forms it at little cost (solver =
        # 'mixed': from its single factorization, before any solve), else None (:meth:`preconditioner`)
        self.compliance = solver.approximate_compliance(C) if approximate and B is None else None
        if self.compliance is not None:
            signs = np.broadcast_to(np.asarray(sign, dtype=float), (C.size,))
            self.compliance *= np.outer(signs, signs)
        self.stiffness, self._dense = None, None
        if diagonal is not None:
            inverse = 1.0 / np.where(diagonal > 0, diagonal, np.inf)
            self.stiffness = 1.0 / (inverse[C] if B is None else B.multiply(B) @ inverse)
        self._rhs, self._out = np.zeros(ndof), np.zeros(ndof)
        self.applications = 0

    def preconditioner(self, U: np.ndarray, D: np.ndarray):
        """r -> (S~_UU + diag(D_U))^-1 r from the approximate compliance S~ (its Cholesky factor kept for the last U
        and D), or None without one, or should that matrix not be positive definite."""
        if self.compliance is None:
            return None
        key = (U.tobytes(), D.tobytes())
        if self._dense is None or self._dense[0] != key:
            A = self.compliance[np.ix_(U, U)]
            A[np.diag_indices_from(A)] += D
            try:
                factor = la.cho_factor(A, overwrite_a=True, check_finite=False)
            except la.LinAlgError:
                return None
            self._dense = (key, lambda r: la.cho_solve(factor, r, check_finite=False))
        return self._dense[1]

    def apply(self, x: np.ndarray) -> np.ndarray:
        """S x for forces x at the points: the points' normal displacement under them."""
        rhs, out = self._rhs, self._out
        if self.B is None:
            rhs[:] = 0.0
            rhs[self.C] = self.sign * x
        else:
            rhs[:] = self.B.T @ x
        if self.solver.warm_start:
            out[:] = 0.0  # (the last product's solution is no guess for this one)
        self.solver.solve(rhs, out)
        self.applications += 1
        return self.sign * out[self.C] if self.B is None else self.B @ out


class DenseSchur:
    """The compliance S = (M^-1)_CC of a few contact dofs, formed (the inverse of their condensed stiffness, which a
    factorization that keeps them last gives): :class:`SchurOperator`'s products as dense ones, where a
    back-substitution would cost a factor's worth (:mod:`workbench.schemes.facet_candidates`). ``stiffness``: the
    diagonal of S^-1, exactly. ``compliance``: S itself, where the caller holds it already.

    It also serves :class:`CoupledNewton` as its ``halfspace``: the springs' system is then preconditioned by its
    own inverse, and its conjugate gradients end after one iteration (:meth:`springs_compliance`).

    >>> S = DenseSchur(np.array([[2.0, -1.0], [-1.0, 2.0]]))
    >>> S.apply(np.array([3.0, 0.0])).round(12).tolist(), S.stiffness.tolist()
    ([2.0, 1.0], [2.0, 2.0])
    """

    def __init__(self, stiffness: np.ndarray, compliance: np.ndarray | None = None):
        self.compliance = inverse(stiffness) if compliance is None else compliance
        self.stiffness = stiffness.diagonal().copy()
        self.largest = len(stiffness)  # (every set of springs: read in place, never computed)
        self.applications = 0
        # (S in Fortran order for BLAS's symmetric product, which reads one triangle: a product is bound by reading
        # S, and measured at 3629 dofs it takes 4.0 ms against 7.6-8.3 ms for the general one. S is symmetric, so
        # where it is C-ordered its transpose is S itself in Fortran order, with no copy. A multiple of a shared
        # factor's compliance, solvers.Multiple, is read as its base with the multiple as BLAS's alpha)
        held, self._alpha = (self.compliance.base, self.compliance.c) if isinstance(self.compliance, Multiple) \
            else (self.compliance, 1.0)
        self._fortran = held if held.flags.f_contiguous else held.T
        self._symv = la.get_blas_funcs("symv", (self._fortran,))

    def apply(self, x: np.ndarray) -> np.ndarray:
        """S x for forces x at the dofs: their displacement under them."""
        self.applications += 1
        return self._symv(self._alpha, self._fortran, x, lower=1) if x.ndim == 1 else self.compliance @ x

    def springs_compliance(self, U: np.ndarray, local: np.ndarray):
        """(S, True): the compliance itself on every dof, exact (the half-space's
        :meth:`~workbench.schemes.halfspace.HalfSpace.springs_compliance`, with no block cut and no scale: the
        springs' factor reads the rows it needs, and grows its dofs U with the contact front)."""
        return self.compliance, True


def matrix_diagonal(mat) -> np.ndarray:
    """The diagonal of an assembled NGSolve sparse matrix."""
    rows, cols, vals = mat.COO()
    rows, cols, vals = np.asarray(rows), np.asarray(cols), np.asarray(vals)
    out = np.zeros(mat.height)
    on = rows == cols
    np.add.at(out, rows[on], vals[on])
    return out


class CondensedNewton:
    """Semismooth Newton on g(u_C) = S0^{-1} (u_C - z_C) + f(u_C) = 0, globalised by a line search.

    For fixed beta every contact term is monotone, so g is the gradient of a convex
    energy and each Newton direction s descends it; phi(a) = energy(u_C + a s) has the
    non-decreasing, piecewise linear derivative g(u_C + a s) . s. The full step is
    taken unless it clearly overshoots (phi'(1) > 1e-3 |phi'(0)|: usually it does not,
    and it is exact once the active branches are right); otherwise a step a in (0, 1)
    with phi'(0)/2 <= phi'(a) <= 0 is found by Illinois regula falsi (an inexact line
    search: the energy decreases and a is near the minimum along s). Without it a
    stiff glue (k gamma_nu large) makes the iteration cycle. Converged when
    |g| <= rtol * max(|S0^{-1} (u_C - z_C)|, |f|), the forces g balances, or where g is at the round-off of its
    terms, 64 eps |S0^{-1}| |u_C - z_C|. (That sum of absolute terms is no scale for the forces: S0^{-1} is dense
    with entries of both signs, and on a slab pressed by a traction it was 10^4 times |f|, so rtol times it
    accepted residuals of 10^-6 of the forces.)
    """

    linear_iterations = 0  # (no inner iterations: one dense solve a Newton step)

    def __init__(self, condensed: CondensedSystem, operator: ContactOperator, rtol: float = 1e-10,
                 max_iterations: int = 40):
        self.condensed, self.op, self.rtol, self.max_iterations = condensed, operator, rtol, max_iterations
        self.iterations = 0

    def solve(self, u_C: np.ndarray, z_C: np.ndarray, time: float, label: str = "") -> np.ndarray:
        """Solve in place from ``u_C`` (the start); return f(u_C) at the solution. ``iterations`` counts up."""
        S0_inv, S0_abs = self.condensed.S0_inv, self.condensed.S0_abs
        f = self.op.force(u_C)
        g_norm = np.inf
        for it in range(self.max_iterations + 1):
            diff = u_C - z_C
            elastic = S0_inv @ diff
            g = elastic + f
            g_norm = np.abs(g).max()
            if not np.isfinite(g_norm):
                break
            forces = max(np.abs(elastic).max(initial=0.0), np.abs(f).max(initial=0.0))
            if g_norm <= max(self.rtol * forces, ROUNDOFF * (S0_abs @ np.abs(diff)).max(initial=0.0), 1e-300):
                return f
            if it == self.max_iterations:
                break
            H = S0_inv + self.op.jacobian(u_C)
            step = la.cho_solve(la.cho_factor(H, check_finite=False), -g, check_finite=False)
            self.iterations += 1
            slope0 = float(g @ step)  # < 0: the step descends
            f_new = self.op.force(u_C + step)
            slope1 = float((S0_inv @ (u_C + step - z_C) + f_new) @ step)
            if slope1 <= 1e-3 * abs(slope0):  # no real overshoot (0 up to round-off once the branches are right)
                u_C += step
                f = f_new
            else:
                alpha = self._line_search(u_C, step, z_C, slope0, slope1)
                u_C += alpha * step
                f = self.op.force(u_C)
            if np.abs(step).max() <= 1e-14 * (np.abs(u_C).max() + np.abs(z_C).max()):
                return f  # stagnated at round-off: the correction no longer moves u_C
        raise NewtonFailed(f"{label}: semismooth Newton did not converge in {self.iterations} iterations "
                           f"at t = {time:.6g} s (residual {g_norm:.3g}); try a smaller k", time=time)

    def _line_search(self, u_C, step, z_C, slope0, slope1):
        """A step a in (0, 1) with phi'(0) / 2 <= phi'(a) <= 0 on phi'(a) = g(u_C + a s) . s (:func:`line_search`)."""
        S0_inv = self.condensed.S0_inv
        return line_search(lambda a: float((S0_inv @ (u_C + a * step - z_C) + self.op.force(u_C + a * step)) @ step),
                           slope0, slope1)


def line_search(slope, slope0: float, slope1: float, steps: int = 80, within: float = 0.5) -> float:
    """A step a in (0, 1) with ``within`` slope0 <= slope(a) <= 0 by Illinois regula falsi on the directional
    derivative ``slope(a)`` of a convex energy, which is non-decreasing and piecewise linear (kinks where a contact
    term changes branch); slope(0) = slope0 < 0 < slope(1) = slope1."""
    a_lo, s_lo, a_hi, s_hi = 0.0, slope0, 1.0, slope1
    a, side = 1.0, 0
    for _ in range(steps):
        a = a_lo - s_lo * (a_hi - a_lo) / (s_hi - s_lo)
        s_a = slope(a)
        if within * slope0 <= s_a <= 0.0:
            break
        if s_a < 0:
            a_lo, s_lo = a, s_a
            if side == -1:
                s_hi *= 0.5  # Illinois: the kept end stalled twice, halve its weight
            side = -1
        else:
            a_hi, s_hi = a, s_a
            if side == 1:
                s_lo *= 0.5
            side = 1
        if a_hi - a_lo <= 1e-15 * max(1.0, a_hi):
            break
    return a


class CoupledNewton:
    """The semismooth Newton of :class:`CondensedNewton` without S0^{-1} (``contact_solver = 'coupled'``): S0 =
    (M^{-1})_CC is applied by one back-substitution (:class:`SchurOperator`) and never formed.

    The iterate is the contact force phi with u_C = z_C - S0 phi, so that S0^{-1} (u_C - z_C) = -phi and the residual
    is g = f(u_C) - phi. A Newton direction s solves (S0^{-1} + J) s = -g = b and comes with s~ = S0^{-1} s, so phi is
    updated as phi - a s~ without inverting S0. The inner solves stop at :attr:`inner` times their first residual
    (inexact Newton); the globalisation is the line search of :class:`CondensedNewton` on the same convex energy.
    ``linear_iterations`` counts the inner iterations (one back-substitution each).

    Where the Jacobian acts on the normal dofs alone (a normal compliance, no glue) and ``halfspace`` is given (a
    :class:`~workbench.schemes.halfspace.HalfSpace` over the contact dofs, 3D), the direction is found in the
    springs' forces t = J s on the dofs R where J is not 0 (Woodbury):

        (J_RR^-1 + S0_RR) t = (S0 b)_R,      s = S0 (b - t),      s~ = b - t,

    J_RR^-1 by a sparse LU factor, by conjugate gradients preconditioned by (J_RR^-1 + c G_RR)^-1, G the half-space's
    compliance scaled to S0's diagonal estimate (a dense LU factor per set of springs). Preconditioned by S0 instead,
    the system in s has the operator I + S0 J, whose spread grows with the springs' stiffness. Measured on the
    hemisphere (hertz3d, tau = 1e-3, 10 steps; ``studies/model_a_contact.py``) at 12k dofs, c_nu = 1e7: 31 inner
    iterations a Newton step before, 12 here. Otherwise, and past ``halfspace.largest`` dofs in R, s is found that
    way.

    The first iterate is the Newton step from the caller's u_C (a linear extrapolation of the last steps): u_C + s
    with (S0^-1 + J) s = -g(u_C), found without S0^-1 as u_C + s - z_C = v, (S0^-1 + J) v = J (u_C - z_C) - f(u_C),
    its force -S0^-1 v coming along. Starting instead from phi = f(u_C), a stiff spring turns the guess's small
    penetrations into large forces that lift the body off, and the iteration climbs back a few points at a time
    (measured on the same run: 250 Newton iterations, against 68 for the condensed solver). Where the guess touches
    nowhere (from rest) that start is the free displacement, the whole side penetrating, and the Newton steps from
    there release the rim a few points at a time: the start is moved to the energy's minimum along the ray of its
    spring forces first (:meth:`_coming_into_contact`).
    """

    inner = 1e-4
    #: The start's inner tolerance: it moves u_C the furthest, and which springs act after it depends on its
    #: accuracy (with a stiff one to c_nu^-1 of u). Measured on hertz3d at 12k dofs, 10 steps: c_nu = 1e7, 109 -> 87
    #: Newton iterations, 1259 -> 994 inner, 8.7 -> 7.4 s against 1e-4; c_nu = 1e5, 387 -> 414 inner.
    start_inner = 1e-6
    #: The dofs a new springs' factor is made for beyond R, as a share of R (:meth:`_with_margin`): a step's first
    #: Newton iteration adds the dofs the front reaches, which then lie within the factor's dofs and update it at low
    #: rank instead of making it anew. Measured on hertz3d at 106k dofs (52 steps): an eighth made 20 factors (the
    #: springs' work 6.2 s), a quarter 14 (6.1 s) and a half 11 (7.8 s), the columns of the updates growing. On the
    #: candidates' exact compliance the factor grows past U itself (:class:`SpringsFactor` ``whole``), and the
    #: margin no longer matters there (5.63 s without it, 5.68 s with an eighth: one run each).
    margin = 0.125

    def __init__(self, schur: SchurOperator, operator: ContactOperator, rtol: float = 1e-10,
                 max_iterations: int = 40, halfspace=None):
        self.schur, self.op, self.rtol, self.max_iterations = schur, operator, rtol, max_iterations
        self.halfspace = halfspace
        self._factor = self._traces = None
        self.iterations = self.linear_iterations = 0

    def solve(self, u_C: np.ndarray, z_C: np.ndarray, time: float, label: str = "") -> np.ndarray:
        op = self.op
        # the start: the Newton step from the caller's u_C, u_C + s with (S0^-1 + J) s = -g(u_C), found without
        # S0^-1 as u_C + s - z_C = v, (S0^-1 + J) v = J (u_C - z_C) - f(u_C); its force phi = -S0^-1 v comes along
        f0 = op.force(u_C)
        v, v_t = self._direction(u_C, op.jacobian(u_C, dense=False) @ (u_C - z_C) - f0, self.start_inner)
        self.iterations += 1
        u_C[:] = z_C + v
        phi = -v_t
        f = op.force(u_C)
        if not np.any(f0) and np.any(f):
            u_C, phi, f = self._coming_into_contact(u_C, phi, f)
        g_norm = last = np.inf
        synced = False
        for it in range(self.max_iterations + 1):
            g = f - phi
            g_norm = np.abs(g).max()
            if not np.isfinite(g_norm):
                break
            target = self.rtol * max(np.abs(phi).max(), np.abs(f).max(), 1e-300)
            if g_norm <= target and synced:  # (phi, not f: the body's u is then z - S0 phi, whose trace is u_C, so
                return phi  # the laws at it give f, and the archived pressures balance the load to g)
            if g_norm <= target:  # (u_C drifted from z_C - S0 phi by the inner solves' inexact s~: taken back to it,
                # one back-substitution, and judged again: the drift, times a stiff spring's slope, is what the
                # archived pressure missed the load by: 4e-5 of it at c_nu = 1e8, found by an outside pass)
                u_C[:] = z_C - self.schur.apply(phi)
                f, synced = op.force(u_C), True
                continue
            synced = False
            if it == self.max_iterations:
                break
            # the inner tolerance (Eisenstat and Walker's second forcing term): loose while the residual falls
            # slowly (the branches still change), tight once it falls fast, never finer than the Newton target
            eta = float(np.clip((g_norm / last) ** 2, 0.1 * target / g_norm, self.inner)) if it else self.inner
            last = g_norm
            step, step_t = self._direction(u_C, -g, eta)
            self.iterations += 1
            slope0 = float(g @ step)
            f_new = op.force(u_C + step)
            slope1 = float((f_new - phi + step_t) @ step)
            alpha = 1.0 if slope1 <= 1e-3 * abs(slope0) else self._search(u_C, phi, step, step_t, slope0, slope1)
            u_C += alpha * step
            phi -= alpha * step_t
            f = f_new if alpha == 1.0 else op.force(u_C)
            if np.abs(step).max() <= 1e-14 * (np.abs(u_C).max() + np.abs(z_C).max()):
                return f
        raise NewtonFailed(f"{label}: semismooth Newton (coupled) did not converge in {self.iterations} iterations "
                           f"at t = {time:.6g} s (residual {g_norm:.3g}); try a smaller k", time=time)

    def _coming_into_contact(self, u_C, phi, f):
        """From the start where the guess had no contact (the free displacement, all of it penetrating): along the
        forces' ray phi + a d, u_C - a S0 d (d = f - phi, one back-substitution), to the energy's minimum on it, as
        the condensed solver's line-searched first step from the guess does. Measured on the hemisphere (c_nu = 1e7,
        the first step from rest): 25 -> 12 Newton iterations at h_contact = 0.02 (condensed: 12), 41 -> 10 on P2 at
        0.04 (condensed: 8). (u_C, phi, f) there; ``u_C`` in place."""
        op, d = self.op, f - phi
        S_d = self.schur.apply(d)

        def slope(a):  # d/da of the energy, g(u) . du/da with g = f - phi, du/da = -S0 d
            return -float((op.force(u_C - a * S_d) - phi - a * d) @ S_d)

        slope0, slope1 = slope(0.0), slope(1.0)
        if not slope0 < 0.0 < slope1:
            return u_C, phi, f
        a = line_search(slope, slope0, slope1, within=1e-8)  # (its minimum: the ray is not a Newton direction)
        u_C -= a * S_d
        return u_C, phi + a * d, op.force(u_C)

    def _direction(self, u_C, b, eta):
        """(s, S0^{-1} s) with (S0^{-1} + J(u_C)) s = b, to the relative tolerance ``eta`` (class docs)."""
        if not np.any(b):
            return np.zeros_like(b), np.zeros_like(b)
        J = self.op.jacobian(u_C, dense=False)
        if self.halfspace is None or self.op.tangential:
            return self._in_displacements(J, b, eta)
        R = np.nonzero(J.diagonal() > 0)[0]
        if R.size > self.halfspace.largest:
            return self._in_displacements(J, b, eta)
        S_b = self.schur.apply(b)
        if R.size == 0:
            return S_b, b.copy()
        found = self._in_forces(J[R][:, R], R, b, S_b, eta, u_C)
        return found if found is not None else self._in_displacements(J, b, eta)

    def _in_forces(self, J, R, b, S_b, eta, u_C):
        """The direction from the springs' forces t = J s on the dofs R (J: J_RR, sparse; class docs); None should
        J_RR be singular."""
        S = self.schur
        # J_RR is singular where the springs miss some combination of R's dofs (a dof whose elements touch at fewer
        # quadrature points than the dofs they couple: most Newton steps on the hemisphere). 1e-10 of its diagonal
        # makes such a mode a compliance 1e10 times the rest, which the preconditioner holds exactly: no force there,
        # as without it
        J = (J + sp.diags(1e-10 * J.diagonal())).tocsr()
        try:
            spring = spla.splu(J.tocsc())
        except RuntimeError:
            return None
        precondition = self._preconditioner(J, R, u_C)
        t, S_t, p = np.zeros(R.size), np.zeros_like(b), np.zeros_like(b)
        r = S_b[R].copy()
        z = precondition(r)
        d, rz = z.copy(), float(r @ z)
        # (the residual of the system in s is J_RR r on R: measured in forces, as the Newton residual)
        target = eta * np.abs(b).max()
        for _ in range(max(50, R.size)):
            if np.abs(J @ r).max() <= target:
                break
            p[R] = d
            S_p = S.apply(p)
            self.linear_iterations += 1
            A_d = spring.solve(d) + S_p[R]
            a = rz / float(d @ A_d)
            t += a * d
            S_t += a * S_p
            r -= a * A_d
            z = precondition(r)
            rz, rz_old = float(r @ z), rz
            d = z + (rz / rz_old) * d
        s_t = b.copy()
        s_t[R] -= t
        return S_b - S_t, s_t

    def _preconditioner(self, J, R, u_C):
        """r -> (J_RR^-1 + c G_RR)^-1 r = (I + J_RR c G_RR)^-1 J_RR r (:class:`SpringsFactor`: an LU factor of the
        bracket, 2/3 |R|^3 as G is dense and J sparse, updated at low rank while R stays within the dofs U it was
        made for: R and the :attr:`margin` nearest to contact at u_C, where the front goes next; on the candidates'
        compliance U grows with R)."""
        if self._factor is None or not self._factor.holds(J, R):
            U = self._with_margin(R, u_C)
            G, whole = self.halfspace.springs_compliance(U, 1.0 / self.schur.stiffness[U])  # (S0's diagonal's)
            self._factor = SpringsFactor(J, R, G, U, whole)
        return self._factor.solver()

    def _with_margin(self, R: np.ndarray, u_C: np.ndarray) -> np.ndarray:
        """R and the :attr:`margin` of dofs off R nearest to contact at u_C (the least gap g - u_nu left at the points
        they carry), sorted; no more than the half-space's ``largest`` in all."""
        extra = min(int(np.ceil(self.margin * R.size)), self.halfspace.largest - R.size, self.op.size - R.size)
        if extra <= 0:
            return R
        side = self.op.side
        if self._traces is None:
            T = abs(side.T_nu).tocsc()
            T.eliminate_zeros()
            self._traces = T
        T = self._traces
        left = (0.0 if side.gap0 is None else side.gap0) - side.u_nu(u_C)
        nearest = np.full(self.op.size, np.inf)
        carries = np.diff(T.indptr) > 0
        nearest[carries] = np.minimum.reduceat(left[T.indices], T.indptr[:-1][carries])
        nearest[R] = np.inf
        chosen = np.argpartition(nearest, extra - 1)[:extra]
        return np.union1d(R, chosen[np.isfinite(nearest[chosen])])

    def _in_displacements(self, J, b, eta):
        """(s, S0^{-1} s) with (S0^{-1} + J) s = b, by conjugate gradients preconditioned by S0 (class docs)."""
        S = self.schur
        x, x_t = np.zeros_like(b), np.zeros_like(b)
        r = b.copy()
        z = S.apply(r)
        p, p_t = z.copy(), r.copy()
        rz = float(r @ z)
        first = np.sqrt(abs(rz))
        for _ in range(max(50, b.size)):
            q = p_t + J @ p
            a = rz / float(p @ q)
            x += a * p
            x_t += a * p_t
            r -= a * q
            self.linear_iterations += 1
            z = S.apply(r)
            rz, rz_old = float(r @ z), rz
            if np.sqrt(abs(rz)) <= eta * first:
                break
            beta = rz / rz_old
            p = z + beta * p
            p_t = r + beta * p_t
        return x, x_t

    def _search(self, u_C, phi, step, step_t, slope0, slope1):
        """The line search with g(u_C + a s) . s = (f(u_C + a s) - phi + a s~) . s."""
        return line_search(lambda a: float((self.op.force(u_C + a * step) - phi + a * step_t) @ step), slope0, slope1)
