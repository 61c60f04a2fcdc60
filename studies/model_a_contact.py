"""Model A's coupled contact Newton on the 3D Hertz hemisphere: today's code against a git revision's, side by side.

    python studies/model_a_contact.py [--out data/hertz] [--levels 0.02 0.01 0.005] [--c-nu 1e5 1e7]
                                      [--before REV] [--condensed-up-to NDOF]

``hertz3d`` (Kelvin-Voigt, tau = 1e-3, normal compliance c_nu, backward Euler, k = 0.1 to T = 1: 10 steps) with
``contact_solver = "coupled"``, and ``"condensed"`` up to ``--condensed-up-to`` dofs (its dense contact stiffness
grows like the contact dofs cubed). ``--before REV`` runs the same coupled cases on the code of that revision
(checked out into a temporary git worktree, imported from there), in the same run. Each run is a process of its
own, one thread. Per run: dofs, contact dofs, Newton iterations, inner iterations (one back-substitution each),
the run's wall time, the largest difference of u at the contact dofs from the first run of its size and c_nu
(the solvers solve the same discrete problem), and the process's peak memory. Writes ``model_a_contact.csv``.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import json, resource, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
import workbench
hc, c_nu, contact_solver, out = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3], sys.argv[4]
with threadpool_limits(1):
    t0 = time.perf_counter()
    ds = workbench.run("hertz3d", h_contact=hc, c_nu=c_nu, tau=1e-3, k=0.1, contact_solver=contact_solver,
                       progress=False, threads=1)
    run = time.perf_counter() - t0
np.save(out, ds.u_contact.values)
print(json.dumps(dict(ndof=int(ds.attrs["ndof"]), contact_points=int(ds.sizes["node"]),
                      newton=int(ds.newton_iterations.sum()),
                      inner=int(ds.linear_iterations.sum()) if "linear_iterations" in ds else 0, run=round(run, 2),
                      peak_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0))))
"""


def one(hc: float, c_nu: float, contact_solver: str, code: str, out: str) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONPATH=code)
    done = subprocess.run([sys.executable, "-c", CHILD, str(hc), str(c_nu), contact_solver, out],
                          capture_output=True, text=True, env=env, check=True, cwd=code)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    import numpy as np

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/hertz")
    p.add_argument("--levels", type=float, nargs="+", default=[0.02, 0.01, 0.005])
    p.add_argument("--c-nu", type=float, nargs="+", default=[1e5, 1e7])
    p.add_argument("--before", default=None, help="a git revision whose coupled solver runs alongside")
    p.add_argument("--condensed-up-to", type=int, default=15000)
    args = p.parse_args()
    here = str(Path(__file__).resolve().parents[1])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        codes = {"now": here}
        if args.before:
            subprocess.run(["git", "-C", here, "worktree", "add", "--detach", f"{tmp}/before", args.before],
                           check=True, capture_output=True)
            codes["before"] = f"{tmp}/before"
        try:
            for c_nu in args.c_nu:
                for hc in args.levels:
                    runs = [("now", "coupled")] + ([("before", "coupled")] if args.before else [])
                    runs += [("now", "condensed")]
                    first = None
                    for code, solver in runs:
                        if solver == "condensed" and rows and rows[-1]["ndof"] > args.condensed_up_to:
                            continue
                        out = f"{tmp}/u.npy"
                        row = dict(c_nu=c_nu, h_contact=hc, code=code, contact_solver=solver)
                        row |= one(hc, c_nu, solver, codes[code], out)
                        u = np.load(out)
                        first = u if first is None else first
                        row["du_rel"] = float(np.abs(u - first).max() / np.abs(first).max())
                        rows.append(row)
                        print(row, flush=True)
        finally:
            if args.before:
                subprocess.run(["git", "-C", here, "worktree", "remove", "--force", f"{tmp}/before"],
                               capture_output=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "model_a_contact.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {out / 'model_a_contact.csv'}")


if __name__ == "__main__":
    main()
