"""Intel MKL PARDISO through ctypes: a supernodal sparse Cholesky factor, and the Schur complement of a matrix on
chosen unknowns, computed inside its factorization.

Why. On the 3D Hertz hemisphere at 46,938 dofs (one thread, in one process) PARDISO, with METIS ordering,
analyses and factors K in 1.16 s against 1.40 s for NGSolve's ``sparsecholesky``, and solves in 0.021 s against
0.070 s. Its Schur complement is what the condensed contact solver needs: K's condensed stiffness on the 5186
contact points took 4.7 s, against one back-substitution per point (an estimated 360 s with NGSolve's factor;
674 s measured when issue 22 was filed). (``python studies/contact_solver.py --pardiso --big``.)

MKL comes from the ``mkl`` wheel on x86-64 (a dependency of workbench there), loaded at the first use. Where it
cannot be loaded, :func:`available` is False and workbench keeps NGSolve's factor and forms condensed stiffnesses by
back-substitution. The 64-bit integer entry point (``pardiso_64``) is called, so MKL's interface layer does not
matter. Every call runs with one MKL thread (``mkl_set_num_threads_local``, given back after the call), as workbench
holds every BLAS pool at one thread while it computes (:mod:`workbench.running.threads`); MKL's threading layer is
left as the process has it.

Examples
--------
>>> import numpy as np, scipy.sparse as sp
>>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(4, 4)).tocsr()
>>> if available():  # (without MKL, the same numbers by dense algebra)
...     x, S = Factor(K).solve(np.ones(4)), schur_complement(K, np.array([3]))
... else:
...     x, S = np.linalg.solve(K.toarray(), np.ones(4)), 1.0 / np.linalg.inv(K.toarray())[3:, 3:]
>>> x.round(6).tolist(), S.round(6).tolist()  # the stiffness at the last unknown, the others free: 2 - 3/4
([2.0, 3.0, 3.0, 2.0], [[1.25]])
"""
from __future__ import annotations

import ctypes
import glob
import os
import site
import sys
import weakref

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

#: PARDISO's matrix types used here: real symmetric positive definite, real symmetric indefinite.
SPD, SYMMETRIC = 2, -2


def _load():
    """libmkl_rt from the environment's ``lib`` (the ``mkl`` wheel puts it there) or the loader's path; None if absent."""
    names = []
    user = site.USER_BASE or ""  # (pip install --user puts the wheel's libraries there)
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix, user, os.environ.get("CONDA_PREFIX", ""))):
        if prefix:
            names += sorted(glob.glob(os.path.join(prefix, "lib", "libmkl_rt.so*")), reverse=True)
    names += ["libmkl_rt.so.3", "libmkl_rt.so.2", "libmkl_rt.so", "mkl_rt.2.dll", "mkl_rt.dll"]
    for name in names:
        try:
            lib = ctypes.CDLL(name)
            lib.pardiso_64  # noqa: B018 (raises AttributeError where the entry point is missing)
        except (OSError, AttributeError):
            continue
        lib.MKL_Set_Num_Threads_Local.restype = ctypes.c_int
        lib.pardiso_64.restype = None
        return lib
    return None


_LIB = None
_LOADED = False


def available() -> bool:
    """Whether MKL PARDISO can be used here. MKL is loaded at the first call, not at ``import workbench``, which
    leaves the user's process as it was."""
    global _LIB, _LOADED
    if not _LOADED:
        _LIB, _LOADED = _load(), True
    return _LIB is not None


def _release(pt: np.ndarray, mtype: int, n: int, iparm: np.ndarray) -> None:
    """Frees PARDISO's memory of one handle (phase -1); called when its :class:`Factor` is collected."""
    if pt.any():
        _call(pt, mtype, -1, n, None, iparm, np.zeros(1), np.zeros(1), 1)


