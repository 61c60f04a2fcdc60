"""Step-size limit of the paper's explicit scheme: predicted before a run, kept up to date during it.

The scheme advances u' = K_A^{-1} (F - K_G u - j(u)): forward Euler on the
elastic and contact terms, so (linearised) it is stable for
k < k_crit = 2 / lambda_max(K_A^{-1} (K_G + D)), where D is the boundary spring
matrix T^T diag(w s) T of the slopes s of the contact terms at the contact
quadrature points. lambda_max comes from Lanczos (SciPy ``eigsh``) on the
generalised problem with the factored K_A.

Which slopes: :func:`critical_step` without ``springs`` takes every term at its
largest slope on the whole contact side (each term says its own:
:meth:`workbench.physics.contact.ContactTerm.max_slope`), a bound for any state.
A run takes only the springs that act (:class:`StepLimit`): the slopes of the laws
at the state, where a point whose law can switch on within the first step counts
(the state after one trial step is included), and it re-checks every step. A
spring that cannot act -- the foundation's under a body pulled away, the
compliance of a curved side off the foundation, the pull of a body pressed in --
does not shorten the step. When the acting springs grow during the run, lambda_max is
estimated again (warm started) once the total spring int s da has grown by
:data:`REESTIMATE_TOTAL` or the local stiffness max_i (K_G + D)_ii / (K_A)_ii by
:data:`REESTIMATE_LOCAL` since the last estimate: the largest mode of a thin body
on springs is global (tp5: springs on the whole bottom give k_crit = 6.97e-4 s, on
the part pressed after one step 3.3e-3 s), so both the amount and the local
stiffness count. A step above the new limit stops the run
(:class:`~workbench.errors.StepLimitExceeded`, the steps so far kept).

Examples
--------
>>> import workbench
>>> est = critical_step(workbench.scene("slab", h=0.05, c_nu=100.0, gamma_nu=20.0))
>>> 1e-4 < est.k_crit < 1e-2
True
"""
from __future__ import annotations

from dataclasses import dataclass

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, LinearOperator, eigsh

from . import solvers
from .errors import ParameterError, StepTooLarge
from .physics import kelvin_voigt

__all__ = ["Estimate", "StepLimit", "critical_step", "check", "StepTooLarge"]

#: Relative growth of the total spring and of the local stiffness (module docs) above which a run estimates
#: lambda_max again: lambda_max grows at most in proportion to the springs, so the limit a run works with is within
#: about these fractions of the limit of the springs it has met.
REESTIMATE_TOTAL, REESTIMATE_LOCAL = 0.10, 0.01


@dataclass(frozen=True)
class Estimate:
    """A predicted limit. ``spring_normal`` / ``spring_tangential``: the largest spring (Pa/m) taken;
    ``acting``: (contact points with a normal spring, with a tangential one, all points), or None for the bound
    over all states."""
    k_crit: float
    lambda_max: float
    spring_normal: float
    spring_tangential: float
    acting: tuple | None = None

    def describe(self) -> str:
        springs = (f"normal {self.spring_normal:.3g}, tangential {self.spring_tangential:.3g} Pa/m")
        if self.acting is None:
            return f"boundary springs at their largest slopes everywhere: {springs}"
        n, t, total = self.acting
        return (f"springs acting in the state: normal on {n} and tangential on {t} of {total} contact points, "
                f"largest {springs}")


