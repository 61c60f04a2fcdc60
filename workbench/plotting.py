"""Plots from result Datasets (no re-running inside plotting).

Every function takes Datasets and returns a matplotlib Figure; with a path it
also writes the figure (PNG, 150 dpi, atomically). Figures are made as
``matplotlib.figure.Figure`` objects, not through pyplot, so this module
chooses no backend and keeps no global state: in Jupyter the returned figure
shows inline (as the cell's value, or with ``display(fig)``); a script saves it.
"""
from __future__ import annotations

import matplotlib.colors
import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

from .input.numerics import is_adaptive

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
    import numpy as np

    fig = _Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=squeeze, **kw)
    for ax in np.ravel(axes):  # no additive offset ("+1.0002e3" at an axis' end): values are read as printed
        ax.ticklabel_format(useOffset=False)
    return fig, axes


#: The file formats a figure is written in, by the path's suffix (matplotlib's own; no suffix: PNG).
FORMATS = ("png", "pdf", "svg", "svgz", "eps", "ps", "jpg", "jpeg", "tif", "tiff")


def file_format(path, option: str = "path") -> str:
    """The format a figure written to ``path`` takes, from its suffix (PNG without one); a ParameterError naming
    ``option`` for a suffix matplotlib does not write. Every figure had been PNG whatever its name (a .pdf that
    LaTeX then refused).

    >>> file_format("out/tp1.pdf"), file_format("out/tp1"), file_format("out/tp1.SVG")
    ('pdf', 'png', 'svg')
    """
    from pathlib import Path

    from .errors import ParameterError

    suffix = Path(path).suffix[1:].lower()
    if not suffix:
        return "png"
    if suffix not in FORMATS:
        raise ParameterError(f"{option} = {str(path)!r}: a figure is written as {', '.join(FORMATS)} (by the "
                             f"suffix), not .{suffix}")
    return suffix


def _save(fig, path):
    if path is not None:
        from .errors import ParameterError
        from .output.files import atomic_write

        if not str(path).strip():
            raise ParameterError("plotting: path = '': give a file name, or None for the figure alone")
        fmt = file_format(path)  # (the temporary file has no suffix: the format is given)
        atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, dpi=150, bbox_inches="tight"))
    return fig


def plain(text) -> str:
    """Text shown as written (a scene name with '$' is not mathtext)."""
    return str(text).replace("$", r"\$")


def _probe_label(ds, p):
    return "(" + ", ".join(f"{float(ds[f'probe_{c}'][p]):g}" for c in ds.component.values) + ")"


def _of_kind(ds, study: bool, where: str) -> None:
    """A ParameterError naming ``where``'s argument unless ``ds`` is a run's Dataset (``study`` False: it has probes)
    or a study's (it has fitted orders): the other kind failed deep inside with a KeyError or an AttributeError."""
    import xarray as xr

    from .errors import ParameterError

    if not isinstance(ds, xr.Dataset):
        raise ParameterError(f"plotting.{where}: give the xarray Dataset of a {'study' if study else 'run'}, "
                             f"got {type(ds).__name__}")
    if not study and "observed_order" not in ds and "u_probe" not in ds:
        raise ParameterError(f"plotting.{where}: the Dataset is neither a run's nor a study's (no u_probe); it draws "
                             "a run's (workbench.run(...) or workbench.load of its archive)")
    if study != ("observed_order" in ds):
        kind, other = ("a study's", "a run's") if study else ("a run's", "a study's")
        raise ParameterError(f"plotting.{where}: the Dataset is {other}; it draws {kind} (workbench."
                             f"{'Study(...).run()' if study else 'run(...)'} or workbench.load of its archive)")


