"""A hierarchical (HODLR) preconditioner for Model A's springs' system, prototyped against the dense factor.

    python studies/springs_hodlr.py [--out data/contact_solver] [--levels 0.005 0.0035 0.0025] [--call 0.95]

Model A's Newton directions on candidate facets solve (J^-1 + S_RR) t = (S b)_R by conjugate gradients
(:class:`workbench.discrete.condensation.CoupledNewton`, S the candidates' compliance G, exact and dense), with the
preconditioner (I + J G_RR)^-1 J: a dense LU factor of 2/3 |R|^3, updated at low rank between factors. This study
asks what a compressed G would give instead. Per level of h_contact, ``hertz3d`` runs at its defaults (one thread)
and one springs' system late in the run is taken as the run built it: G, J, R, b (the ``--call`` share of its
Newton directions on the candidates; at 193k dofs the zone outgrows them late in the run, and the coupled solver's
systems after that are not taken). On it, each preconditioner below is made, applied and used by the same
conjugate gradients to the run's tolerance:

* ``dense``: the LU factor of I + J G_RR, as the package makes it (one iteration: it is exact);
* ``dense, lumped J``: the same with J replaced by the diagonal of its row sums (is J's coupling needed?);
* ``hodlr TOL``: G compressed once per operator (the candidates split in halves along their longest extent down to
  64 points, each pair of halves' block of G by a randomized SVD, singular values above TOL x ||G||_2), and
  I + J G~ factored by recursive Woodbury on that tree. A block of J G~ between halves x and y is J_xx G~_xy plus
  J's couplings out of x (its halo H) times the exact G_Hy, so its rank is G's plus |H|.

Per row: |R|, the one-time compression, the factor, one application, the iterations, and t's largest difference
from the dense preconditioner's, over t's largest. Writes ``springs_hodlr.csv`` (about 12 minutes at the defaults,
8 of them and 3.7 GB for 193k dofs).
This is a prototype in NumPy, measured to decide whether to build it (docs/schemes.md), not a solver of the package.
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

LEAF = 64


def captured(h_contact: float, share: float) -> dict:
    """One springs' system of a ``hertz3d`` run, as :meth:`CoupledNewton._in_forces` received it."""
    from threadpoolctl import threadpool_limits

    import workbench
    from workbench.discrete.condensation import CoupledNewton, DenseSchur

    calls, original = [], CoupledNewton._in_forces

    def in_forces(self, J, R, b, S_b, eta, u_C):
        if isinstance(self.schur, DenseSchur):  # (the candidates' exact compliance, not the coupled solver's)
            calls.append(dict(G=self.schur.compliance, J=J.tocsr(), R=R, b=b, S_b=S_b, eta=eta,
                              points=self.op.dof_points()[0]))
        return original(self, J, R, b, S_b, eta, u_C)

    CoupledNewton._in_forces = in_forces
    try:
        with threadpool_limits(1):
            ds = workbench.run("hertz3d", h_contact=h_contact, progress=False, threads=1)
    finally:
        CoupledNewton._in_forces = original
    found = calls[min(int(share * len(calls)), len(calls) - 1)]
    found["ndof"] = int(ds.attrs["ndof"])
    return found