def critical_step(disc_or_scene, solver=None) -> Estimate:
    """Predict k_crit for the explicit scheme on a discretisation (or a scene, discretised here).

    ``solver`` (the factored K_A, e.g. the explicit scheme's) avoids refactoring.
    """
    from . import discretisation
    from .scenes import Scene

    d = discretisation.build(disc_or_scene) if isinstance(disc_or_scene, Scene) else disc_or_scene
    model = d.model
    s_nu, s_tau = model.contact.max_slope(model.beta0)
    if d.world.parallel:  # (several MPI processes: the springs at the contact points, Lanczos over the ranks)
        w = d.side.weights if d.side is not None else np.zeros(0)
        lam, _ = DistributedOperators(d, solver).largest_eigenvalue(s_nu * w, s_tau * w)
        return Estimate(2.0 / lam, lam, s_nu, s_tau)
    u, w = d.fes.TnT()
    stiff = ngs.BilinearForm(d.fes, symmetric=True)
    stiff += kelvin_voigt.energy_product(model.elastic, u, w, d.dim) * ngs.dx
    if s_nu > 0 or s_tau > 0:
        u_nu, u_tau = d._normal_and_tangential(u)
        w_nu, w_tau = d._normal_and_tangential(w)
        spring = s_nu * u_nu * w_nu
        if s_tau > 0 and u_tau is not None:
            spring = spring + s_tau * ngs.InnerProduct(u_tau, w_tau)
        stiff += spring * ngs.ds(d.contact_name)
    stiff.Assemble()
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    K = solvers.to_scipy(stiff.mat)[free][:, free]
    KA = _viscous_on(d, free, solver)
    inv = solver or solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec,
                                   solvers.choose(d.scene["solver"], d.dim, d.ndof, iterative=True), fes=d.fes)
    full_in, full_out = np.zeros(d.ndof), np.zeros(d.ndof)

    def apply_inverse(x):
        full_in[free] = np.ravel(x)
        inv.solve(full_in, full_out)
        return full_out[free].copy()

    lam, _ = _largest_eigenvalue(K, KA, apply_inverse, np.ones(free.size), getattr(inv, "preconditioner", None))
    return Estimate(2.0 / lam, lam, s_nu, s_tau)


def _viscous_on(d, free, solver):
    """K_A on the free dofs: the iterative solver's own copy when it has one (the largest matrix of a 3D run)."""
    KA = getattr(solver, "K", None)
    return solvers.to_scipy(d.viscous.mat)[free][:, free] if KA is None else KA


def _largest_eigenvalue(K, KA, apply_inverse, v0, preconditioner=None):
    """(lambda_max, its eigenvector) of K x = lambda KA x; a named error when it cannot be had.

    Lanczos with the solves of the factored K_A; with an iterative solver (its ``preconditioner``, an approximate
    K_A^-1) instead LOBPCG for the smallest 1/lambda of K_A x = mu K x, which needs no solves: 12 iterations on the
    P2 block at 5.5k dofs, lambda within 1e-6 of Lanczos (measured)."""
    n = K.shape[0]
    if preconditioner is not None and n > 3:
        return _lobpcg(K, KA, preconditioner, v0)
    try:
        if n <= 3:
            lam = float(np.max(np.real(np.linalg.eigvals(np.linalg.solve(KA.toarray(), K.toarray())))))
            vec = v0
        else:
            Minv = LinearOperator((n, n), matvec=apply_inverse, dtype=float)
            vals, vecs = eigsh(K, k=1, M=KA, Minv=Minv, which="LM", tol=1e-4, v0=v0)
            lam, vec = float(vals[0]), vecs[:, 0]
    except (ArpackError, ArpackNoConvergence, np.linalg.LinAlgError) as err:
        raise ParameterError(f"the explicit scheme's step limit k_crit cannot be estimated for these values (the "
                             f"eigenvalue iteration failed: {str(err).splitlines()[0][:80]}); check the moduli "
                             "(E, a1, a2, c_nu, gamma_nu) or use scheme = 'implicit'") from None
    if not np.isfinite(lam) or lam <= 0:
        raise ParameterError(f"the explicit scheme's step limit k_crit is not finite for these values (lambda_max = "
                             f"{lam:.3g}); check the moduli (E, a1, a2, c_nu, gamma_nu) or use scheme = 'implicit'")
    return lam, vec


def _lobpcg(K, KA, preconditioner, v0):
    import warnings

    from scipy.sparse.linalg import lobpcg

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mu, vec = lobpcg(KA, np.asarray(v0, dtype=float)[:, None], B=K, M=preconditioner, largest=False, tol=1e-5,
                         maxiter=500)
    lam = 1.0 / float(mu[0])
    if any("not reaching the requested tolerance" in str(w.message) for w in caught) or not np.isfinite(lam) \
            or lam <= 0:
        raise ParameterError("the explicit scheme's step limit k_crit cannot be estimated for these values (LOBPCG did "
                             "not converge in 500 iterations); check the moduli (E, a1, a2, c_nu, gamma_nu) or use "
                             "scheme = 'implicit'")
    return lam, vec[:, 0]