def overview(ds, path=None):
    """A run at a glance: probe displacements over time, then what the model has on its contact side.

    Model A: the bonding field at the far facet over time (if adhesion is modelled) and the
    normal displacement along the contact side at four times. Model B: the contact pressure
    and the normal displacement along the contact side (gap drawn) at four times, and the
    contact states of every node over time (the rod: pressure and state over time).
    """
    _of_kind(ds, False, "overview")
    comp = ds.component.values[-1]  # vertical (normal) component in 2D/3D, x in 1D
    model_b = "contact_state" in ds
    panels = _overview_panels(ds)
    fig, axes = figure(1, len(panels), figsize=(4.2 * len(panels), 3.4), squeeze=False)
    times = np.unique(np.quantile(ds.time.values, [0.25, 0.5, 0.75, 1.0], method="nearest"))
    order = np.argsort(ds.node_x.values)
    x_nodes = ds.node_x.values[order]
    # a 3D contact side is a surface: its vertices against x are a cloud, drawn as points (a line zig-zagged)
    style = dict(ls="none", marker=".", ms=3) if "node_y" in ds.coords and "node_z" in ds.coords else {}
    for ax, panel in zip(axes[0], panels):
        if panel == "probes":
            for p in ds.probe.values:
                ax.plot(ds.time, ds.u_probe.sel(probe=p, component=comp), label=_probe_label(ds, p))
            ax.set(xlabel="t [s]", ylabel=f"u_{comp} [m]", title="displacement at probes")
            ax.legend(fontsize=7)
        elif panel == "beta":
            from .output.results import far_facet

            far = far_facet(ds.beta)
            ax.plot(ds.time, far)
            ax.set(xlabel="t [s]", ylabel="beta [1]", title=f"bonding field at x = {float(far.facet_x):.3g}")
        elif panel == "u_contact":
            for t in times:
                ax.plot(x_nodes, ds.u_contact.sel(time=t, component=comp).values[order], label=f"t = {t:.3g}", **style)
            if model_b:  # u_nu = -u_y (2D) / -u_z (3D) reaches the rigid layer at -gap
                ax.axhline(-float(ds.attrs["gap"]), color="0.5", ls="--", lw=0.8, label="rigid limit")
            ax.set(xlabel="x [m]", ylabel=f"u_{comp} [m]", title="contact side")
            ax.legend(fontsize=7)
        elif panel == "pressure":
            for t in times:
                ax.plot(x_nodes, ds.contact_pressure.sel(time=t).values[order], label=f"t = {t:.3g}", **style)
            ax.set(xlabel="x [m]", ylabel="contact pressure [Pa]", title="contact pressure")
            ax.legend(fontsize=7)
        elif panel == "states":
            _states_panel(fig, ax, ds, x_nodes, order)
        elif panel == "pressure_t":
            _pressure_state_panel(ax, ds)
    status = "" if ds.attrs.get("status") == "complete" else "  [INCOMPLETE]"
    # (error-controlled: its tolerance and steps; "k = " the largest step read as a step the user chose, an outside pass)
    steps = f"rtol = {ds.attrs['rtol']:.3g}, {ds.attrs['accepted_steps']} steps" if "accepted_steps" in ds.attrs \
        else f"k = {ds.attrs.get('k_actual'):.3g}"
    fig.suptitle(f"{plain(ds.attrs.get('scene'))}: scheme {ds.attrs.get('scheme')}, h = {ds.attrs.get('h_max'):.3g}, "
                 f"{steps}{status}", fontsize=9)
    return _save(fig, path)


def _overview_panels(ds):
    """The panels of :func:`overview` for this run: what its model records, along the contact side or at one end."""
    along_side = ds.sizes.get("node", 0) > 1
    panels = ["probes"]
    if "beta" in ds:
        panels.append("beta")
    if "contact_state" in ds:
        panels += ["pressure", "u_contact", "states"] if along_side else ["pressure_t"]
    elif along_side:
        panels.append("u_contact")
    return panels


def _states_panel(fig, ax, ds, x_nodes, order):
    """The contact state of every node over time (Model B along a contact side), one colour per state."""
    st = ds.contact_state.values[:, order].astype(float)
    st[st < 0] = np.nan
    cmap = matplotlib.colors.ListedColormap(["#dddddd", "#4c72b0", "#55a868", "#c44e52"])
    im = ax.pcolormesh(x_nodes, ds.time.values, st, cmap=cmap, vmin=-0.5, vmax=3.5, shading="nearest")
    cb = fig.colorbar(im, ax=ax, ticks=[0, 1, 2, 3])
    cb.ax.set_yticklabels(["separated", "stuck", "compliant", "rigid"], fontsize=7)
    ax.set(xlabel="x [m]", ylabel="t [s]", title="contact states")


