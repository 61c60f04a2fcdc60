"""Does a tolerance deliver what it promises from the first step on? (issue 23, item 1)

A rod whose end is moved back and forth, ``delta = 0.3 sin(2 pi t)`` (tension, then compression into the
foundation's compliance, adhesion), run error-controlled with backward Euler (rtol = 1e-2 ... 1e-4) and BDF2
(1e-3 ... 1e-6), once with the documented first step k = 0.01 and once with k = 1e-4. The error is the largest |u(length, t)
- u_ref(length, t)| over the recorded times over max |u_ref(length, t)|, against the rod's ODE reference (Radau,
rtol 1e-11: :func:`workbench.references.rod_ode`, independent of the finite-element code; the rod's u is linear
in x, so P1 elements are exact in space). Before the first step was checked, the error at k = 0.01 did not fall
below the first step's own error whatever rtol was.

Run::

    python studies/first_step.py                    # the table (about 5 minutes: backward Euler at 1e-4 takes 67k steps)
    python studies/first_step.py --out data/studies/first_step.txt
    python studies/first_step.py --slab             # the check's cost on a body that starts from rest (below)

``--slab``: the slab of ``studies/time_stepping.py`` (P2, h = 0.025), BDF2 at rtol = 1e-3 from the first step
0.0316, with atol = 1e-9 (the default), 1e-4 and 1e-3 m: steps, cost and the tip error at T against that study's
reference. The tolerance is relative to the largest |u| so far, so a checked first step resolves the initial layer
of a body loaded from rest; a larger atol says how much absolute accuracy is wanted there.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import workbench
from workbench.references import rod_reference

SCENE = dict(T=1.0, h=0.1, delta="0.3*sin(2*pi*t)")
#: The tolerances per scheme (backward Euler's steps grow like 1/rtol: 1e-5 would take about 1e6 steps).
RTOLS = {"implicit": (1e-2, 1e-3, 1e-4), "bdf2": (1e-3, 1e-4, 1e-5, 1e-6)}


def measure(scheme: str, rtol: float, k: float) -> dict:
    sc = workbench.scene("rod", k=k, rtol=rtol, scheme=scheme, **SCENE)
    t0 = time.perf_counter()
    ds = workbench.run(sc, progress=False)
    wall = time.perf_counter() - t0
    ref = rod_reference(sc)
    length = float(sc["length"])
    end = int(np.argmin(np.abs(np.asarray(ds.probe_x.values).reshape(len(ds.probe), -1)[:, 0] - length)))
    u = ds.u_probe.isel(probe=end, component=0).values
    exact = np.asarray(ref(ds.time.values, length)[0]).ravel()
    err = float(np.max(np.abs(u - exact)) / np.max(np.abs(exact)))
    return dict(scheme=scheme, rtol=rtol, k=k, error=err, ratio=err / rtol, steps=int(ds.attrs["nsteps"]),
                rejected=int(ds.attrs.get("rejected_steps", 0)), wall=wall)


def slab() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import time_stepping as ts

    ref = 2.767665531853845  # u_y(1, 0, T), BDF2 at k = 3.125e-4 (data/time_stepping/summary.json; 1.7e-7 from 2k)
    for atol in (1e-9, 1e-4, 1e-3):
        tip, cost, steps, rejected = ts._run(h=0.025, scheme="bdf2", rtol=1e-3, k=0.0316, atol=atol)
        print(f"slab, BDF2, rtol 1e-3, atol {atol:g}: {steps} steps (+{rejected} rejected), {cost:.2f} s, tip error at T "
              f"{abs(tip - ref) / ref:.2e}", flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="also write the table to this file")
    parser.add_argument("--slab", action="store_true", help="the check's cost on the slab instead (module docs)")
    args = parser.parse_args(argv)
    if args.slab:
        slab()
        return 0
    rows = [measure(s, r, k) for s in RTOLS for k in (0.01, 1e-4) for r in RTOLS[s]]
    lines = [f"{'scheme':9} {'first k':>8} {'rtol':>7} {'max rel. error':>15} {'error/rtol':>10} {'steps':>6} "
             f"{'rejected':>8} {'wall s':>7}"]
    for r in rows:
        lines.append(f"{r['scheme']:9} {r['k']:8.0e} {r['rtol']:7.0e} {r['error']:15.3e} {r['ratio']:10.2f} "
                     f"{r['steps']:6d} {r['rejected']:8d} {r['wall']:7.2f}")
    text = "\n".join(lines)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(f"# python studies/first_step.py ({workbench.__version__})\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
