"""Which direct solver for K_A v = r in ``plain_explicit.py``: time one factorisation and one solve each.

K_A is the viscous matrix of the slab on the free dofs (nx × ny = 160 × 16 by
default, 5440 unknowns), reverse Cuthill–McKee ordered. The explicit scheme
factors it once and solves with it every step, so the solve time decides.
Candidates:

* ``dpbtrs``: LAPACK banded Cholesky (``dpbtrf`` once), called directly;
* ``cho_solve_banded``: the same through SciPy's wrapper (argument checks per call);
* ``splu/<ordering>``: SuperLU LU with the column orderings SciPy offers;
* ``factorized``: ``scipy.sparse.linalg.factorized`` (UMFPACK if scikit-umfpack is
  installed, else SuperLU/COLAMD).

Reported: factor nonzeros, factorisation time, and the best of 5 × 200 solves,
with 1 BLAS thread (set OPENBLAS_NUM_THREADS=1 etc. before the run).

Command (from the repository root)::

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 python studies/baseline/bench_solvers.py
"""
from __future__ import annotations

import argparse
import sys
import time
import timeit
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_solve_banded
from scipy.sparse.linalg import factorized, splu

sys.path.insert(0, str(Path(__file__).resolve().parent))
import plain_explicit as plain  # noqa: E402


def best_time(f, number: int = 200, repeat: int = 5) -> float:
    """Best mean time of ``f()`` in seconds over ``repeat`` runs of ``number`` calls."""
    return min(timeit.repeat(f, number=number, repeat=repeat)) / number


def main(argv=None) -> None:
    """Print one line per solver."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nx", type=int, default=160)
    ap.add_argument("--ny", type=int, default=16)
    a = ap.parse_args(argv)
    args = plain.parse(["--nx", str(a.nx), "--ny", str(a.ny)])
    slab = plain.Slab(args)
    K = plain.stiffness(slab.xy, slab.tri, args.a1, args.a2)[slab.dofs][:, slab.dofs].tocsc()  # RCM order
    b = np.random.default_rng(0).normal(size=K.shape[0])
    print(f"K_A: {K.shape[0]} unknowns, {K.nnz} nonzeros")
    rows = []

    t0 = time.perf_counter()
    band = plain.BandedCholesky(K)
    t_fac = time.perf_counter() - t0
    rows.append(("dpbtrs (banded Cholesky)", band.factor.size, t_fac, best_time(lambda: band.solve(b))))
    rows.append(("cho_solve_banded", band.factor.size, t_fac,
                 best_time(lambda: cho_solve_banded((band.factor, False), b, check_finite=False))))
    for spec in ("COLAMD", "MMD_AT_PLUS_A", "MMD_ATA", "NATURAL"):
        t0 = time.perf_counter()
        lu = splu(K, permc_spec=spec)
        t_fac = time.perf_counter() - t0
        rows.append((f"splu/{spec}", lu.L.nnz + lu.U.nnz, t_fac, best_time(lambda: lu.solve(b))))
    t0 = time.perf_counter()
    solve = factorized(K)
    rows.append(("factorized", -1, time.perf_counter() - t0, best_time(lambda: solve(b))))

    ref = band.solve(b)
    print(f"banded: bandwidth {band.bandwidth}; all solvers agree to "
          f"{max(np.abs(lu.solve(b) - ref).max(), np.abs(solve(b) - ref).max()) / np.abs(ref).max():.1e}")
    print(f"{'solver':<26} {'factor nnz':>11} {'factor [ms]':>12} {'solve [ms]':>11}")
    for name, nnz, tf, ts in rows:
        print(f"{name:<26} {nnz:>11} {1e3 * tf:>12.2f} {1e3 * ts:>11.3f}")


if __name__ == "__main__":
    main()
