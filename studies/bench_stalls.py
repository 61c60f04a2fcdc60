"""Random stalls: the same whole-process run repeated, median and worst wall time.

Run:  python studies/bench_stalls.py [--runs 12] [--scene tp5] [--old PATH]

Each run is a fresh process (``python -m workbench.cli run SCENE -o TMP.nc --no-progress``)
with the shell's default thread settings (no OPENBLAS_NUM_THREADS in the environment), as a
user would start it. Before workbench held the BLAS pools at one thread, one run in six to eight
took 5-13 s instead of 1.5 s (NumPy's, SciPy's and NGSolve's OpenBLAS pools and NGSolve's task
manager oversubscribing 2 cores). Goal: worst of 12 within 1.5x the median.

``--old PATH`` also times a checkout of an older workbench (its package folder's parent on
PYTHONPATH), alternating the two in one run so that both see the same machine load.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time


def once(scene, pythonpath=None) -> float:
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        # (cwd: a folder of its own. From the repository root, ``-m`` would put the current package ahead of
        # PYTHONPATH, and --old timed the current checkout twice)
        subprocess.run([sys.executable, "-m", "workbench.cli", "run", scene, "-o", os.path.join(tmp, "x.nc"),
                        "--no-progress"], check=True, env=env, cwd=tmp, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL)
        return time.perf_counter() - t0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=12)
    p.add_argument("--scene", default="tp5")
    p.add_argument("--old", help="parent folder of an older workbench package to compare with")
    a = p.parse_args(argv)
    variants = {"current": None} | ({"old": a.old} if a.old else {})
    times = {name: [] for name in variants}
    for _ in range(a.runs):
        for name, path in variants.items():
            times[name].append(once(a.scene, path))
    for name, ts in times.items():
        med, worst = statistics.median(ts), max(ts)
        print(f"{name:8s} runs {len(ts)}  median {med:.2f} s  worst {worst:.2f} s  worst/median {worst / med:.2f}  "
              f"all: {' '.join(f'{t:.2f}' for t in ts)}")


if __name__ == "__main__":
    main()
