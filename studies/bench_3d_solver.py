"""3D within memory: the P2 block's explicit run with a direct factor and with solver = 'cg', as whole processes.

Run:  python studies/bench_3d_solver.py [--h 0.025 0.0125] [--solvers sparsecholesky cg] [--steps 10]

Each case is ``workbench run block --order 2 --h H --set solver=S --set k=1e-4 --set T=STEPS*1e-4`` in a fresh
process under ``/usr/bin/time -v`` (one at a time, so the peak resident memory is the run's own), and reports
dofs, the peak memory, the setup (assembly, factorisation or AMG set-up, the k_crit estimate and its trial step),
the time per step, and for cg the mean iterations per step. The fields of the cases of one h are compared
(largest difference of u at the probes, relative). ``--out FILE`` writes the table as JSON.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def case(h, solver, steps, threads=None):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.nc"
        cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "workbench.cli", "run", "block", "--order", "2",
               "--h", str(h), "--set", f"solver={solver}", "--set", "k=1e-4", "--set", f"T={steps * 1e-4!r}",
               "--set", "snapshots=", "-o", str(out), "--no-progress"] + (["--threads", str(threads)] if threads else [])
        proc = subprocess.run(cmd, capture_output=True, text=True)
        peak = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
        wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", proc.stderr)
        row = dict(h=h, solver=solver, returncode=proc.returncode, peak_gb=int(peak.group(1)) / 2**20 if peak else None,
                   process_s=_seconds(wall.group(1)) if wall else None)
        if proc.returncode != 0:
            row["error"] = proc.stderr.strip().splitlines()[-1][:300] if proc.stderr.strip() else ""
            return row, None
        import workbench

        ds = workbench.load(out)
        row.update(ndof=int(ds.attrs["ndof"]), linear_solver=ds.attrs["linear_solver"],
                   setup_s=float(ds.attrs["setup_time"]), step_s=float(ds.attrs["wall_time"]) / int(ds.attrs["nsteps"]),
                   k_crit=float(ds.attrs["k_crit"]))
        if "cg_iterations" in ds:
            row["cg_iterations_mean"] = float(ds.cg_iterations.values[1:].mean())
        return row, ds.u_probe.values


def _seconds(text):
    parts = [float(p) for p in text.split(":")]
    return sum(p * 60 ** i for i, p in enumerate(reversed(parts)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, nargs="*", default=[0.025, 0.0125])
    ap.add_argument("--solvers", nargs="*", default=["sparsecholesky", "cg"])
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = []
    for h in args.h:
        fields = {}
        for solver in args.solvers:
            row, u = case(h, solver, args.steps, args.threads)
            fields[solver] = u
            rows.append(row)
            print(json.dumps(row), flush=True)
        done = [u for u in fields.values() if u is not None]
        if len(done) > 1:
            ref = done[0]
            diff = max(float(np.abs(u - ref).max() / np.abs(ref).max()) for u in done[1:])
            print(f"h = {h}: largest difference of u at the probes between the solvers {diff:.2e} (relative)",
                  flush=True)
            rows.append(dict(h=h, probe_difference=diff))
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
