"""The largest eigenvalue of a body on boundary springs, K x = lambda K_A x with K = K_G + T^T diag(w s) T: what the
explicit scheme's step limit needs (:mod:`workbench.discrete.stability`), as linear algebra.

A discretisation hands out the operators of its body (:meth:`workbench.discrete.discretisation.Discretisation.springs`):
:class:`SpringOperators` on one process, assembled with SciPy and solved by Lanczos (ARPACK) with the factored
K_A, or by LOBPCG with an iterative solver's preconditioner; a body distributed over MPI processes has its own
(:class:`workbench.parallel.algebra.DistributedOperators`), which runs :func:`lanczos_largest` or
:func:`lobpcg_smallest` with products and inner products reduced over the ranks. Both offer the same three methods:
``largest_eigenvalue(ws_nu, ws_tau, v0)``, ``diagonals()`` and ``cumulated(values)``.

Examples
--------
>>> import numpy as np, scipy.sparse as sp
>>> K, KA = sp.diags([2.0, 6.0, 3.0]).tocsr(), sp.diags([1.0, 2.0, 3.0]).tocsr()
>>> lam, _ = largest_eigenvalue(K, KA, lambda x: x / KA.diagonal(), np.ones(3))
>>> round(lam, 12)
3.0
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, LinearOperator, eigsh

from ..errors import ParameterError
from . import solvers


class SpringOperators:
    """K_G, K_A on the free dofs and the contact side's traces of a discretisation on one process, with the factored
    (or iteratively solved) K_A ``solver``: the operators of the step limit's eigenvalue problem."""

    def __init__(self, d, solver):
        self.d, self.solver = d, solver
        self.free = free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
        self.KG = solvers.to_scipy(d.elastic.mat)[free][:, free]
        self.KA = solver.matrix if solver.matrix is not None else solvers.to_scipy(d.viscous.mat)[free][:, free]
        side = d.side
        self.T_nu = side.T_nu[:, free].tocsr() if side is not None else sp.csr_matrix((0, free.size))
        self.T_tau = [T[:, free].tocsr() for T in side.T_tau] if side is not None else []
        self._in, self._out = np.zeros(d.ndof), np.zeros(d.ndof)

    def diagonals(self):
        """The diagonals of K_G and K_A on the free dofs."""
        return self.KG.diagonal(), self.KA.diagonal()

    @staticmethod
    def cumulated(values: np.ndarray) -> np.ndarray:
        """Per-dof sums of contributions (one process: they are whole already)."""
        return values

    def largest_eigenvalue(self, ws_nu, ws_tau, v0=None):
        """(lambda_max of (K_G + T^T diag(w s) T) x = lambda K_A x, its eigenvector on the free dofs): ``ws_nu``,
        ``ws_tau`` the weighted springs w s at the contact points (``v0``: a start, e.g. the last eigenvector)."""
        K = self.KG
        if self.T_nu.shape[0]:
            K = K + self.T_nu.T @ sp.diags(ws_nu) @ self.T_nu
            for T in self.T_tau:
                K = K + T.T @ sp.diags(ws_tau) @ T
        free, full_in, full_out = self.free, self._in, self._out

        def apply_inverse(x):
            full_in[free] = np.ravel(x)
            self.solver.solve(full_in, full_out)
            return full_out[free].copy()

        start = v0 if v0 is not None else np.ones(free.size)
        return largest_eigenvalue(K.tocsr(), self.KA, apply_inverse, start, self.solver.preconditioner)


def largest_eigenvalue(K, KA, apply_inverse, v0, preconditioner=None):
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
