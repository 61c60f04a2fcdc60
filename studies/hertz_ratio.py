"""The 3D Hertz run against one factorization of its own stiffness, at three sizes: how issue 22's ratio moves with n.

    python studies/hertz_ratio.py [--out data/hertz] [--levels 0.005 0.0035 0.0025] [--compare]

Issue 22 measures the whole Signorini Hertz run of ``memory_hertz3d`` (defaults: ``contact_solver = solver =
"auto"``, from rest to the full load in 4 steps) against one sparse Cholesky factorization of a P1 elasticity matrix
of the same size (NGSolve's ``sparsecholesky``, one thread). Each level is a process of its own, one thread: it
makes the mesh (netgen's meshing is cached on disk after the first time and is not timed), assembles and factors
the hemisphere's K twice with NGSolve (the faster kept), then times ``workbench.run``. Per level: dofs, the solvers
taken, back-substitutions and conjugate gradient iterations, the assembly of K, the factorization, the run, their
ratio, the same run made again in the same process (``run_again``, ``ratio_again``: the modules the first imported,
xarray and, where installed, dask among them, then loaded, as in a session's second run), and the process's peak
memory; ``process`` and ``ratio_process`` (``auto``'s rows): the whole ``workbench run memory_hertz3d --set
h_contact=H --threads 1 --no-progress -o X.nc`` process, from the interpreter's start to its exit, as a user runs it
(the command line hides dask from xarray's lookup: tests/test_startup.py); ``per_step``: the first run's time
loop's wall time less PARDISO's factorizations inside it (timed in the run), over its steps, and ``slope`` its
least-squares slope against the dofs in log-log. Writes ``hertz_ratio.csv`` (about 10 minutes at the default
levels; the last, 193k dofs, takes 6 of them and 3.3 GB).
Each level runs twice: as ``auto`` takes it now (``candidates``: the condensed solver on the points of smallest
gap first, :mod:`workbench.schemes.candidates`) and with the coupled solver alone (``half-space, predicted``, as
before the candidates), in the ``preconditioner`` column. ``--compare``: also without the zone predicted on the
half-space model (``CoupledActiveSet.predict = False``: the half-space preconditioner alone) and without the
half-space at all (``HalfSpace.bounds = (0, 0)``: the diagonal preconditioner). ``--k K``: steps of K instead of the
scene's 4 (``hertz_ratio_kK.csv``: a step's cost when each step moves the zone by less).
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

import numpy as np

CHILD = """
import json, resource, sys, time
sys.path.insert(0, "studies")
from threadpoolctl import threadpool_limits
import workbench
from workbench.discrete import discretisation, pardiso, solvers
from workbench.schemes.candidates import Candidates
from workbench.schemes.coupled_contact import CoupledActiveSet, HalfSpace
from workbench.schemes.memory_vi import MemoryVI
hc, preconditioner = float(sys.argv[1]), sys.argv[2]
step_k = dict(k=float(sys.argv[3])) if sys.argv[3] != "default" else {}
if preconditioner == "diagonal":
    HalfSpace.bounds = (0, 0)
if preconditioner != "candidates":  # (the coupled solver alone, as before the candidates)
    Candidates.most = classmethod(lambda cls, ndof, method, steps: 0)
CoupledActiveSet.predict = preconditioner in ("candidates", "half-space, predicted")
with threadpool_limits(1):
    times = []
    for _ in range(2):
        d = discretisation.build(workbench.scene("memory_hertz3d", h_contact=hc))
        t0 = time.perf_counter()
        d.elastic.Assemble()
        t1 = time.perf_counter()
        solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "sparsecholesky")
        times.append((t1 - t0, time.perf_counter() - t1))
        del d
    assemble, factor = min(times, key=lambda t: t[1])
    factoring = []  # (PARDISO's factorizations inside the run, (start, duration): a step's cost is the loop's
    # without those made in it; the candidates' factor is made in the setup, the coupled solver's at t = 0's solve)
    init, start = pardiso.Factor.__init__, MemoryVI.start
    loop = []

    def timed(self, *args, **kwargs):
        t = time.perf_counter()
        init(self, *args, **kwargs)
        factoring.append((t, time.perf_counter() - t))

    def started(self, t0):
        loop.append(time.perf_counter())
        return start(self, t0)

    pardiso.Factor.__init__, MemoryVI.start = timed, started
    t0 = time.perf_counter()
    ds = workbench.run("memory_hertz3d", h_contact=hc, progress=False, threads=1, **step_k)
    run = time.perf_counter() - t0
    pardiso.Factor.__init__, MemoryVI.start = init, start
    t0 = time.perf_counter()  # (again: the modules the first run imported, xarray's among them, now loaded)
    again = workbench.run("memory_hertz3d", h_contact=hc, progress=False, threads=1, **step_k)
    run_again = time.perf_counter() - t0
    assert float(abs(again.u_probe - ds.u_probe).max()) == 0.0  # (the same run)
    del again