def _call(pt, mtype, phase, n, matrix, iparm, b, x, nrhs, perm=None):
    """One call of ``pardiso_64`` (MKL's 64-bit integer interface) with one MKL thread."""
    i64 = ctypes.c_int64
    ptr = np.ctypeslib.as_ctypes
    error = i64(0)
    data, indptr, indices = matrix if matrix is not None else (np.zeros(1), np.zeros(2, np.int64), np.zeros(1, np.int64))
    perm = np.zeros(max(n, 1), dtype=np.int64) if perm is None else perm
    before = _LIB.MKL_Set_Num_Threads_Local(ctypes.c_int(1))
    try:
        _LIB.pardiso_64(ptr(pt), ctypes.byref(i64(1)), ctypes.byref(i64(1)), ctypes.byref(i64(mtype)),
                        ctypes.byref(i64(phase)), ctypes.byref(i64(n)), data.ctypes.data_as(ctypes.c_void_p),
                        ptr(indptr), ptr(indices), ptr(perm), ctypes.byref(i64(nrhs)), ptr(iparm),
                        ctypes.byref(i64(0)), b.ctypes.data_as(ctypes.c_void_p), x.ctypes.data_as(ctypes.c_void_p),
                        ctypes.byref(error))
    finally:
        _LIB.MKL_Set_Num_Threads_Local(ctypes.c_int(before))
    if error.value:
        raise RuntimeError(f"MKL PARDISO failed in phase {phase} with error {error.value} (-4: a zero pivot, the "
                           "matrix is singular or not positive definite; -2: out of memory)")


def _upper(A: sp.spmatrix):
    """The upper triangle of a symmetric matrix in 0-based CSR with sorted columns and every diagonal entry stored
    (PARDISO's symmetric storage), as (data, indptr, indices) with 64-bit indices."""
    U = sp.triu(sp.csr_matrix(A), format="coo")
    n = A.shape[0]
    diagonal = np.arange(n)
    U = sp.coo_matrix((np.concatenate([U.data, np.zeros(n)]), (np.concatenate([U.row, diagonal]),
                       np.concatenate([U.col, diagonal]))), shape=A.shape).tocsr()  # (explicit zeros are kept)
    U.sort_indices()
    return (np.ascontiguousarray(U.data, dtype=np.float64), U.indptr.astype(np.int64), U.indices.astype(np.int64))


def _parameters(schur: bool) -> np.ndarray:
    """iparm: METIS ordering, 0-based indices, no scaling or matching (symmetric input), Schur complement if asked."""
    iparm = np.zeros(64, dtype=np.int64)
    iparm[0] = 1  # the values below, not PARDISO's defaults
    iparm[1] = 2  # nested dissection from METIS
    iparm[7] = 0  # iterative refinement only where pivots were perturbed
    iparm[9] = 13  # pivot perturbation 1e-13 (symmetric indefinite only)
    iparm[17] = -1  # report the factor's nonzeros in iparm[17]
    iparm[34] = 1  # 0-based indices
    iparm[35] = 1 if schur else 0  # the Schur complement, dense, returned in x at the factorization
    return iparm


