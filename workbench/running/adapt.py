"""Adaptive refinement in space (``space_tol > 0``): run, estimate, mark, refine, run again.

A quasistatic contact problem with history (memory, bonding, a growing contact zone) is refined here by repeating
the whole run on each mesh, not by changing the mesh during a run: the estimator
(:mod:`workbench.discrete.estimator`) is evaluated at recorded times at least T/50 apart (and at the snapshots and
T: ``runner.ESTIMATE_SPACING``), each element keeps the largest
indicator it had over the run, and the elements that carry the share ``DORFLER`` of the sum of those are bisected
(Dörfler marking; netgen keeps the curved sides on their geometry), or with ``space_adapt = "remesh"`` the body is
meshed anew from its geometry with the sizes that equidistribute them (:func:`remesh_sizes`: finer and coarser, not
nested; the Hertz bodies). So the final mesh is fine wherever the solution needed it at any time (the edge of a
contact zone at all its radii), and the run on it is an ordinary run, with no transfer of state between meshes. With
``space_goal = "pressure"`` the marked quantity is each element's largest eta_K(u) eta_K(z) over the snapshots and T,
z the dual problem of the contact pressure (:class:`workbench.discrete.estimator.PressureGoal`); the tolerance is
still the energy estimate's. It stops when the largest relative estimate over the run is at most ``space_tol``, or
when refining again would exceed ``max_dofs`` dofs, or after ``MAX_LEVELS`` meshes.

The Dataset is the run on the final mesh, with ``space_error_estimate(time)``, ``ndof(time)``, the meshes' history
(``level_ndof(level)``, ``level_space_error_estimate(level)``, ``level_wall_time(level)``) and the attributes
``space_error_estimate`` (the final run's largest), ``space_levels``, ``space_stop`` (why it stopped) and
``adaptive_wall_time`` (all levels; ``setup_time`` counts the meshes before the final one, so that setup and time
loop together are the whole cost); its snapshots carry the final mesh (UGRID) and ``space_indicator(cell)`` says
where the final mesh's error is. ``max_dofs`` at or below the given mesh's dofs estimates without refining.
"""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import xarray as xr

from ..discrete.estimator import longest_edges
from ..discrete.world import finished, signals_held
from ..errors import Diverged
from ..input.geometry import on_mesh
from ..input.meshes import to_text

#: The share of the summed squared indicators the marked elements carry.
DORFLER = 0.5
#: The most meshes an adaptive run tries.
MAX_LEVELS = 15
#: space_adapt = "remesh": the next mesh's elements over this one's, and how fast netgen lets sizes grow between
#: the sizes asked for (its ``grading``; in a prototype 0.15 gave the 2D Hertz pressure 0.47 % lumped at 1828 dofs,
#: netgen's default 0.3 gave 0.65 % at 1540).
REMESH_GROWTH, REMESH_GRADING = 2.0, 0.15
#: edge_tol: the size asked at the contact zone's edge, as a share of what the tolerance allows, and how fast sizes
#: may grow away from it (h <= size + EDGE_GRADING * distance). Both were compared on Lee and Radok's Hertz
#: (docs/adaptivity.md): a share below 1 (room for the edge to move before it fails again) cost more dofs for no
#: better radius, and a mesh refined only at the edge, not graded, put the radius 2.7 % short.
EDGE_MARGIN, EDGE_GRADING = 1.0, 0.5


def mark(indicators: np.ndarray, share: float = DORFLER) -> np.ndarray:
    """The smallest set of elements whose indicators (eta_K^2) add up to ``share`` of their sum (Dörfler).

    >>> mark(np.array([1.0, 5.0, 0.5, 3.0]), 0.5).tolist()
    [False, True, False, False]
    >>> mark(np.array([1.0, 5.0, 0.5, 3.0]), 0.7).tolist()
    [False, True, False, True]
    """
    order = np.argsort(indicators)[::-1]
    reached = np.cumsum(indicators[order]) >= share * indicators.sum() * (1 - 1e-12)
    out = np.zeros(len(indicators), dtype=bool)
    out[order[:int(np.argmax(reached)) + 1]] = True
    return out


def refine(mesh, marked: np.ndarray):
    """The netgen mesh of ``mesh`` (an NGSolve mesh) with the ``marked`` elements bisected (a copy: ``mesh`` is kept)."""
    import ngsolve as ngs

    fine = ngs.Mesh(mesh.ngmesh.Copy())
    fine.SetRefinementFlags([bool(m) for m in marked])  # (element order)
    fine.Refine()
    return fine.ngmesh


def refined(body, ds: xr.Dataset):
    """The body on its mesh (``body.mesh()``, on which ``ds`` was run) refined where the run's indicators
    (``space_indicator``) ask, by Dörfler marking: the next mesh of the adaptive loop.

    Examples
    --------
    >>> import warnings, workbench
    >>> sc = workbench.scene("memory_hertz", h=0.2, h_contact=0.02, T=0.5, k=0.5)
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")  # (max_dofs below the mesh's: estimate only, which warns)
    ...     ds = workbench.run(sc, space_tol=0.01, max_dofs=100, progress=False)
    >>> body = sc.model_of().geometry
    >>> finer = refined(body, ds)
    >>> body.mesh().ne < finer.mesh().ne
    True
    """
    return on_mesh(body, refine(body.mesh(), mark(ds.space_indicator.values ** 2)))