class StepLimit:
    """The explicit scheme's limit for the springs that act, as the state evolves (module docs).

    Holds the envelope of the slopes met so far per contact quadrature point (normal, and the largest
    eigenvalue of the tangential slope), which only grows, and the estimate for it.

    Parameters
    ----------
    disc : workbench.discretisation.Discretisation
        Model A's, with its contact side.
    solver
        The factored K_A (the explicit scheme's).
    """

    def __init__(self, disc, solver):
        d = self.d = disc
        self.side, self.contact, self.solver = d.side, d.model.contact, solver
        self.world = d.world
        self.free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
        side = self.side
        if self.world.parallel:  # this rank's part: its facets' traces on all its dofs, the diagonals summed over ranks
            self.distributed = DistributedOperators(d, solver)
            self.T_nu, self.T_tau = side.T_nu, side.T_tau
            self.diag_KG, self.diag_KA = self.distributed.diagonals(self.free)
        else:
            self.KG = solvers.to_scipy(d.elastic.mat)[self.free][:, self.free]
            self.KA = _viscous_on(d, self.free, solver)
            self.T_nu = side.T_nu[:, self.free].tocsr()
            self.T_tau = [T[:, self.free].tocsr() for T in side.T_tau]
            self.diag_KG, self.diag_KA = self.KG.diagonal(), self.KA.diagonal()
        # (T^2)^T (w s) is the diagonal of T^T diag(w s) T: the indicator costs one sparse product
        self.sq_nu = self.T_nu.multiply(self.T_nu).T.tocsr()
        self.sq_tau = sum((T.multiply(T).T.tocsr() for T in self.T_tau), sp.csr_matrix(self.sq_nu.shape))
        self.tangential = self.contact.tangential and bool(side.T_tau)
        self.normal = np.zeros(side.points)
        self.tangent = np.zeros(side.points)
        self.estimate, self.indicator, self.updates, self._vector = None, (-np.inf, -np.inf), 0, None
        self._in, self._out = np.zeros(d.ndof), np.zeros(d.ndof)

    def slopes(self, u_nu, u_tau, beta_q):
        """(normal, tangential) spring per point at a state: the laws' slopes, the tangential one as the largest
        eigenvalue of d p_tau / d u_tau."""
        s_nu = self.contact.normal_slope(u_nu, beta_q, self.side.gap0)
        if not self.tangential:
            return s_nu, None
        S = self.contact.tangential_slope(u_tau, beta_q)
        if S.shape[-1] == 1:
            return s_nu, S[..., 0, 0]
        a, b, c = S[..., 0, 0], 0.5 * (S[..., 0, 1] + S[..., 1, 0]), S[..., 1, 1]
        return s_nu, 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)

    def grows(self, s_nu, s_tau) -> bool:
        """Whether a state's springs exceed the envelope somewhere (the per-step test, with :meth:`slopes` about 40 us
        at 160 points; every step, since an unstable contact mode alternates from step to step and a sparser check
        can see the same phase only: measured on tp4)."""
        return self.world.any(np.any(s_nu > self.normal) or (s_tau is not None and np.any(s_tau > self.tangent)))

    def absorb(self, s_nu, s_tau) -> bool:
        """Take a state's springs into the envelope; True when lambda_max must be estimated again."""
        np.maximum(self.normal, s_nu, out=self.normal)
        if s_tau is not None:
            np.maximum(self.tangent, s_tau, out=self.tangent)
        total, local = self._indicator()
        return (total > self.indicator[0] * (1.0 + REESTIMATE_TOTAL)
                or local > self.indicator[1] * (1.0 + REESTIMATE_LOCAL))

    def _indicator(self) -> tuple:
        """(int s_nu + s_tau da, max_i (K_G + D)_ii / (K_A)_ii) of the envelope."""
        w, world = self.side.weights, self.world
        springs = self.sq_nu @ (w * self.normal) + self.sq_tau @ (w * self.tangent)
        if world.parallel:  # (a shared dof's spring is summed over the ranks whose facets touch it)
            springs = self.distributed.cumulated(springs)[self.free]
        ratio = (self.diag_KG + springs) / self.diag_KA
        return world.sum(w @ (self.normal + self.tangent)), world.max(np.max(ratio, initial=0.0))

    def estimate_now(self) -> Estimate:
        """lambda_max for the envelope (warm started from the last eigenvector)."""
        w = self.side.weights
        if self.world.parallel:
            lam, self._vector = self.distributed.largest_eigenvalue(w * self.normal, w * self.tangent, self._vector)
            return self._estimated(lam)
        K = self.KG + self.T_nu.T @ sp.diags(w * self.normal) @ self.T_nu
        for T in self.T_tau:
            K = K + T.T @ sp.diags(w * self.tangent) @ T
        free, full_in, full_out = self.free, self._in, self._out

        def apply_inverse(x):
            full_in[free] = np.ravel(x)
            self.solver.solve(full_in, full_out)
            return full_out[free].copy()

        v0 = self._vector if self._vector is not None else np.ones(free.size)
        lam, self._vector = _largest_eigenvalue(K.tocsr(), self.KA, apply_inverse, v0,
                                                getattr(self.solver, "preconditioner", None))
        return self._estimated(lam)

    def _estimated(self, lam: float) -> Estimate:
        self.indicator = self._indicator()
        self.updates += 1
        self.estimate = self._described(lam)
        return self.estimate

    def _described(self, lam: float) -> Estimate:
        """The estimate lambda_max = ``lam`` of the envelope, with its largest springs and where they act."""
        world = self.world
        acting = tuple(int(world.sum(n)) for n in (np.count_nonzero(self.normal), np.count_nonzero(self.tangent),
                                                   self.side.points))
        return Estimate(2.0 / lam, lam, world.max(self.normal.max(initial=0.0)),
                        world.max(self.tangent.max(initial=0.0)), acting)

    def state(self) -> dict:
        """The envelope and the last estimate, as copies (a restart goes on with them)."""
        return {"step_limit_normal": self.normal.copy(), "step_limit_tangent": self.tangent.copy(),
                "step_limit": [*self.indicator, float(self.updates), self.estimate.lambda_max]}

    def restore(self, state: dict) -> None:
        self.normal[:], self.tangent[:] = state["step_limit_normal"], state["step_limit_tangent"]
        numbers = list(state["step_limit"])
        self.indicator, self.updates = (numbers[0], numbers[1]), int(numbers[2])
        self.estimate = self._described(numbers[3])


