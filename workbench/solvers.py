"""Factor a constant symmetric positive definite matrix once; solve many times.

``banded``: reverse Cuthill–McKee ordering of the free dofs, then LAPACK's
banded Cholesky (``dpbtrf``/``dpbtrs`` via SciPy). On thin domains (the paper's
slab) the bandwidth is ~2 (ny + 1) and a back-substitution is 2–4x faster than
NGSolve's ``sparsecholesky`` (measured in ``studies/bench_explicit_step.py``).
``sparsecholesky`` / ``umfpack``: NGSolve's own direct solvers.
``auto`` takes ``banded`` when the ordered bandwidth is small against the size.

All solvers work on NumPy views of NGSolve vectors: ``solve(rhs, out)`` writes
the solution on the free dofs and zero on the Dirichlet dofs.

Examples
--------
>>> import numpy as np, scipy.sparse as sp
>>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()
>>> s = BandedCholesky(K, np.arange(1, 5))
>>> out = np.zeros(5); s.solve(np.ones(5), out); out.round(3).tolist()
[0.0, 2.0, 3.0, 3.0, 2.0]
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_solve_banded, cholesky_banded, get_lapack_funcs
from scipy.sparse.csgraph import reverse_cuthill_mckee

def to_scipy(mat) -> sp.csr_matrix:
    """An NGSolve sparse matrix as SciPy CSR (the full matrix, also for symmetric storage)."""
    rows, cols, vals = mat.COO()
    rows, cols, vals = np.asarray(rows), np.asarray(cols), np.asarray(vals)
    n = mat.height
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    if getattr(mat, "symmetric", False) or not np.any(rows < cols):  # lower triangle stored only
        A = A + sp.tril(A, -1).T
    return A.tocsr()


class BandedCholesky:
    """RCM-ordered banded Cholesky of ``K[free][:, free]`` (``perm``: a precomputed RCM order of it)."""

    name = "banded"

    def __init__(self, K: sp.spmatrix, free: np.ndarray, perm=None):
        Kf = K[free][:, free].tocsr()
        if perm is None:
            perm = reverse_cuthill_mckee(Kf, symmetric_mode=True)
        self.order = free[perm]  # position i of the banded system is dof order[i]
        Kp = Kf[perm][:, perm].tocoo()
        upper = Kp.row <= Kp.col
        self.bandwidth = bw = int(np.max(Kp.col[upper] - Kp.row[upper]))
        ab = np.zeros((bw + 1, Kf.shape[0]))
        ab[bw + Kp.row[upper] - Kp.col[upper], Kp.col[upper]] = Kp.data[upper]
        self.factor = cholesky_banded(ab, lower=False, check_finite=False)
        self.fixed = np.setdiff1d(np.arange(K.shape[0]), free)
        # LAPACK's dpbtrs itself, as cho_solve_banded calls it, without the wrapper's checks (0.05 ms a step at 5k dofs)
        (self._pbtrs,) = get_lapack_funcs(("pbtrs",), (self.factor,))

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        x, info = self._pbtrs(self.factor, rhs[self.order], lower=0, overwrite_b=1)
        if info != 0:
            raise ValueError(f"dpbtrs: illegal value in argument {-info}")
        out[self.fixed] = 0.0
        out[self.order] = x


    def solve_many(self, R: np.ndarray) -> np.ndarray:
        """Solutions for the columns of R (n x m), zero on the Dirichlet dofs."""
        X = np.zeros_like(R)
        X[self.order] = cho_solve_banded((self.factor, False), R[self.order], check_finite=False)
        return X


class NGSolveDirect:
    """NGSolve's ``Inverse`` on the free dofs (``sparsecholesky`` needs a symmetric matrix)."""

    def __init__(self, mat, freedofs, method: str, fes_vector):
        self.name = method
        self.inv = mat.Inverse(freedofs, inverse=method)
        self.x, self.y = fes_vector.CreateVector(), fes_vector.CreateVector()

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        self.y.FV().NumPy()[:] = rhs
        self.x.data = self.inv * self.y
        out[:] = self.x.FV().NumPy()

    def solve_many(self, R: np.ndarray) -> np.ndarray:
        """Solutions for the columns of R (n x m), zero on the Dirichlet dofs."""
        X = np.empty_like(R)
        for j in range(R.shape[1]):
            self.solve(R[:, j], X[:, j])
        return X


def rcm(K: sp.spmatrix, free: np.ndarray):
    """(RCM permutation of K[free][:, free], its bandwidth)."""
    Kf = K[free][:, free].tocsr()
    perm = reverse_cuthill_mckee(Kf, symmetric_mode=True)
    Kp = Kf[perm][:, perm].tocoo()
    return perm, (int(np.max(np.abs(Kp.row - Kp.col))) if Kp.nnz else 0)


#: Largest band storage ``auto`` takes the banded Cholesky for (the slab of tp5 at 160k dofs: 0.47 GB, banded 1.7x
#: faster per solve than sparsecholesky; the P2 block at 118k dofs: 2.2 GB, 4.6 GB peak).
BAND_BYTES = 1.0e9


def factor(mat, freedofs, vector, method: str = "auto"):
    """Factor an NGSolve SPD matrix on ``freedofs`` with ``method`` (see module docs)."""
    free = np.nonzero(np.array(freedofs, dtype=bool))[0]
    if method in ("banded", "auto"):
        K = to_scipy(mat)
        perm, bandwidth = rcm(K, free)
        # a narrow band (thin bodies: ~2 (ny + 1) dofs) solves 2-4x faster than the sparse factor; but its storage,
        # (bandwidth + 1) x n doubles, grows like n^(5/3) in 3D (the P2 block at 271k dofs: 11.7 GB, 17 GB peak with
        # the copies SciPy makes): above BAND_BYTES the sparse factor
        narrow = bandwidth <= max(64, 0.02 * free.size) and 8.0 * (bandwidth + 1) * free.size <= BAND_BYTES
        if method == "banded" or narrow:
            return BandedCholesky(K, free, perm)
        method = "sparsecholesky"
    return NGSolveDirect(mat, freedofs, method, vector)