def _pressure_state_panel(ax, ds):
    """The pressure at the contact end over time with its contact states shaded (Model B, the rod)."""
    ax.plot(ds.time, ds.contact_pressure.isel(node=-1), color="k", lw=1)
    states = ds.contact_state.isel(node=-1).values
    for code, colour, name in ((1, "#4c72b0", "stuck"), (2, "#55a868", "compliant"), (3, "#c44e52", "rigid")):
        on = states == code
        if on.any():
            ax.fill_between(ds.time, 0, 1, where=on, color=colour, alpha=0.25, lw=0, label=name,
                            transform=ax.get_xaxis_transform())
    ax.set(xlabel="t [s]", ylabel="contact pressure [Pa]", title="contact end: pressure and state")
    ax.legend(fontsize=7)


def _series(study_ds):
    """(along, x, series dims, other dims) of a study Dataset's convergence plot."""
    if "level" in study_ds.dims and ("level" in study_ds.h.dims or "level" in study_ds.k.dims):  # k = C h: refining
        return "h+k", study_ds.h.values + study_ds.k.values, ["level"], None
    along = "h" if study_ds.sizes.get("h", 1) > 1 else "k"
    return along, study_ds[along].values, [along], {d: -1 for d in ("h", "k") if d != along and d in study_ds.dims}


def _combinations(da, skip):
    """Every selection of ``da`` over its dims except ``skip`` (dicts of dim -> value)."""
    import itertools

    dims = [d for d in da.dims if d not in skip]
    for combo in itertools.product(*(da[d].values for d in dims)):
        yield dict(zip(dims, combo))


def _label(sel):
    parts = []
    for d, v in sel.items():
        parts.append(f"P{v}" if d == "order" else (str(v) if d == "scheme" else f"{d}={v:g}"
                                                  if isinstance(v, (float, np.floating)) else f"{d}={v}"))
    return " ".join(parts)


def convergence(study_ds, path=None, norms=("error", "error_V", "error_Q", "error_beta")):
    """Log-log error against h + k (coupled sweeps), h or k, with fitted orders and a slope-1 guide; a sweep of
    tolerances alone (an ``rtol`` axis, one h and one k) is drawn by :func:`tolerance`."""
    _of_kind(study_ds, True, "convergence")
    if study_ds.sizes.get("rtol", 1) > 1 and study_ds.sizes.get("h", 1) == 1 and study_ds.sizes.get("k", 1) == 1:
        return tolerance(study_ds, path)
    along, x, series, finest = _series(study_ds)
    norms = [n for n in norms if n in study_ds and np.isfinite(study_ds[n].values).any()]
    if not norms:  # (a reference that gave no error: said in the figure, which is still written, not a traceback)
        fig, ax = figure(1, 1)
        ax.set_axis_off()
        ax.text(0.5, 0.5, f"no errors to draw: the reference ({plain(study_ds.attrs.get('reference'))}) gave none\n"
                "(see the study's warnings; give a finer run as the reference)", ha="center", va="center",
                wrap=True, fontsize=8)
        return _save(fig, path)
    fig, axes = figure(1, len(norms), figsize=(3.8 * len(norms), 3.6), squeeze=False)
    for ax, norm in zip(axes[0], norms):
        err_all = study_ds[norm] if finest is None else study_ds[norm].isel(finest)
        for sel in _combinations(err_all, series):
            y = np.ravel(err_all.sel(sel).values)
            good = np.isfinite(y) & (y > 0)
            if not good.any():
                continue
            fitted = study_ds.observed_order.sel(norm=norm, along=along)  # (per case of the axes it was fitted on)
            rate = float(fitted.sel({d: v for d, v in sel.items() if d in fitted.dims}).max())
            ax.loglog(x[good], y[good], "o-", label=f"{_label(sel)}: {rate:.2f}")
            ax.loglog(x[good], y[good][0] * (x[good] / x[good][0]), ":", color="gray")
        units = study_ds[norm].attrs.get("units", "")
        ax.set(xlabel=f"{along} [{'m + s' if along == 'h+k' else ('m' if along == 'h' else 's')}]",
               ylabel=f"{norm} [{units}]", title=norm)
        shown = np.log10(x[np.isfinite(x) & (x > 0)])
        if shown.size and shown.max() - shown.min() >= 1.0:  # (within a decade the minor ticks are the only labels)
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.legend(fontsize=7, title="fitted order", title_fontsize=7)
    fig.suptitle(f"{plain(study_ds.attrs.get('scene'))}: reference {plain(study_ds.attrs.get('reference'))} "
                 f"(dotted: slope 1)", fontsize=9)
    return _save(fig, path)


