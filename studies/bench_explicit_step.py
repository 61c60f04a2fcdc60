"""Cost of one explicit step against its floor (one back-substitution), on the slab.

Run:  python studies/bench_explicit_step.py [--sizes 220 440 900] [--steps 40]

For each mesh (nx x nx/10 cells, P1) it times, in one process and interleaved,
(a) a back-substitution with the factored viscous matrix (the floor) and
(b) a whole step of the paper's scheme (load, elastic matvec, contact and
bonding forms, solve, update, the step-limit check) and (c) the same step with
the step-limit check switched off, and reports medians and the ratio (b)/(a),
with and without NGSolve's TaskManager. It also times 1000 steps at nx = 80, 160, 320 for
comparison with other codes, and the five paper problems at the paper's resolution.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

import workbench
from workbench.discrete import discretisation
from workbench import schemes
from workbench.running.threads import blas_single_threaded
from workbench.running.threads import task_manager as _threads


def scene(nx, solver):
    return workbench.scene("tp5", nx=nx, ny=max(1, nx // 10), k=1e-4, solver=solver)


def per_step(nx, steps, solver="auto", threads=None):
    sc = scene(nx, solver)
    with blas_single_threaded():  # as in a run (setup and factorisation included)
        t0 = time.perf_counter()
        d = discretisation.build(sc)
        setup = time.perf_counter() - t0
        t0 = time.perf_counter()
        sch = schemes.ExplicitEuler(d)
        factor = time.perf_counter() - t0
    rhs = np.random.default_rng(0).standard_normal(d.ndof)
    out = np.zeros(d.ndof)
    solve, step, unchecked = [], [], []
    t = 0.0
    with _threads(threads), blas_single_threaded():
        sch.preflight(1e-4)  # driven as the time loop drives it (the preflight sets up the step-limit re-check)
        sch.start(t)
        sch.accept(t)
        for _ in range(steps):
            a = time.perf_counter()
            sch.solver.solve(rhs, out)
            solve.append(time.perf_counter() - a)
            for checked, times in ((True, step), (False, unchecked)):
                limit, sch.limit = sch.limit, (sch.limit if checked else None)
                a = time.perf_counter()
                sch.step(t, t + 1e-4)
                sch.accept(t + 1e-4)
                times.append(time.perf_counter() - a)
                sch.limit = limit
                t += 1e-4
    s, f = statistics.median(step), statistics.median(solve)
    return dict(nx=nx, ndof=d.ndof, solver=sch.solver.name, threads=threads or 1, setup_s=setup, factor_s=factor, step_ms=1e3 * s,
                solve_ms=1e3 * f, ratio=s / f, unchecked_ms=1e3 * statistics.median(unchecked))


def thousand_steps(nx):
    ds = workbench.run("tp5", nx=nx, ny=nx // 10, k=1e-3, T=1.0, progress=False, record_times=[0, 1.0])
    return dict(nx=nx, ndof=ds.attrs["ndof"], steps=ds.attrs["nsteps"], wall_s=ds.attrs["wall_time"],
                setup_s=ds.attrs["setup_time"])


def paper_problems():
    """Wall time of tp1 ... tp5 at the paper's resolution (rod h = k = 0.01; slab presets), run one after another."""
    out = {}
    for name in ("tp1", "tp2", "tp3", "tp4", "tp5"):
        a = time.perf_counter()
        workbench.run(name, progress=False)
        out[name] = time.perf_counter() - a
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[220, 440, 900])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--solvers", nargs="*", default=["banded", "sparsecholesky"])
    ap.add_argument("--threads", type=int, nargs="*", default=[1, 2], help="TaskManager threads to compare")
    ap.add_argument("--thousand", type=int, nargs="*", default=[80, 160, 320])
    args = ap.parse_args()
    rows = []
    for nx in args.sizes:
      for solver in args.solvers:
       for threads in args.threads:
        r = per_step(nx, args.steps, solver, threads)
        rows.append(r)
        print(f"nx={r['nx']:4d} ndof={r['ndof']:7d} {r['solver']:>14} threads={threads}  step {r['step_ms']:8.2f} ms  floor (solve) {r['solve_ms']:8.2f} ms"
              f"  ratio {r['ratio']:.2f}  (without the step-limit check {r['unchecked_ms']:.2f} ms; factor "
              f"{r['factor_s']:.2f} s, setup {r['setup_s']:.2f} s)", flush=True)
    for nx in args.thousand:
        r = thousand_steps(nx)
        rows.append(r)
        print(f"1000 steps, nx={nx:4d} ndof={r['ndof']:6d}: {r['wall_s']:.2f} s (+ setup {r['setup_s']:.2f} s)", flush=True)
    times = paper_problems()
    print("paper problems at the paper's resolution: " + ", ".join(f"{k} {v:.2f} s" for k, v in times.items())
          + f"; total {sum(times.values()):.2f} s", flush=True)
    rows.append(times)
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
