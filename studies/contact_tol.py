"""What ``contact_tol`` trades: back-substitutions and time against the solution's distance from the tight solve,
beside the Hertz pressure's own discretisation error.

    python studies/contact_tol.py [--out data/hertz] [--levels 0.01 0.005] [--tols 1e-11 1e-9 1e-7 1e-6] [--reps 3]

``memory_hertz3d`` (Signorini, from rest to the full load in 4 steps) with the coupled contact solver, the one that
reads the tolerance, asked by name (``auto`` takes the condensed solver at 0.01 and solves on candidate points first
at 0.005, exactly per active set: contact_tol then acts only if the zone outgrows them, and it does not here) at
each h_contact, one process per level, one thread. After a warm-up
run the tolerances are run round-robin ``reps`` times (the machine's drift spread over all of them) and the median
wall time of ``workbench.run`` is kept. Per row: dofs, contact vertices, the back-substitutions, the median time and
its ratio to the tightest tolerance's, the largest difference of u at the contact points from the tightest run
(relative to its largest value), the same for the contact pressure, and the pressure's relative L2 error against
Hertz (``node_weight``-weighted, :func:`workbench.references.hertz.profile`). Writes ``contact_tol.csv`` (about 2
minutes at the defaults).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

CHILD = """
import json, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
import workbench
from workbench.references import hertz
hc, tols, reps = float(sys.argv[1]), [float(t) for t in sys.argv[2].split(",")], int(sys.argv[3])
times, runs = {tol: [] for tol in tols}, {}
with threadpool_limits(1):
    workbench.run("memory_hertz3d", h_contact=hc, progress=False, threads=1, contact_solver="coupled")  # (warm-up)
    for _ in range(reps):
        for tol in tols:
            t0 = time.perf_counter()
            runs[tol] = workbench.run("memory_hertz3d", h_contact=hc, contact_tol=tol, progress=False, threads=1,
                                      contact_solver="coupled")
            times[tol].append(time.perf_counter() - t0)
tight = runs[min(tols)]
u0, p0 = tight.u_contact.values, tight.contact_pressure.values
base = float(np.median(times[min(tols)]))
for tol in tols:
    ds = runs[tol]
    print(json.dumps(dict(h_contact=hc, ndof=int(ds.attrs["ndof"]), contact_vertices=int(ds.sizes["node"]),
                          contact_solver=ds.attrs["contact_solver_used"], contact_tol=tol,
                          backsubs=int(ds.linear_solves.sum()), run=round(float(np.median(times[tol])), 3),
                          ratio=round(float(np.median(times[tol])) / base, 3),
                          u_difference=float(np.abs(ds.u_contact.values - u0).max() / np.abs(u0).max()),
                          p_difference=float(np.abs(ds.contact_pressure.values - p0).max() / np.abs(p0).max()),
                          l2_hertz=round(hertz.profile(ds)["l2"], 6))))
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("data/hertz"))
    parser.add_argument("--levels", type=float, nargs="+", default=[0.01, 0.005])
    parser.add_argument("--tols", type=float, nargs="+", default=[1e-11, 1e-9, 1e-7, 1e-6])
    parser.add_argument("--reps", type=int, default=3)
    args = parser.parse_args()
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    rows = []
    for hc in args.levels:
        done = subprocess.run([sys.executable, "-c", CHILD, str(hc), ",".join(map(str, args.tols)), str(args.reps)],
                              capture_output=True, text=True, env=env, check=True)
        for line in done.stdout.splitlines():
            row = json.loads(line)
            rows.append(row)
            print(f"h_contact {hc:g} ({row['ndof']} dofs, {row['contact_solver']}): contact_tol "
                  f"{row['contact_tol']:.0e} {row['backsubs']} back-substitutions, {row['run']:.2f} s "
                  f"({row['ratio']:.2f} x), u moved {row['u_difference']:.1e}, p {row['p_difference']:.1e}, "
                  f"Hertz L2 {100 * row['l2_hertz']:.3f} %", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "contact_tol.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