class DistributedOperators:
    """K_G, K_A, its solve and the springs T^T diag(w s) T of a body distributed over MPI processes
    (:mod:`workbench.parallel`), applied to this rank's parts of dof vectors: for the step limit's Lanczos
    (:func:`lanczos_largest`) and its diagonals. Vectors x that are multiplied are cumulated; products K x are
    distributed (each rank its part of the sum); inner products of one of each are summed over the ranks."""

    def __init__(self, d, solver):
        self.d, self.solver, self.world = d, solver, d.world
        self.x, self.y = d.u.vec.CreateVector(), d.u.vec.CreateVector()
        self.fixed = np.nonzero(~np.array(d.fes.FreeDofs(), dtype=bool))[0]

    def cumulated(self, values: np.ndarray) -> np.ndarray:
        from .parallel import cumulate

        return cumulate(self.y, values)

    def diagonals(self, free):
        """The diagonals of K_G and K_A on the free dofs (each rank's matrix holds its part of a shared dof's)."""
        d = self.d
        return tuple(self.cumulated(solvers.to_scipy(m.local_mat).diagonal())[free]
                     for m in (d.elastic.mat, d.viscous.mat))

    def _apply(self, mat, x: np.ndarray) -> np.ndarray:
        from .parallel import status

        self.x.FV().NumPy()[:] = x
        status(self.x, distributed=False)
        self.y.data = mat * self.x
        out = self.y.FV().NumPy().copy()
        out[self.fixed] = 0.0
        return out

    def largest_eigenvalue(self, ws_nu, ws_tau, v0=None):
        """(lambda_max of (K_G + T^T diag(w s) T) x = lambda K_A x, its eigenvector): ``ws_nu``, ``ws_tau`` are the
        weighted springs at this rank's contact points."""
        d, side = self.d, self.d.side

        def apply_K(x):
            y = self._apply(d.elastic.mat, x)
            if side is not None:
                y += side.T_nu_t @ (ws_nu * (side.T_nu @ x))
                for T, Tt in zip(side.T_tau, side.T_tau_t):
                    y += Tt @ (ws_tau * (T @ x))
            y[self.fixed] = 0.0
            return y

        def solve(y):
            out = np.zeros_like(y)
            self.solver.solve(y, out)
            return out

        if v0 is None:  # (the same start on every rank: a shared dof's copies must agree)
            v0 = np.ones(d.ndof)
            v0[self.fixed] = 0.0
        apply_KA = lambda x: self._apply(d.viscous.mat, x)  # noqa: E731
        inner = lambda x, y: self.world.sum(x @ y)  # noqa: E731
        if getattr(self.solver, "pre", None) is not None:  # (CG: LOBPCG with its preconditioner, no solves)
            mu, vector = lobpcg_smallest(apply_KA, apply_K, self.solver.precondition, inner, v0)
            return 1.0 / mu, vector
        return lanczos_largest(apply_K, apply_KA, solve, inner, v0)


