"""The figures of the paper's Section 7 (Chau–Fernández–Shillor–Sofonea 2003, Figs. 2–19) from Datasets.

Every function takes a result Dataset (and, for the rod problems, an independent
reference) and returns a matplotlib Figure; given ``path`` it also writes a PNG
(150 dpi) and closes the figure. Nothing here runs a simulation.

=====================================  ===========================  ==================
function                               shows                        paper figures
=====================================  ===========================  ==================
:func:`rod_displacement_field`         u(x) at the snapshot times   2, 5, 8
:func:`rod_displacement_evolution`     u(x, t) at the rod probes    3, 6, 9
:func:`rod_bonding`                    beta(1, t)                   4, 7, 10
:func:`slab_deformed_mesh`             deformed mesh at T           12, 16
:func:`slab_von_mises`                 von Mises norm at T          13, 17
:func:`slab_contact_displacement`      u_y on Gamma_3, u_y(t)       14, 18
:func:`slab_bonding`                   beta on Gamma_3, beta(1, t)  15, 19
:func:`paper_figures`                  all of one problem           —
=====================================  ===========================  ==================

A reference ``ref`` is any callable ``ref(t, x=...) -> (u, beta)`` such as
:func:`workbench.references.tp1_exact` or :func:`workbench.references.rod_ode`;
with it the rod figures get a second panel with the pointwise error.

Examples
--------
>>> import workbench
>>> from workbench.references import tp1_exact
>>> ds = workbench.run("tp1", h=0.1, k=0.05, progress=False)
>>> fig = rod_bonding(ds, tp1_exact())
>>> len(fig.axes)
2
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.tri import Triangulation

from ..plotting import FIELD_CMAP, _save, figure, plain

#: Paper figure numbers of each problem's figure kinds (used in titles and by :func:`paper_figures`).
FIGURE_NUMBERS = {
    "tp1": {"displacement": 2, "evolution": 3, "bonding": 4},
    "tp2": {"displacement": 5, "evolution": 6, "bonding": 7},
    "tp3": {"displacement": 8, "evolution": 9, "bonding": 10},
    "tp4": {"deformed_mesh": 12, "von_mises": 13, "contact_displacement": 14, "bonding": 15},
    "tp5": {"deformed_mesh": 16, "von_mises": 17, "contact_displacement": 18, "bonding": 19},
}
ROD_KINDS = ("displacement", "evolution", "bonding")
SLAB_KINDS = ("deformed_mesh", "von_mises", "contact_displacement", "bonding")


#: What a reader of a figure must know about the paper's own version of it (docs/choices.md).
PAPER_REMARKS = {
    "tp2": "the paper's curves (u(1, 1) ~ -0.107) disagree with the reduced ODE (-0.0939) shown here; "
           "they match a flipped sign of the adhesive traction",
}


def _title(ds, kind, text):
    """Figure title: what, scene, discretisation, the paper figure it corresponds to, and any remark on it."""
    scene = plain(ds.attrs.get("scene", "?"))
    base = ds.attrs.get("base_scene", scene)
    fig_no = FIGURE_NUMBERS.get(base, {}).get(kind)
    paper = f" (cf. paper Fig. {fig_no})" if fig_no else ""
    h, k = ds.attrs.get("h_max", float("nan")), ds.attrs.get("k_actual", float("nan"))
    status = "" if ds.attrs.get("status", "complete") == "complete" else "  [INCOMPLETE RUN]"
    remark = f"\nnote: {PAPER_REMARKS[base]}" if fig_no and base in PAPER_REMARKS else ""
    return f"{scene}: {text}{paper}\nh = {h:.3g}, k = {k:.3g}{status}{remark}"


def _nearest(values, wanted):
    """Index of the entry of ``values`` nearest to ``wanted``."""
    return int(np.argmin(np.abs(np.asarray(values) - wanted)))


def _check_dim(ds, dim, what):
    if ds.sizes["component"] != dim:
        raise ValueError(f"{what} needs a {dim}D result, got {ds.sizes['component']} components")


def _error_axis(ax, errors_max, ylabel):
    ax.set(ylabel=ylabel)
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    ax.set_title(f"max = {errors_max:.3g}", fontsize=9)


# ---------------------------------------------------------------------------- rod (tp1–tp3)

def rod_displacement_field(ds, ref=None, path=None, ref_label="reference"):
    """Displacement u(x) of a rod at the snapshot times, and its pointwise error against ``ref``.

    Parameters
    ----------
    ds : xarray.Dataset
        A rod result with snapshots (``u_nodes``, ``vertex_x``, ``snapshot_time``).
    ref : callable, optional
        ``ref(t, x=array) -> (u, beta)``; adds the panel |u_h(x, t) - u(x, t)|.
    path : str or Path, optional
        Write a PNG there (and close the figure).
    ref_label : str
        How the reference is named in the error panel.

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_dim(ds, 1, "rod_displacement_field")
    x = ds.vertex_x.values
    order = np.argsort(x)
    ncols = 1 if ref is None else 2
    fig, axes = figure(1, ncols, figsize=(5.2 * ncols, 3.8), squeeze=False)
    emax = 0.0
    for i, t in enumerate(ds.snapshot_time.values):
        u = ds.u_nodes.isel(snapshot=i, component=0).values
        axes[0, 0].plot(x[order], u[order], label=f"t = {t:g}")
        if ref is not None:
            err = np.abs(u - np.asarray(ref(float(t), x=x)[0]))
            emax = max(emax, float(err.max()))
            axes[0, 1].plot(x[order], err[order], label=f"t = {t:g}")
    axes[0, 0].set(xlabel="x [m]", ylabel="u_h(x, t) [m]")
    axes[0, 0].legend(fontsize=7)
    if ref is not None:
        ax = axes[0, 1]
        ax.set(xlabel="x [m]")
        _error_axis(ax, emax, f"|u(x,t) - u_h(x,t)| [m]  vs {ref_label}")
        ax.legend(fontsize=7)
    fig.suptitle(_title(ds, "displacement", "displacement field"), fontsize=9)
    return _save(fig, path)


