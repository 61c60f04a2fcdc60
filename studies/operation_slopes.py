"""The floor under issue 22's slope: how the cheapest operations on the hemisphere's K grow with the dofs.

    python studies/operation_slopes.py [--out data/hertz] [--levels 0.005 0.0035 0.0025] [--repeats 15]

Issue 22 asks for the cost of a Model B step to grow with slope at most 1.2 against the dofs (log-log, three sizes).
A step does at least one solve with K's factor and a few products with K. This study times those alone on the
meshes of ``studies/hertz_ratio.py`` (``memory_hertz3d`` at each ``h_contact``), one thread, in one process: a
PARDISO back-substitution (both halves, one right-hand side), the factor's nonzeros, a product with NGSolve's K and
one with K as a SciPy CSR matrix, each the median of ``--repeats`` calls, and fits each one's slope. Writes
``operation_slopes.csv`` (about 2 minutes, 2.4 GB at the largest level).
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np


def median_time(call, repeats: int) -> float:
    call()  # (warm: the first call pays page faults and caches)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def level(h_contact: float, repeats: int) -> dict:
    import workbench
    from workbench.discrete import discretisation, pardiso, solvers

    d = discretisation.build(workbench.scene("memory_hertz3d", h_contact=h_contact))
    K = solvers.to_scipy(d.elastic.mat)
    free = np.flatnonzero(np.array(d.fes.FreeDofs(), dtype=bool))
    Kf = K[free][:, free].tocsr()
    b = np.random.default_rng(0).standard_normal(Kf.shape[0])
    t0 = time.perf_counter()
    factor = pardiso.Factor(Kf)
    factor_time = time.perf_counter() - t0
    u, v = d.u.vec.CreateVector(), d.u.vec.CreateVector()
    u.FV().NumPy()[:] = 1.0
    mat = d.elastic.mat

    def ngsolve_product():
        v.data = mat * u

    x = np.ones(K.shape[0])
    return {"h_contact": h_contact, "ndof": d.ndof, "factor_nonzeros": factor.nonzeros,
            "factor": round(factor_time, 3), "backsub": median_time(lambda: factor.solve(b), repeats),
            "product_ngsolve": median_time(ngsolve_product, repeats),
            "product_scipy": median_time(lambda: K @ x, repeats)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/hertz")
    p.add_argument("--levels", type=float, nargs="+", default=[0.005, 0.0035, 0.0025])
    p.add_argument("--repeats", type=int, default=15)
    args = p.parse_args()
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        rows = [level(h, args.repeats) for h in args.levels]
    n = np.log([r["ndof"] for r in rows])
    for key in ("factor_nonzeros", "factor", "backsub", "product_ngsolve", "product_scipy"):
        slope = float(np.polyfit(n, np.log([r[key] for r in rows]), 1)[0])
        for r in rows:
            r[f"slope_{key}"] = round(slope, 3)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "operation_slopes.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    for r in rows:
        print(f"{r['ndof']:>7} dofs: back-substitution {1e3 * r['backsub']:.1f} ms, K product "
              f"{1e3 * r['product_ngsolve']:.2f} ms (SciPy {1e3 * r['product_scipy']:.2f} ms), factor "
              f"{r['factor']:.2f} s, {r['factor_nonzeros']} nonzeros")
    print("slopes:", {k[6:]: v for k, v in rows[0].items() if k.startswith("slope_")})


if __name__ == "__main__":
    main()
