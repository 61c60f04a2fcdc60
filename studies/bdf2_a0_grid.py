"""How fine should error-controlled BDF2 snap its a0? Factorisations against steps (``BDF2.A0_LEVELS``).

BDF2's step matrix a0 K_A + K_G depends on the step and on the step ratio, so an error-controlled run shortens each
free step a little, until a0 lies on the grid 2^(j / A0_LEVELS) s^-1, and then meets the same few matrices again in
its cache of factored operators (:meth:`workbench.schemes.bdf2.BDF2.admissible_step`). A finer grid shortens the
steps less; a coarser one meets fewer matrices. A run whose step grows over many octaves (from a small first step,
through contact fronts) factors about once per level it passes, so in 3D, where a factorisation costs a few steps,
the grid's spacing decides a good share of the run.

Each case runs once per number of levels, one process, one thread, at rtol = 1e-3: the run's wall time, its
accepted and rejected steps, PARDISO's or NGSolve's factorisations (the calls to ``solvers.factor``) and the largest
difference of ``u_contact`` at T from the run at the finest grid, over its largest value (the grid must not change
the answer beyond the tolerance).

Run::

    python studies/bdf2_a0_grid.py                              # the slab and hertz3d at 12k dofs (about 3 minutes)
    python studies/bdf2_a0_grid.py --cases hertz3d:0.005        # 47k dofs (about 12 minutes)

Writes ``data/time_stepping/bdf2_a0_grid.csv`` (``--out``), one row per case and grid, appended to what the file
holds for other cases.
"""
from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

#: The slab of ``studies/time_stepping.py`` at h = 0.05 (P2, 410 dofs), from the first step a user would pick.
SLAB = dict(E=1000, nu=0.3, a1=30, a2=20, c_nu=100, gamma_nu=20, eps_a=1e-3, L=0.3, c_tau=10,
            bonding_truncation="symmetric", traction_top="(0, 5*t*ifpos(x - 0.5, 1, 0))", order=2, h=0.05,
            T=1.0, k=0.0316)

CHILD = """
import json, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
import workbench
from workbench.discrete import solvers
from workbench.schemes.bdf2 import BDF2
levels, scene, overrides, out = int(sys.argv[1]), sys.argv[2], json.loads(sys.argv[3]), sys.argv[4]
BDF2.A0_LEVELS = levels
calls = [0]
factor = solvers.factor

def counted(*args, **kwargs):
    calls[0] += 1
    return factor(*args, **kwargs)

solvers.factor = counted
with threadpool_limits(1):
    t0 = time.perf_counter()
    ds = workbench.run(scene, scheme="bdf2", rtol=1e-3, progress=False, threads=1, **overrides)
    run = time.perf_counter() - t0
np.save(out, ds.u_contact.isel(time=-1).values)
print(json.dumps(dict(ndof=int(ds.attrs["ndof"]), run=round(run, 2), accepted=int(ds.attrs["accepted_steps"]),
                      rejected=int(ds.attrs["rejected_steps"]), factorisations=calls[0])))
"""


def case(name: str) -> tuple[str, dict]:
    """``slab`` or ``hertz3d:H`` (h_contact = H) as (scene, overrides)."""
    if name == "slab":
        return "slab", SLAB
    scene, _, h = name.partition(":")
    return scene, (dict(h_contact=float(h)) if h else {})


def measure(name: str, levels: list[int], scratch: Path) -> list[dict]:
    scene, overrides = case(name)
    rows, finest = [], None
    for n in sorted(levels, reverse=True):
        out = scratch / f"u_{n}.npy"
        done = subprocess.run([sys.executable, "-c", CHILD, str(n), scene, json.dumps(overrides), str(out)],
                              capture_output=True, text=True, check=True)
        row = dict(case=name, levels=n) | json.loads(done.stdout.strip().splitlines()[-1])
        u = np.load(out)
        finest = u if finest is None else finest
        row["u_change"] = float(np.abs(u - finest).max() / np.abs(finest).max())
        print(row, flush=True)
        rows.append(row)
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=["slab", "hertz3d:0.01"])
    parser.add_argument("--levels", nargs="+", type=int, default=[8, 4, 2])
    parser.add_argument("--out", type=Path, default=Path("data/time_stepping/bdf2_a0_grid.csv"))
    args = parser.parse_args(argv)
    scratch = args.out.parent / ".bdf2_a0_grid"
    scratch.mkdir(parents=True, exist_ok=True)
    rows = [row for name in args.cases for row in measure(name, args.levels, scratch)]
    kept = []
    if args.out.exists():
        with open(args.out) as f:
            kept = [r for r in csv.DictReader(f) if r["case"] not in args.cases]
    with open(args.out, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(kept + rows)
    for file in scratch.iterdir():
        file.unlink()
    scratch.rmdir()


if __name__ == "__main__":
    main()