def rod_displacement_evolution(ds, ref=None, path=None, ref_label="reference"):
    """u(x, t) at the rod's probe points (x = 0.25, 0.5, 1 in the presets) and the error against ``ref``.

    Parameters
    ----------
    ds : xarray.Dataset
        A rod result (``u_probe``, ``probe_x``).
    ref : callable, optional
        ``ref(t_array, x=x_array) -> (u[time, point], beta[time])``.
    path : str or Path, optional
    ref_label : str

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_dim(ds, 1, "rod_displacement_evolution")
    t = ds.time.values
    xs = ds.probe_x.values
    uh = ds.u_probe.isel(component=0).values  # (time, probe)
    ncols = 1 if ref is None else 2
    fig, axes = figure(1, ncols, figsize=(5.2 * ncols, 3.8), squeeze=False)
    for p, x in enumerate(xs):
        axes[0, 0].plot(t, uh[:, p], label=f"x = {x:g}")
    axes[0, 0].set(xlabel="t [s]", ylabel="u_h(x, t) [m]")
    axes[0, 0].legend(fontsize=7)
    if ref is not None:
        u_ref = np.asarray(ref(t, x=xs)[0]).reshape(len(t), len(xs))
        err = np.abs(uh - u_ref)
        for p, x in enumerate(xs):
            axes[0, 1].plot(t, err[:, p], label=f"x = {x:g}")
        axes[0, 1].set(xlabel="t [s]")
        _error_axis(axes[0, 1], float(err.max()), f"|u(x,t) - u_h(x,t)| [m]  vs {ref_label}")
        axes[0, 1].legend(fontsize=7)
    fig.suptitle(_title(ds, "evolution", "evolution of the displacement"), fontsize=9)
    return _save(fig, path)


def compression_intervals(ds):
    """Time intervals [t0, t1] where the rod end is in compression (u_nu = u(1, t) > 0).

    Returns
    -------
    list of (float, float)
        Maximal runs of recorded times with ``u_contact > 0``, extended by half a
        record interval on each side (so that single-step runs stay visible).
    """
    t = ds.time.values
    u_end = ds.u_contact.isel(node=-1, component=0).values
    comp = u_end > 0
    out = []
    i = 0
    half = 0.5 * (t[1] - t[0]) if len(t) > 1 else 0.0
    while i < len(t):
        if comp[i]:
            j = i
            while j + 1 < len(t) and comp[j + 1]:
                j += 1
            out.append((max(t[0], t[i] - half), min(t[-1], t[j] + half)))
            i = j + 1
        else:
            i += 1
    return out


def rod_bonding(ds, ref=None, path=None, ref_label="reference", shade_compression=None):
    """beta(1, t) at the rod end, its error against ``ref``, and the compression intervals shaded.

    Parameters
    ----------
    ds : xarray.Dataset
        A rod result with ``beta``.
    ref : callable, optional
        ``ref(t_array) -> (u, beta[time])``; adds the panel |beta - beta_h|.
    path : str or Path, optional
    ref_label : str
    shade_compression : bool, optional
        Shade the times where the end is in compression (u(1, t) > 0), where the
        tension-only bonding law keeps beta flat. Default: when there are any.

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_dim(ds, 1, "rod_bonding")
    if "beta" not in ds:
        raise ValueError("rod_bonding: the result has no bonding field (adhesion not modelled)")
    t = ds.time.values
    b = ds.beta.isel(facet=-1).values
    ncols = 1 if ref is None else 2
    fig, axes = figure(1, ncols, figsize=(5.2 * ncols, 3.8), squeeze=False)
    ax = axes[0, 0]
    ax.plot(t, b, color="tab:blue", label="beta_h(1, t)")
    intervals = compression_intervals(ds)
    if shade_compression is None:
        shade_compression = bool(intervals)
    if shade_compression:
        for i, (t0, t1) in enumerate(intervals):
            ax.axvspan(t0, t1, color="tab:orange", alpha=0.2, lw=0,
                       label="compression u(1,t) > 0" if i == 0 else None)
    ax.set(xlabel="t [s]", ylabel="beta_h(1, t)")
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.legend(fontsize=7)
    if ref is not None:
        b_ref = np.asarray(ref(t, x=1.0)[1])
        err = np.abs(b - b_ref)
        axes[0, 1].plot(t, err)
        axes[0, 1].set(xlabel="t [s]")
        _error_axis(axes[0, 1], float(err.max()), f"|beta(1,t) - beta_h(1,t)|  vs {ref_label}")
    fig.suptitle(_title(ds, "bonding", "evolution of the bonding field at x = 1"), fontsize=9)
    return _save(fig, path)