steps = int(ds.attrs["nsteps"])
in_loop = sum(t for at, t in factoring if at >= loop[0])
print(json.dumps(dict(h_contact=hc, preconditioner=preconditioner, ndof=int(ds.attrs["ndof"]),
                      contact_vertices=int(ds.sizes["node"]),
                      contact_solver=ds.attrs["contact_solver_used"], linear_solver=ds.attrs["linear_solver"],
                      candidates=int(ds.attrs["contact_candidates"]),
                      candidates_missed=int(ds.attrs["contact_candidates_missed"]),
                      in_contact=int(ds.n_rigid.values[-1] + ds.n_stuck.values[-1] + ds.n_compliant.values[-1]),
                      backsubs=int(ds.linear_solves.sum()),
                      cg_iterations=int(ds.linear_iterations.sum()) if "linear_iterations" in ds else 0,
                      assemble=round(assemble, 2), factor_sparsecholesky=round(factor, 2), run=round(run, 2),
                      ratio=round(run / factor, 2), run_again=round(run_again, 2),
                      ratio_again=round(run_again / factor, 2), loop=round(float(ds.attrs["wall_time"]), 2),
                      factor_in_run=round(sum(t for _, t in factoring), 2), factor_in_loop=round(in_loop, 2),
                      per_step=round((float(ds.attrs["wall_time"]) - in_loop) / steps, 3),
                      peak_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0))))
"""


ENV = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")


def one(hc: float, preconditioner: str, k=None) -> dict:
    args = [sys.executable, "-c", CHILD, str(hc), preconditioner, "default" if k is None else str(k)]
    done = subprocess.run(args, capture_output=True, text=True, env=ENV, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def process(hc: float, k=None) -> float:
    """The whole ``workbench run memory_hertz3d`` process as a user starts it, to its archive, one thread: from the
    interpreter's start to its exit (imports, the cached mesh read, the run, the netCDF written)."""
    with tempfile.TemporaryDirectory() as tmp:
        args = [str(Path(sys.executable).parent / "workbench"), "run", "memory_hertz3d", "--set", f"h_contact={hc}",
                "--threads", "1", "--no-progress", "-o", str(Path(tmp) / "run.nc")]
        if k is not None:
            args += ["--k", str(k)]
        t0 = time.perf_counter()
        subprocess.run(args, capture_output=True, text=True, env=ENV, check=True)
        return time.perf_counter() - t0


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/hertz")
    p.add_argument("--levels", type=float, nargs="+", default=[0.005, 0.0035, 0.0025])
    p.add_argument("--compare", action="store_true")
    p.add_argument("--k", type=float, default=None, help="the step (default: the scene's, 4 steps to T = 1)")
    args = p.parse_args()
    rows = []
    for hc in args.levels:
        variants = ("candidates", "half-space, predicted", "half-space", "diagonal")
        for preconditioner in variants if args.compare else variants[:2]:
            rows.append(one(hc, preconditioner, args.k))
            if preconditioner == "candidates":  # (auto, as a user's process takes it)
                rows[-1]["process"] = round(process(hc, args.k), 2)
                rows[-1]["ratio_process"] = round(rows[-1]["process"] / rows[-1]["factor_sparsecholesky"], 2)
            print(rows[-1], flush=True)
    for variant in dict.fromkeys(r["preconditioner"] for r in rows):
        same = [r for r in rows if r["preconditioner"] == variant]
        if len(same) > 1:  # (issue 22: a step's cost against the dofs, slope <= 1.2 in log-log)
            fit = np.polyfit(np.log([r["ndof"] for r in same]), np.log([r["per_step"] for r in same]), 1)[0]
            for r in same:
                r["slope"] = round(float(fit), 3)
            print(f"{variant}: slope of a step's cost (the loop without its factorizations) against the dofs:",
                  round(float(fit), 3))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "hertz_ratio.csv" if args.k is None else f"hertz_ratio_k{args.k:g}.csv"
    with open(out / name, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(dict.fromkeys(k for r in rows for k in r)))
        writer.writeheader()
        writer.writerows(rows)
    print("| h_contact | dofs | contact vertices (in contact) | solver | variant | candidates (missed) | "
          "solves (CG) | assemble K | factor K | run | run / factor | whole process / factor | peak |\n|" + "---|" * 13)
    for r in rows:
        print(f"| {r['h_contact']} | {r['ndof']} | {r['contact_vertices']} ({r['in_contact']}) | "
              f"{r['contact_solver']}, {r['linear_solver']} | {r['preconditioner']} | {r['candidates']} "
              f"({r['candidates_missed']}) | {r['backsubs']} ({r['cg_iterations']}) | "
              f"{r['assemble']} s | "
              f"{r['factor_sparsecholesky']} s | {r['run']} s ({r['run_again']} s again) | {r['ratio']} x "
              f"({r['ratio_again']} x) | {r.get('process', '')} s ({r.get('ratio_process', '')} x) | "
              f"{r['peak_mb']} MB |")


if __name__ == "__main__":
    main()