def lobpcg_smallest(apply_A, apply_B, precondition, inner, v0, tol: float = 1e-9, maxiter: int = 500):
    """(mu_min, its eigenvector) of A x = mu B x (A, B symmetric positive definite) by LOBPCG with one vector
    (Knyazev): Rayleigh-Ritz on x, the preconditioned residual and the previous direction, one application of the
    preconditioner and of A and B an iteration, no solves; stopped when mu changes by less than ``tol`` relative
    (mu converges as the square of the vector's error). ``inner``, ``v0``: as :func:`lanczos_largest`. The step
    limit's estimate on several processes with conjugate gradients: lambda_max = 1 / mu_min of K_A x = mu K x.

    >>> import numpy as np
    >>> A, B = np.diag([1.0, 2.0, 4.0, 8.0]), np.diag([1.0, 4.0, 2.0, 1.0])
    >>> mu, _ = lobpcg_smallest(lambda x: A @ x, lambda x: B @ x, lambda r: r / np.diag(A), lambda x, y: x @ y,
    ...                         np.ones(4))
    >>> round(mu, 10)
    0.5
    """
    import scipy.linalg as la

    def normalised(v, Av, Bv):
        n = np.sqrt(max(inner(v, Bv), 1e-300))
        return v / n, Av / n, Bv / n

    x, Ax, Bx = normalised(np.asarray(v0, dtype=float).copy(), apply_A(v0), apply_B(v0))
    mu = inner(x, Ax)
    p = None
    for _ in range(maxiter):
        w = precondition(Ax - mu * Bx)
        Aw, Bw = apply_A(w), apply_B(w)
        if not inner(w, Bw) > 0:  # (the residual vanished: x is an eigenvector)
            break
        basis = [(x, Ax, Bx), normalised(w, Aw, Bw)] + ([p] if p is not None else [])
        while True:  # Rayleigh-Ritz on the basis; a basis that became dependent drops its last direction
            GA = np.array([[inner(u[0], v[1]) for v in basis] for u in basis])
            GB = np.array([[inner(u[0], v[2]) for v in basis] for u in basis])
            try:
                values, vectors = la.eigh(0.5 * (GA + GA.T), 0.5 * (GB + GB.T))
                break
            except (la.LinAlgError, ValueError):
                if len(basis) == 2:
                    return mu, x
                basis = basis[:-1]
        c = vectors[:, 0]
        new = [sum(ci * b[j] for ci, b in zip(c, basis)) for j in range(3)]
        p = normalised(*[sum(ci * b[j] for ci, b in zip(c[1:], basis[1:])) for j in range(3)])
        x, Ax, Bx = normalised(*new)
        mu_new = float(values[0])
        if abs(mu_new - mu) <= tol * abs(mu_new):
            return mu_new, x
        mu = mu_new
    else:
        raise ParameterError(f"the explicit scheme's step limit k_crit cannot be estimated for these values (LOBPCG "
                             f"did not settle in {maxiter} iterations); check the moduli (E, a1, a2, c_nu, gamma_nu) "
                             "or use scheme = 'implicit'")
    return mu, x


