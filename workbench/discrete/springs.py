"""The springs' system of :class:`~workbench.discrete.condensation.CoupledNewton`: (I + J G)^-1 J on the dofs R
where the contact springs J act, G a dense compliance, kept from one Newton iteration to the next as the contact
front moves.

The system is dense on R, so a factor costs 2/3 |R|^3 and the front must not force one each step. A factor of
M0 = I + J0 G is made on dofs U (R and a margin where the front goes next) and kept:

* springs that differ from J0 on a few dofs D correct it at low rank (Woodbury: :class:`LowRank`), each column
  M0^-1 e_i solved once while the factor lasts, each row (J - J0)_i G made once while that row of J stays, and
  their products kept, so a Newton iteration pays for the dofs its own springs changed;
* where G is the compliance of every dof (``whole``: the candidates' exact compliance), the dofs the front reaches
  beyond U are added to U: no springs there yet, their rows of M0 are the identity's, and the factor holds as it is
  (its margin columns J0 G_R,N are the only new work).

A new factor is made only when more than :attr:`SpringsFactor.share` of U has changed.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from .solvers import Multiple


def _grown(A: np.ndarray, shape: tuple) -> np.ndarray:
    """A within an array of at least ``shape`` (twice the needed size along a grown axis, A's entries kept): the
    buffers of :class:`LowRank` grow a few rows or columns a Newton iteration, and are copied only now and then."""
    if A.shape[0] >= shape[0] and A.shape[1] >= shape[1]:
        return A
    new = np.empty(tuple(a if n <= a else max(n, 2 * a) for n, a in zip(shape, A.shape)))
    new[:A.shape[0], :A.shape[1]] = A
    return new


def _padded(A, n: int):
    """The CSR matrix A within n x n zeros (rows and columns added after its own)."""
    return sp.csr_matrix((A.data, A.indices, np.r_[A.indptr, np.full(n - A.shape[0], A.indptr[-1])]), shape=(n, n))


class LowRank:
    """Woodbury's correction of a factor of M0 to M = M0 + E_D W on n dofs, W = (J - J0)_D G: the columns
    Z = M0^-1 E_D, the rows of W and their products W Z kept, so that they are made once while they hold (a column
    while the factor does; a row while that row of J - J0 stays).

    >>> rng = np.random.default_rng(0)
    >>> M0, G = np.eye(6) + 0.1 * rng.random((6, 6)), rng.random((6, 6))
    >>> dJ = sp.csr_matrix(np.diag([0.0, 2.0, 0.0, 0.0, 1.0, 0.0]))
    >>> D, c = np.array([1, 4]), LowRank(6)
    >>> correct = c.solver(dJ, D, lambda b: np.linalg.solve(M0, b), lambda rows: rows @ G)
    >>> b = rng.random(6)
    >>> bool(np.allclose(correct(np.linalg.solve(M0, b)), np.linalg.solve(M0 + dJ @ G, b)))
    True
    """

    def __init__(self, n: int):
        self.n = n
        self._Z, self._col, self._c = np.empty((n, 0)), np.full(n, -1), 0  # (columns kept: the first _c of _Z)
        self._W, self._row, self._k = np.empty((0, n)), np.full(n, -1), 0  # (rows kept: the first _k of _W)
        self._P = np.empty((0, 0))  # (W Z over the rows and columns kept)
        self._dJ = sp.csr_matrix((n, n))  # (the rows of J - J0 the kept rows of W were made from)

    @property
    def columns(self) -> int:
        """The columns M0^-1 e_i solved so far."""
        return self._c

    def grow(self, m: int, rows_at) -> None:
        """n -> n + m dofs, M0's rows there the identity's (no springs yet): the columns kept are 0 there, and
        ``rows_at(dJ_rows, cols)`` = (dJ_rows G) at the new dofs ``cols`` gives the kept rows' new entries."""
        n, self.n = self.n, self.n + m
        Z = np.zeros((self.n, self._Z.shape[1]))
        Z[:n] = self._Z
        self._Z, self._col = Z, np.r_[self._col, np.full(m, -1)]
        W = np.empty((self._W.shape[0], self.n))
        W[:, :n] = self._W
        if self._k:
            kept = np.nonzero(self._row >= 0)[0]
            W[self._row[kept], n:] = rows_at(self._dJ[kept], np.arange(n, self.n))
        self._W, self._row = W, np.r_[self._row, np.full(m, -1)]
        self._dJ = _padded(self._dJ, self.n)

    def solver(self, dJ, D: np.ndarray, solve0, rows):
        """x -> x - Z (I + W Z)^-1 W x on D, the dofs where ``dJ`` = J - J0 (CSR, n x n) has rows: M^-1 b from
        x = M0^-1 b. ``solve0(E)`` = M0^-1 E, ``rows(dJ_rows)`` = dJ_rows G (n columns)."""
        self._rows(dJ, D, rows)
        self._columns(D, solve0)
        i, j = self._row[D], self._col[D]
        K = self._P[np.ix_(i, j)]
        K[np.diag_indices_from(K)] += 1.0
        lu = la.lu_factor(K, overwrite_a=True, check_finite=False)
        # (with every row and column kept rather than D's gathered: a product a little larger, no |D| x n copies)
        W, Z, y = self._W[:self._k], self._Z[:, :self._c], np.zeros(self._c)

        def correct(x):
            y[j] = la.lu_solve(lu, (W @ x)[i], check_finite=False)
            return x - Z @ y

        return correct

    def _rows(self, dJ, D, rows):
        """W's rows on D made where none is kept or J - J0 changed there since (with their products)."""
        stale = self._row[D] < 0
        kept = D[~stale]
        if kept.size:
            moved = (dJ[kept] - self._dJ[kept]).tocsr()
            moved.eliminate_zeros()
            stale[~stale] = np.diff(moved.indptr) > 0
        D = D[stale]
        if not D.size:
            return
        new = D[self._row[D] < 0]
        self._row[new] = self._k + np.arange(new.size)
        self._k += new.size
        self._W = _grown(self._W, (self._k, self.n))
        self._P = _grown(self._P, (self._k, self._P.shape[1]))
        W = rows(dJ[D])
        self._W[self._row[D]] = W
        self._P[self._row[D], :self._c] = W @ self._Z[:, :self._c]
        mark = np.zeros(self.n)
        mark[D] = 1.0
        self._dJ = (sp.diags(1.0 - mark) @ self._dJ + sp.diags(mark) @ dJ).tocsr()

    def _columns(self, D, solve0):
        """M0^-1 e_i for the dofs of D without one (with their products with the rows kept)."""
        new = D[self._col[D] < 0]
        if not new.size:
            return
        E = np.zeros((self.n, new.size))
        E[new, np.arange(new.size)] = 1.0
        self._col[new] = self._c + np.arange(new.size)
        self._c += new.size
        self._Z = _grown(self._Z, (self.n, self._c))
        self._P = _grown(self._P, (self._P.shape[0], self._c))
        Z = solve0(E)
        self._Z[:, self._col[new]] = Z
        self._P[:self._k, self._col[new]] = self._W[:self._k] @ Z


class SpringsFactor:
    """(I + J G)^-1 J on the springs' dofs R for :class:`~workbench.discrete.condensation.CoupledNewton`'s
    preconditioner (module docs), J = J_RR sparse, from an LU factor of I + J0 G_R0R0 made on the dofs U.

    ``G`` is the compliance on U (|U| x |U|: the half-space's block), or with ``whole`` on every dof (indexed by the
    dofs' numbers: the candidates' exact compliance); then U grows with R.

    Measured on hertz3d at 106k dofs (52 steps on the candidate facets, one thread; docs/schemes.md, "Model A's
    implicit steps on candidate facets"): grown with the front, 14 factors instead of 20 and the springs' system
    5.6-5.9 s against 7.3-7.7 s (two pairs of runs), u equal to 3e-10 of its largest. Model B's active set does the
    like for its points (:class:`~workbench.schemes.halfspace.ModelFactor`, which borders its factor with points
    gained).

    >>> x = np.linspace(0.0, 1.0, 16)
    >>> G = 1.0 / (1.0 + 10.0 * np.abs(x[:, None] - x[None, :]))  # (a compliance: falls with distance)
    >>> F = SpringsFactor(sp.diags(np.full(16, 2.0)).tocsr(), np.arange(16), G)
    >>> R1 = np.arange(15)  # (the last spring released, one stiffer: two dofs changed, within 16 / 4)
    >>> J1 = sp.diags(np.r_[np.full(14, 2.0), 3.0]).tocsr()
    >>> r = np.cos(np.arange(15.0))
    >>> exact = np.linalg.solve(np.eye(15) + J1 @ G[:15, :15], J1 @ r)
    >>> F.holds(J1, R1), bool(np.abs(F.solver()(r) - exact).max() < 1e-13)
    (True, True)
    """

    #: The most changed dofs a low-rank update takes, as a share of U. Each changed dof's column M0^-1 e_i costs about
    #: 2 |R|^2 flops once while the factor lasts, its row of W 2 |U| nnz(J_i), and a Newton iteration's update |D|^3
    #: (its LU) and 4 |D| |U| a product, against a new factor's 2/3 |R|^3.
    share = 0.25

    def __init__(self, J, R: np.ndarray, G: np.ndarray, U: np.ndarray | None = None, whole: bool = False):
        # (G is symmetric: where it is F-ordered, as LAPACK's inverse leaves it, its transpose is the same matrix in
        # C order, which scipy's products with a sparse matrix read in place instead of copying all of it. A multiple
        # of a shared factor's compliance, solvers.Multiple, is read as its base, the multiple applied to what is cut)
        G, self._scale = (G.base, G.c) if isinstance(G, Multiple) else (G, 1.0)
        self.G = G if G.flags.c_contiguous else G.T
        self.U, self.whole = (R if U is None else U).copy(), whole
        # (the position in U of each dof, -1 off U; with whole, over every dof, so that U may grow)
        self._pos = np.full(G.shape[0] if whole else int(self.U.max()) + 1, -1)
        self._pos[self.U] = np.arange(self.U.size)
        self._r = self._pos[R]
        self._m = np.setdiff1d(np.arange(self.U.size), self._r)
        self.J0 = self._embedded(J, self._r)
        # M0 = I + J0 G has identity rows off R (no springs there yet): in the order (R, margin) it is [[A, B], [0, I]]
        # with A = I + J G_RR and B = J G_R,margin, so only A is factored and the margin costs no factor work
        self._J = J = J.tocsr()
        g = self._g(self._r)
        A = J @ self._cut(np.ix_(g, g))
        A[np.diag_indices_from(A)] += 1.0
        self._B = J @ self._cut(np.ix_(g, self._g(self._m)))
        # (A^T's factor, in place: A is C-ordered, so A^T is LAPACK's order and no further |R|^2 array is made)
        self.lu = la.lu_factor(A.T, overwrite_a=True, check_finite=False)
        self._update = LowRank(self.U.size)
        self._last = None  # (the springs holds() last took: (positions of R in U, J on U, J - J0 on U, D))
        self.holds(J, R)

    @property
    def columns(self) -> int:
        """The columns M0^-1 e_i solved for the updates so far."""
        return self._update.columns

    def _g(self, at: np.ndarray) -> np.ndarray:
        """G's rows for the dofs at positions ``at`` of U."""
        return self.U[at] if self.whole else at

    def _cut(self, key) -> np.ndarray:
        """A block of G (times the multiple given, where G was one)."""
        return self.G[key] if self._scale == 1.0 else self._scale * self.G[key]

    def _lu(self, b: np.ndarray) -> np.ndarray:
        """M0^-1 b (a vector or columns on U): b off R as it is, and A x_R = b_R - B b_margin (A y = c from A^T's
        factor)."""
        x = b.copy()
        x[self._r] = la.lu_solve(self.lu, b[self._r] - self._B @ b[self._m], trans=1, check_finite=False)
        return x

    def _rows(self, dJ, at=None) -> np.ndarray:
        """dJ G_UU for rows dJ on U's positions (CSR), at the positions ``at`` (default all)."""
        data = dJ.data if self._scale == 1.0 else self._scale * dJ.data  # (G's multiple, on the few rows' nonzeros)
        in_G = sp.csr_matrix((data, self._g(dJ.indices), dJ.indptr), shape=(dJ.shape[0], self.G.shape[0]))
        if at is not None:
            return in_G @ self.G[:, self._g(at)]
        return (in_G @ self.G)[:, self.U] if self.whole else in_G @ self.G

    def _embedded(self, J, at):
        """J (on R, positions ``at`` in U) on U: rows and columns of U off R zero."""
        J = J.tocoo()
        return sp.csr_matrix((J.data, (at[J.row], at[J.col])), shape=(self.U.size,) * 2)

    def _within(self, R: np.ndarray):
        """The positions of R in U, U grown first where G covers the dofs beyond it; None where it cannot."""
        at = self._pos[R] if R.max(initial=-1) < self._pos.size else np.full(R.size, -1)
        if np.all(at >= 0):
            return at
        if not self.whole:
            return None
        self._grow(R[at < 0])
        return self._pos[R]

    def _grow(self, N: np.ndarray) -> None:
        """U -> U and N (dofs without springs in J0: M0's rows there the identity's, the factor unchanged)."""
        n = self.U.size
        self.U = np.r_[self.U, N]
        self._pos[N] = at = n + np.arange(N.size)
        self._m = np.r_[self._m, at]
        self._B = np.hstack([self._B, self._J @ self._cut(np.ix_(self._g(self._r), N))])
        self.J0 = _padded(self.J0, self.U.size)
        self._update.grow(N.size, self._rows)

    def holds(self, J, R) -> bool:
        """Whether the factor serves the springs (J, R): R within U (grown to it where ``whole``) and J differing
        from the factor's on at most :attr:`share` of U's dofs."""
        at = self._within(R)
        if at is None:
            return False
        J_U = self._embedded(J, at)
        dJ = (J_U - self.J0).tocsr()
        dJ.eliminate_zeros()
        D = np.nonzero(np.diff(dJ.indptr))[0]
        if D.size > self.share * self.U.size:
            return False
        self._last = (at, J_U, dJ, D)
        return True

    def solver(self):
        """r (on R) -> (I + J G_RR)^-1 J r for the springs (J, R) that :meth:`holds` last took."""
        at, J_U, dJ, D = self._last
        correct = self._update.solver(dJ, D, self._lu, self._rows) if D.size else None

        def apply(r):
            y = np.zeros(self.U.size)
            y[at] = r
            x = self._lu(J_U @ y)
            return (x if correct is None else correct(x))[at]

        return apply