class Factor:
    """The sparse Cholesky factor of a symmetric positive definite SciPy matrix ``A`` (PARDISO, METIS ordering).

    ``solve(b)`` solves for one right-hand side or for the columns of an n x m array (several at once cost far less
    than one at a time: the factor is read once per call). ``nonzeros``: the factor's. ``single``: the factor in
    single precision (half the memory; solves to about 10^-3 on a stiffness matrix, a preconditioner:
    :class:`workbench.discrete.solvers.MixedPrecision`).

    With ``keep`` (unknowns), the factorization eliminates the other unknowns first and stops there: ``schur`` is
    the dense Schur complement S = A_kk - A_ko A_oo^-1 A_ok on ``keep`` (sorted), computed inside this one
    factorization, and the factor of A_oo is kept. A solve then runs in parts: :meth:`forward` turns b into y, whose
    kept part is the condensed load b_k - A_ko A_oo^-1 b_o; the caller solves on the kept unknowns, with S or with
    anything that holds them (a contact problem), writes x_k into y's kept part, and :meth:`backward` returns the
    whole x. :meth:`solve` does the middle part with S's dense Cholesky. The kept unknowns' factor costs as much as
    a plain factorization (measured on the block at 28k and 77k dofs, 440 and 855 kept), and a solve in parts 1.1-1.2
    plain solves.

    >>> A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(4, 4)).tocsr()
    >>> if available():
    ...     F = Factor(A, keep=np.array([3]))
    ...     y = F.forward(np.ones(4))
    ...     S, y_k = F.schur.round(6).tolist(), round(float(y[3]), 6)
    ...     y[3] = y[3] / F.schur[0, 0]  # (the kept unknown solved by hand)
    ...     x = F.backward(y).round(6).tolist()
    ... else:
    ...     S, y_k, x = [[1.25]], 2.5, [2.0, 3.0, 3.0, 2.0]
    >>> S, y_k, x  # the last unknown's stiffness with the others free (2 - 3/4), its condensed load, the solution
    ([[1.25]], 2.5, [2.0, 3.0, 3.0, 2.0])
    """

    def __init__(self, A: sp.spmatrix, keep=None, single: bool = False):
        if not available():
            raise RuntimeError("MKL PARDISO is not available here (install the 'mkl' wheel)")
        self.n = A.shape[0]
        self.keep = None if keep is None else np.unique(np.asarray(keep, dtype=np.int64))
        self._matrix = _upper(A)
        self._dtype = np.float32 if single else np.float64
        if single:  # (PARDISO's iparm[27] = 1: the matrix, right-hand sides and solutions all in single precision)
            self._matrix = (self._matrix[0].astype(np.float32),) + self._matrix[1:]
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = _parameters(self.keep is not None)
        self._iparm[27] = 1 if single else 0
        self._perm = None
        self.schur, self._schur_factor = None, None
        out = np.zeros(1)
        if self.keep is not None:
            if self.n - self.keep.size < 2:  # (MKL's Schur complement then reads memory it never wrote: _schur)
                raise ValueError(f"a factor keeping {self.keep.size} of {self.n} unknowns: keep at most n - 2")
            self._iparm[35] = 2  # the Schur complement, and the factor of the other unknowns kept for solves in parts
            self._perm = np.zeros(self.n, dtype=np.int64)
            self._perm[self.keep] = 1
            self.schur = out = np.zeros((self.keep.size, self.keep.size), dtype=self._dtype)
        _call(self._pt, SPD, 12, self.n, self._matrix, self._iparm, np.zeros(1, self._dtype), out, 1, self._perm)
        self.nonzeros = int(self._iparm[17])
        weakref.finalize(self, _release, self._pt, SPD, self.n, self._iparm)

    def _phase(self, phase: int, b: np.ndarray) -> np.ndarray:
        nrhs = 1 if np.ndim(b) == 1 else np.shape(b)[1]
        # (PARDISO takes the right-hand sides one after the other, in the factor's precision; a copy: 331 writes)
        rhs = np.array(b, dtype=self._dtype, order="F")
        x = np.zeros_like(rhs, order="F")
        if self.n and nrhs:
            _call(self._pt, SPD, phase, self.n, self._matrix, self._iparm, rhs, x, nrhs, self._perm)
        return x if self._dtype is np.float64 else x.astype(np.float64)

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self.keep is None:
            return self._phase(33, b)
        y = self.forward(b)
        y[self.keep] = self.kept_solve(y[self.keep])
        return self.backward(y)

    def kept_solve(self, y_k: np.ndarray) -> np.ndarray:
        """S^-1 y_k on the kept unknowns (S's dense Cholesky, formed at the first call)."""
        if self._schur_factor is None:
            self._schur_factor = la.cho_factor(self.schur, check_finite=False)
        return la.cho_solve(self._schur_factor, y_k, check_finite=False)

    def forward(self, b: np.ndarray) -> np.ndarray:
        """The first part of a solve (``keep`` given): y, whose kept part is the condensed load (class docs)."""
        return self._phase(331, b)

    def backward(self, y: np.ndarray) -> np.ndarray:
        """The last part of a solve: x from :meth:`forward`'s y with the kept unknowns' values in its kept part."""
        return self._phase(333, y)


