"""Plots from result Datasets (no re-running inside plotting).

Every function takes Datasets and returns a matplotlib Figure; with a path it
also writes the figure (PNG, 150 dpi, atomically). Figures are made as
``matplotlib.figure.Figure`` objects, not through pyplot, so this module
chooses no backend and keeps no global state: in Jupyter the returned figure
shows inline (as the cell's value, or with ``display(fig)``); a script saves it.
"""
from __future__ import annotations

import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

#: A perceptually uniform colour map for fields (not jet).
FIELD_CMAP = "viridis"


class _Figure(Figure):
    """A Figure that shows itself in Jupyter as PNG (``_repr_png_``), whether or not pyplot was ever used."""

    def _repr_png_(self):
        import io

        buf = io.BytesIO()
        self.savefig(buf, format="png", dpi=100, bbox_inches="tight")
        return buf.getvalue()


def figure(nrows=1, ncols=1, *, figsize=(5, 3.8), squeeze=True, **kw):
    """(Figure, axes) with constrained layout, outside pyplot."""
    fig = _Figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots(nrows, ncols, squeeze=squeeze, **kw)


def _save(fig, path):
    if path is not None:
        from .files import atomic_write

        atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=150, bbox_inches="tight"))
    return fig


def _probe_label(ds, p):
    return "(" + ", ".join(f"{float(ds[f'probe_{c}'][p]):g}" for c in ds.component.values) + ")"


def overview(ds, path=None):
    """Probe displacements over time, beta at the facet nearest the far end, u_nu on the contact side at T."""
    has_beta = "beta" in ds
    ncols = 2 + (ds.sizes.get("node", 0) > 1)
    fig, axes = figure(1, ncols, figsize=(4.2 * ncols, 3.4))
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


def convergence(study_ds, path=None, norms=("error", "error_V", "error_Q", "error_beta")):
    """Log-log error against h + k (coupled sweeps), h or k, with fitted orders and a slope-1 guide."""
    coupled = "level" in study_ds.dims
    if coupled:
        along, x = "h+k", study_ds.h.values + study_ds.k.values
    elif study_ds.sizes.get("h", 1) > 1:
        along, x = "h", study_ds.h.values
    else:
        along, x = "k", study_ds.k.values
    norms = [n for n in norms if n in study_ds and np.isfinite(study_ds[n].values).any()]
    fig, axes = figure(1, len(norms), figsize=(3.6 * len(norms), 3.4), squeeze=False)
    for ax, norm in zip(axes[0], norms):
        for order in study_ds.order.values:
            for scheme in study_ds.scheme.values:
                err = study_ds[norm].sel(order=order, scheme=scheme)
                if not coupled:
                    err = err.isel(k=-1) if along == "h" else err.isel(h=-1)
                y = np.ravel(err.values)
                good = np.isfinite(y) & (y > 0)
                if not good.any():
                    continue
                rate = float(study_ds.observed_order.sel(norm=norm, along=along, order=order, scheme=scheme))
                ax.loglog(x[good], y[good], "o-", label=f"P{order} {scheme}: {rate:.2f}")
                ref = y[good][0] * (x[good] / x[good][0])
                ax.loglog(x[good], ref, ":", color="gray")
        ax.set(xlabel=along, title=norm)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.legend(fontsize=7, title="fitted order", title_fontsize=7)
    fig.suptitle(f"{study_ds.attrs.get('scene')}: reference {study_ds.attrs.get('reference')} "
                 f"(dotted: slope 1)", fontsize=9)
    return _save(fig, path)


def pareto(study_ds, path=None, error="error", cost="wall_time"):
    """Error against cost (wall time incl. setup) of every case, the Pareto front joined."""
    err = study_ds[error].values.ravel()
    c = (study_ds[cost] + (study_ds["setup_time"] if cost == "wall_time" else 0)).values.ravel()
    ok = np.isfinite(err) & np.isfinite(c)
    front = np.array([ok[i] and not np.any(ok & (err <= err[i]) & (c <= c[i]) & ((err < err[i]) | (c < c[i])))
                      for i in range(err.size)])
    fig, ax = figure(figsize=(5, 3.8))
    stacked = study_ds[error].stack(case=study_ds[error].dims)
    labels = [", ".join(f"{d}={v}" for d, v in zip(stacked.indexes["case"].names, idx)) for idx in stacked.indexes["case"]]
    ax.loglog(c[ok], err[ok], "o", color="tab:blue", alpha=0.6)
    order = np.argsort(c[front & ok])
    ax.loglog(c[front & ok][order], err[front & ok][order], "-", color="tab:red", label="Pareto front")
    for ci, ei, lab, f in zip(c, err, labels, front):
        if f and np.isfinite(ci) and np.isfinite(ei):
            ax.annotate(lab, (ci, ei), fontsize=6)
    label = study_ds[error].attrs.get("long_name", error)
    ax.set(xlabel=f"{cost} + setup [s]", ylabel=error, title=f"{study_ds.attrs.get('scene')}: accuracy vs cost")
    ax.text(0.02, 0.02, label, transform=ax.transAxes, fontsize=6)
    ax.legend(fontsize=7)
    return _save(fig, path)
