"""3D at scale on a factor in single precision: issue 22's memory_block (Model B) at about 250k dofs, 10 steps, with
``solver = mixed`` (what ``auto`` takes there now), ``pardiso`` (the double factor) and ``cg`` (what ``auto`` took).

    python studies/mixed_precision.py [--h 0.023] [--solvers mixed pardiso] [--out data/contact_solver]

Each case is ``workbench run memory_block --set h=H --set k=0.1 --set solver=S -o run.nc`` in a fresh process under
``/usr/bin/time -v``, one after the other (so each peak is the run's own; a case with ``cg`` takes about 40 minutes).
Per case: dofs, the solver and contact solver taken, wall time and CPU time of the whole process, its peak resident
memory, the setup and the time loop, the back-substitutions (``linear_solves``: for ``mixed`` and ``cg`` each one an
iterative solve), and the largest difference of u at the probes from the first case, relative.
Writes ``mixed_precision.csv``.
"""
from __future__ import annotations

import argparse
import csv
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def _seconds(text: str) -> float:
    parts = [float(p) for p in text.split(":")]
    return sum(p * 60.0 ** i for i, p in enumerate(reversed(parts)))


def case(h: float, solver: str) -> tuple[dict, object]:
    """One whole process: its row, and the probes' u (None if it failed)."""
    import workbench

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.nc"
        cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "workbench.cli", "run", "memory_block", "--set", f"h={h}",
               "--set", "k=0.1", "--set", f"solver={solver}", "-o", str(out), "--no-progress"]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        err = proc.stderr
        field = {k: re.search(pattern, err) for k, pattern in (
            ("peak", r"Maximum resident set size \(kbytes\): (\d+)"),
            ("wall", r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)"),
            ("user", r"User time \(seconds\): ([\d.]+)"), ("system", r"System time \(seconds\): ([\d.]+)"))}
        row = dict(h=h, solver=solver, returncode=proc.returncode,
                   peak_gb=round(int(field["peak"].group(1)) / 2**20, 3) if field["peak"] else None,
                   process_s=_seconds(field["wall"].group(1)) if field["wall"] else None,
                   cpu_s=round(sum(float(field[k].group(1)) for k in ("user", "system")), 2) if field["user"] else None)
        if proc.returncode != 0:
            row["error"] = err.strip().splitlines()[-1][:300] if err.strip() else ""
            return row, None
        ds = workbench.load(out)
        row |= dict(ndof=int(ds.attrs["ndof"]), linear_solver=ds.attrs.get("linear_solver"),
                    contact_solver_used=ds.attrs.get("contact_solver_used"), steps=int(ds.sizes["time"]) - 1,
                    setup_s=round(float(ds.attrs["setup_time"]), 2), loop_s=round(float(ds.attrs["wall_time"]), 2),
                    backsubs=int(ds.linear_solves.sum()),
                    status=ds.attrs.get("status"))
        return row, ds.u_probe.values.copy()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, default=0.023)
    ap.add_argument("--solvers", nargs="+", default=["mixed", "pardiso"])
    ap.add_argument("--out", default="data/contact_solver")
    a = ap.parse_args(argv)
    rows, first = [], None
    for solver in a.solvers:
        row, u = case(a.h, solver)
        if u is not None:
            first = u if first is None else first
            row["u_vs_first"] = float(np.abs(u - first).max() / np.abs(first).max())
        rows.append(row)
        print(row, flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(out / "mixed_precision.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    print("wrote", out / "mixed_precision.csv")


if __name__ == "__main__":
    main()
