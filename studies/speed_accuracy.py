"""The speed/accuracy trade on the slab: P1 vs P2, several k, explicit, backward Euler, BDF2 and error control.

Run:  python studies/speed_accuracy.py [--out data/studies] [--quick]

Scene: the stiff slab of the stability issue (tp4's point force at the top-right
corner, c_nu = 100, gamma_nu = 20, L = 0.3), T = 1. The explicit scheme must
stay below k_crit ~ 7e-4; the implicit ones (backward Euler, BDF2) may take any k;
error-controlled runs (rtol = 1e-2, 1e-3, 1e-4, first step 0.01) choose their own. One
Study: the union of a k-grid per scheme and an rtol grid, so that every kind of run
lies on one Pareto plot. Errors are taken against one fine run (P2, h = 0.00625,
implicit, k = 2.5e-4) at T: the tip displacement u_y(1, 0.1) and beta at (1, 0)
(the Study's measures ``tip`` and ``beta``), relative to the reference's values
(``rel_error_tip``, ``rel_error_beta``; the load is switched on at t = 0, so a
max over time would measure how well each k resolves that jump, not the run).
Cost = setup + time loop wall time (cases run one at a time, so timings are not
disturbed by each other). Writes ``speed_accuracy.nc`` (the study Dataset) and
``speed_accuracy_pareto.png`` / ``speed_accuracy_pareto_beta.png`` (Pareto fronts
of the two relative errors), and prints the cheapest discretisation for 10%, 1%
and 0.1% in each quantity.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import workbench
from workbench import plotting
from workbench.output.results import far_facet
from workbench.study import Study, cheapest

STIFF = dict(c_nu=100.0, gamma_nu=20.0, L=0.3)
REFERENCE = dict(h=0.00625, k=0.00025, order=2, scheme="implicit")


def end_values(ds):
    """u_y at the tip (1, 0.1) and beta at the facet at (1, 0), at T (none for a case that did not reach T)."""
    if ds.attrs.get("status") != "complete":
        return {}
    return {"tip": float(ds.u_probe.isel(probe=-1, time=-1).sel(component="y")),
            "beta": float(far_facet(ds.beta).isel(time=-1))}


def sweep(out: Path, quick: bool):
    grids = [{"scheme": ["implicit"], "k": [0.02, 0.005] if quick else [0.02, 0.01, 0.005, 0.0025]},
             {"scheme": ["explicit"], "k": [0.0005] if quick else [0.0005, 0.00025]},
             {"scheme": ["bdf2"], "k": [0.02, 0.005] if quick else [0.04, 0.02, 0.01, 0.005]},
             # error-controlled (k: the first step only): backward Euler and BDF2 at three tolerances
             {"scheme": ["implicit", "bdf2"], "rtol": [1e-2] if quick else [1e-2, 1e-3, 1e-4], "k": [0.01]}]
    ref = dict(REFERENCE, h=0.0125, k=0.001) if quick else REFERENCE
    st = Study("tp4", h=[0.05, 0.025] if quick else [0.05, 0.025, 0.0125], order=[1, 2], grids=grids, reference=ref,
               measures=end_values, workers=1, n_compare=5, **STIFF)
    ds = st.run(out / "speed_accuracy.cases", progress=True)
    units = {"tip": ("m", "u_y at (1, 0.1), t = T"), "beta": ("1", "beta at (1, 0), t = T")}
    for name, (unit, what) in units.items():
        ds[name].attrs.update(units=unit, long_name=what)
        ds[f"rel_error_{name}"].attrs.update(units="1", long_name=f"|{name} - {name}_ref| / |{name}_ref|: {what}")
    ds.attrs["study"] = "speed/accuracy trade, stiff slab"
    return ds


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="data/studies")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    out = Path(args.out)
    ds = sweep(out, args.quick)
    workbench.write(ds, out / "speed_accuracy.nc")
    plotting.pareto(ds, out / "speed_accuracy_pareto.png", error="rel_error_tip")
    plotting.pareto(ds, out / "speed_accuracy_pareto_beta.png", error="rel_error_beta")
    for quantity in ("rel_error_tip", "rel_error_beta"):
        for tol in (0.1, 0.01, 0.001):
            best = cheapest(ds, tol, error=quantity)
            what = "none of the cases" if best is None else \
                (f"P{best['order']} {best['scheme']}, h = {best['h']:g}, "
                 + (f"rtol = {best['rtol']:g}" if best.get("rtol") else f"k = {best['k']:g}") + ": "
                 f"error {100 * best[quantity]:.3g} %, {best['wall_time']:.2f} s")
            print(f"{quantity} <= {100 * tol:g} %: {what}")
    table = ds[["rel_error_tip", "rel_error_beta", "wall_time", "setup_time", "ndof", "nsteps"]].to_dataframe()
    print(table.dropna(subset=["rel_error_tip"]).to_string())


if __name__ == "__main__":
    main()
