"""An elastic half-space's compliance between 3D contact points: the coupled contact solvers' model of S = B K^-1 B^T.

S, the body's compliance at its contact points, is dense and known only through back-substitutions. Near a contact
zone small against the body (Hertz's own assumption) it is close to a half-space's: Boussinesq's point force, a
normal force F at distance r lowering the surface by F (1 - nu^2) / (pi E r), and a point's own share w of the
surface loaded evenly as a disc, 2 (1 - nu^2) / (pi E a) with pi a^2 = w. Two things about the modelled body make
that far closer (:class:`HalfSpace`, ``mirrors`` and ``held``):

* a body modelled by symmetry (the Hertz hemisphere's quarter x, y >= 0, rollers on x = 0 and y = 0) is loaded by
  each force's mirror images too, at distances comparable with the zone's where the zone meets the planes;
* a load-driven body whose apex is held in the normal direction (the indenters: ``pins_contact``) returns each
  contact force through that point: a point force F at x_j and -F at the apex p, displacements measured from p's,

      G~_ij = G_ij - G_ip - G_pj + G_pp,

  a rank-two change of G that holds most of what the body's own compliance adds to the half-space's.

Measured on the hemisphere at h_contact = 0.01 (the 287 points in contact at the full load, S formed column by
column): the generalised eigenvalues of (S, c G_UU) span 0.93-134.8 with the plain half-space, 0.94-66.9 with the
images, 1.10-3.66 with images and apex (0.57-1740 for the diagonal 1 / K_ii). That makes the model good enough to
*predict* the contact zone (:class:`ZonePrediction`), not only to precondition the solves on it. Both solve with
the model's dense matrix on sets of points that change a little from one solve to the next, through one factor
updated by low-rank corrections (:class:`ModelFactor`).

Examples
--------
>>> import numpy as np
>>> x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
>>> G = HalfSpace(x, np.full(2, np.pi)).compliance(np.arange(2))  # discs of radius 1, 1 apart
>>> (G * np.pi).round(6).tolist()  # own: 2 / a; the other's: 1 / r
[[2.0, 1.0], [1.0, 2.0]]
"""
from __future__ import annotations

import itertools

import numpy as np
import scipy.linalg as la

from ..discrete import solvers
from ..physics.unilateral import COMPLIANT, RIGID, SEPARATED, STUCK


