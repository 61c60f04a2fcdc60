"""Model B cost per step: Prony recursion (O(1)) against the general-kernel quadrature (O(n)).

Run:  python studies/bench_memory.py [--h 0.1] [--steps 10000]

On memory_slab (h = 0.1 by default) it advances the scheme step by step with
the same exponential kernel given (a) as a Prony term and (b) as an expression
(``kernel = exp(-t/0.5)``), and reports the median wall time per step in
windows around steps 10, 1000 and 10000, plus linear solves per step.
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


def per_step_times(memory, h, steps, k):
    extra = dict(prony=((-1000.0, 0.3, 0.5),)) if memory == "prony" else \
        dict(prony=(), kernel="exp(-t/0.5)", kernel_E=-1000.0, kernel_nu=0.3)
    sc = workbench.scene("memory_slab", h=h, k=k, T=k * steps, **extra)
    d = discretisation.build(sc)
    sch = schemes.scheme_class("vi")(d)
    times, solves = np.zeros(steps), np.zeros(steps)
    t = 0.0
    sch.start(t)  # as the time loop does (workbench.schemes.stepping.march): u(0) solves the inequality at t = 0
    sch.accept(t)
    for n in range(steps):
        a = time.perf_counter()
        sch.step(t, t + k)
        times[n] = time.perf_counter() - a
        solves[n] = sch.diag["linear_solves"]
        t += k
        sch.accept(t)
    return times, solves, d.ndof


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--h", type=float, default=0.1)
    ap.add_argument("--steps", type=int, default=10000)
    ap.add_argument("--k", type=float, default=1e-4)
    args = ap.parse_args()
    out = {}
    for memory in ("prony", "kernel"):
        t, solves, ndof = per_step_times(memory, args.h, args.steps, args.k)
        windows = {}
        for n in (10, 1000, 10000):
            if n <= args.steps:
                lo, hi = max(0, n - 5), min(args.steps, n + 5)
                windows[n] = 1e3 * statistics.median(t[lo:hi])
        out[memory] = dict(ndof=ndof, ms_per_step=windows, mean_solves=float(solves.mean()), total_s=float(t.sum()))
        print(f"{memory:6s} ndof={ndof}: " + ", ".join(f"step {n}: {v:.3f} ms" for n, v in windows.items())
              + f"; linear solves/step {solves.mean():.2f}; total {t.sum():.1f} s", flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
