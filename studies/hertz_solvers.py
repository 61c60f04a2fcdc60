"""Hertz in 2D and 3D at four levels, the contact solver of today against the one issue 22 was filed on.

    python studies/hertz_solvers.py [--out data/hertz] [--skip-before-above NDOF] [--table-only]

Each run is a process of its own, one thread, so that its peak memory (the process's peak resident set) and its
whole time (imports and meshing included) are its own. Per run: dofs, contact vertices, the contact and linear
solvers taken, active-set iterations, back-substitutions (``setup_backsubs``: those that form the contact stiffness,
one per contact vertex on NGSolve's factor), conjugate gradient iterations, the run's wall time (``workbench.run``,
after the imports, which ``imports`` times apart), the process's wall time and peak memory, and against Hertz (the
Signorini limit, Model B): the pressure's L2 error (lumped and recovered), the peak's error (the apex left out: it is held, and its value is a
reaction) and the contact radius (the farthest vertex in contact and the nearest out of it, over a).

``now``: the defaults (``contact_solver = solver = "auto"``). ``before``: the solver when issue 22 was filed,
``contact_solver = "condensed"`` on NGSolve's ``sparsecholesky``, which forms the contact stiffness by one
back-substitution per contact vertex. Both solve the same discrete problem, so their errors agree; only the cost
differs. ``--skip-before-above`` leaves ``before`` out above that many dofs (the hemisphere at 47k dofs takes
about 13 minutes that way). Writes ``hertz_solvers.csv`` and prints the table of docs/reproduction.md
(``--table-only``: from the csv already written, without running).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import xarray as xr
from pressure_recovery import measures  # (studies/: the same measures as the recovery's table)

from workbench.references import hertz

#: h_contact of each level (memory_hertz's default is 0.0025)
LEVELS = [("memory_hertz", [0.005, 0.0025, 0.00125, 0.000625]), ("memory_hertz3d", [0.04, 0.02, 0.01, 0.005])]
TEXT = {"case", "solver", "contact_solver", "linear_solver"}
SOLVERS = {"now": {}, "before": dict(contact_solver="condensed", solver="sparsecholesky")}

CHILD = """
import json, resource, sys, time
t0 = time.perf_counter()
import ngsolve, scipy.sparse, xarray  # (the imports a run makes at its first call, timed apart from it)
from threadpoolctl import threadpool_limits
import workbench
from workbench.discrete import pardiso
pardiso.available()  # (loads MKL where it is)
imports = time.perf_counter() - t0
name, kw, path = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
with threadpool_limits(1):
    t0 = time.perf_counter()
    ds = workbench.run(name, progress=False, threads=1, **kw)
    wall = time.perf_counter() - t0
ds.attrs["run_wall"], ds.attrs["imports"] = wall, imports
ds.to_netcdf(path)
print(json.dumps({"peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}))
"""


def one(name, hc, solver, tmp):
    """One run in its own process; the row of the table."""
    kw = dict(SOLVERS[solver], h_contact=hc)
    path = os.path.join(tmp, "run.nc")
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, name, json.dumps(kw), path], capture_output=True, text=True,
                          env=env, check=True)
    process = time.perf_counter() - t0
    peak = json.loads(done.stdout.strip().splitlines()[-1])["peak_mb"]
    with xr.open_dataset(path) as ds:
        ds.load()
    r = hertz.profile(ds)
    # the condensed solver on NGSolve's factor forms the contact stiffness by one back-substitution per contact vertex
    # and operator (one here: no memory); linear_solves counts the steps' only
    formed_by_solves = ds.attrs["contact_solver_used"] == "condensed" and ds.attrs["linear_solver"] == "sparsecholesky"
    lumped, recovered = measures(ds, "contact_pressure"), measures(ds, "contact_pressure_recovered")
    return dict(case=name, h_contact=hc, solver=solver,
                contact_solver=ds.attrs["contact_solver_used"], linear_solver=ds.attrs["linear_solver"],
                ndof=int(ds.attrs["ndof"]), contact_vertices=int(ds.sizes["node"]),
                active_set_iterations=int(ds.iterations.sum()), backsubs=int(ds.linear_solves.sum()),
                cg_iterations=int(ds.linear_iterations.sum()) if "linear_iterations" in ds else 0,
                setup_backsubs=int(ds.sizes["node"]) if formed_by_solves else 0,
                run_wall=round(float(ds.attrs["run_wall"]), 2), imports=round(float(ds.attrs["imports"]), 2),
                process_wall=round(process, 2),
                peak_mb=round(peak), l2=round(lumped["l2"], 5), l2_recovered=round(recovered["l2"], 5),
                peak=round(lumped["peak"], 5), peak_recovered=round(recovered["peak"], 5),
                a_last=round(r["a_last"] / r["a"] - 1, 5), a_next=round(r["a_next"] / r["a"] - 1, 5),
                force=round(r["force"], 9))


def table(rows) -> str:
    out = ["| body | h_contact | dofs | contact vertices | solver | active-set iterations | back-substitutions: "
           "forming S + steps (CG) | run | process | peak memory | L2 error, lumped / recovered | peak, recovered | "
           "last in / first out of contact, over a |", "|" + "---|" * 13]
    for r in rows:
        solver = f"{r['solver']}: {r['contact_solver']}, {r['linear_solver']}"
        out.append(f"| `{r['case']}` | {r['h_contact']} | {r['ndof']} | {r['contact_vertices']} | {solver} | "
                   f"{r['active_set_iterations']} | {r['setup_backsubs']} + {r['backsubs']} ({r['cg_iterations']}) | "
                   f"{r['run_wall']} s | "
                   f"{r['process_wall']} s | {r['peak_mb']} MB | "
                   f"{100 * r['l2']:.2f} / {100 * r['l2_recovered']:.2f} % | "
                   f"{100 * r['peak_recovered']:+.2f} % | {100 * r['a_last']:+.1f} / {100 * r['a_next']:+.1f} % |")
    return "\n".join(out)


def agreement(rows):
    """The same discrete problem: both solvers' pressures agree wherever both ran; the ratios of their run times."""
    now = {(r["case"], r["h_contact"]): r for r in rows if r["solver"] == "now"}
    ratios = []
    for b in (r for r in rows if r["solver"] == "before"):
        a = now[b["case"], b["h_contact"]]
        assert a["ndof"] == b["ndof"] and abs(a["l2"] - b["l2"]) <= 1e-4 * max(b["l2"], 1e-12), (a, b)
        ratios.append(round(b["run_wall"] / a["run_wall"], 1))
    return ratios


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/hertz")
    p.add_argument("--skip-before-above", type=int, default=None)
    p.add_argument("--table-only", action="store_true")
    args = p.parse_args()
    out = Path(args.out)
    if args.table_only:
        with open(out / "hertz_solvers.csv") as f:
            rows = [{k: (v if k in TEXT else float(v) if "." in v else int(v)) for k, v in r.items()}
                    for r in csv.DictReader(f)]
        print(table(rows))
        print("ratios, before over now (run):", agreement(rows))
        return
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, levels in LEVELS:
            for hc in levels:
                for solver in SOLVERS:
                    if solver == "before" and args.skip_before_above and rows and \
                            rows[-1]["ndof"] > args.skip_before_above:
                        continue
                    rows.append(one(name, hc, solver, tmp))
                    print(rows[-1], flush=True)
    ratios = agreement(rows)
    with open(out / "hertz_solvers.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(table(rows))
    print("ratios, before over now (run):", ratios)


if __name__ == "__main__":
    main()
