"""Per-step cost of the stable implicit scheme against an explicit step, and time-to-solution at 1%.

Run:  python studies/bench_implicit_step.py [--sizes 220 440] [--steps 100]

On the stiff slab of the stability issue (tp4 load, c_nu = 100, gamma_nu = 20)
it times, in one process, the median explicit step and the median implicit step
over the first ``steps`` steps (k = 0.01 for the implicit scheme: 100 steps =
the whole run to T = 1, including the load's initial transient; Newton
iterations per step reported) at nx x nx/10 cells, and then
the wall time each scheme needs for a 1% tip-displacement error at T = 1 on the
nx = 80 mesh (explicit: the largest stable k; implicit: the k that reaches 1%).
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

STIFF = dict(c_nu=100.0, gamma_nu=20.0, L=0.3)


def median_step(nx, scheme, k, steps):
    """Median step and first step (with the factorisation) driven as the time loop drives them (start, step,
    accept), every BLAS pool at one thread as in a run."""
    with blas_single_threaded():
        sc = workbench.scene("tp4", nx=nx, ny=nx // 10, k=k, scheme=scheme, **STIFF)
        d = discretisation.build(sc)
        t0 = time.perf_counter()
        sch = schemes.SCHEMES[scheme](d)
        sch.start(0.0)
        sch.accept(0.0)
        sch.step(0.0, k)  # first step: factorisation and (implicit) condensation
        sch.accept(k)
        first = time.perf_counter() - t0
        times, iters = [], []
        t = k
        for _ in range(steps):
            a = time.perf_counter()
            sch.step(t, t + k)
            sch.accept(t + k)
            times.append(time.perf_counter() - a)
            iters.append(sch.diagnostics().get("newton_iterations", 0))
            t += k
    return statistics.median(times), first, float(np.mean(iters))


def tip(ds):
    return float(ds.u_probe.isel(time=-1, probe=-1).sel(component="y"))


def time_to_solution():
    ref = workbench.run("tp4", scheme="implicit", k=0.0002, progress=False, **STIFF)
    exact = tip(ref)
    out = {}
    for scheme, ks in (("explicit", [0.00065, 0.0005]), ("implicit", [0.02, 0.01, 0.008, 0.005, 0.0025])):
        for k in ks:
            ds = workbench.run("tp4", scheme=scheme, k=k, progress=False, **STIFF)
            err = abs(tip(ds) - exact) / abs(exact)
            print(f"  {scheme:8s} k={k:<8g} tip error {100 * err:6.3f} %  wall {ds.attrs['wall_time']:.2f} s "
                  f"(+ setup {ds.attrs['setup_time']:.2f} s)", flush=True)
            if err <= 0.01 and scheme not in out:
                out[scheme] = dict(k=k, error=err, wall=ds.attrs["wall_time"] + ds.attrs["setup_time"])
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[220, 440])
    ap.add_argument("--steps", type=int, default=100)
    args = ap.parse_args()
    rows = []
    for nx in args.sizes:
        ex, ex_first, _ = median_step(nx, "explicit", 5e-4, min(args.steps, 40))
        im, im_first, it = median_step(nx, "implicit", 0.01, args.steps)
        rows.append(dict(nx=nx, steps=args.steps, explicit_ms=1e3 * ex, implicit_ms=1e3 * im, ratio=im / ex, newton=it,
                         explicit_first_s=ex_first, implicit_first_s=im_first))
        print(f"nx={nx}: median over {args.steps} steps: explicit step {1e3 * ex:.2f} ms, implicit step {1e3 * im:.2f} ms "
              f"(ratio {im / ex:.2f}, "
              f"{it:.2f} Newton iterations/step); first step incl. factorisation: {ex_first:.2f} s / {im_first:.2f} s",
              flush=True)
    print("time to 1% tip accuracy (nx = 80, T = 1):")
    rows.append(time_to_solution())
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
