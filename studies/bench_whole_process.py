"""Whole-process timing: ``workbench run tp5`` against the plain NumPy/SciPy baseline.

Both programs solve the same discrete problem (the paper's explicit scheme PV^hk,
test problem 5 on the slab, P1, nx × ny = 160 × 16 squares, 5474 dofs, k = 0.001,
1000 steps; see ``studies/baseline/plain_explicit.py`` for the equations and
``studies/baseline/check_agreement.py`` for the proof that the results agree to
round-off). Each repetition starts both as fresh processes, one after the other,
alternating which goes first (so that a drift in the machine's load hits both
alike), with OPENBLAS_NUM_THREADS = OMP_NUM_THREADS = MKL_NUM_THREADS = 1:

    plain:     python studies/baseline/plain_explicit.py --nx NX --ny NY --k K --out X.npz
    workbench: workbench run tp5 --h H --k K -o X.nc --no-progress

Reported per program: median and worst (largest) whole-process wall time over
the repetitions, and the median in-process time-loop time (plain: its printed
``loop_time``; workbench: ``ds.attrs["wall_time"]`` of the archive); then the
ratio workbench / plain of the medians, of the worst times, and the median of
the per-repetition ratios (each pair measured back to back in this run).
One untimed warm-up run of each comes first (disk caches, bytecode).

Command (from the repository root; ~1 min at the default 7 repetitions)::

    python studies/bench_whole_process.py [--reps 7] [--h 0.00625] [--k 0.001] [--old CHECKOUT]

``--old CHECKOUT`` times an older checkout too (e.g. ``git worktree add /tmp/old COMMIT``), in the
same rotation.
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PLAIN = ROOT / "studies" / "baseline" / "plain_explicit.py"
THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def workbench_command() -> list[str]:
    """The ``workbench`` console script of this Python environment (else the one on PATH)."""
    here = Path(sys.executable).parent / "workbench"
    found = str(here) if here.exists() else shutil.which("workbench")
    if found is None:
        raise SystemExit("the `workbench` command is not installed in this environment")
    return [found]


def timed(cmd: list[str], env: dict, cwd=ROOT) -> tuple[float, str]:
    """Run ``cmd`` to completion; return (wall seconds, stdout). A failure stops the benchmark."""
    start = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr}")
    return wall, proc.stdout


def plain_loop_time(stdout: str) -> float:
    """The ``loop_time`` the plain script prints."""
    m = re.search(r"loop_time ([0-9.eE+-]+) s", stdout)
    return float(m.group(1)) if m else float("nan")


def main(argv=None) -> None:
    """Time both programs alternately and print the summary."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=7, help="timed repetitions of each program (default 7)")
    ap.add_argument("--h", type=float, default=0.00625, help="mesh size: nx = 1 / h, ny = 0.1 / h")
    ap.add_argument("--k", type=float, default=0.001, help="time step")
    ap.add_argument("--old", help="also time an older checkout: the parent folder of its workbench package (run as "
                    "python -m workbench.cli with it on PYTHONPATH, from a folder of its own)")
    args = ap.parse_args(argv)
    nx, ny = round(1.0 / args.h), round(0.1 / args.h)  # the slab is 1 x 0.1, as in the tp5 preset

    env = dict(os.environ, **THREADS)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        commands = {
            "plain": lambda i: [sys.executable, str(PLAIN), "--nx", str(nx), "--ny", str(ny), "--k", repr(args.k),
                                "--out", str(tmp / f"plain{i}.npz")],
            "workbench": lambda i: workbench_command() + ["run", "tp5", "--h", repr(args.h), "--k", repr(args.k),
                                                          "-o", str(tmp / f"wb{i}.nc"), "--no-progress"],
        }
        envs, cwds = {name: env for name in commands}, {name: ROOT for name in commands}
        if args.old:  # (from its own folder: -m from the repository root would import the current package)
            commands["old"] = lambda i: [sys.executable, "-m", "workbench.cli", "run", "tp5", "--h", repr(args.h),
                                         "--k", repr(args.k), "-o", str(tmp / f"old{i}.nc"), "--no-progress"]
            envs["old"], cwds["old"] = dict(env, PYTHONPATH=str(Path(args.old).resolve())), tmp
        names = list(commands)
        for name, cmd in commands.items():  # warm-up, untimed
            timed(cmd("warm"), envs[name], cwds[name])
        wall = {name: [] for name in commands}
        loop = {name: [] for name in commands}
        for i in range(args.reps):
            for name in names[i % len(names):] + names[: i % len(names)]:  # each goes first in turn
                seconds, out = timed(commands[name](i), envs[name], cwds[name])
                wall[name].append(seconds)
                if name == "plain":
                    loop[name].append(plain_loop_time(out))
            print(f"rep {i + 1}/{args.reps}: " + ", ".join(f"{n} {wall[n][-1]:.3f} s" for n in names), flush=True)

        import workbench  # after the timing: reading the archives must not load the machine meanwhile

        for i in range(args.reps):
            for name, prefix in (("workbench", "wb"), ("old", "old")):
                if name in commands:
                    loop[name].append(float(workbench.load(str(tmp / f"{prefix}{i}.nc")).attrs["wall_time"]))

    med = {n: statistics.median(w) for n, w in wall.items()}
    worst = {n: max(w) for n, w in wall.items()}
    print(f"\ntp5, {nx}x{ny} squares, k = {args.k:g}, {args.reps} repetitions, 1 BLAS/OpenMP thread each")
    print(f"{'program':<10} {'median [s]':>11} {'worst [s]':>10} {'best [s]':>9} {'loop median [s]':>16}")
    for n in wall:
        print(f"{n:<10} {med[n]:>11.3f} {worst[n]:>10.3f} {min(wall[n]):>9.3f} {statistics.median(loop[n]):>16.3f}")
    paired = [w / p for w, p in zip(wall["workbench"], wall["plain"])]
    print(f"ratio workbench / plain: medians {med['workbench'] / med['plain']:.2f}, "
          f"worst {worst['workbench'] / worst['plain']:.2f}, median of paired ratios {statistics.median(paired):.2f}, "
          f"time loops {statistics.median(loop['workbench']) / statistics.median(loop['plain']):.2f}")
    if "old" in wall:
        paired = [w / o for w, o in zip(wall["workbench"], wall["old"])]
        print(f"ratio workbench / old: medians {med['workbench'] / med['old']:.2f}, median of paired ratios "
              f"{statistics.median(paired):.2f}, time loops "
              f"{statistics.median(loop['workbench']) / statistics.median(loop['old']):.2f}")


if __name__ == "__main__":
    main()