def tolerance(study_ds, path=None, error="error", cost="wall_time"):
    """Error-controlled sweeps (an ``rtol`` axis): the achieved error against the tolerance (with the lines
    error = rtol, 0.1 rtol and 10 rtol), and the cost against the achieved error, one line per other case."""
    _of_kind(study_ds, True, "tolerance")
    if "rtol" not in study_ds.dims:
        from .errors import ParameterError

        raise ParameterError("plotting.tolerance: the study has no rtol axis: it draws a sweep of tolerances "
                             "(sweep={'rtol': [...]})")
    rtol = study_ds.rtol.values
    err_all = study_ds[error]
    c_all = study_ds[cost] + (study_ds["setup_time"] if cost == "wall_time" else 0)
    fig, (left, right) = figure(1, 2, figsize=(9, 3.8))
    for sel in _combinations(err_all, ["rtol"]):
        y, c = np.ravel(err_all.sel(sel).values), np.ravel(c_all.sel(sel).values)
        good = np.isfinite(y) & (y > 0) & is_adaptive(rtol)
        if not good.any():
            continue
        label = _label(sel) or "cases"
        left.loglog(rtol[good], y[good], "o-", label=label)
        right.loglog(y[good], c[good], "o-", label=label)
        for x, yy, cc in zip(rtol[good], y[good], c[good]):
            right.annotate(f"{x:g}", (yy, cc), xytext=(3, 3), textcoords="offset points", fontsize=6)
    lo, hi = rtol[is_adaptive(rtol)].min(), rtol.max()
    grid = np.array([lo, hi])
    for factor, style in ((1.0, "-"), (0.1, ":"), (10.0, ":")):
        left.loglog(grid, factor * grid, style, color="gray", lw=0.8)
    units = err_all.attrs.get("units", "")
    left.set(xlabel="rtol [1]", ylabel=f"{error} [{units}]", title="achieved error (gray: rtol, 0.1 and 10 rtol)")
    right.set(xlabel=f"{error} [{units}]", ylabel=f"{cost} + setup [s]" if cost == "wall_time" else f"{cost} [s]",
              title="cost (points labelled by rtol)")
    left.legend(fontsize=7)
    fig.suptitle(f"{plain(study_ds.attrs.get('scene'))}: error control, reference "
                 f"{plain(study_ds.attrs.get('reference'))}", fontsize=9)
    return _save(fig, path)


def _kinds(index, names):
    """(label, mask, marker) per kind of run: one per scheme, error-controlled runs (rtol > 0) apart; one group
    'cases' when the study sweeps neither."""
    keys = [name for name in ("scheme", "rtol") if name in names]
    if not keys:
        return [("cases", np.ones(len(index), dtype=bool), "o")]
    scheme = np.asarray(index.get_level_values("scheme")) if "scheme" in keys else np.full(len(index), "")
    adaptive = is_adaptive(index.get_level_values("rtol")) if "rtol" in keys \
        else np.zeros(len(index), dtype=bool)
    out = []
    for name in dict.fromkeys(scheme):
        for adapt in (False, True):
            members = (scheme == name) & (adaptive == adapt)
            if members.any():
                out.append((f"{name or 'cases'}{' (error-controlled)' if adapt else ''}", members,
                            "s" if adapt else "o"))
    return out