class HalfSpace:
    """The half-space's compliance between contact points (module docs), in units of (1 - nu^2) / E, dense, with
    the preconditioner and the prediction the coupled contact solvers build on it.

    Parameters
    ----------
    positions : array (m, 3)
        The contact points.
    w : array (m,)
        Each point's share of the contact surface.
    largest : int
        The most points factored densely (:meth:`largest_for`).
    mirrors : tuple of int
        The axes a whose planes x_a = 0 the modelled body is mirrored across (each force acts at its images too).
    held : array (3,) or None
        A point held in the normal direction through which the contact forces return (the indenters' apex).

    >>> x = np.array([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    >>> G = HalfSpace(x, np.full(2, np.pi), mirrors=(0,)).compliance(np.arange(2))
    >>> (G * np.pi).round(6).tolist()  # the first point lies on x = 0 (own disc twice its area, twice loaded)
    [[2.828427, 2.0], [2.0, 2.5]]
    """

    #: The range of :meth:`largest_for` (the most points factored): never fewer than the first, nor more than the
    #: second (a matrix of 290 MB).
    bounds = (2000, 6000)

    def __init__(self, positions: np.ndarray, w: np.ndarray, largest: int = 2000, mirrors: tuple = (),
                 held=None):
        self.x, self.w, self.largest = np.asarray(positions, dtype=float), np.asarray(w, dtype=float), largest
        self.mirrors, self.held_point = tuple(mirrors), held
        flips = [np.where(np.isin(np.arange(self.x.shape[1]), axes), -1.0, 1.0)
                 for n in range(len(mirrors) + 1) for axes in itertools.combinations(mirrors, n)]
        self.flips = np.array(flips)
        # (no two points nearer than the smallest disc's radius, which a fair mesh never has: the point force's
        # formula no longer holds there, and coincident points would divide by 0)
        self._a2 = float(self.w.min() / np.pi) if self.w.size else 1.0
        self.own = self._own(self.x, self.w)
        self.held = None
        if held is not None and self.w.size:
            p = np.asarray(held, dtype=float)[None, :]
            near = np.argsort(np.linalg.norm(self.x - p, axis=1))[:6]  # (its patch: as large as its neighbours')
            self.held = (self._kernel(self.x, p)[:, 0], float(self._own(p, np.median(self.w[near]))[0]))
        self._block = (np.zeros(0, dtype=int), np.zeros((0, 0)))
        self._store = None  # (the flat storage a block is written into next: :meth:`_spare_block`)
        self.factors = ModelFactor(self)

    @classmethod
    def of_body(cls, positions, w, geometry, largest: int = 2000) -> "HalfSpace":
        """The half-space of a body: its mirror planes and held apex (:class:`~workbench.input.geometry.Geometry`'s
        ``mirror_axes`` and ``pins_contact``)."""
        held = np.zeros(np.shape(positions)[1]) if geometry.pins_contact else None
        return cls(positions, w, largest, mirrors=geometry.mirror_axes, held=held)

    @classmethod
    def largest_for(cls, ndof: int, method: str, backsubs: float = 2.0) -> int:
        """The most points worth a dense factor beside K's (``method``: the step's solver, ``ndof`` its dofs): as
        many as cost ``backsubs`` back-substitutions (:func:`dense_points`), within :attr:`bounds`. Measured on the
        hemisphere at 193k dofs (4700 points in contact at the end): 3760 points, 274 back-substitutions and 78.6 s,
        against 355 and 79.6 s with 2000 (a factor for each active set; Model B's solver now updates its factors
        and affords more: :attr:`~workbench.schemes.coupled_contact.CoupledActiveSet.model_backsubs`).

        >>> [HalfSpace.largest_for(n, "sparsecholesky") for n in (12_000, 46_938, 193_464, 500_000)]
        [2000, 2473, 4640, 6000]
        """
        return int(np.clip(dense_points(ndof, method, backsubs), *cls.bounds))

    def _kernel(self, x, y) -> np.ndarray:
        """sum over the images y' of the points y of 1 / (pi |x - y'|), (len(x), len(y))."""
        sx, sy = np.einsum("ij,ij->i", x, x), np.einsum("ij,ij->i", y, y)
        G, d2 = np.zeros((len(x), len(y))), np.empty((len(x), len(y)))
        for flip in self.flips:  # (|x - y'|^2 from the Gram matrix: no m x m x 3 temporary)
            np.matmul(x, (y * flip).T, out=d2)
            d2 *= -2.0
            d2 += sx[:, None]
            d2 += sy[None, :]
            np.maximum(d2, self._a2, out=d2)
            np.sqrt(d2, out=d2)
            np.divide(1.0 / np.pi, d2, out=d2)
            G += d2
        return G

    def _own(self, x, w) -> np.ndarray:
        """Each point's compliance to its own force: the disc of its whole patch (w times the images that fall on
        it) loaded that many times, and its images elsewhere."""
        x, w = np.atleast_2d(x), np.broadcast_to(w, len(np.atleast_2d(x)))
        tiny = 1e-9 * max(float(np.abs(self.x).max()) if self.x.size else 1.0, 1e-300)
        distance = np.linalg.norm(x[None, :, :] * (1.0 - self.flips[:, None, :]), axis=2)  # (image, point)
        on = distance <= tiny
        count = on.sum(axis=0)
        others = np.where(on, 0.0, 1.0 / (np.pi * np.sqrt(np.maximum(distance ** 2, self._a2)))).sum(axis=0)
        return count * 2.0 / (np.pi * np.sqrt(count * w / np.pi)) + others

    def compliance(self, U: np.ndarray) -> np.ndarray:
        """The half-space's compliance between the points U (images and held point included), dense."""
        return self._between(U, U)

    def _between(self, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
        G = self._kernel(self.x[P], self.x[Q])
        same = np.nonzero(P[:, None] == Q[None, :]) if P is not Q else (np.arange(P.size),) * 2
        G[same] = self.own[P[same[0]]]
        if self.held is not None:
            g, own = self.held
            G -= g[P][:, None]
            G -= g[Q][None, :]
            G += own
        return G

    def between(self, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """The compliance between the points P (rows) and Q (columns): cut from the last block where that holds
        both, else computed (the last block kept)."""
        last, G = self._block
        at = [np.searchsorted(last, V) for V in (P, Q)]
        if last.size and all(np.array_equal(last[np.minimum(a, last.size - 1)], V) for a, V in zip(at, (P, Q))):
            return G[np.ix_(*at)]
        return self._between(P, Q)

    def block(self, U: np.ndarray, scale: float | None = None) -> np.ndarray:
        """``scale`` x :meth:`compliance` of U, a new array; without ``scale`` the compliance itself, which may be the
        block kept (to read, not to write). Cut from the last block computed when that holds U (the active set's
        systems and the prediction's work on subsets of one set of points), and where it holds most of U only the new
        points' rows computed (the next step's points: measured on the hemisphere at 193k dofs, the kernel's
        evaluations over the run 4.1 s -> 1.1 s)."""
        last, G = self._block
        where = np.minimum(np.searchsorted(last, U), max(last.size - 1, 0))
        held = (last[where] == U) if last.size else np.zeros(U.size, dtype=bool)
        if held.all():
            if scale is None and U.size == last.size:
                return G
            B = G[np.ix_(where, where)]
            if scale is not None:
                B *= scale
            return B
        if np.count_nonzero(held) > 0.5 * U.size:
            old, new = np.nonzero(held)[0], np.nonzero(~held)[0]
            B = self._spare_block(U.size)
            # (every last point kept, as when the zone only grows: the block itself scattered, with no cut copy first)
            B[np.ix_(old, old)] = G if old.size == last.size else G[np.ix_(where[old], where[old])]
            B[new] = self._between(U[new], U)
            B[:, new] = B[new].T
        else:
            B = self.compliance(U)
        self._block = (np.array(U), B)
        return B if scale is None else scale * B

    def _spare_block(self, m: int) -> np.ndarray:
        """An m x m array on storage kept from one block to the next: the block before last's, which nothing reads
        any more (its callers cut copies from it), grown by a tenth beyond m when too small. A block of thousands of
        points on fresh memory paid its page faults at every extension: measured for 5824 points (271 MB), 0.2-1.3 s
        a block on fresh memory against 0.09 s on kept storage; on the hemisphere at 193k dofs in 16 steps the blocks
        took 7.9 s -> 1.8 s, for 0.17 GB more at the peak."""
        store, self._store = self._store, self._block[1].base if self._block[1].base is not None else None
        if store is None or store.size < m * m:
            store = np.empty(int((1.1 * m) ** 2))
        return store[: m * m].reshape(m, m)

    def scale(self, U: np.ndarray, local: np.ndarray) -> float:
        """c matching c G_ii to ``local`` (S's diagonal estimate 1 / K_ii on the points U) at the median."""
        return float(np.median(local / self.own[U]))

    def springs_compliance(self, U: np.ndarray, local: np.ndarray):
        """(c G_UU, False): the compliance a springs' factor of :class:`~workbench.discrete.condensation.CoupledNewton`
        takes on the points U, scaled to ``local`` (:meth:`scale`): a block of U alone, which the factor cannot grow
        beyond U (:class:`~workbench.discrete.springs.SpringsFactor`)."""
        return self.block(U, self.scale(U, local)), False

    def preconditioner(self, U: np.ndarray, D: np.ndarray, c: float):
        """r -> (c G_UU + diag(D))^-1 r (``c``: :meth:`scale`); None for fewer than 2 or more than :attr:`largest`
        points, or should the matrix not be positive definite. Its factor is updated, not redone, while U and D
        change by a few points (:class:`ModelFactor`)."""
        if not 2 <= U.size <= self.largest:
            return None
        try:
            return self.factors(U, D, c)
        except la.LinAlgError:
            return None


class ModelFactor:
    """Solves with the model's matrix A_U = c G_UU + diag(D_U) of a :class:`HalfSpace` for sets of points U that
    change by a few points from one call to the next (the active set's iterations and steps), exactly, with one dense
    Cholesky factor of a *base* set U0 and low-rank corrections. The points of U0 not in U (or whose D changed), R,
    are held at 0 by multipliers; the points of U not in U0 (or whose D changed), N, border the base system:

        A_0 x_0 + A_0N x_N + E_R mu = r_0,   A_N0 x_0 + A_NN x_N = r_N,   E_R^T x_0 = 0.

    With Z_N = A_0^-1 A_0N and Y_R = A_0^-1 E_R (a column per point, computed once per base and kept while the point
    stays changed, dropped once it is not) x_N solves T x_N = r_N - A_N0 q + Z_R^T Y_RR^-1 q_R, q = A_0^-1 r_0,
    where T = A_NN - A_N0 Z_N + Z_R^T Y_RR^-1 Z_R is the Schur complement A_NN - A_NI A_II^-1 A_IN (Z_R: Z_N's rows
    R, Y_RR: Y_R's). A solve costs one solve with the base factor and products with the |R| + |N| columns; a set
    beyond :attr:`rebase` x |U| changed points (or another c) becomes the new base. ``factorizations`` counts the
    base factors.

    >>> x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    >>> half = HalfSpace(x, np.full(4, 0.1))
    >>> factors = ModelFactor(half)
    >>> factors.rebase = 2.0  # (so few points: always an update)
    >>> _ = factors(np.array([0, 1, 2]), np.zeros(3), 1.0)
    >>> U, D = np.array([1, 2, 3]), np.array([0.0, 5.0, 0.0])  # one point removed, one added, one D changed
    >>> A = half.compliance(U) + np.diag(D)
    >>> bool(np.allclose(A @ factors(U, D, 1.0)(np.ones(3)), 1.0)), factors.factorizations
    (True, 1)
    """

    #: The share of changed points beyond which the set becomes the new base (measured on the hemisphere at 193k
    #: dofs: see docs/schemes.md).
    rebase = 0.25

    def __init__(self, half: HalfSpace):
        self.half = half
        self.factorizations = 0
        self._base = None  # (U0, D0, c, Cholesky factor of A_0)
        self._columns = ({}, {})  # (Y's column per removed base position, (A_0N's, Z's) per (new point, its D))
        self._last = (None, None)

    def __call__(self, U: np.ndarray, D: np.ndarray, c: float):
        """r -> A_U^-1 r (r: (|U|,) or (|U|, k)); raises LinAlgError where A_U is not positive definite."""
        key = (U.tobytes(), D.tobytes(), c)
        if key == self._last[0]:
            return self._last[1]
        solve = self._updated(U, D) if self._base is not None and self._base[2] == c else None
        if solve is None:
            A = self.half.between(U, U)
            A *= c
            A[np.diag_indices_from(A)] += D
            self._base, self._columns, self._last = None, ({}, {}), (None, None)
            # (A is symmetric: its transpose is the same matrix in Fortran order, which LAPACK factors in place; A
            # itself, in C order, was copied first, a second m x m array at every new base)
            factor = la.cho_factor(A.T, lower=True, overwrite_a=True, check_finite=False)
            self.factorizations += 1
            self._base = (U.copy(), D.copy(), c, factor)
            solve = lambda r: la.cho_solve(factor, r, check_finite=False)  # noqa: E731
        self._last = (key, solve)
        return solve

    def _updated(self, U, D):
        """The solve on U through the base factor (class docs), or None where too many points changed."""
        U0, D0, c, factor = self._base
        at = np.minimum(np.searchsorted(U0, U), U0.size - 1)
        same = (U0[at] == U) & (D0[at] == D)
        kept = np.zeros(U0.size, dtype=bool)
        kept[at[same]] = True
        R, N = np.nonzero(~kept)[0], np.nonzero(~same)[0]
        if R.size + N.size > self.rebase * U.size:
            return None
        kept_at, kept_U = at[same], np.nonzero(same)[0]
        if R.size == 0 and N.size == 0:
            return lambda r: la.cho_solve(factor, r, check_finite=False)
        Y, (A_0N, Z) = self._border(R, U[N], D[N])
        Y_RR = la.cho_factor(Y[R], check_finite=False) if R.size else None
        Z_R = Z[R]
        T = None
        if N.size:
            T = c * self.half.between(U[N], U[N])
            T[np.diag_indices_from(T)] += D[N]
            T -= A_0N.T @ Z
            if R.size:
                T += Z_R.T @ la.cho_solve(Y_RR, Z_R, check_finite=False)
            T = la.cho_factor(T, check_finite=False)

        def solve(r):
            q = np.zeros((U0.size,) + r.shape[1:])
            q[kept_at] = r[kept_U]
            q = la.cho_solve(factor, q, check_finite=False)
            x = np.empty_like(r)
            mu = la.cho_solve(Y_RR, q[R], check_finite=False) if R.size else None
            if N.size:
                rhs = r[N] - A_0N.T @ q
                if R.size:
                    rhs += Z_R.T @ mu
                x[N] = x_N = la.cho_solve(T, rhs, check_finite=False)
                q -= Z @ x_N
                if R.size:
                    mu -= la.cho_solve(Y_RR, Z_R @ x_N, check_finite=False)
            if R.size:
                q -= Y @ mu
            x[kept_U] = q[kept_at]
            return x

        return solve

    def _border(self, R, points, D):
        """(Y_R, (A_0N, Z_N)) for the removed base positions R and the new ``points`` with their D, the columns not
        kept yet solved for at once (and kept)."""
        U0, _, c, factor = self._base
        removed, new = self._columns
        missing = [i for i in R if i not in removed]
        if missing:
            E = np.zeros((U0.size, len(missing)))
            E[missing, np.arange(len(missing))] = 1.0
            for i, column in zip(missing, la.cho_solve(factor, E, check_finite=False).T):
                removed[i] = column
        keys = list(zip(points.tolist(), D.tolist()))
        absent = [j for j, key in enumerate(keys) if key not in new]
        if absent:
            A = c * self.half.between(U0, points[absent])
            for j, a, z in zip(absent, A.T, la.cho_solve(factor, A, check_finite=False).T):
                new[keys[j]] = (a, z)
        # (only the columns of the points changed now are kept: a set that drifts within ``rebase`` of its base over
        # many steps would otherwise keep one for every point it ever changed)
        self._columns = removed, new = {i: removed[i] for i in R}, {key: new[key] for key in keys}
        Y = np.array([removed[i] for i in R]).T if R.size else np.zeros((U0.size, 0))
        A_0N = np.array([new[key][0] for key in keys]).T if keys else np.zeros((U0.size, 0))
        Z = np.array([new[key][1] for key in keys]).T if keys else np.zeros((U0.size, 0))
        return Y, (A_0N, Z)


class _Cycled(Exception):
    """The model's active set did not settle."""


class _Outgrown(Exception):
    """The model's active set holds more points than a dense factor is allowed."""


def state_system(layer, w: np.ndarray, states: np.ndarray, b: np.ndarray):
    """The linear system of fixed ``states`` (:mod:`~workbench.schemes.coupled_contact`'s module docs) with the
    points' displacement b under no force: (the points whose force is unknown, their right-hand side, the layer's
    diagonal D, the forces known: the compliant points' w F when c = 0, else 0)."""
    comp = states == COMPLIANT
    fixed = (states == STUCK) | (states == RIGID)
    unknown = fixed | comp if layer.c > 0 else fixed
    rhs = b - np.where(states == RIGID, layer.g, 0.0)
    D = np.zeros(len(w))
    if layer.c > 0:
        rhs = np.where(comp, b + layer.F / layer.c, rhs)
        D[comp] = 1.0 / (w[comp] * layer.c)
    known = np.zeros(len(w))
    known[comp & ~unknown] = w[comp & ~unknown] * layer.F  # (c = 0: the layer's force is F alone)
    return unknown, rhs, D, known


class ZonePrediction:
    """A step's contact problem solved on the half-space model M = c G~ of S (:class:`HalfSpace`), from the last
    forces lam0: S lam ~ S lam0 + M (lam - lam0). No back-substitution; dense factors of the model's active sets.
    The coupled active set starts from its states (and, where a step adds many points, its forces there:
    :meth:`~workbench.schemes.coupled_contact.CoupledActiveSet._start`), and its own iterations then only correct
    the zone's rim. Measured on the hemisphere at h_contact = 0.01, the model's zone against the true one at the four
    load steps: 6, 6, 2, 6 points wrong of 115-287 (the exact active set then took 3, 3, 2, 3 iterations from it,
    against 14, 6, 4, 6 from the last step's states).

    Above half :attr:`HalfSpace.largest` points the problem is first solved on clusters of points (a grid of cells,
    about :attr:`clusters` of them; their forces summed, displacements averaged), and then on the points of the
    clusters in contact and their neighbours. (Up to the whole of it, the model on every point had been solved at
    once: its active set factors the model's block each iteration, updated at low rank, and on the hemisphere at
    47k dofs, 3085 points of which 1182 touch, that took 2.7 s of a 6.5 s run, against 4.5 s by the clusters, with
    the same 78 back-substitutions.) A zone larger than :attr:`HalfSpace.largest` is not predicted; a model
    whose active set cycles twice running is dropped for the run.
    """

    max_iterations = 30
    #: About as many clusters as this fraction of the most points factored.
    clusters = 0.3

    def __init__(self, halfspace: HalfSpace, layer):
        self.half, self.layer = halfspace, layer
        self._coarse = None
        #: Predictions whose active set cycled, running; at two the prediction is dropped for the run (the model is
        #: no guide to this body: measured on memory_block).
        self.misses, self.dropped = 0, False

    def __call__(self, b: np.ndarray, lam0: np.ndarray, rho, local: np.ndarray):
        """(states, lam) at all points, or None; ``b``: the points' displacement under lam0 (s_free - S lam0),
        ``rho``: the active set's prediction scale, ``local``: S's diagonal estimate."""
        if self.dropped or self.clusters * self.half.largest < 2:  # (no dense factor allowed: HalfSpace.bounds)
            return None
        try:
            found = self._predict(self.half.scale(np.arange(b.size), local), b, lam0, rho)
        except _Cycled:
            self.misses += 1
            self.dropped = self.misses == 2
            return None
        except _Outgrown:
            return None
        self.misses = 0
        return found

    def _predict(self, c, b, lam0, rho):
        half, w = self.half, self.half.w
        if w.size <= half.largest // 2:  # (class docs: beyond, the clusters first)
            C, states = np.arange(w.size), None
        else:
            C, states = self._on_clusters(c, b, lam0, rho)
            if np.count_nonzero(states != SEPARATED) > half.largest:
                raise _Outgrown  # (before the model's block is formed; the clusters' zone alone is no start: measured
                # at 193k dofs, 137 and 130 back-substitutions in the two steps it served, 120 and 81 from the last
                # states)
        found = self._solve(half, C, c, (b[C], w[C], lam0[C], rho[C] if np.ndim(rho) else rho), states)
        states, lam = np.full(w.size, SEPARATED), np.zeros(w.size)
        states[C], lam[C] = found
        return states, lam

    def _solve(self, half, C, c, problem, states=None):
        """The primal-dual active set on the model M = c G~_CC of ``half`` (points C), s = b - M (lam - lam0), for
        ``problem`` = (b, w, lam0, rho) on C: (states, lam); raises _Cycled or _Outgrown (more unknowns than a dense
        factor is allowed). Its factors are updated from one active set to the next (:class:`ModelFactor`)."""
        b, w, lam0, rho = problem
        G = half.block(C)  # (M = c G, never formed: G may be the half-space's own block)
        layer, shifted = self.layer, b + c * (G @ lam0)  # (s = shifted - M lam)
        if states is None:
            states = layer.state_of(b + rho * lam0, rho * w)
        seen = set()
        for _ in range(self.max_iterations):
            if states.tobytes() in seen:
                break
            seen.add(states.tobytes())
            unknown, rhs, D, lam = state_system(layer, w, states, shifted)
            U = np.nonzero(unknown)[0]
            if U.size > self.half.largest:
                raise _Outgrown
            if U.size:
                try:
                    solve = half.factors(C[U], D[U], c)
                except la.LinAlgError:
                    raise _Cycled from None  # (the model is not positive definite here: no guide either)
                lam[U] = solve(rhs[U] - c * (G[U] @ lam) if lam.any() else rhs[U])  # (lam: the forces known, mostly 0)
            new = layer.state_of(shifted - c * (G @ lam) + rho * lam, rho * w)
            if np.array_equal(new, states):
                return states, lam
            states = new
        raise _Cycled

    def _on_clusters(self, c, b, lam0, rho):
        """(the points to solve on, their first states) from the problem on clusters."""
        if self._coarse is None:
            self._coarse = self._cluster()
        label, keys, half, W = self._coarse
        B = np.bincount(label, self.half.w * b, minlength=W.size) / W
        # (rho: a point's displacement per force, here the mean member's over as many members as share the force)
        count = np.bincount(label, minlength=W.size)
        rho = np.bincount(label, np.broadcast_to(rho, label.shape), minlength=W.size) / count ** 2
        states, _ = self._solve(half, np.arange(W.size), c, (B, W, np.bincount(label, lam0, minlength=W.size), rho))
        touching = states != SEPARATED
        near = {tuple(k + o) for k in keys[touching] for o in itertools.product((-1, 0, 1), repeat=keys.shape[1])}
        ring = np.array([tuple(k) in near for k in keys])
        C = np.nonzero(ring[label] | (lam0 != 0))[0]
        return C, np.where(touching[label[C]], states[label[C]], SEPARATED)

    def _cluster(self):
        """(each point's cluster, the clusters' cells, their HalfSpace, their areas): cells of a grid twice, three
        times... the points' spacing, until there are at most :attr:`clusters` x ``largest`` of them."""
        x, w = self.half.x, self.half.w
        spacing = float(np.sqrt(np.median(w)))
        for n in itertools.count(2):
            cells = np.floor(x / (n * spacing)).astype(np.int64)
            keys, label = np.unique(cells, axis=0, return_inverse=True)
            if len(keys) <= self.clusters * self.half.largest:
                break
        label = label.ravel()
        W = np.bincount(label, w)
        X = np.column_stack([np.bincount(label, w * x[:, i]) for i in range(x.shape[1])]) / W[:, None]
        return label, keys, HalfSpace(X, W, self.half.largest, self.half.mirrors, self.half.held_point), W


def dense_points(ndof: int, method: str, backsubs: float) -> int:
    """The number of points m whose dense Cholesky factor costs as much as ``backsubs`` back-substitutions through
    the sparse factor of K (``method``, ``ndof`` dofs, 3D): m^3 / 3 flops at about 30 GFlop/s on one core against
    16 bytes read per nonzero of the factor (:func:`~workbench.discrete.solvers.sparse_factor_bytes`) at about
    10 GB/s, so m^3 = 144 backsubs nnz.

    >>> dense_points(46_938, "sparsecholesky", 2.0)
    2473
    """
    nnz = solvers.sparse_factor_bytes(3, ndof, method) / 8.0
    return int(round((144.0 * backsubs * nnz) ** (1.0 / 3.0)))