# ---------------------------------------------------------------------------- slab (tp4, tp5)

def nice_scale(value):
    """The largest of 1, 2, 5 x 10^n not above ``value`` (a readable magnification factor).

    >>> nice_scale(0.068), nice_scale(3.0), nice_scale(1.0)
    (0.05, 2.0, 1.0)
    """
    if not np.isfinite(value) or value <= 0:
        return 1.0
    e = math.floor(math.log10(value))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**e <= value * (1 + 1e-12):
            return float(m * 10.0**e)
    return float(10.0**e)  # pragma: no cover


def magnification(ds, snapshot=-1, fraction=0.25):
    """Magnification so that the largest displacement at ``snapshot`` shows as ``fraction`` of the body size.

    Returns a :func:`nice_scale` number; 1 when the displacement is zero.
    """
    u = ds.u_nodes.isel(snapshot=snapshot).values
    umax = float(np.max(np.linalg.norm(u, axis=1)))
    size = max(float(np.ptp(ds.vertex_x.values)), float(np.ptp(ds.vertex_y.values)))
    return nice_scale(fraction * size / umax) if umax > 0 else 1.0


def _note(ax, text):
    """A note under the axes (outside the data, which fills the body's whole box)."""
    ax.annotate(text, xy=(0.0, 0.0), xycoords="axes fraction", xytext=(0, -30), textcoords="offset points",
                va="top", ha="left", fontsize=8, annotation_clip=False)


def _deformed(ds, snapshot, scale):
    x, y = ds.vertex_x.values, ds.vertex_y.values
    u = ds.u_nodes.isel(snapshot=snapshot).values
    return x, y, x + scale * u[:, 0], y + scale * u[:, 1], ds.cell_vertices.values[:, :3]