class Cluster:
    """The candidates split in halves along their longest extent, down to LEAF points."""

    def __init__(self, idx: np.ndarray, points: np.ndarray):
        self.idx, self.children = idx, None
        if idx.size > LEAF:
            p = points[idx]
            order = idx[np.argsort(p[:, int(np.argmax(p.max(0) - p.min(0)))], kind="stable")]
            self.children = (Cluster(order[: order.size // 2], points), Cluster(order[order.size // 2:], points))

    def compress(self, G: np.ndarray, tol: float, rng) -> None:
        """G[a, b] ~ U diag(s) V^T for the halves (a, b) of every cluster (randomized, the rank grown to tol)."""
        if self.children is None:
            return
        a, b = self.children
        A = G[np.ix_(a.idx, b.idx)]
        r = 8
        while True:
            Q = np.linalg.qr(A @ rng.standard_normal((b.idx.size, min(r + 8, b.idx.size))))[0]
            U, s, Vt = np.linalg.svd(Q.T @ A, full_matrices=False)
            k = int(np.sum(s > tol))
            if k < Q.shape[1] - 4 or Q.shape[1] >= min(A.shape):
                break
            r *= 2
        self.U, self.s, self.V = Q @ U[:, :k], s[:k], Vt[:k].T
        self.order = (np.argsort(a.idx), np.argsort(b.idx))
        a.compress(G, tol, rng)
        b.compress(G, tol, rng)

    def rows_of(self, half: int, candidates: np.ndarray) -> np.ndarray:
        """The rows of the compressed factors (U for half 0, V for half 1) for ``candidates`` of that half."""
        idx, order = self.children[half].idx, self.order[half]
        return order[np.searchsorted(idx[order], candidates)]


class HodlrFactor:
    """r -> (I + J G~)^-1 J r on R by recursive Woodbury over the clusters restricted to R (study docs)."""

    def __init__(self, root: Cluster, G: np.ndarray, J, R: np.ndarray):
        self.G, self.J, self.R = G, J.tocsr(), R
        self.at = np.full(G.shape[0], -1)
        self.at[R] = np.arange(R.size)
        self.root = self._factor(root)

    def _factor(self, cluster: Cluster) -> dict:
        p = self.at[cluster.idx]
        rows = np.sort(p[p >= 0])
        if cluster.children is None or rows.size <= LEAF:
            M = self.J[rows] @ self.G[np.ix_(self.R, self.R[rows])]
            M[np.arange(rows.size), np.arange(rows.size)] += 1.0
            return dict(rows=rows, lu=la.lu_factor(M, check_finite=False))
        fa, fb = (self._factor(c) for c in cluster.children)
        U_ab, V_ab = self._block(cluster, fa["rows"], fb["rows"], 0)
        U_ba, V_ba = self._block(cluster, fb["rows"], fa["rows"], 1)
        DU_ab, DU_ba = self._solve(fa, U_ab), self._solve(fb, U_ba)
        ka = U_ab.shape[1]
        cap = np.eye(ka + U_ba.shape[1])
        cap[:ka, ka:] = V_ab.T @ DU_ba
        cap[ka:, :ka] = V_ba.T @ DU_ab
        return dict(rows=rows, children=(fa, fb), ia=np.searchsorted(rows, fa["rows"]),
                    ib=np.searchsorted(rows, fb["rows"]), V=(V_ab, V_ba), DU=(DU_ab, DU_ba), ka=ka,
                    cap=la.lu_factor(cap, check_finite=False))

    def _block(self, cluster, rx, ry, half):
        """(J G~)[rx, ry] = U V^T: J_xx G~_xy (G~ compressed) and J_xH G_Hy (H: J's columns off x, G exact)."""
        Jx = self.J[rx]
        cx, cy = self.R[rx], self.R[ry]
        if half == 0:
            Ux, Vy = cluster.U[cluster.rows_of(0, cx)] * cluster.s, cluster.V[cluster.rows_of(1, cy)]
        else:
            Ux, Vy = cluster.V[cluster.rows_of(1, cx)] * cluster.s, cluster.U[cluster.rows_of(0, cy)]
        inside = np.zeros(self.R.size, dtype=bool)
        inside[rx] = True
        H = np.unique(Jx.indices[~inside[Jx.indices]])
        U = Jx[:, rx] @ Ux
        if not H.size:
            return U, Vy
        return np.hstack([U, Jx[:, H].toarray()]), np.hstack([Vy, self.G[np.ix_(cy, self.R[H])]])

    def _solve(self, f: dict, x: np.ndarray) -> np.ndarray:
        if "lu" in f:
            return la.lu_solve(f["lu"], x, check_finite=False)
        (fa, fb), (V_ab, V_ba), (DU_ab, DU_ba), ka = f["children"], f["V"], f["DU"], f["ka"]
        ya, yb = self._solve(fa, x[f["ia"]]), self._solve(fb, x[f["ib"]])
        w = la.lu_solve(f["cap"], np.concatenate([V_ab.T @ yb, V_ba.T @ ya]), check_finite=False)
        out = np.empty_like(x)
        out[f["ia"]], out[f["ib"]] = ya - DU_ab @ w[:ka], yb - DU_ba @ w[ka:]
        return out

    def __call__(self, r: np.ndarray) -> np.ndarray:
        return self._solve(self.root, self.J @ r)


def dense(G, J, R):
    """r -> (I + J G_RR)^-1 J r by a dense LU factor, as the package makes it."""
    A = J @ G[np.ix_(R, R)]
    A[np.diag_indices_from(A)] += 1.0
    lu = la.lu_factor(A.T, overwrite_a=True, check_finite=False)
    return lambda r: la.lu_solve(lu, J @ r, trans=1, check_finite=False)


def cg(s: dict, precondition, most: int = 200):
    """The conjugate gradients of CoupledNewton._in_forces on the captured system: (iterations, t)."""
    G, J, R, b = s["G"], s["J"], s["R"], s["b"]
    G_RR = G[np.ix_(R, R)]
    spring = spla.splu((J + sp.diags(1e-10 * J.diagonal())).tocsc())
    t, r = np.zeros(R.size), s["S_b"][R].copy()
    z = precondition(r)
    d, rz = z.copy(), float(r @ z)
    for it in range(most):
        if np.abs(J @ r).max() <= s["eta"] * np.abs(b).max():
            return it, t
        A_d = spring.solve(d) + G_RR @ d
        a = rz / float(d @ A_d)
        t += a * d
        r -= a * A_d
        z = precondition(r)
        rz, rz_old = float(r @ z), rz
        d = z + (rz / rz_old) * d
    return most, t


def timed(make, probe):
    t0 = time.perf_counter()
    precondition = make()
    t1 = time.perf_counter()
    for _ in range(5):
        precondition(probe)
    return precondition, t1 - t0, (time.perf_counter() - t1) / 5


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/contact_solver")
    p.add_argument("--levels", type=float, nargs="+", default=[0.005, 0.0035, 0.0025])
    p.add_argument("--call", type=float, default=0.95, help="which springs' system, as a share of the run's")
    args = p.parse_args()
    rows = []
    for hc in args.levels:
        s = captured(hc, args.call)
        G, J, R = s["G"], s["J"], s["R"]
        probe = np.random.default_rng(1).standard_normal(R.size)
        precondition, factor, apply = timed(lambda: dense(G, J, R), probe)
        iterations, t_dense = cg(s, precondition)
        base = dict(h_contact=hc, ndof=s["ndof"], candidates=len(G), R=R.size)
        rows.append(dict(base, preconditioner="dense", compress=0.0, factor=factor, apply=apply,
                         iterations=iterations, t_difference=0.0))
        lumped = sp.diags(np.asarray(abs(J).sum(axis=1)).ravel()).tocsr()
        precondition, factor, apply = timed(lambda: dense(G, lumped, R), probe)
        iterations, t = cg(s, precondition)
        rows.append(dict(base, preconditioner="dense, lumped J", compress=0.0, factor=factor, apply=apply,
                         iterations=iterations, t_difference=float(np.abs(t - t_dense).max() / np.abs(t_dense).max())))
        norm = np.linalg.norm(G, 2)
        for tol in (1e-4, 1e-6):
            root = Cluster(np.arange(len(G)), s["points"])
            t0 = time.perf_counter()
            root.compress(G, tol * norm, np.random.default_rng(0))
            compress = time.perf_counter() - t0
            precondition, factor, apply = timed(lambda: HodlrFactor(root, G, J, R), probe)
            iterations, t = cg(s, precondition)
            rows.append(dict(base, preconditioner=f"hodlr {tol:g}", compress=compress, factor=factor, apply=apply,
                             iterations=iterations,
                             t_difference=float(np.abs(t - t_dense).max() / np.abs(t_dense).max())))
        for r in rows[-4:]:
            print({k: round(v, 4) if isinstance(v, float) else v for k, v in r.items()}, flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "springs_hodlr.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for r in rows:
            writer.writerow({k: f"{v:.4g}" if isinstance(v, float) else v for k, v in r.items()})


if __name__ == "__main__":
    main()