def lanczos_largest(apply_K, apply_KA, solve, inner, v0, tol: float = 1e-8, steps: int = 300):
    """(lambda_max, its eigenvector) of K x = lambda K_A x (K symmetric, K_A SPD) by Lanczos on K_A^-1 K, which is
    self-adjoint in the K_A inner product, with full reorthogonalisation: one solve and two products a step, stopped
    when the largest Ritz value changes by less than ``tol`` relative. ``inner(x, y)``: x^T y for x a vector and y a
    product (on several processes: summed over the ranks); ``v0``: the start.

    >>> import numpy as np
    >>> K, KA = np.diag([1.0, 4.0, 2.0]), np.diag([1.0, 2.0, 4.0])
    >>> lam, _ = lanczos_largest(lambda x: K @ x, lambda x: KA @ x, lambda y: np.linalg.solve(KA, y),
    ...                          lambda x, y: x @ y, np.ones(3))
    >>> round(lam, 12)
    2.0
    """
    r = np.asarray(v0, dtype=float).copy()
    p = apply_KA(r)
    beta = np.sqrt(max(inner(r, p), 0.0))
    if not beta > 0:
        raise ParameterError("the explicit scheme's step limit k_crit cannot be estimated: the start vector of the "
                             "eigenvalue iteration vanishes on the free dofs")
    basis, products, alphas, betas = [], [], [], []
    theta_old, vector = np.inf, None
    for j in range(steps):
        q, pq = r / beta, p / beta
        basis.append(q)
        products.append(pq)
        Kq = apply_K(q)
        alpha = inner(q, Kq)
        alphas.append(alpha)
        r = solve(Kq)
        for _ in range(2):  # full reorthogonalisation in the K_A inner product (twice is enough)
            for qi, pi in zip(basis, products):
                r -= inner(r, pi) * qi
        p = apply_KA(r)
        beta = np.sqrt(max(inner(r, p), 0.0))
        T = np.diag(alphas) + np.diag(betas, 1) + np.diag(betas, -1)
        values, vectors = np.linalg.eigh(T)
        theta = float(values[-1])
        # (decided on reduced numbers only: on several processes every rank stops at the same step)
        if (j > 0 and abs(theta - theta_old) <= tol * abs(theta)) or beta <= 1e-14 * abs(theta):
            vector = sum(c * b for c, b in zip(vectors[:, -1], basis))
            break
        theta_old = theta
        betas.append(beta)
    else:
        raise ParameterError(f"the explicit scheme's step limit k_crit cannot be estimated for these values (Lanczos "
                             f"did not settle in {steps} steps); check the moduli (E, a1, a2, c_nu, gamma_nu) or use "
                             "scheme = 'implicit'")
    if not np.isfinite(theta) or theta <= 0:
        raise ParameterError(f"the explicit scheme's step limit k_crit is not finite for these values (lambda_max = "
                             f"{theta:.3g}); check the moduli (E, a1, a2, c_nu, gamma_nu) or use scheme = 'implicit'")
    return theta, vector


def check(k: float, estimate: Estimate, bound: Estimate | None = None) -> None:
    """Raise :class:`StepTooLarge` with the estimate and the ways out when k > k_crit (``bound``: the limit with
    every spring acting, said too when it is lower: the run may reach it)."""
    if k > estimate.k_crit:
        also = ""
        if bound is not None and bound.k_crit < 0.99 * estimate.k_crit:
            also = (f"; with every spring acting, which later states may reach, k_crit = {bound.k_crit:.3g} s")
        raise StepTooLarge(
            f"k = {k:.3g} s exceeds the predicted stability limit of the explicit scheme, "
            f"k_crit = {estimate.k_crit:.3g} s (2 / lambda_max of K_A^-1 (K_G + springs); {estimate.describe()}"
            f"{also}). "
            f"Ways out: k <= {0.9 * estimate.k_crit:.2g}, or scheme = 'implicit' (stable), "
            "or allow_unstable = true to run anyway (recorded in the results).")
