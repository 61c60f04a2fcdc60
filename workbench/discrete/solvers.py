"""Factor a constant symmetric positive definite matrix once; solve many times.

``banded``: reverse Cuthill–McKee ordering of the free dofs, then LAPACK's
banded Cholesky (``dpbtrf``/``dpbtrs`` via SciPy). On thin domains (the paper's
slab) the bandwidth is ~2 (ny + 1) and a back-substitution is 2–4x faster than
NGSolve's ``sparsecholesky`` (measured in ``studies/bench_explicit_step.py``).
``pardiso``: MKL PARDISO's supernodal Cholesky, METIS-ordered (:mod:`workbench.discrete.pardiso`): on the 3D
hemisphere at 47k dofs it factors 1.2x and solves 3.3x faster than NGSolve's ``sparsecholesky``, and it
forms a condensed contact stiffness inside one factorization (:meth:`Solver.condensed_stiffness`). ``auto`` takes
it where the band is wide, when MKL can be loaded.
``sparsecholesky`` / ``umfpack``: NGSolve's own direct solvers.
``cg``: conjugate gradients preconditioned by smoothed-aggregation AMG (pyamg) with
the rigid-body modes as near-null space, warm started from ``out`` (the explicit scheme puts its velocity
extrapolated from the last two steps there),
to a relative residual of :data:`CG_TOL`: no factor, so memory grows like the matrix
(the P2 block at 271k dofs, a whole explicit run: 2.1 GB peak and 37 s setup against 5.1 GB and 115 s with
NGSolve's sparse factor; 7.9 s a step against 2.1 s; `studies/bench_3d_solver.py`).
``mixed``: conjugate gradients in double precision on PARDISO's factor in single precision (:class:`MixedPrecision`:
half the factor's memory, 4-5 iterations a solve).
``cg`` and ``mixed`` serve the explicit scheme, and the implicit ones with the coupled contact solver (which needs
products with K^-1 only); the condensed contact solver takes one solve per contact dof and wants a factor.
``auto`` takes ``banded`` when the ordered bandwidth is small against the size, else ``pardiso``, and, where an
iterative solver serves, in 3D ``mixed`` when the double factor would exceed :data:`FACTOR_BYTES` and the single one
would not, else ``cg`` (:func:`choose`).

Every solver is a :class:`Solver` (the protocol, with its defaults): ``solve(rhs, out)``
writes the solution on the free dofs and zero on the Dirichlet dofs (NumPy views of
NGSolve vectors), ``solve_many(R)`` does so for the columns of R; ``warm_start`` says
whether ``solve`` starts from the values in ``out``, ``iterative`` whether it iterates
(then ``last_iterations`` counts the last solve's iterations), ``preconditioner`` is an
approximate inverse on the free dofs (a SciPy operator, or None) and ``matrix`` the
matrix on the free dofs when the solver holds one as SciPy CSR (else None). A body
distributed over MPI processes has its own (:mod:`workbench.parallel.algebra`).

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
import scipy.linalg as la
import scipy.sparse as sp
from scipy.linalg import cho_solve_banded, cholesky_banded, get_lapack_funcs
from scipy.sparse.csgraph import reverse_cuthill_mckee

from . import pardiso


class Solver:
    """The solver protocol (module docs) and its defaults: a direct solver that holds no SciPy matrix."""

    name = ""
    warm_start = False
    iterative = False
    preconditioner = None
    matrix = None
    last_iterations = 0

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        raise NotImplementedError

    def solve_many(self, R: np.ndarray) -> np.ndarray:
        """Solutions for the columns of R (n x m), zero on the Dirichlet dofs."""
        X = np.zeros_like(R)
        for j in range(R.shape[1]):
            self.solve(R[:, j], X[:, j])
        return X

    def condensed_stiffness(self, C: np.ndarray, B=None):
        """The dense stiffness the contact points feel, ((K^-1)_CC)^-1 for dofs C or (B K^-1 B^T)^-1 for a trace B,
        computed inside a factorization (:mod:`workbench.discrete.pardiso`); None where this solver cannot (then
        the caller pays one back-substitution per point)."""
        return None

    def split(self, C: np.ndarray):
        """Solves in two parts around the dofs C (:class:`SplitSolve`), where the factor keeps C last; else None."""
        return None

    def approximate_compliance(self, C: np.ndarray):
        """(K^-1)_CC for dofs C, dense and approximate (a preconditioner's), where this solver forms it at little
        cost; else None."""
        return None

    def kept(self, C: np.ndarray, again: bool = False):
        """(the condensed stiffness on the dofs C, its inverse: their compliance, the solve in two parts around them),
        from one factorization that keeps C last, where this solver makes one (asked before any solve, or ``again``:
        its factor made anew); else None, and no work done."""
        return None


class Multiple:
    """c A for a dense symmetric matrix A, read without forming it: a block or a row cut from A comes scaled (a
    copy, as NumPy's fancy indexing gives), a product is A's scaled. :class:`Scaled`'s condensed stiffness c S and
    compliance S^-1 / c for each multiple of one factor: formed, each was an n x n copy per step size (at 2525
    contact dofs 51 MB and about 25 ms; error control met 57 step sizes on the hemisphere at 47k dofs).

    Whatever would read the whole matrix through NumPy (``np.asarray``, ``np.diag``) is refused, so that no copy is
    made unseen: :meth:`diagonal` gives the diagonal.

    >>> A = Multiple(np.array([[2.0, 1.0], [1.0, 3.0]]), 0.5)
    >>> (A @ np.ones(2)).tolist(), A[1].tolist(), A[np.ix_([1], [1])].tolist(), A.diagonal().tolist()
    ([1.5, 2.0], [0.5, 1.5], [[1.5]], [1.0, 1.5])
    """

    __slots__ = ("base", "c")

    def __init__(self, base: np.ndarray, c: float):
        self.base, self.c = base, float(c)

    shape = property(lambda self: self.base.shape)
    ndim = property(lambda self: self.base.ndim)
    dtype = property(lambda self: self.base.dtype)

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, key) -> np.ndarray:
        return self.c * self.base[key]

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        return self.c * (self.base @ x)

    def diagonal(self) -> np.ndarray:
        return self.c * self.base.diagonal()

    def __array__(self, dtype=None, copy=None):
        raise TypeError("a Multiple is read by blocks, rows, products and diagonal() only: forming c A whole would "
                        "copy it")


class Scaled(Solver):
    """The solver of c K from a direct ``solver`` of K: one factor serves every multiple of K (a Kelvin-Voigt body
    with A = tau G, whose step operators a0 K_A + K_G are (a0 tau + 1) K_G; Model B's trapezoid rule with relaxation
    tensors that are multiples of A).

    What the base's factorization gives about the contact dofs (their condensed stiffness, the solve in parts around
    them) is scaled too: c S and the parts of c K's solve. ``found`` holds it for every multiple of one base (give each
    the same dict), so a factorization that keeps the contact dofs is made once for all of them.

    >>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()
    >>> out = np.zeros(5)
    >>> Scaled(BandedCholesky(K, np.arange(1, 5)), 2.0).solve(np.ones(5), out); out.round(12).tolist()
    [0.0, 1.0, 1.5, 1.5, 1.0]
    """

    def __init__(self, solver: Solver, c: float, found: dict | None = None):
        self.base, self.c, self.name = solver, float(c), solver.name
        self.found = {} if found is None else found

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        self.base.solve(rhs, out)
        out /= self.c

    def solve_many(self, R: np.ndarray) -> np.ndarray:
        return self.base.solve_many(R) / self.c

    def condensed_stiffness(self, C: np.ndarray, B=None):
        if B is not None:  # (a trace: Model B's, never shared so far; the base's, scaled)
            S = self.base.condensed_stiffness(C, B)
            return None if S is None else self.c * S
        found = self._found(C, lambda: dict(stiffness=self.base.condensed_stiffness(C), split=self.base.split(C)))
        return None if found is None else self.c * found["stiffness"]

    def split(self, C: np.ndarray):
        found = self._found(C, lambda: None)
        return None if found is None or found["split"] is None else found["split"].scaled(self.c)

    def kept(self, C: np.ndarray, again: bool = False):
        # (``again``: the base's factorization made anew where it does not keep C already; where it does, the
        # multiples share it as it is. The compliance's inverse, a dense Cholesky of C's size, is formed once too:
        # 1.07 s at 2525 dofs, for each of the 57 step sizes of BDF2 on hertz3d at 47k dofs under rtol = 1e-3)
        def make():
            made = self.base.kept(C, again or bool(self.found))
            return None if made is None else dict(zip(("stiffness", "compliance", "split"), made))

        found = self._found(C, make)
        if found is None or found["split"] is None:
            return None
        if "compliance" not in found:
            found["compliance"] = inverse(found["stiffness"])
        return (Multiple(found["stiffness"], self.c), Multiple(found["compliance"], 1.0 / self.c),
                found["split"].scaled(self.c))

    def _found(self, C: np.ndarray, make):
        """What the base's factorization gave about C ({stiffness, split (None where it cannot), compliance where
        formed}), made by ``make`` where ``found`` holds another C (or nothing), and held for the base's other
        multiples; None where it cannot."""
        if "C" not in self.found or not np.array_equal(self.found["C"], C):
            made = make()
            if made is None or made["stiffness"] is None:
                return None
            self.found.clear()
            self.found.update(made, C=np.array(C))
        return self.found


def to_scipy(mat) -> sp.csr_matrix:
    """An NGSolve sparse matrix as SciPy CSR (the full matrix, also for symmetric storage)."""
    rows, cols, vals = mat.COO()
    rows, cols, vals = np.asarray(rows), np.asarray(cols), np.asarray(vals)
    n = mat.height
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    if not np.any(rows < cols):  # symmetric storage: the lower triangle only (SPD matrices here)
        A = A + sp.tril(A, -1).T
    return A.tocsr()


def inverse(A: np.ndarray) -> np.ndarray:
    """The inverse of the symmetric positive definite A from its Cholesky factor (LAPACK's potri: a third of the
    work of solving with the identity; at 1590 points 0.12 s against 0.45 s). A condensed stiffness's inverse is
    the points' compliance, and the other way round.

    >>> inverse(np.array([[2.0, 1.0], [1.0, 2.0]])).round(6).tolist()
    [[0.666667, -0.333333], [-0.333333, 0.666667]]
    """
    potrf, potri = la.get_lapack_funcs(("potrf", "potri"), (A,))
    factor, info = potrf(A, lower=True, clean=False, overwrite_a=False)
    if info == 0:
        factor, info = potri(factor, lower=True, overwrite_c=True)
    if info != 0:
        raise la.LinAlgError(f"the condensed stiffness is not positive definite (LAPACK info {info})")
    n, block = len(factor), 256  # (the upper triangle from the lower one, a band of rows at a time: no n x n temporary)
    for i in range(0, n, block):
        factor[i:i + block, i + block:] = factor[i + block:, i:i + block].T
        diagonal = factor[i:i + block, i:i + block]
        upper = np.triu_indices(len(diagonal), 1)
        diagonal[upper] = diagonal.T[upper]
    return factor


class _HoldsMatrix:
    """Condensed stiffnesses from the SciPy matrix ``matrix`` on the ``free`` dofs, by MKL PARDISO's Schur
    complement, where MKL is available (:meth:`Solver.condensed_stiffness`)."""

    def _free_positions(self, C: np.ndarray):
        """The positions of the dofs C among the free dofs (the rows of ``matrix``); None if one of them is held."""
        where = np.full(self.size, -1, dtype=np.int64)
        where[self.free] = np.arange(self.free.size)
        keep = where[C]
        return None if np.any(keep < 0) else keep

    def condensed_stiffness(self, C: np.ndarray, B=None):
        if not pardiso.available():
            return None
        if B is None:
            keep = self._free_positions(C)  # (None: a contact dof held by a Dirichlet condition has no stiffness)
            return None if keep is None else pardiso.schur_complement(self.matrix, keep)
        S = pardiso.compliance(self.matrix, sp.csr_matrix(B)[:, self.free])
        return inverse(S) if S.size else S


class BandedCholesky(_HoldsMatrix, Solver):
    """RCM-ordered banded Cholesky of ``K[free][:, free]`` (``perm``: a precomputed RCM order of it)."""

    name = "banded"

    def __init__(self, K: sp.spmatrix, free: np.ndarray, perm=None, block=None):
        self.size, self.free = K.shape[0], free
        self.matrix = Kf = free_block(K, free) if block is None else block
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


class PardisoCholesky(_HoldsMatrix, Solver):
    """MKL PARDISO's supernodal Cholesky of ``K[free][:, free]``, METIS-ordered (:mod:`workbench.discrete.pardiso`).

    >>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()
    >>> s = PardisoCholesky(K, np.arange(1, 5)) if pardiso.available() else BandedCholesky(K, np.arange(1, 5))
    >>> out = np.zeros(5); s.solve(np.ones(5), out); out.round(3).tolist()  # (dof 0 held)
    [0.0, 2.0, 3.0, 3.0, 2.0]
    """

    name = "pardiso"

    def __init__(self, K: sp.spmatrix, free: np.ndarray, block=None):
        self.size, self.free = K.shape[0], free
        self.matrix = free_block(K, free) if block is None else block  # (block: the cut, where already made)
        self._factor = None  # (factored at the first use: a condensed stiffness asked first is formed inside it)
        self._kept = None

    @property
    def factor(self) -> pardiso.Factor:
        if self._factor is None:
            self._factor = pardiso.Factor(self.matrix)
        return self._factor

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        x = self.factor.solve(rhs[self.free])
        out[:] = 0.0
        out[self.free] = x

    def solve_many(self, R: np.ndarray) -> np.ndarray:
        X = np.zeros_like(R)
        X[self.free] = self.factor.solve(R[self.free])
        return X

    def condensed_stiffness(self, C: np.ndarray, B=None):
        """As :meth:`Solver.condensed_stiffness`; for dofs C asked before any solve, formed inside the factorization
        itself, which keeps C last (:class:`pardiso.Factor` with ``keep``): one factorization instead of two."""
        if B is None and self._factor is None:
            keep = self._free_positions(C)
            if keep is not None and 0 < keep.size < self.matrix.shape[0] and keep.size == np.unique(keep).size:
                self._factor, self._kept = pardiso.Factor(self.matrix, keep), C.copy()
                at = np.searchsorted(self._factor.keep, keep)
                return self._factor.schur[np.ix_(at, at)]
        return super().condensed_stiffness(C, B)

    def kept(self, C: np.ndarray, again: bool = False):
        if again and self._free_positions(C) is not None:
            self._factor = self._kept = None  # (the old factor freed first: one factor's memory at a time)
        if self._factor is not None or self._free_positions(C) is None:
            return None
        stiffness = self.condensed_stiffness(C)
        split = self.split(C)
        return None if split is None else (stiffness, inverse(stiffness), split)

    def split(self, C: np.ndarray):
        """Solves in parts on the dofs C (:class:`SplitSolve`) where the factor keeps them last, else None."""
        if self._kept is None or not np.array_equal(C, self._kept):
            return None
        return SplitSolve(self, C)


class SplitSolve:
    """A solve of c K u = r in two parts around the dofs C that a :class:`PardisoCholesky` factor of K keeps last:
    :meth:`free_displacement` at C, S_C^-1 y_C / c from the load C feels with the other dofs free, y_C = r_C -
    K_CO K_OO^-1 r_O (S_C the condensed stiffness; y_C is the same for every multiple c of K); then :meth:`expand` the
    values u_C found there (a contact problem solved with c S_C) to the whole u. One solve's work in all, where the
    contact step otherwise pays two solves (the free displacement, then the contact forces' response).

    ``c`` (1: K itself) serves the multiples of K from its one factor (:class:`Scaled`): u_O = K_OO^-1 (r_O / c -
    K_OC u_C), so the first part's y_O, which depends on r_O alone (C is eliminated last), is divided by c before the
    second part.
    """

    def __init__(self, solver: PardisoCholesky, C: np.ndarray, c: float = 1.0):
        self.solver, self.C, self.c = solver, C, float(c)
        self.at = solver._free_positions(C)
        self._sorted = np.searchsorted(solver.factor.keep, self.at)  # (the factor's kept dofs are sorted)
        self._y = None

    def scaled(self, c: float) -> "SplitSolve":
        """The solve in parts of c K (this one's K) with the same factor."""
        return SplitSolve(self.solver, self.C, c)

    def holds(self) -> bool:
        """Whether the solver's factor still keeps C last (a factor shared by several operators may have been made
        again keeping more dofs since: :class:`Scaled`)."""
        return self.solver._kept is not None and np.array_equal(self.solver._kept, self.C)

    def free_displacement(self, rhs: np.ndarray) -> np.ndarray:
        """u_C for the load ``rhs`` (a dof vector) with nothing acting at C, S_C^-1 y_C / c, in C's order."""
        s = self.solver
        self._y = s.factor.forward(rhs[s.free])
        return s.factor.kept_solve(self._y[s.factor.keep])[self._sorted] / self.c

    def condensed_load(self, rhs: np.ndarray) -> np.ndarray:
        """y_C for the load ``rhs``, in C's order: the first part of the solve alone, for a caller that holds C's
        compliance (u_C = S_C^-1 y_C / c is then a dense product, and S_C's own Cholesky factor is never formed)."""
        s = self.solver
        self._y = s.factor.forward(rhs[s.free])
        return self._y[self.at]

    def expand(self, u_C: np.ndarray, out: np.ndarray) -> None:
        """The solution on the free dofs, given its values ``u_C`` on C, for the last load (the held dofs of ``out``
        are the caller's, left as they are)."""
        s = self.solver
        if self.c != 1.0:
            self._y /= self.c  # (its part at C is overwritten next)
        self._y[self.at] = u_C
        out[s.free] = s.factor.backward(self._y)
        out[self.C] = u_C  # (exactly: the contact problem's values, no round-off of the backward part)


class NGSolveDirect(Solver):
    """NGSolve's ``Inverse`` on the free dofs (``sparsecholesky`` needs a symmetric matrix)."""

    def __init__(self, mat, freedofs, method: str, fes_vector):
        self.name = method
        self.inv = mat.Inverse(freedofs, inverse=method)
        self.x, self.y = fes_vector.CreateVector(), fes_vector.CreateVector()

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        self.y.FV().NumPy()[:] = rhs
        self.x.data = self.inv * self.y
        out[:] = self.x.FV().NumPy()



class _Iterative(Solver):
    """What the iterative solvers share: the free block of K, warm starts from ``out``, iteration counts, and the
    solution written back with zeros on the held dofs."""

    warm_start = iterative = True  # (the scheme puts its first guess in ``out``)

    def __init__(self, K: sp.spmatrix, free: np.ndarray, block=None):
        self.free = free
        self.matrix = free_block(K, free) if block is None else block
        self.fixed = np.setdiff1d(np.arange(K.shape[0]), free)
        self.iterations = self.solves = 0  # summed over the solves
        self.last_iterations = 0

    def _start(self, rhs: np.ndarray, out: np.ndarray):
        """(the load on the free dofs, the first guess there: ``out``'s, or None where it is not finite)."""
        x = out[self.free]
        return rhs[self.free], (x if np.all(np.isfinite(x)) else None)

    def _finish(self, b: np.ndarray, x: np.ndarray, count: int, out: np.ndarray, converged: bool, what: str) -> None:
        """Counts the solve; writes x into ``out``, or raises Diverged naming ``what`` where it did not converge."""
        self.last_iterations = count
        self.iterations += count
        self.solves += 1
        if not converged:
            from ..errors import Diverged

            residual = float(np.linalg.norm(b - self.matrix @ x) / max(np.linalg.norm(b), 1e-300))
            raise Diverged(f"the {what} did not converge: relative residual {residual:.2g} after {count} iterations")
        out[self.fixed] = 0.0
        out[self.free] = x


class MixedPrecision(_Iterative):
    """Conjugate gradients on ``K[free][:, free]`` in double precision, preconditioned by MKL PARDISO's Cholesky
    factor of the same matrix in *single* precision (:class:`pardiso.Factor` with ``single``), to a relative residual
    of :data:`MIXED_TOL` (the true residual at most :data:`CG_TOL`, or at round-off): a factor in half the memory of
    the double one, and a solve of a few iterations.

    Why. The single factor alone solves to about 10^-3 on a stiffness matrix, but as a preconditioner it leaves the
    conjugate gradients a spectrum within about 10^-3 of 1, so each iteration gains about three digits. Measured
    (one thread, a random load, from 0): on the hemisphere at 47k dofs 4 iterations, 0.085 s a solve against 0.028 s
    for the double factor; on the P1 block at 209k, 5 iterations, 0.74 s against 0.24 s (and 2.5-3.7 s for ``cg``),
    the factor and a first solve in 14.2 s against 23.0 s (docs/schemes.md gives the command). ``auto`` takes it where the double factor would exceed
    :data:`FACTOR_BYTES` and the single one would not (:func:`choose`). Rounding in single precision makes the
    preconditioner not quite linear, so the search directions are conjugated by Polak-Ribiere's formula (flexible
    CG, Notay, SISC 22 (2000)), which is the usual one where it is; the residual checked at the end is the true one.
    Asked first, the factorization keeps the contact dofs last and gives their compliance in single precision
    (:meth:`approximate_compliance`): Model B's coupled contact solve takes it as preconditioner (memory_block at 267k
    dofs: 99 back-substitutions against 392, 125 s against 337 s).

    >>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()
    >>> s = MixedPrecision(K, np.arange(1, 5)) if pardiso.available() else BandedCholesky(K, np.arange(1, 5))
    >>> out = np.zeros(5); s.solve(np.ones(5), out); out.round(9).tolist()  # (dof 0 held)
    [0.0, 2.0, 3.0, 3.0, 2.0]
    """

    name = "mixed"

    #: The most contact dofs whose compliance :meth:`approximate_compliance` forms (a dense matrix, 8 m^2 bytes).
    compliance_up_to = 4000

    def __init__(self, K: sp.spmatrix, free: np.ndarray, block=None):
        super().__init__(K, free, block)
        self._norm = float(abs(self.matrix).sum(axis=1).max()) if self.matrix.nnz else 0.0  # ||K||_inf (its copy of
        # |K| goes before the factor comes)
        self._factor = None  # (made at the first use: a compliance asked first is formed inside it)

    @property
    def factor(self) -> pardiso.Factor:
        if self._factor is None:
            self._factor = pardiso.Factor(self.matrix, single=True)
        return self._factor

    def approximate_compliance(self, C: np.ndarray):
        """(K^-1)_CC in single precision's accuracy, from the Schur complement of the free block on C that PARDISO
        forms inside this solver's single factorization (asked before any solve, and for at most
        :attr:`compliance_up_to` free dofs C); else None. It preconditions the coupled contact solve."""
        at = np.searchsorted(self.free, C)
        if self._factor is not None or not 0 < C.size <= self.compliance_up_to or C.size >= self.free.size:
            return None
        if np.any(at >= self.free.size) or np.any(self.free[at] != C) or np.unique(C).size != C.size:
            return None  # (a held or repeated dof)
        self._factor = pardiso.Factor(self.matrix, keep=at, single=True)
        order = np.searchsorted(self._factor.keep, at)
        stiffness = self._factor.schur[np.ix_(order, order)].astype(float)
        return inverse(stiffness)

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        b, x = self._start(rhs, out)
        x = np.zeros_like(b) if x is None else x
        norm, count = float(np.linalg.norm(b)), 0
        # The recursion's residual is followed to MIXED_TOL, where the true one may stall above it at double
        # precision's floor (measured 3e-12 on the hemisphere for a load on 50 points, 1.2e-10 on the P2 block's
        # BDF2 operator at 271k dofs); that true residual is then checked, and the iteration restarted from it
        # (iterative refinement) while it is neither below CG_TOL nor at round-off (:meth:`_solved`).
        for _ in range(3):
            r = b - self.matrix @ x if x.any() else b.copy()
            if self._solved(r, x, norm):
                break
            count += self._iterate(x, r, MIXED_TOL * norm, MIXED_MAXITER)
        else:
            r = b - self.matrix @ x
        self._finish(b, x, count, out, self._solved(r, x, norm), "mixed-precision solve (solver = 'mixed'; "
                     "'pardiso', the double factor, or 'cg' solve without single precision)")

    def _solved(self, r: np.ndarray, x: np.ndarray, norm: float) -> bool:
        """Whether the residual r of x is below CG_TOL relative to the load's norm, or at double precision's round-off:
        a normwise backward error max |r| <= 1000 eps ||K||_inf max |x| (x then solves a system within 2e-13 of K's,
        as a direct factor's solution does)."""
        if float(np.linalg.norm(r)) <= CG_TOL * norm:
            return True
        return float(np.abs(r).max()) <= 1000.0 * np.finfo(float).eps * self._norm * float(np.abs(x).max())

    def _iterate(self, x: np.ndarray, r: np.ndarray, target: float, limit: int) -> int:
        """Flexible PCG from x (updated in place) and its residual r until the recursion's residual is at most
        ``target``; returns the iterations."""
        K, precondition = self.matrix, self._precondition
        z = precondition(r)
        p, rz = z.copy(), float(r @ z)
        for count in range(1, limit + 1):
            q = K @ p
            pq = float(p @ q)
            if not pq > 0.0:  # (p = 0: the residual is 0 in single precision's view; the caller checks the true one)
                return count - 1
            a = rz / pq
            x += a * p
            r_old, r = r, r - a * q
            if float(np.linalg.norm(r)) <= target:
                return count
            z = precondition(r)
            rz, beta = float(r @ z), float(z @ (r - r_old)) / rz  # (Polak-Ribiere: flexible)
            p = z + beta * p
        return limit


    def _precondition(self, r: np.ndarray) -> np.ndarray:
        """The single factor's solve of r scaled to a largest entry of 1: single precision's range is 1e-38-3e38,
        and a residual below it, as a Newton correction's of 1e-26 is after 12 digits gained, would vanish (the
        slab's BDF2 under error control divided by that zero)."""
        scale = float(np.abs(r).max())
        return scale * self.factor.solve(r / scale) if scale > 0.0 else np.zeros_like(r)


class AMGConjugateGradient(_Iterative):
    """CG on ``K[free][:, free]`` with a smoothed-aggregation AMG preconditioner (pyamg) built on the near-null space
    ``modes`` (n x m), warm started from ``out`` (module docs).

    >>> import numpy as np, scipy.sparse as sp
    >>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()
    >>> s = AMGConjugateGradient(K, np.arange(1, 5), np.ones((5, 1)))
    >>> out = np.zeros(5); s.solve(np.ones(5), out); out.round(6).tolist()
    [0.0, 2.0, 3.0, 3.0, 2.0]
    """

    name = "cg"

    def __init__(self, K: sp.spmatrix, free: np.ndarray, modes: np.ndarray):
        import pyamg

        super().__init__(K, free)
        # theta = 0: every connection strong (elasticity's couplings are all of one order); a coarse level of up to
        # 2000 unknowns is solved by a sparse LU (the default pseudo-inverse took 65 s at 271k dofs)
        self.amg = pyamg.smoothed_aggregation_solver(self.matrix, B=np.ascontiguousarray(modes[free]), symmetry="hermitian",
                                                     strength=("symmetric", {"theta": 0.0}), max_coarse=2000,
                                                     coarse_solver="splu")
        self.preconditioner = self.amg.aspreconditioner(cycle="V")

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> None:
        from scipy.sparse.linalg import cg

        b, x0 = self._start(rhs, out)
        count = [0]

        def counted(_):
            count[0] += 1

        # SciPy's CG stops on the true residual, ||b - K x||_2 <= CG_TOL ||b||_2 (pyamg's own on the preconditioned
        # one, which let the true residual lie 3x above the tolerance)
        x, info = cg(self.matrix, b, x0=x0, rtol=CG_TOL, atol=0.0, maxiter=1000, M=self.preconditioner, callback=counted)
        self._finish(b, x, count[0], out, info == 0, "conjugate gradient solve (solver = 'cg')")


def rigid_body_modes(fes) -> np.ndarray:
    """The rigid-body motions as dof vectors of the displacement space (ndof x 1 on the rod, 3 in 2D, 6 in 3D): the
    space interpolates linear fields exactly, so these are exact (high-order dofs zero)."""
    import ngsolve as ngs

    dim = fes.mesh.dim
    x, y, z = ngs.x, ngs.y, ngs.z
    fields = {1: [1.0], 2: [(1, 0), (0, 1), (-y, x)],
              3: [(1, 0, 0), (0, 1, 0), (0, 0, 1), (-y, x, 0), (0, -z, y), (z, 0, -x)]}[dim]
    g = ngs.GridFunction(fes)
    out = np.empty((fes.ndof, len(fields)))
    for j, f in enumerate(fields):
        g.Set(ngs.CF(f))
        out[:, j] = g.vec.FV().NumPy()
    return out


def free_block(K: sp.spmatrix, free: np.ndarray) -> sp.csr_matrix:
    """K[free][:, free] as CSR: the rows cut, then the columns renumbered by a table (about as fast as SciPy's column
    indexing: 0.13-0.16 s against 0.17 s at 193k dofs; what saves time is cutting once, :func:`factor`).

    >>> K = sp.csr_matrix(np.arange(16.0).reshape(4, 4))
    >>> free_block(K, np.array([0, 2, 3])).toarray().tolist()
    [[0.0, 2.0, 3.0], [8.0, 10.0, 11.0], [12.0, 14.0, 15.0]]
    """
    rows = sp.csr_matrix(K)[free]
    number = np.full(K.shape[1], -1, dtype=np.int64)
    number[free] = np.arange(free.size)
    columns = number[rows.indices]
    keep = columns >= 0
    counts = np.bincount(np.repeat(np.arange(free.size), np.diff(rows.indptr))[keep], minlength=free.size)
    indptr = np.concatenate([[0], np.cumsum(counts)])
    return sp.csr_matrix((rows.data[keep], columns[keep], indptr), shape=(free.size, free.size))


def rcm(K: sp.spmatrix, free: np.ndarray, block=None):
    """(RCM permutation of K[free][:, free], its bandwidth); ``block``: K[free][:, free] as CSR where already cut. The
    bandwidth is read from the positions of the nonzeros, without permuting the matrix (at 193k dofs the free block's
    three cuts and the permuted copy took 0.2-1.0 s of the setup, the first run in a process the most)."""
    Kf = free_block(K, free) if block is None else block
    perm = reverse_cuthill_mckee(Kf, symmetric_mode=True)
    position = np.empty_like(perm)
    position[perm] = np.arange(perm.size, dtype=perm.dtype)
    rows = np.repeat(np.arange(Kf.shape[0]), np.diff(Kf.indptr))
    return perm, (int(np.max(np.abs(position[rows] - position[Kf.indices]))) if Kf.nnz else 0)


#: Largest band storage ``auto`` takes the banded Cholesky for (the slab of tp5 at 160k dofs: 0.47 GB, banded 1.7x
#: faster per solve than sparsecholesky; the P2 block at 118k dofs: 2.2 GB, 4.6 GB peak).
BAND_BYTES = 1.0e9


#: The estimated sparse factor above which ``auto`` takes ``cg`` in 3D (the P2 block at 271k dofs: NGSolve's factor
#: 4.3 GB, 130 s to factor; PARDISO's 2.05 GB; measured): about 150k dofs with NGSolve's factor, 240k with PARDISO's.
FACTOR_BYTES = 2.0e9
#: Relative residual ||b - K x|| / ||b|| at which ``cg`` stops.
CG_TOL = 1e-10
#: Relative residual at which ``mixed`` stops (each iteration gains about three digits, so it affords a tighter one
#: than ``cg``), and the most iterations it may take (measured: 4-5).
MIXED_TOL, MIXED_MAXITER = 1e-12, 30
#: The most iterations a conjugate gradient solve on several processes may take (BDDC: 2-10 on the boxes).
CG_MAXITER = 500


#: Bytes of a 3D sparse Cholesky factor over n^(4/3), by the factor: NGSolve's ``sparsecholesky`` (the P2 block at 271k
#: dofs: 4.3 GB) and MKL PARDISO's, METIS-ordered, whose analysis counts the factor's nonzeros: 8 x 11.0-16.5 n^(4/3)
#: bytes on the P1 block (28k, 78k, 267k dofs: 0.09, 0.40, 2.27 GB), the P2 block (5.5k, 37k, 271k: 0.008, 0.12,
#: 2.05 GB) and the hemisphere (47k: 0.15 GB), the largest taken.
FILL_3D = {"sparsecholesky": 8.0 * 31.0, "pardiso": 8.0 * 16.5}
#: PARDISO's memory over the factor its analysis counts (measured on the P1 block at 267k dofs: 2.93 GB, 2.27 GB).
PARDISO_WORK = 1.3


def factor_kind(method: str) -> str:
    """The sparse factor ``method`` resolves to in 3D: ``pardiso`` (``auto`` or ``pardiso`` where MKL loads) or
    ``sparsecholesky`` (NGSolve's, for any other factor too)."""
    return "pardiso" if method in ("auto", "pardiso", "mixed") and pardiso.available() else "sparsecholesky"


def sparse_factor_bytes(dim: int, ndof: int, method: str = "sparsecholesky") -> float:
    """The memory of the sparse Cholesky factor ``method`` resolves to (``auto`` and ``pardiso``: PARDISO's where MKL
    loads, else NGSolve's; ``mixed``: PARDISO's in single precision, half of it), order of magnitude (:data:`FILL_3D`;
    in 2D nested-dissection-like fill).

    >>> round(sparse_factor_bytes(3, 271_000, "sparsecholesky") / 1e9, 1)  # (measured: 4.3 GB on the P2 block)
    4.3
    """
    single = 0.5 if method == "mixed" and pardiso.available() else 1.0
    if dim == 3:
        return single * FILL_3D[factor_kind(method)] * ndof ** (4.0 / 3.0)
    return single * 8.0 * 30.0 * ndof * max(1.0, np.log2(max(ndof, 2)))


def factors_kept(dim: int, ndof: int, method: str, most: int) -> int:
    """How many factored operators a scheme may hold at once: ``most``, or as many as fit :data:`FACTOR_BYTES`
    together (at least one) where each is large (``method``: the step's solver; ``cg`` holds no factor).

    Measured: BDF2 on the P2 block at 271k dofs (``mixed``) factors its first, backward-Euler step's operator and
    then its own; holding both took the run to 5.67 GB.

    >>> factors_kept(3, 20_000, "pardiso", 4), factors_kept(3, 200_000, "pardiso", 4), factors_kept(3, 10**6, "cg", 4)
    (4, 1, 4)
    """
    if method == "cg":
        return most
    each = sparse_factor_bytes(dim, ndof, method) * (PARDISO_WORK if factor_kind(method) == "pardiso" else 1.0)
    return int(max(1, min(most, FACTOR_BYTES // max(each, 1.0))))


def choose(method: str, dim: int, ndof: int, iterative: bool) -> str:
    """The method ``auto`` resolves to before anything is assembled. For a 3D body whose factor (the one ``auto``
    takes: PARDISO's where MKL loads) would exceed :data:`FACTOR_BYTES`, when the caller can take an iterative solver
    (``iterative``): ``mixed`` (:class:`MixedPrecision`) where PARDISO's factor in single precision would not, else
    ``cg``. Otherwise ``auto`` (banded or sparse, decided on the matrix by :func:`factor`).

    Why ``mixed`` first: on the P1 block at 209k dofs its solve took 0.74 s against 2.5-3.7 s for ``cg``'s, for a
    factor of 0.8 GB (:class:`MixedPrecision`); it covers about 1.7 x the dofs the double factor does.

    >>> choose("auto", 3, 300_000, False), choose("auto", 2, 10**6, True), choose("auto", 3, 700_000, True)
    ('auto', 'auto', 'cg')
    >>> choose("auto", 3, 300_000, True) == ("mixed" if pardiso.available() else "cg")
    True
    """
    if method == "auto" and iterative and dim == 3 and sparse_factor_bytes(dim, ndof, method) > FACTOR_BYTES:
        return "mixed" if pardiso.available() and sparse_factor_bytes(dim, ndof, "mixed") <= FACTOR_BYTES else "cg"
    return method


def forms_schur(method: str) -> bool:
    """Whether the factor ``method`` resolves to forms a condensed contact stiffness inside one factorization (MKL
    PARDISO's Schur complement: the banded and the PARDISO factors, where MKL loads; a distributed body's solvers
    do not, and their methods are never these)."""
    return pardiso.available() and method in ("auto", "banded", "pardiso")


def factor(mat, freedofs, vector, method: str = "auto", fes=None):
    """Factor an NGSolve SPD matrix on ``freedofs`` with ``method`` (see module docs); ``cg`` needs the displacement
    space ``fes`` (for the rigid-body modes)."""
    free = np.nonzero(np.array(freedofs, dtype=bool))[0]
    K = block = None
    if method == "cg":
        if fes is None:
            raise ValueError("solver = 'cg' needs the displacement space (its rigid-body modes)")
        return AMGConjugateGradient(to_scipy(mat), free, rigid_body_modes(fes))
    if method == "mixed":
        if not pardiso.available():
            raise ValueError("solver = 'mixed' needs MKL (pip install mkl): its factor is PARDISO's")
        return MixedPrecision(to_scipy(mat), free)
    if method in ("banded", "auto"):
        K = to_scipy(mat)
        block = free_block(K, free)  # (cut once, for the order and the factor)
        perm, bandwidth = rcm(K, free, block)
        # a narrow band (thin bodies: ~2 (ny + 1) dofs) solves 2-4x faster than the sparse factor; but its storage,
        # (bandwidth + 1) x n doubles, grows like n^(5/3) in 3D (the P2 block at 271k dofs: 11.7 GB, 17 GB peak with
        # the copies SciPy makes): above BAND_BYTES the sparse factor
        narrow = bandwidth <= max(64, 0.02 * free.size) and 8.0 * (bandwidth + 1) * free.size <= BAND_BYTES
        if method == "banded" or narrow:
            return BandedCholesky(K, free, perm, block)
        method = "pardiso" if pardiso.available() else "sparsecholesky"
    if method == "pardiso":
        if not pardiso.available():
            raise ValueError("solver = 'pardiso' needs MKL (pip install mkl); 'sparsecholesky' is NGSolve's own")
        return PardisoCholesky(to_scipy(mat) if K is None else K, free, block)
    return NGSolveDirect(mat, freedofs, method, vector)