def slab_deformed_mesh(ds, path=None, snapshot=-1, scale=None):
    """The mesh in the reference (grey) and deformed (blue) configuration at a snapshot (default: T).

    Parameters
    ----------
    ds : xarray.Dataset
        A 2D result with snapshots.
    path : str or Path, optional
    snapshot : int
        Snapshot index (default the last, t = T).
    scale : float, optional
        Displacement magnification; default :func:`magnification`. Written on the figure.

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_dim(ds, 2, "slab_deformed_mesh")
    scale = magnification(ds, snapshot) if scale is None else float(scale)
    x, y, xd, yd, tris = _deformed(ds, snapshot, scale)
    t = float(ds.snapshot_time[snapshot])
    fig, ax = figure(figsize=(8, 3.2))
    ax.triplot(Triangulation(x, y, tris), color="0.75", lw=0.3)
    ax.triplot(Triangulation(xd, yd, tris), color="tab:blue", lw=0.4)
    ax.set_aspect("equal")
    ax.set(xlabel="x [m]", ylabel="y [m]")
    _note(ax, f"displacement magnified x {scale:g}; grey: reference configuration")
    fig.suptitle(_title(ds, "deformed_mesh", f"deformed mesh at t = {t:g} s (x {scale:g})"), fontsize=9)
    return _save(fig, path)


def slab_von_mises(ds, path=None, snapshot=-1, scale=None, cmap=FIELD_CMAP):
    """The von Mises norm of the P0 stress on the deformed configuration (``tripcolor``, one value per cell).

    Parameters
    ----------
    ds : xarray.Dataset
        A 2D result with snapshots.
    path : str or Path, optional
    snapshot : int
        Snapshot index (default the last, t = T).
    scale : float, optional
        Displacement magnification of the configuration; default :func:`magnification`.
    cmap : str
        Colour map (default perceptually uniform; the paper's figures use a rainbow map).

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_dim(ds, 2, "slab_von_mises")
    scale = magnification(ds, snapshot) if scale is None else float(scale)
    _, _, xd, yd, tris = _deformed(ds, snapshot, scale)
    vm = ds.von_mises.isel(snapshot=snapshot).values
    t = float(ds.snapshot_time[snapshot])
    fig, ax = figure(figsize=(8, 3.2))
    pc = ax.tripcolor(Triangulation(xd, yd, tris), facecolors=vm, cmap=cmap, shading="flat")
    fig.colorbar(pc, ax=ax, label="|sigma|_vM [Pa]", shrink=0.8)
    ax.set_aspect("equal")
    ax.set(xlabel="x [m]", ylabel="y [m]")
    i = int(np.argmax(vm))
    cx, cy = xd[tris[i]].mean(), yd[tris[i]].mean()
    ax.plot(cx, cy, "w*", ms=10, mec="k")
    _note(ax, f"displacement magnified x {scale:g}; max {vm[i]:.4g} Pa at the star")
    fig.suptitle(_title(ds, "von_mises", f"von Mises norm of sigma at t = {t:g} s, deformed configuration"),
                 fontsize=9)
    return _save(fig, path)


def slab_contact_displacement(ds, path=None, times=(0.1, 0.4, 0.7, 1.0), points=(0.25, 0.5, 0.75, 1.0)):
    """u_y on the contact side Gamma_3 at ``times`` (left) and u_y(t) at the contact points x = ``points`` (right).

    The values are the recorded vertex displacements ``u_contact`` at the recorded
    times nearest to ``times`` and at the contact vertices nearest to ``points``
    (labels give the values actually used).

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_dim(ds, 2, "slab_contact_displacement")
    tt = ds.time.values
    nx = ds.node_x.values
    order = np.argsort(nx)
    uy = ds.u_contact.sel(component="y").values  # (time, node)
    fig, axes = figure(1, 2, figsize=(10.4, 3.8))
    for t in times:
        i = _nearest(tt, t)
        axes[0].plot(nx[order], uy[i, order], label=f"t = {tt[i]:.3g}")
    axes[0].set(xlabel="x [m]", ylabel="u_y(x, 0, t) [m]", title="on the contact side")
    axes[0].legend(fontsize=7)
    for x in points:
        j = _nearest(nx, x)
        axes[1].plot(tt, uy[:, j], label=f"x = ({nx[j]:.3g}, 0)")
    axes[1].set(xlabel="t [s]", ylabel="u_y(x, 0, t) [m]", title="at contact points")
    axes[1].legend(fontsize=7)
    fig.suptitle(_title(ds, "contact_displacement", "vertical displacement of the contact side"), fontsize=9)
    return _save(fig, path)


def slab_bonding(ds, path=None, times=(0.4, 0.6, 0.8, 1.0)):
    """beta on Gamma_3 at ``times`` (left; P0: one value per facet) and beta(t) at (1, 0) (right).

    The point (1, 0) is represented by the contact facet with the largest ``facet_x``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_dim(ds, 2, "slab_bonding")
    if "beta" not in ds:
        raise ValueError("slab_bonding: the result has no bonding field (adhesion not modelled)")
    tt = ds.time.values
    fx = ds.facet_x.values
    order = np.argsort(fx)
    b = ds.beta.values  # (time, facet)
    fig, axes = figure(1, 2, figsize=(10.4, 3.8))
    for t in times:
        i = _nearest(tt, t)
        axes[0].plot(fx[order], b[i, order], drawstyle="steps-mid", label=f"t = {tt[i]:.3g}")
    axes[0].set(xlabel="x [m]", ylabel="beta_h(x, t)", title="on the contact side")
    axes[0].legend(fontsize=7)
    far = int(np.argmax(fx))
    axes[1].plot(tt, b[:, far])
    axes[1].set(xlabel="t [s]", ylabel="beta_h(1, 0, t)",
                title=f"facet at x = {fx[far]:.4g} (nearest (1, 0)); beta(T) = {b[-1, far]:.5f}")
    for ax in axes:
        ax.ticklabel_format(axis="y", useOffset=False)
    fig.suptitle(_title(ds, "bonding", "bonding field"), fontsize=9)
    return _save(fig, path)


# ---------------------------------------------------------------------------- all of one problem

def figure_paths(ds, folder, prefix=None):
    """The PNG paths :func:`paper_figures` writes for ``ds``: ``{folder}/{prefix}_{kind}.png`` by kind."""
    prefix = prefix or ds.attrs.get("scene", "result")
    kinds = ROD_KINDS if ds.sizes["component"] == 1 else SLAB_KINDS
    if "beta" not in ds:
        kinds = tuple(k for k in kinds if k != "bonding")
    return {kind: Path(folder) / f"{prefix}_{kind}.png" for kind in kinds}


def paper_figures(ds, folder, ref=None, prefix=None, ref_label="reference", scale=None):
    """Write every figure of the paper's kind for one result (rod: 3 figures; slab: 4).

    Parameters
    ----------
    ds : xarray.Dataset
        A rod (tp1–tp3-like) or slab (tp4/tp5-like) result.
    folder : str or Path
    ref : callable, optional
        Rod reference for the error panels (ignored for slabs).
    prefix : str, optional
        File name prefix (default: the scene name).
    ref_label : str
    scale : float, optional
        Slab magnification (default: :func:`magnification`).

    Returns
    -------
    list of Path
        The files written.
    """
    paths = figure_paths(ds, folder, prefix)
    if ds.sizes["component"] == 1:
        makers = {"displacement": lambda p: rod_displacement_field(ds, ref, p, ref_label),
                  "evolution": lambda p: rod_displacement_evolution(ds, ref, p, ref_label),
                  "bonding": lambda p: rod_bonding(ds, ref, p, ref_label)}
    elif ds.sizes["component"] == 2:
        makers = {"deformed_mesh": lambda p: slab_deformed_mesh(ds, p, scale=scale),
                  "von_mises": lambda p: slab_von_mises(ds, p, scale=scale),
                  "contact_displacement": lambda p: slab_contact_displacement(ds, p),
                  "bonding": lambda p: slab_bonding(ds, p)}
    else:
        raise ValueError("paper_figures: only 1D rod and 2D slab results have paper figures")
    for kind, path in paths.items():
        makers[kind](path)
    return list(paths.values())


__all__ = ["rod_displacement_field", "rod_displacement_evolution", "rod_bonding", "compression_intervals",
           "slab_deformed_mesh", "slab_von_mises", "slab_contact_displacement", "slab_bonding",
           "magnification", "nice_scale", "paper_figures", "figure_paths", "FIGURE_NUMBERS"]