def schur_complement(A: sp.spmatrix, keep: np.ndarray) -> np.ndarray:
    """A_kk - A_ko A_oo^-1 A_ok for the symmetric positive definite ``A``, kept unknowns ``keep``, in their order.

    It is the stiffness the kept unknowns feel with the others free, ((A^-1)_kk)^-1, computed inside one partial
    factorization (the others eliminated first) instead of one solve per kept unknown.
    """
    keep = np.asarray(keep, dtype=np.int64)
    m = keep.size
    if m == 0:
        return np.zeros((0, 0))
    if m == A.shape[0]:
        return sp.csr_matrix(A).toarray()[np.ix_(keep, keep)]
    order = np.argsort(keep)
    S = _schur(_upper(A), A.shape[0], SPD, keep[order])
    out = np.empty_like(S)
    out[np.ix_(order, order)] = S
    return out


def compliance(A: sp.spmatrix, B: sp.spmatrix) -> np.ndarray:
    """B A^-1 B^T for the symmetric positive definite ``A`` and a sparse ``B`` (rows: points, e.g. a trace).

    The Schur complement of [[A, B^T], [B, 0]] on its second block is -B A^-1 B^T; PARDISO computes it inside one
    factorization of that symmetric indefinite matrix (A's unknowns eliminated first need no pivoting).
    """
    m = B.shape[0]
    if m == 0:
        return np.zeros((0, 0))
    n = A.shape[0]
    saddle = sp.bmat([[sp.csr_matrix(A), sp.csr_matrix(B).T], [sp.csr_matrix(B), None]], format="csr")
    S = -_schur(_upper(saddle), n + m, SYMMETRIC, np.arange(n, n + m))
    return 0.5 * (S + S.T)


def _schur(matrix, n: int, mtype: int, keep: np.ndarray) -> np.ndarray:
    """The dense Schur complement on the sorted unknowns ``keep`` (one handle, released at once). Where one unknown
    is left to eliminate, by dense algebra: MKL's Schur complement then reads memory it never wrote, and crashed the
    process (the rod at h = 0.5, its two free dofs and one contact dof; deterministic with MALLOC_PERTURB_ set)."""
    if n - keep.size < 2:
        return _dense_schur(matrix, n, keep)
    if not available():
        raise RuntimeError("MKL PARDISO is not available here (install the 'mkl' wheel)")
    pt, iparm = np.zeros(64, dtype=np.int64), _parameters(True)
    perm = np.zeros(n, dtype=np.int64)
    perm[keep] = 1
    S = np.zeros((keep.size, keep.size))
    try:
        _call(pt, mtype, 12, n, matrix, iparm, np.zeros(1), S, 1, perm)
    finally:
        _release(pt, mtype, n, iparm)
    return S


def _dense_schur(matrix, n: int, keep: np.ndarray) -> np.ndarray:
    """A_kk - A_ko A_oo^-1 A_ok from the upper triangle (:func:`_upper`'s triple), densely: for a matrix with one
    unknown (or none) outside ``keep``."""
    data, indptr, indices = matrix
    U = sp.csr_matrix((data, indices, indptr), shape=(n, n)).toarray()
    A = U + np.triu(U, 1).T
    other = np.setdiff1d(np.arange(n), keep)
    S = A[np.ix_(keep, keep)]
    if other.size:
        S = S - A[np.ix_(keep, other)] @ np.linalg.solve(A[np.ix_(other, other)], A[np.ix_(other, keep)])
    return S
