"""Plots from result Datasets (no re-running inside plotting).

Every function takes Datasets and returns a matplotlib Figure; with a path it
also writes the figure (PNG, 150 dpi) and closes it.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _save(fig, path):
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=150, bbox_inches="tight")
        plt.close(fig)
    return fig


def _probe_label(ds, p):
    return "(" + ", ".join(f"{float(ds[f'probe_{c}'][p]):g}" for c in ds.component.values) + ")"


def overview(ds, path=None):
    """Probe displacements over time, beta at the facet nearest the far end, u_nu on the contact side at T."""
    has_beta = "beta" in ds
    ncols = 2 + (ds.sizes.get("node", 0) > 1)
    fig, axes = plt.subplots(1, ncols, figsize=(4.2 * ncols, 3.4), constrained_layout=True)
    ax = axes[0]
    comp = ds.component.values[-1]  # vertical (normal) component in 2D/3D, x in 1D
    for p in ds.probe.values:
        ax.plot(ds.time, ds.u_probe.sel(probe=p, component=comp), label=_probe_label(ds, p))
    ax.set(xlabel="t [s]", ylabel=f"u_{comp} [m]", title="displacement at probes")
    ax.legend(fontsize=7)
    ax = axes[1]
    if has_beta:
        far = int(np.argmax(ds.facet_x.values))
        ax.plot(ds.time, ds.beta.isel(facet=far))
        ax.set(xlabel="t [s]", ylabel="beta", title=f"bonding field at x = {float(ds.facet_x[far]):.3g}")
    else:
        ax.text(0.5, 0.5, "no adhesion modelled", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
    if ncols == 3:
        ax = axes[2]
        order = np.argsort(ds.node_x.values)
        for t in np.unique(np.quantile(ds.time.values, [0.25, 0.5, 0.75, 1.0], method="nearest")):
            ax.plot(ds.node_x.values[order], ds.u_contact.sel(time=t, component=comp).values[order],
                    label=f"t = {t:.3g}")
        ax.set(xlabel="x [m]", ylabel=f"u_{comp} [m]", title="contact side")
        ax.legend(fontsize=7)
    status = "" if ds.attrs.get("status") == "complete" else "  [INCOMPLETE]"
    fig.suptitle(f"{ds.attrs.get('scene')}: scheme {ds.attrs.get('scheme')}, h = {ds.attrs.get('h_max'):.3g}, "
                 f"k = {ds.attrs.get('k_actual'):.3g}{status}", fontsize=9)
    return _save(fig, path)
