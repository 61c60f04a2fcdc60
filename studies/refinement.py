"""O(h + k) confirmation studies: archives in data/refinement/, convergence plots, fitted orders.

Run:  python studies/refinement.py [slab | memory | rod | all] [--out data/refinement] [--quick]

* ``rod``    — tp1 and tp2 k-sweeps (Model A) against the exact / reduced-ODE solution (docs/models.md).
* ``slab``   — Model A, tp5 (the paper's slab, periodic traction), coupled k = 0.2 h with the
  paper's explicit scheme (k stays below k_crit ~ 0.03), P1 and P2, against the finest P2 case.
* ``memory`` — Model B, memory_slab, coupled k = 0.4 h, P1, against the finest case.

Every study prints its fitted orders (least-squares slope of log error against log(h + k) or
log k) for the paper's norm and for each part.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import workbench
from workbench import plotting
from workbench.study import Study

STUDIES = {
    "rod_tp1": lambda q: dict(scene="tp1", k=[0.04, 0.02, 0.01, 0.005, 0.0025], reference="ode"),
    "rod_tp2": lambda q: dict(scene="tp2", k=[0.04, 0.02, 0.01, 0.005, 0.0025], reference="ode"),
    "slab": lambda q: dict(scene="tp5", h=[0.05, 0.025, 0.0125] + ([] if q else [0.00625, 0.003125]),
                           k_over_h=0.2, order=[1, 2], n_compare=10, reference="finest"),
    "memory": lambda q: dict(scene="memory_slab", h=[0.25, 0.125, 0.0625] + ([] if q else [0.03125, 0.015625]),
                             k_over_h=0.4, n_compare=10, reference="finest"),
}
GROUPS = {"rod": ["rod_tp1", "rod_tp2"], "slab": ["slab"], "memory": ["memory"]}


def run_study(name: str, out: Path, quick: bool = False, workers: int = 2):
    spec = STUDIES[name](quick)
    scene = spec.pop("scene")
    st = Study(scene, workers=workers, **spec)
    ds = st.run(out / f"{name}.cases", progress=True)
    workbench.write(ds, out / f"{name}.nc")
    plotting.convergence(ds, out / f"{name}.png")
    along = "h+k" if st.coupled else "k"
    rates = {}
    for norm in ("error", "error_V", "error_Q", "error_beta"):
        r = ds.observed_order.sel(norm=norm, along=along)
        s = ds.observed_order_stderr.sel(norm=norm, along=along)
        if np.isfinite(r.values).any():
            rates[norm] = [(int(o), round(float(r.sel(order=o).squeeze()), 3), round(float(s.sel(order=o).squeeze()), 3))
                           for o in ds.order.values]
    print(f"{name}: fitted orders along {along} (order, rate, stderr): {rates}")
    print(f"{name}: wrote {out / (name + '.nc')} and {out / (name + '.png')}")
    return ds


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("which", nargs="?", default="all", choices=["all", *GROUPS])
    ap.add_argument("--out", default="data/refinement")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    names = [n for g in (GROUPS if args.which == "all" else [args.which]) for n in GROUPS[g]]
    for name in names:
        run_study(name, Path(args.out), args.quick, args.workers)


if __name__ == "__main__":
    main()
