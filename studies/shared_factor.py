"""One factor of K_G for every step operator of a body with A = tau G (``SharedFactor``), against a factor per
operator, on the Hertz hemisphere under error control.

    python studies/shared_factor.py [--h-contact 0.005] [--scheme bdf2] [--rtol 1e-3] [--T 0.5] [--repeat 2]
                                    [--out data/hertz]

``hertz3d`` derives its viscosity from its elasticity (A = tau G), so each implicit step operator a0 K_A + K_G is
(a0 tau + 1) K_G. Under error control every step size has its own a0, and before ``SharedFactor`` each was factored.
With the shared factor the contact candidates are kept once for every operator, so error control takes them too
(docs/schemes.md, "One factor for a body with A = tau G"); "own" runs the coupled solver on the whole side.
Each run is a process of its own, one thread; the two variants alternate (the first of each repetition swaps), and
"own" disables ``SharedFactor.of``. Per run: the factorizations (calls of ``solvers.factor``), the steps, the run's
wall time, and u and the pressures against the other variant of the same repetition. Writes ``shared_factor.csv``.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

CHILD = """
import json, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
import workbench
from workbench.discrete import solvers
from workbench.schemes import step_operators
variant, hc, scheme, rtol, T, out = sys.argv[1], float(sys.argv[2]), sys.argv[3], float(sys.argv[4]), \\
    float(sys.argv[5]), sys.argv[6]
made = []
factor = solvers.factor
solvers.factor = lambda *args, **kwargs: made.append(1) or factor(*args, **kwargs)
if variant == "own":
    step_operators.SharedFactor.of = classmethod(lambda cls, d, scheme: None)
with threadpool_limits(1):
    t0 = time.perf_counter()
    ds = workbench.run("hertz3d", h_contact=hc, scheme=scheme, rtol=rtol, T=T, progress=False, threads=1)
    run = time.perf_counter() - t0
np.savez(out, u=ds.u_probe.values, p=ds.contact_pressure.values)
print(json.dumps(dict(variant=variant, ndof=int(ds.attrs["ndof"]), contact_solver=ds.attrs["contact_solver_used"],
                      factorizations=len(made), steps=int(ds.attrs["nsteps"]), run=round(run, 2))))
"""


def one(variant: str, args, out: Path) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    argv = [sys.executable, "-c", CHILD, variant, str(args.h_contact), args.scheme, str(args.rtol), str(args.T),
            str(out)]
    done = subprocess.run(argv, capture_output=True, text=True, env=env, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--h-contact", type=float, default=0.005)
    p.add_argument("--scheme", default="bdf2", choices=["implicit", "bdf2"])
    p.add_argument("--rtol", type=float, default=1e-3)
    p.add_argument("--T", type=float, default=0.5)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--out", default="data/hertz")
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for rep in range(args.repeat):
        order = ("own", "shared") if rep % 2 == 0 else ("shared", "own")
        arrays = {}
        for variant in order:
            rows.append(one(variant, args, out / f".shared_factor_{variant}.npz") | {"repeat": rep})
            arrays[variant] = np.load(out / f".shared_factor_{variant}.npz")
            print(rows[-1], flush=True)
        for name, key in (("u_difference", "u"), ("p_difference", "p")):
            a, b = arrays["own"][key], arrays["shared"][key]
            diff = float(np.nanmax(np.abs(a - b)) / np.nanmax(np.abs(a))) if a.shape == b.shape else float("nan")
            for r in rows[-2:]:
                r[name] = f"{diff:.2g}"
    for variant in ("own", "shared"):
        (out / f".shared_factor_{variant}.npz").unlink(missing_ok=True)
    with open(out / "shared_factor.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    for variant in ("own", "shared"):
        runs = [r["run"] for r in rows if r["variant"] == variant]
        print(f"{variant}: median {np.median(runs):.2f} s over {len(runs)}: {runs}")


if __name__ == "__main__":
    main()