def pareto(study_ds, path=None, error="error", cost="wall_time"):
    """Error against cost (wall time incl. setup) of every case; the Pareto front (``study_ds.pareto``) joined and
    numbered, the numbers explained beside the plot."""
    _of_kind(study_ds, True, "pareto")
    err_da = study_ds[error]
    c_da = study_ds[cost] + (study_ds["setup_time"] if cost == "wall_time" else 0)
    front_da = study_ds["pareto"] if error == "error" and "pareto" in study_ds else None
    stacked = err_da.stack(case=err_da.dims)
    err, c = stacked.values, c_da.stack(case=err_da.dims).values
    ok = np.isfinite(err) & np.isfinite(c)
    if front_da is not None:
        front = front_da.stack(case=err_da.dims).values.astype(bool) & ok
    else:
        from .study.evaluate import pareto_front

        front = pareto_front(err, c).astype(bool) & ok
    fig, ax = figure(figsize=(7.5, 3.8))
    names = stacked.indexes["case"].names
    for label, members, marker in _kinds(stacked.indexes["case"], names):
        sel = ok & members
        if sel.any():
            ax.loglog(c[sel], err[sel], marker, alpha=0.5, label=label)
    idx = np.nonzero(front)[0][np.argsort(c[front])]
    ax.loglog(c[idx], err[idx], "-o", color="black", mfc="none", label="Pareto front")
    lines = []
    for n, i in enumerate(idx, start=1):
        ax.annotate(str(n), (c[i], err[i]), xytext=(4, 4), textcoords="offset points", fontsize=7, color="black")
        values = stacked.indexes["case"][i]
        lines.append(f"{n}: " + ", ".join(f"{d}={v:g}" if isinstance(v, (float, np.floating)) else f"{d}={v}"
                                          for d, v in zip(names, values) if study_ds.sizes.get(d, 1) > 1
                                          or d in ("h", "k")))
    units = err_da.attrs.get("units", "")
    ax.set(xlabel=f"{cost} + setup [s]" if cost == "wall_time" else f"{cost} [s]", ylabel=f"{error} [{units}]",
           title=f"{plain(study_ds.attrs.get('scene'))}: accuracy vs cost")
    ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(1.02, 0.0))  # beside the data, below the numbers
    ax.text(1.02, 1.0, "\n".join(lines), transform=ax.transAxes, va="top", fontsize=7, family="monospace")
    return _save(fig, path)


def space(ds, path=None):
    """An adapted run (``space_tol > 0``): the relative estimate in space at the estimate times against the tolerance,
    and how the mesh grew: the dofs over time with the refinements marked (``space_adapt = "during"``), or the estimate
    against the dofs of each mesh of the repeated loop (``"repeat"``).

    >>> import workbench
    >>> ds = workbench.run("tp4", scheme="implicit", T=0.1, h=0.05, space_tol=0.1, space_adapt="during", progress=False)
    >>> fig = space(ds)
    >>> [ax.get_title() for ax in fig.axes]
    ['estimate in space', 'dofs over time']
    """
    _of_kind(ds, False, "space")
    if "space_error_estimate" not in ds:
        from .errors import ParameterError

        raise ParameterError("plotting.space: the run is not adapted: it draws a run with space_tol > 0 (its "
                             "space_error_estimate)")
    tol = float(ds.attrs.get("space_tol", np.nan))
    fig, (left, right) = figure(1, 2, figsize=(9, 3.6))
    t, e = ds.time.values, ds.space_error_estimate.values
    known = np.isfinite(e)
    left.plot(t[known], e[known], "o-", ms=3, label="energy estimate / largest energy norm")
    left.axhline(tol, color="gray", ls=":", lw=1, label=f"space_tol = {tol:g}")
    if "contact_edge_resolution" in ds:  # (edge_tol: the contact zone's edge, also a share, on the same axis)
        r = ds.contact_edge_resolution.values
        seen = np.isfinite(r)
        left.plot(t[seen], r[seen], "s-", ms=3, color="C1", label="contact edge's facet / zone's size")
        left.axhline(float(ds.attrs.get("edge_tol", np.nan)), color="C1", ls=":", lw=1,
                     label=f"edge_tol = {float(ds.attrs.get('edge_tol', np.nan)):g}")
    left.set(xlabel="t [s]", ylabel="relative [1]", title="estimate in space")
    left.legend(fontsize=7)
    if "refinement" in ds.dims:
        right.step(t, ds.ndof.values, where="post")
        for time in ds.refinement_time.values:
            right.axvline(time, color="gray", ls=":", lw=0.8)
        right.set(xlabel="t [s]", ylabel="displacement dofs", title="dofs over time")
    else:
        right.loglog(ds.level_ndof.values, ds.level_space_error_estimate.values, "o-")
        right.axhline(tol, color="gray", ls=":", lw=1)
        right.set(xlabel="displacement dofs", ylabel="largest estimate over the run [1]", title="meshes of the loop")
    fig.suptitle(f"{plain(ds.attrs.get('scene'))}: {ds.attrs.get('space_stop', '')} at {ds.attrs.get('ndof')} dofs",
                 fontsize=9)
    return _save(fig, path)
