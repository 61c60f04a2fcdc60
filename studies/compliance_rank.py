"""How compressible the candidates' compliance is: the numerical ranks of its off-diagonal blocks on the hemisphere.

    python studies/compliance_rank.py [--out data/contact_solver] [--levels 0.005 0.0035]

Model A's implicit steps on candidate facets (``hertz3d``, :mod:`workbench.schemes.facet_candidates`) factor the
springs' system I + J G on the dofs R in contact densely, G the candidates' compliance: about 2/3 |R|^3 per factor.
As R is a patch of the surface, |R| grows like n^(2/3) and the dense work like n^2: that is what lifts a step's cost
above the slope of 1.2 issue 22 asks for (docs/schemes.md). A hierarchical (HODLR) representation of G would cost
about |R| k^2 per level instead, k the rank of the blocks between the two halves of a cluster. This study measures
those ranks on the compliance the run itself forms.

Per level of h_contact: ``hertz3d`` runs at its defaults (one thread); the compliance of the candidates its last
factorization keeps (the inverse of their condensed stiffness, exact) and the candidates' positions are taken.
The points are split in halves along their longest extent, recursively, down to 64 points; each pair of halves'
block of G gets its singular values. Per level of that tree: the blocks, their size, and the largest and mean rank
at each relative tolerance (singular values above tol x ||G||_2; ``norm_over_diagonal``: ||G||_2 over G's largest
diagonal entry, large as every candidate moves under a load at any one of them, so a tolerance relative to the
norm is that many times looser against the entries near the diagonal). ``storage``: the entries of a HODLR
representation at that tolerance (the ranks' factors, the leaves dense) over the n^2 of the dense G. Writes
``compliance_rank.csv`` (about 3 minutes at the default levels).
"""
from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

TOLERANCES = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
LEAF = 64


def compliance(h_contact: float):
    """(G, the candidates' positions, ndof) from the last operator ``hertz3d`` makes at ``h_contact``."""
    from threadpoolctl import threadpool_limits

    import workbench
    from workbench.schemes import facet_candidates

    made, original = {}, facet_candidates.FacetCandidates.operator

    def operator(self, solver, again=False):
        found = original(self, solver, again)
        if found is not None:  # (the last one: the candidates grow in the run)
            made.update(G=found[1].schur.compliance.copy(), x=self.sub.dof_points()[0].copy())
        return found

    facet_candidates.FacetCandidates.operator = operator
    try:
        with threadpool_limits(1):
            ds = workbench.run("hertz3d", h_contact=h_contact, progress=False, threads=1)
    finally:
        facet_candidates.FacetCandidates.operator = original
    return made["G"], made["x"], int(ds.attrs["ndof"])


def ranks(G: np.ndarray, x: np.ndarray) -> dict:
    """{tree level: [(size of the first half, size of the second, [rank at each tolerance])]} by bisection."""
    norm = np.linalg.norm(G, 2)
    out: dict = {}

    def split(idx, level):
        if idx.size <= LEAF:
            return
        points = x[idx]
        axis = int(np.argmax(points.max(0) - points.min(0)))
        order = idx[np.argsort(points[:, axis], kind="stable")]
        a, b = order[: idx.size // 2], order[idx.size // 2:]
        s = np.linalg.svd(G[np.ix_(a, b)], compute_uv=False)
        out.setdefault(level, []).append((a.size, b.size, [int(np.sum(s > tol * norm)) for tol in TOLERANCES]))
        split(a, level + 1)
        split(b, level + 1)

    split(np.arange(len(G)), 0)
    return out


def storage(tree: dict, n: int) -> list:
    """Per tolerance, a HODLR representation's entries over n^2: each pair of halves as two rank-k factors (both
    ways: G is symmetric, but the springs' system I + J G is not), the leaves dense."""
    leaves = n * LEAF  # (at most: the leaves are <= LEAF points each, n points in all)
    out = []
    for i in range(len(TOLERANCES)):
        low_rank = sum(2 * r[i] * (na + nb) for blocks in tree.values() for na, nb, r in blocks)
        out.append(round((low_rank + leaves) / n**2, 3))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/contact_solver")
    p.add_argument("--levels", type=float, nargs="+", default=[0.005, 0.0035])
    args = p.parse_args()
    rows = []
    for hc in args.levels:
        G, x, ndof = compliance(hc)
        tree = ranks(G, x)
        share = storage(tree, len(G))
        spread = float(np.linalg.norm(G, 2) / G.diagonal().max())
        for level, blocks in sorted(tree.items()):
            r = np.array([b[2] for b in blocks])
            for i, tol in enumerate(TOLERANCES):
                rows.append(dict(h_contact=hc, ndof=ndof, candidates=len(G), level=level, blocks=len(blocks),
                                 size=blocks[0][0], tol=tol, max_rank=int(r[:, i].max()),
                                 mean_rank=round(float(r[:, i].mean()), 1), storage=share[i],
                                 norm_over_diagonal=round(spread, 1)))
        print(f"h_contact {hc}: {ndof} dofs, {len(G)} candidates, ||G||_2 / max diag {spread:.0f}; HODLR storage at "
              f"tolerances {list(TOLERANCES)}, over n^2: {share}", flush=True)
        for level, blocks in sorted(tree.items()):
            r = np.array([b[2] for b in blocks])
            print(f"  level {level}: {len(blocks)} blocks of {blocks[0][0]} points, largest ranks "
                  f"{r.max(0).tolist()}", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "compliance_rank.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