def remesh_sizes(mesh, indicators: np.ndarray, order: int, growth: float = REMESH_GROWTH):
    """(element centroids, the element sizes asked of the next mesh) for ``space_adapt = "remesh"``: equidistribution.

    An indicator of a smooth solution falls like h^(2p + d) on its element (p the order, d the dimension: the squared
    energy error, and the goal's product eta_K(u) eta_K(z) alike). So the size that gives every element the same
    indicator m* is h_K (m* / m_K)^(1 / (2p + d)), and m* is chosen so that the new mesh has ``growth`` times the
    elements, sum_K (h_K / h_new)^d. Each size stays within 1/4 and 4 times the element's (its longest edge): the
    mesh is coarsened where the indicator is small, not only refined.

    >>> from ngsolve.meshes import MakeStructured2DMesh
    >>> m = MakeStructured2DMesh(quads=False, nx=4, ny=4)
    >>> where, size = remesh_sizes(m, np.r_[np.full(16, 1e-6), np.full(16, 1.0)], order=1)
    >>> where.shape, bool(size[:16].max() > size[16:].max())
    ((32, 2), True)
    """
    centroids, h = element_sizes(mesh)
    d = mesh.dim
    rate = 2 * order + d
    m = np.maximum(np.asarray(indicators, dtype=float), 1e-300 * max(float(np.max(indicators)), 1e-300))
    target = growth * len(h)
    m_star = (np.sum(m ** (d / rate)) / target) ** (rate / d)
    size = np.clip(h * (m_star / m) ** (1.0 / rate), h / 4, 4 * h)
    # (sizes in steps of 2^(1/8), 9 %: indicators that differ at round-off then ask for the same mesh; unrounded,
    # three runs of the hemisphere made 6651, 6534 and 6651 dofs at the third mesh, netgen's answer to sizes that
    # differed in the last digits)
    return centroids, 2.0 ** (np.round(8 * np.log2(size)) / 8)


def element_sizes(mesh):
    """(the centroids, the longest edges) of an NGSolve mesh's elements."""
    ngmesh = mesh.ngmesh  # (keep the wrapper alive: Coordinates() is a view into it)
    xyz = np.array(ngmesh.Coordinates()).reshape(mesh.nv, -1)[:, :mesh.dim]
    cells = np.array([[v.nr for v in el.vertices] for el in mesh.Elements()], dtype=np.int64)
    corners = xyz[cells]
    return corners.mean(axis=1), longest_edges(corners)


def refine_toward(mesh, points: np.ndarray, size: float, max_dofs: int, grading: float | None = None):
    """The netgen mesh of ``mesh`` bisected until each element is at most ``size`` plus ``grading`` times its
    distance to the nearest of ``points``, and at most ``size`` where one of them lies in it: a mesh graded toward
    the points (the edge of a contact zone, ``edge_tol``; ``grading`` None: ``EDGE_GRADING``). Stops early once the
    mesh has ``max_dofs`` P1 dofs.

    >>> from ngsolve.meshes import MakeStructured2DMesh
    >>> m = MakeStructured2DMesh(quads=False, nx=8, ny=8)
    >>> import ngsolve
    >>> fine = ngsolve.Mesh(refine_toward(m, np.array([[0.5, 0.0]]), 0.02, max_dofs=10**6))
    >>> where, h = element_sizes(fine)
    >>> near = np.hypot(where[:, 0] - 0.5, where[:, 1]) < 0.03
    >>> bool(h[near].max() <= 0.02), bool(h[~near].max() > 0.1), fine.ne < 2 * 64 * 4
    (True, True, True)
    """
    import ngsolve as ngs
    from scipy.spatial import cKDTree

    tree, current = cKDTree(points), mesh
    grading = EDGE_GRADING if grading is None else grading
    while current.dim * current.nv < max_dofs:
        centroids, h = element_sizes(current)
        distance = tree.query(centroids)[0]
        marked = (h > size + grading * distance) | ((distance <= h) & (h > size))
        if not marked.any():
            break
        current = ngs.Mesh(refine(current, marked))
    return current.ngmesh


def displacement_dofs(ngmesh, geometry, order: int) -> int:
    """The dofs of the displacement space on a mesh (before any work on it)."""
    import ngsolve as ngs

    from ..discrete.discretisation import vector_space

    return vector_space(geometry, ngs.Mesh(ngmesh), order).ndof


