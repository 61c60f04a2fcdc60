"""The speed/accuracy trade on the slab: P1 vs P2, several k, explicit vs implicit.

Run:  python studies/speed_accuracy.py [--out data/studies] [--quick]

Scene: the stiff slab of the stability issue (tp4's point force at the top-right
corner, c_nu = 100, gamma_nu = 20, L = 0.3), T = 1. The explicit scheme must
stay below k_crit ~ 7e-4; the implicit one may take any k. Errors are taken
against one fine run (P2, h = 0.00625, implicit, k = 2.5e-4) at T: the tip
displacement u_y(1, 0.1) and beta at (1, 0), relative to the reference's values
(the load is switched on at t = 0, so a max over time would measure how well
each k resolves that jump, not the run). Cost = setup + time loop wall time
(cases run one at a time, so timings are not disturbed by each other).
Writes ``speed_accuracy.nc`` (the combined study Dataset, with ``rel_error_tip``
and ``rel_error_beta``) and ``speed_accuracy_pareto.png``, and prints the cheapest
discretisation for 10%, 1% and 0.1% in each quantity.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import xarray as xr

import workbench
from workbench import plotting
from workbench.study import Study, cheapest

STIFF = dict(c_nu=100.0, gamma_nu=20.0, L=0.3)
REFERENCE = dict(h=0.00625, k=0.00025, order=2, scheme="implicit")


def sweep(out: Path, quick: bool):
    hs = [0.05, 0.025] if quick else [0.05, 0.025, 0.0125]
    runs = {
        "implicit": dict(k=[0.02, 0.005] if quick else [0.02, 0.01, 0.005, 0.0025], scheme=["implicit"]),
        "explicit": dict(k=[0.0005] if quick else [0.0005, 0.00025], scheme=["explicit"]),
    }
    ref = dict(REFERENCE, h=0.0125, k=0.001) if quick else REFERENCE
    parts, studies = [], []
    for kw in runs.values():
        st = Study("tp4", h=hs, order=[1, 2], reference=ref, workers=1, n_compare=5, **kw, **STIFF)
        parts.append(st.run(out / "speed_accuracy.cases", progress=True))
        studies.append(st)
    cases = out / "speed_accuracy.cases"
    tip_ref, beta_ref = end_values(workbench.load(cases / f"{st.ref_case.key}.nc"))
    ds = xr.concat([p.drop_vars("pareto") for p in parts], dim="scheme", data_vars="all", coords="minimal",
                   compat="override", join="outer")
    rel_tip = xr.full_like(ds.error, np.nan)
    rel_beta = xr.full_like(ds.error, np.nan)
    for case in (c for study in studies for c in study.cases):
        path = cases / f"{case.key}.nc"
        if path.exists():
            tip, beta = end_values(workbench.load(path))
            where = dict(h=case.h, k=case.k, order=case.order, scheme=case.scheme)
            rel_tip.loc[where] = abs(tip - tip_ref) / abs(tip_ref)
            rel_beta.loc[where] = abs(beta - beta_ref) / beta_ref
    ds["rel_error_tip"] = rel_tip.assign_attrs(units="1", long_name="|u_y - u_y,ref| / |u_y,ref| at (1, 0.1), t = T")
    ds["rel_error_beta"] = rel_beta.assign_attrs(units="1", long_name="|beta - beta_ref| / beta_ref at (1, 0), t = T")
    ds["error"] = ds["rel_error_tip"]  # the Pareto front of the plot is taken on the tip error
    ds["pareto"] = (ds.error.dims, _front(ds.error.values, (ds.wall_time + ds.setup_time).values))
    ds.attrs = dict(parts[0].attrs, reference=str(ref), study="speed/accuracy trade, stiff slab")
    return ds


def end_values(ds):
    """u_y at the tip (1, 0.1) and beta at the facet at (1, 0), at T."""
    tip = float(ds.u_probe.isel(probe=-1, time=-1).sel(component="y"))
    return tip, float(ds.beta.isel(facet=int(np.argmax(ds.facet_x.values)), time=-1))


def _front(err, cost):
    e, c = err.ravel(), cost.ravel()
    ok = np.isfinite(e) & np.isfinite(c)
    out = np.zeros(e.shape, dtype=np.int8)
    for i in np.nonzero(ok)[0]:
        out[i] = not np.any(ok & (e <= e[i]) & (c <= c[i]) & ((e < e[i]) | (c < c[i])))
    return out.reshape(err.shape)


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
                (f"P{best['order']} {best['scheme']}, h = {best['h']:g}, k = {best['k']:g}: "
                 f"error {100 * best[quantity]:.3g} %, {best['wall_time']:.2f} s")
            print(f"{quantity} <= {100 * tol:g} %: {what}")
    table = ds[["rel_error_tip", "rel_error_beta", "wall_time", "setup_time", "ndof", "nsteps"]].to_dataframe()
    print(table.dropna(subset=["rel_error_tip"]).to_string())


if __name__ == "__main__":
    main()
