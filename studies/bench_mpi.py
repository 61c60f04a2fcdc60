"""One case on several MPI processes against one process: time, memory per rank, agreement.

Each case is a whole ``workbench run`` of the P2 block (Model A, the explicit scheme, the
block preset's load; or ``--scheme bdf2``, or ``--scene memory_block --scheme vi`` for Model B), as a
user starts it:

    one process:   workbench run SCENE --scheme SCHEME --order 2 --h H --k K --T T -o X.nc
    N processes:   mpiexec -n N workbench run SCENE ... --set solver=S -o X.nc

The one-process run takes ``solver = "auto"`` (a factor; the implicit schemes condense their contact
problem on it), the MPI runs the solver asked for (with ``cg`` the implicit schemes solve their contact
problem by the coupled solver on rank 0, :mod:`workbench.parallel.contact`).

with every rank under ``/usr/bin/time`` (its own peak resident memory). Rank 0 of an MPI
run holds no part of the body (netgen's master): it gathers, records and writes; ranks 1 ... N-1
compute. Reported per case: the whole process's wall time, the archive's ``setup_time`` and
``wall_time`` (the time loop) per step, the CG iterations per step, the peak memory of rank 0
and of the largest computing rank, and the largest difference of the final u (``u_dofs``) from
the one-process run, relative to its largest value. The cases run one after the other, in one
invocation (the machine is shared: compare ratios within one run).

Command (from the repository root; ~2 min at the defaults)::

    python studies/bench_mpi.py [--h 0.05 0.025] [--ranks 2 3] [--solvers cg sparsecholesky] [--out FILE.json]
    python studies/bench_mpi.py --scheme bdf2 --k 0.004 --steps 10 --h 0.05 --out data/studies/bench_mpi_bdf2.json
    python studies/bench_mpi.py --scene memory_block --scheme vi --k 0.05 --steps 10 --h 0.05 \
        --out data/studies/bench_mpi_vi.json
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from workbench.discrete.world import alone

ROOT = Path(__file__).resolve().parent.parent


def _executable(name):
    here = Path(sys.executable).parent / name
    found = str(here) if here.exists() else shutil.which(name)
    if found is None:
        raise SystemExit(f"`{name}` is not installed in this environment (pip install -e '.[mpi]')")
    return found


#: Each rank under /usr/bin/time, writing its peak resident memory (kB) to FOLDER/peak.RANK (PMI_RANK: MPICH's).
TIMED = ["sh", "-c", '/usr/bin/time -f %M -o "$0/peak.${PMI_RANK:-0}" "$@"']


def _peaks(folder: Path, ranks: int) -> list:
    """Peak resident memory (GB) of each rank, rank 0 first."""
    return [int((folder / f"peak.{r}").read_text().split()[-1]) / 1e6 for r in range(ranks)]


def case(scene, scheme, h, order, k, T, ranks, solver, folder):
    import workbench

    out = Path(folder) / f"{scene}-h{h}-n{ranks}-{solver}.nc"
    run = [sys.executable, "-m", "workbench.cli", "run", scene, "--scheme", scheme, "--order", str(order), "--h", str(h),
           "--k", str(k), "--T", str(T), "--set", f"solver={solver}", "--set", f"snapshots=[{T!r}]", "-o", str(out),
           "--no-progress"]
    timed = TIMED + [str(folder)]
    cmd = timed + run if ranks == 1 else [_executable("mpiexec"), "-n", str(ranks)] + timed + run
    env = alone()
    start = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - start
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stderr[-3000:]}")
    ds = workbench.load(out)
    a = ds.attrs
    peaks = _peaks(Path(folder), ranks)
    its = next((ds[n] for n in ("cg_iterations", "linear_iterations") if n in ds), None)  # (explicit, implicit)
    row = {"scene": scene, "scheme": scheme, "h": h, "order": order, "ranks": ranks,
           "solver": a.get("linear_solver", solver), "contact_solver": a.get("contact_solver_used"),
           "ndof": int(a["ndof"]), "nsteps": int(a["nsteps"]), "process_s": wall, "setup_s": float(a["setup_time"]),
           "loop_s": float(a["wall_time"]), "step_s": float(a["wall_time"]) / int(a["nsteps"]),
           "cg_iterations": float(its[1:].mean()) if its is not None else None,
           "peak_gb_rank0": peaks[0], "peak_gb_workers": max(peaks[1:], default=None),
           "k_crit": float(a["k_crit"]) if "k_crit" in a else None}
    return row, ds.u_dofs.isel(snapshot=-1).values


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="block")
    ap.add_argument("--scheme", default="explicit")
    ap.add_argument("--h", type=float, nargs="+", default=[0.05, 0.025])
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--k", type=float, default=2e-4, help="time step (below the block's k_crit)")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--ranks", type=int, nargs="+", default=[2, 3], help="MPI process counts (beside one process)")
    ap.add_argument("--solvers", nargs="+", default=["cg", "sparsecholesky"], help="solvers of the MPI runs")
    ap.add_argument("--out", help="write the rows as JSON here")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for h in args.h:
            T = args.steps * args.k
            serial, u_ref = case(args.scene, args.scheme, h, args.order, args.k, T, 1, "auto", folder)
            serial["u_vs_one_process"] = 0.0
            rows.append(serial)
            print(json.dumps(serial), flush=True)
            for ranks in args.ranks:
                for solver in args.solvers:
                    row, u = case(args.scene, args.scheme, h, args.order, args.k, T, ranks, solver, folder)
                    row["u_vs_one_process"] = float(np.abs(u - u_ref).max() / np.abs(u_ref).max())
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    print(f"\n{'ndof':>8} {'ranks':>5} {'solver':>14} {'process s':>9} {'setup s':>8} {'step s':>8} {'its':>6} "
          f"{'peak GB rank 0':>14} {'largest other':>13} {'u vs 1 proc':>11}")
    for r in rows:
        its = "" if r["cg_iterations"] is None else f"{r['cg_iterations']:.1f}"
        other = "" if r["peak_gb_workers"] is None else f"{r['peak_gb_workers']:.2f}"
        print(f"{r['ndof']:>8} {r['ranks']:>5} {r['solver']:>14} {r['process_s']:>9.2f} {r['setup_s']:>8.2f} "
              f"{r['step_s']:>8.4f} {its:>6} {r['peak_gb_rank0']:>14.2f} {other:>13} {r['u_vs_one_process']:>11.1e}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