def run(make_job, model, numerics, execute_args: tuple):
    """The adaptive loop (module docs): ``make_job(model)`` builds a run of the model (a runner ``_Run`` that
    estimates), ``execute_args`` are its ``execute``'s arguments. Returns the final run's Dataset."""
    levels, ds, done, stop, job = [], None, None, None, None  # (done: the last mesh's run, complete to T, its body)
    try:  # (a stop signal anywhere in the loop keeps the last complete level; one where it said it was over, the run)
        while True:
            job = make_job(model)
            ds = job.execute(*execute_args)
            with signals_held():  # (a stop signal here comes once the level is counted, which it then keeps)
                scale = job.largest_norm if job.largest_norm > 0 else 1.0  # (the estimates relative to the largest
                ds["space_error_estimate"] = ds.space_error_estimate / scale  # norm)
                ds["space_indicator"] = ("cell", np.sqrt(job.indicators) / scale, {
                    "units": "1", "long_name": "the element's largest error indicator over the run (both parts), "
                    "relative to the largest energy norm of u: what marking used"})
                levels.append((job.disc.ndof, job.space_estimate / scale,
                               ds.attrs["setup_time"] + ds.attrs["wall_time"]))
                done = (ds, model.geometry)
                stop = _stop(levels, numerics)
            if stop:
                break
            geometry = _next(model.geometry, job.marked, numerics)
            if displacement_dofs(geometry.adapted_mesh, geometry, numerics.order) > numerics.max_dofs:
                stop = "max_dofs"
                break
            model = dataclasses.replace(model, geometry=geometry)
        if stop != "met":
            warnings.warn(f"space_tol = {numerics.space_tol:g} not met: the estimate is {levels[-1][1]:.3g} at "
                          f"{levels[-1][0]} dofs ({'max_dofs' if stop == 'max_dofs' else f'{MAX_LEVELS} meshes'} "
                          "reached)", RuntimeWarning, stacklevel=4)
    except KeyboardInterrupt as err:
        if job is not None and isinstance(job.failed, Diverged):  # (a diverged level, unwinding: its own failure)
            raise job.failed from None
        if done is None:
            raise
        if not stop:  # (a signal after the loop had ended comes after the run: dropped, as at a run's end)
            raise _kept(err, done, levels) from None
    with signals_held(drop=True):  # (the loop is over: a stop signal while the levels are added is dropped, and the
        out = _with_levels(ds, levels, stop, model.geometry)  # result kept for the command line, world.finished)
        finished(out)
        return out


def _kept(err, done, levels) -> Exception:
    """A stop signal while the loop went on to a finer mesh: Interrupted with the last mesh's run, complete to T, and
    the levels before (a signal there lost every complete level, or kept the partial steps of the last alone: found
    by an outside pass)."""
    from ..discrete.world import stopped_by
    from ..errors import Interrupted

    ds, body = done
    signal = err.signal if isinstance(err, Interrupted) else 2
    return Interrupted(f"{ds.attrs['scene']}: {stopped_by(signal)} while the adaptive loop went on to mesh "
                       f"{len(levels)}; the run on mesh {len(levels) - 1} ({levels[-1][0]} dofs), complete to T, is "
                       "kept", dataset=_with_levels(ds, levels, "interrupted", body), signal=signal)


def _next(body, marked: np.ndarray, numerics):
    """The next mesh's body: ``body``'s mesh bisected where ``marked`` asks (Dörfler), or with ``space_adapt =
    "remesh"`` a new mesh of its geometry sized by :func:`remesh_sizes`."""
    mesh = body.mesh()
    if numerics.space_adapt == "remesh":
        return body.remeshed(*remesh_sizes(mesh, marked, numerics.order), REMESH_GRADING)
    return on_mesh(body, refine(mesh, mark(marked)))


def _stop(levels: list, numerics) -> str:
    ndof, estimate, _ = levels[-1]
    if estimate <= numerics.space_tol:
        return "met"
    if ndof >= numerics.max_dofs:
        return "max_dofs"
    if len(levels) >= MAX_LEVELS:
        return "levels"
    return ""


def _with_levels(ds: xr.Dataset, levels: list, stop: str, body) -> xr.Dataset:
    ndof, estimate, wall = (np.array(column) for column in zip(*levels))
    level = np.arange(len(levels))
    ds = ds.assign_coords(level=("level", level, {"units": "1", "long_name": "mesh of the adaptive loop (0: given)"}))
    ds["level_ndof"] = ("level", ndof.astype(np.int64), {"units": "1", "long_name": "dofs of each mesh"})
    ds["level_space_error_estimate"] = ("level", estimate, {"units": "1", "long_name": "relative energy error "
                                                            "estimate of the run on each mesh"})
    ds["level_wall_time"] = ("level", wall, {"units": "s", "long_name": "wall time of the run on each mesh"})
    ds["ndof"] = ("time", np.full(ds.sizes["time"], ndof[-1], dtype=np.int64),
                  {"units": "1", "long_name": "dofs of the mesh the record was made on"})
    if len(levels) > 1:  # (the final mesh, to compare the run with others on theirs: geometry.of_run)
        ds["adapted_mesh"] = ((), to_text(body.adapted_mesh), {"long_name": "the adapted mesh (netgen .vol text)"})
    # (the meshes before the final one count as its setup: a study's cost, setup + time loop, is the whole loop's)
    ds.attrs.update(space_error_estimate=float(estimate[-1]), space_levels=len(levels), space_stop=stop,
                    adaptive_wall_time=float(wall.sum()), setup_time=ds.attrs["setup_time"] + float(wall[:-1].sum()))
    return ds
