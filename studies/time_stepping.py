"""What second order and error control buy: cost to a given error on the slab, and Model B's memory cost per step.

Run:  python studies/time_stepping.py [--out data/time_stepping] [--quick] [--part slab|memory|all]

**Slab** (the held-out slab of the time-stepping issue: E = 1000, nu = 0.3, a1 = 30, a2 = 20,
c_nu = 100, gamma_nu = 20, eps_a = 1e-3, L = 0.3, c_tau = 10, symmetric truncation, traction
(0, 5t) on the top for x >= 0.5, P2, h = 0.025, T = 1). The error is that of the tip displacement
u_y(1, 0, T), relative, against fixed BDF2 at k = 3.125e-4 (its own error is estimated by the run at
twice its step and printed; it must stay far below the smallest target). Runs: fixed backward
Euler (k = 0.01 / 2^j), fixed BDF2 (k = 0.04 / 2^j), error-controlled backward Euler and BDF2
(rtol = 1e-2 ... 1e-5, first step 0.1 sqrt(rtol / 1e-2)). Cost = setup + time-loop wall time of
``workbench.run`` (runs one at a time; runs under 2 s repeated three times, the median taken).
For each target (1 %, 0.1 %, 0.01 %) and method: the cheapest run that reaches it, and the cost
interpolated log-log between the two runs that bracket it (the figure used for the ratios).

**Memory** (Model B, memory_slab at h = 0.1, k = 1e-4): the wall time per step at steps 10, 1000
and 10000 (median of a window of 11 steps) for a general kernel b(t) = (1 + t/0.05)^-1.5 (a power
law: no exact Prony form) by the O(n) quadrature and by the exponential-sum approximation
(``kernel_approximation = "exponentials"``, kernel_tol = 1e-6), and the largest difference of u
between the two over the run (the approximation's effect on the solution).

Writes ``slab.nc`` (one record per run: method, k or rtol, steps, cost, tip value, error),
``memory.nc`` (per-step times), ``time_stepping.png`` (error against cost) and
``summary.json`` (the figures printed). ``--quick``: h = 0.05, fewer runs, 1000 memory steps
(a check that the script works; the figures are not the benchmark's).
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from pathlib import Path

import numpy as np

SLAB = dict(E=1000, nu=0.3, a1=30, a2=20, c_nu=100, gamma_nu=20, eps_a=1e-3, L=0.3, c_tau=10,
            bonding_truncation="symmetric", traction_top="(0, 5*t*ifpos(x - 0.5, 1, 0))", order=2,
            T=1.0, probes=[(1.0, 0.0)])
TARGETS = (1e-2, 1e-3, 1e-4)
KERNEL = "(1 + t/0.05)**(-1.5)"


def _run(cheap_repeats=3, **kw):
    """(tip u_y at T, cost in s, accepted steps, rejected steps) of one run; cheap runs repeated (median cost)."""
    import warnings

    import workbench

    costs = []
    for _ in range(cheap_repeats):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # bonding-resolution note of coarse fixed steps
            ds = workbench.run("slab", **SLAB, progress=False, **kw)
        costs.append(ds.attrs["setup_time"] + ds.attrs["wall_time"])
        if costs[-1] > 2.0:
            break
    tip = float(ds.u_probe.isel(probe=-1, time=-1).sel(component="y"))
    return tip, statistics.median(costs), int(ds.attrs["nsteps"]), int(ds.attrs.get("rejected_steps", 0))


def slab(h, quick):
    """Every run of the slab part, as a list of dicts, and the reference with its own error estimate."""
    k_ref = 6.25e-4 if quick else 3.125e-4
    ref, ref_cost, _, _ = _run(1, h=h, scheme="bdf2", k=k_ref)
    ref2, _, _, _ = _run(1, h=h, scheme="bdf2", k=2 * k_ref)
    print(f"reference: BDF2 k = {k_ref:g}: u_y(1, 0, T) = {ref:.9f} ({ref_cost:.1f} s); at 2k: {ref2:.9f} "
          f"(difference {abs(ref2 - ref) / abs(ref):.1e} rel.; BDF2: the reference's own error ~ 1/3 of it)", flush=True)
    n_be, n_bdf, tols = (5, 4, (1e-2, 1e-3)) if quick else (10, 7, (1e-2, 1e-3, 1e-4, 1e-5))
    plan = ([("implicit", dict(scheme="implicit", k=0.01 / 2 ** j)) for j in range(n_be)]
            + [("bdf2", dict(scheme="bdf2", k=0.04 / 2 ** j)) for j in range(n_bdf)]
            + [("adaptive bdf2", dict(scheme="bdf2", rtol=r, k=0.1 * math.sqrt(r / 1e-2))) for r in tols]
            + [("adaptive implicit", dict(scheme="implicit", rtol=r, k=0.1 * math.sqrt(r / 1e-2)))
               for r in tols[:2]])  # (rtol 1e-4: 135069 steps, 579 s, error 2.6e-4 - measured once, left out)
    rows = []
    for method, kw in plan:
        tip, cost, steps, rejected = _run(h=h, **kw)
        err = abs(tip - ref) / abs(ref)
        rows.append(dict(method=method, k=kw["k"], rtol=kw.get("rtol", 0.0), steps=steps, rejected=rejected,
                         cost=cost, tip=tip, error=err))
        print(f"{method:18s} k={kw['k']:<10.4g} rtol={kw.get('rtol', 0):<7g} steps {steps:6d} (+{rejected} rejected) "
              f"{cost:8.3f} s   tip {tip:.7f}  error {err:.2e}", flush=True)
    return rows, dict(reference=ref, reference_k=k_ref, reference_2k=ref2, reference_cost=ref_cost)


def cost_to(rows, method, target):
    """(cheapest run reaching target, log-log interpolated cost to it) for one method; None where not reached."""
    runs = sorted((r for r in rows if r["method"] == method), key=lambda r: r["cost"])
    reached = [r for r in runs if r["error"] <= target]
    best = min(reached, key=lambda r: r["cost"]) if reached else None
    interp = None
    by_err = sorted(runs, key=lambda r: -r["error"])  # from coarse to fine
    for a, b in zip(by_err, by_err[1:]):
        if a["error"] >= target >= b["error"] > 0:
            s = (math.log(target) - math.log(a["error"])) / (math.log(b["error"]) - math.log(a["error"]))
            interp = math.exp(math.log(a["cost"]) + s * (math.log(b["cost"]) - math.log(a["cost"])))
            break
    if interp is None and best is not None and best["error"] <= target:
        interp = best["cost"]  # reached already by the coarsest run: no bracket, its cost is an upper bound
    return best, interp


def memory(steps):
    """Per-step wall times of the general kernel by quadrature and by exponential sums on memory_slab."""
    import workbench
    from workbench.discrete import discretisation
    from workbench.running.threads import blas_single_threaded
    from workbench.schemes import scheme_class

    k, out, finals = 1e-4, {}, {}
    with blas_single_threaded():
        for how in ("quadrature", "exponentials"):
            sc = workbench.scene("memory_slab", h=0.1, k=k, T=k * steps, prony=(), kernel=KERNEL,
                                 kernel_E=-1000.0, kernel_nu=0.3, kernel_approximation=how, kernel_tol=1e-6)
            d = discretisation.build(sc)
            sch = scheme_class("vi")(d)
            info = sch.preflight(k)
            sch.start(0.0)
            sch.accept(0.0)
            times = np.zeros(steps)
            u_np = d.u.vec.FV().NumPy()
            us = []
            for n in range(steps):
                a = time.perf_counter()
                sch.step(n * k, (n + 1) * k)
                sch.accept((n + 1) * k)
                times[n] = time.perf_counter() - a
                if (n + 1) % max(1, steps // 100) == 0:
                    us.append(u_np.copy())
            windows = {}
            for m in (10, 1000, 10000):
                if m <= steps:
                    windows[m] = 1e3 * statistics.median(times[max(0, m - 6):min(steps, m + 5)])
            out[how] = dict(ndof=d.ndof, ms_per_step=windows, total_s=float(times.sum()), times=times, **info)
            finals[how] = np.array(us)
            print(f"{how:12s} ndof={d.ndof}: " + ", ".join(f"step {m}: {v:.3f} ms" for m, v in windows.items())
                  + f"; total {times.sum():.1f} s" + (f"; {info}" if info else ""), flush=True)
    diff = float(np.abs(finals["quadrature"] - finals["exponentials"]).max())
    scale = float(np.abs(finals["quadrature"]).max())
    print(f"largest |u_quadrature - u_exponentials| over the run: {diff:.2e} m ({diff / scale:.1e} of max |u|)")
    return out, dict(u_difference=diff, u_scale=scale)


def plot(rows, targets, path):
    from workbench.plotting import _save, figure

    fig, ax = figure(1, 1, figsize=(6.4, 4.4))
    for method in dict.fromkeys(r["method"] for r in rows):
        runs = sorted((r for r in rows if r["method"] == method), key=lambda r: r["cost"])
        ax.loglog([r["cost"] for r in runs], [r["error"] for r in runs], "o-" if "adaptive" not in method else "s--",
                  label=method)
    for t in targets:
        ax.axhline(t, color="gray", lw=0.6, ls=":")
    ax.set(xlabel="setup + time loop [s]", ylabel="relative error of u_y(1, 0, T) [1]",
           title="slab, P2 h = 0.025: error against cost")
    ax.legend(fontsize=8)
    _save(fig, path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="data/time_stepping")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--part", choices=("slab", "memory", "all"), default="all")
    args = ap.parse_args(argv)
    import xarray as xr

    from workbench.output.files import atomic_write

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {"quick": args.quick}
    if args.part in ("slab", "all"):
        h = 0.05 if args.quick else 0.025
        rows, ref = slab(h, args.quick)
        summary["slab"] = {"h": h, **ref, "cost_to": {}}
        print("\ncost to a target error (cheapest run reaching it | log-log interpolated):")
        for target in TARGETS:
            line = {}
            for method in dict.fromkeys(r["method"] for r in rows):
                best, interp = cost_to(rows, method, target)
                line[method] = dict(cheapest=None if best is None else {k: best[k] for k in ("k", "rtol", "steps",
                                                                                               "cost", "error")},
                                    interpolated_cost=interp)
            be = line.get("implicit", {}).get("interpolated_cost")
            print(f"  {target:.0e}: " + "; ".join(
                f"{m} {v['interpolated_cost']:.3g} s" + (f" ({be / v['interpolated_cost']:.1f}x less than BE)"
                                                         if be and v['interpolated_cost'] and m != 'implicit' else "")
                if v["interpolated_cost"] else f"{m} not reached" for m, v in line.items()))
            summary["slab"]["cost_to"][f"{target:g}"] = line
        ds = xr.Dataset({key: ("run", np.array([r[key] for r in rows])) for key in rows[0]},
                        attrs={"title": "time stepping: cost to error on the slab", "h": h, **ref})
        atomic_write(out / "slab.nc", lambda tmp: ds.to_netcdf(tmp, format="NETCDF4"))
        plot(rows, TARGETS, out / "time_stepping.png")
    if args.part in ("memory", "all"):
        steps = 1000 if args.quick else 10000
        mem, diff = memory(steps)
        summary["memory"] = {how: {k: v for k, v in m.items() if k != "times"} for how, m in mem.items()} | diff
        ds = xr.Dataset({f"{how}_step_time": ("step", m["times"]) for how, m in mem.items()},
                        attrs={"title": "Model B: wall time per step, general kernel", "kernel": KERNEL, **{
                            k: v for k, v in summary["memory"]["exponentials"].items() if not isinstance(v, dict)}})
        atomic_write(out / "memory.nc", lambda tmp: ds.to_netcdf(tmp, format="NETCDF4"))
    atomic_write(out / "summary.json", lambda tmp: Path(tmp).write_text(json.dumps(summary, indent=1, default=float)))
    print(f"written: {out}/")


if __name__ == "__main__":
    main()
