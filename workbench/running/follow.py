"""The mesh follows the solution during the run (``space_tol > 0``, ``space_adapt = "during"``).

Where :mod:`workbench.running.adapt` repeats the whole run on each finer mesh, here one run goes from 0 to T and
refines its mesh on the way. A first pass over the whole run on the given mesh sets the scale (its largest energy
norm), so that ``space_tol`` means what it means for the repeated loop. Then at every estimate time (recorded times
at least ``runner.ESTIMATE_SPACING`` T apart, the snapshots and T) whose estimate exceeds ``space_tol`` times that
scale (or the largest norm so far, if larger), the run goes back to the last estimate time that met the tolerance,
bisects the elements that carry half of the squared indicators of the failing time (Dörfler marking, as the
repeated loop) and goes on from there on the finer mesh with its whole state carried over (:func:`carry`): the
displacement, velocity and the accepted states a multistep formula or a predictor keeps, Model B's memory
histories and stored steps (dof vectors of the displacement's space), the bonding field on the contact facets, the
contact points' states and forces (a warm start only), the step controller and the record schedule. Checkpoints
(``checkpoint_every``) fall on the estimate times that met the tolerance, so a continuation goes on as the run did.
With ``edge_tol > 0`` an estimate time also fails where the facets across the contact zone's edge are longer than
``edge_tol`` times the zone's size (:class:`workbench.discrete.estimator.ContactEdge`); the finer mesh is then graded
toward that edge (:func:`workbench.running.adapt.refine_toward`).

**The transfer is exact.** netgen's bisection nests the meshes, so every coarse P1 or P2 field is a field of the
finer space, and the prolongation (``discrete/transfer.py``) reproduces it; a facet's bonding field passes to both
halves. On a curved side the new vertices lie on the geometry, slightly off the coarse faceted side: there the
carried field is extrapolated from the nearest coarse cell, which makes a transfer error of the size of the
geometry's own (measured in ``docs/adaptivity.md``). The step after a refinement then solves on the finer mesh from
a history computed on the coarser ones: the error the coarse mesh made before stays, as the estimate said it was.

**The archive** is on the final mesh: every record made on a coarser mesh is carried onto it (the fields at the
snapshots exactly, by the prolongation; the contact vertices by position, NaN where a vertex did not exist yet;
the bonding field facet by facet). ``ndof(time)`` says which mesh each record was made on, ``refinement_time`` and
``refinement_ndof`` list the refinements, the final mesh is in ``adapted_mesh`` and the snapshots (UGRID).

Examples
--------
>>> import workbench
>>> ds = workbench.run("memory_hertz", h_contact=0.01, space_tol=0.08, space_adapt="during", progress=False)
>>> int(ds.ndof[0]) < int(ds.ndof[-1]), ds.attrs["space_refinements"] == ds.sizes["refinement"] > 0
(True, True)
"""
from __future__ import annotations

import dataclasses
import json
import re
import warnings

import numpy as np
import xarray as xr

from ..discrete.world import finished, signals_held
from ..errors import Diverged, Interrupted
from ..input.geometry import adapted_mesh, on_mesh
from ..input.meshes import from_text, to_text
from ..output.results import ugrid_mesh
from . import adapt
from .restart import without_state


class Refine(Exception):
    """Raised at an estimate time whose estimate asks for a finer mesh: the state kept at the last estimate time that
    met the tolerance (``saved``: (t, :func:`workbench.running.restart.capture`), None at the start), the records of
    the run so far and the finer body."""

    def __init__(self, saved, dataset: xr.Dataset, geometry):
        super().__init__("refine" + (f" from t = {saved[0]:g} s" if saved else " from the start"))
        self.saved, self.geometry = saved, geometry
        self.dataset = dataset if saved is None else _until(dataset, saved[0])


def _until(ds: xr.Dataset, t: float) -> xr.Dataset:
    """The records of ``ds`` up to the time ``t`` (and its snapshots up to t)."""
    tol = 1e-9 * max(1.0, abs(t))
    ds = ds.isel(time=np.nonzero(ds.time.values <= t + tol)[0])
    if "snapshot" in ds.dims:
        ds = ds.isel(snapshot=np.nonzero(ds.snapshot_time.values <= t + tol)[0])
        if not ds.sizes["snapshot"]:
            ds = ds.drop_dims("snapshot")
    return ds


class Follow:
    """What a run that adapts during itself decides at its estimate times: refine now (``geometry``, the finer body)
    or not. ``norm`` is the largest energy norm so far, carried from mesh to mesh; the estimate is judged against
    the larger of it and ``scale``, the largest norm of the first pass over the whole run on the given mesh. While
    ``watching`` (that first pass) nothing is refined: the estimates and the states of every estimate time are kept
    (``seen``, ``kept``) until the scale is known."""

    def __init__(self, tol: float, max_dofs: int, order: int, atol: float, edge_tol: float = 0.0):
        self.tol, self.max_dofs, self.order, self.atol, self.edge_tol = tol, max_dofs, order, atol, edge_tol
        self.norm = self.scale = 0.0
        self.geometry = None
        self.saved = None  # (t, state) at the last estimate time that met the tolerance
        self.refinements = []  # (the time the run went back to, the finer mesh's dofs)
        self._dofs = 0
        self.full = False  # (max_dofs reached: the run goes on on its mesh)
        self.watching, self.seen, self.kept = False, [], []
        self.segments = []  # (the driver's: the meshes left so far, for the checkpoints)
        self.checkpoint_step = 0
        self.earlier_ndof = None  # (a continued run: the mesh of each record before it)
        self.earlier_indicators = None  # (and the largest indicators on its last mesh, squared, absolute)
        self.earlier_meshes = ([], {})  # (and of its snapshots: [(time, topology name)], the coarser meshes' variables)
        self._carried = {}  # (segments carried onto the last mesh: Follow.onto)

    def onto(self, disc, ds: xr.Dataset, final_disc, final: xr.Dataset):
        """:func:`_onto`, kept for the segment and the last mesh: a run's checkpoints merge the same segments again
        (measured: tp4's slab with a checkpoint at every step spent 2.7 of its 8.6 s carrying them)."""
        key = (id(ds), id(final_disc))
        if key not in self._carried:
            self._carried = {k: v for k, v in self._carried.items() if k[1] == id(final_disc)}
            self._carried[key] = (ds, final_disc, _onto(disc, ds, final_disc, final))
        return self._carried[key][2]

    def record(self) -> dict:
        """What a continuation needs besides the run's state (the archive's ``space_follow_json``)."""
        return {"scale": self.scale, "norm": self.norm, "full": self.full, "checkpoint_step": self.checkpoint_step}

    def resume(self, archive: xr.Dataset, state: dict) -> xr.Dataset:
        """Continue from ``archive`` (a checkpoint of a run that followed its solution, at the estimate time of
        ``state``): this object's record back, and the archive as its records go on (the estimates absolute again,
        the meshes of its records kept aside)."""
        for key, value in json.loads(archive.attrs["space_follow_json"]).items():
            setattr(self, key, value)
        if "refinement_time" in archive:
            self.refinements = list(zip(archive.refinement_time.values.tolist(),
                                        archive.refinement_ndof.values.tolist()))
        self.earlier_ndof = archive.ndof.values.copy()
        # (the indicators its last mesh met before: the run goes on on that mesh until it refines again)
        self.earlier_indicators = (archive.space_indicator.values * (self.norm if self.norm > 0 else 1.0)) ** 2
        if "snapshot_mesh" in archive:
            self.earlier_meshes = (list(zip(archive.snapshot_time.values, archive.snapshot_mesh.values.astype(str))),
                                   {n: v for n, v in archive.variables.items() if re.match(r"mesh_\d+", n)})
        self.saved = (state["time"], state)
        out = archive.drop_vars("ndof")
        out["space_error_estimate"] = archive.space_error_estimate * max(self.scale, self.norm, 1e-300)
        return out

    def failing(self, estimate, displacement: float) -> tuple[bool, bool]:
        """(whether the energy estimate exceeds its tolerance, whether the contact zone's edge is resolved more
        coarsely than ``edge_tol``). Neither while the largest ``displacement`` is below ``atol``: a body at rest holds
        round-off, whose relative error is anything."""
        if displacement <= self.atol:
            return False, False
        edge = estimate.edge is not None and 0 < self.edge_tol < estimate.edge.resolution
        return estimate.total > self.tol * max(self.norm, self.scale), edge

    def too_large(self, estimate, displacement: float) -> bool:
        """Whether ``estimate`` asks for a finer mesh (:meth:`failing`)."""
        return any(self.failing(estimate, displacement))

    def consider(self, estimate, body, mesh, displacement: float) -> None:
        """At an estimate time: refine where ``estimate`` is large if it exceeds the tolerance."""
        self.norm = max(self.norm, estimate.norm)
        if self.watching:  # (judged once the whole run's largest norm is known)
            self.seen.append((estimate, displacement, body, mesh))
            return
        if not self.full and self.too_large(estimate, displacement):
            self.refine(estimate, body, mesh, *self.failing(estimate, displacement))

    def refine(self, estimate, body, mesh, energy: bool = True, edge: bool = False) -> None:
        """The finer body (``geometry``): bisected by Dörfler marking of the estimate's ``marking`` if the
        ``energy`` failed, and graded toward the contact zone's edge if the ``edge`` did (:func:`adapt.refine_toward`,
        to ``EDGE_MARGIN`` of what edge_tol allows there), unless it would exceed max_dofs."""
        import ngsolve as ngs

        finer = adapt.refine(mesh, adapt.mark(estimate.marking)) if energy else mesh.ngmesh
        if edge:
            e = estimate.edge
            finer = adapt.refine_toward(ngs.Mesh(finer), e.points, adapt.EDGE_MARGIN * self.edge_tol * e.zone,
                                        self.max_dofs)
        # (through the archive's text of the mesh, whose coordinates differ by an ulp: a continuation then reads the
        # very mesh the run went on with, and is bitwise the run straight through)
        finer = on_mesh(body, from_text(to_text(finer)))
        self._dofs = adapt.displacement_dofs(finer.adapted_mesh, finer, self.order)
        if self._dofs > self.max_dofs:
            self.full = True
            return
        self.geometry = finer

    def refined(self, t: float) -> None:
        """The run goes back to ``t`` on the finer mesh."""
        self.refinements.append((t, self._dofs))
        self.geometry = self.saved = None


class Carried:
    """The continuation of a run on a finer mesh (what the runner's resume takes): the coarse run's state, carried
    onto the finer discretisation when it is built, and its records' schedule."""

    def __init__(self, refine: Refine, job):
        self.time, self.state = refine.saved
        self.coarse = (job.disc, job.scheme)
        # (the records so far stay in their segment: the finer run starts an empty record on its own mesh)
        ds = refine.dataset
        self.archive = ds.drop_dims([d for d in ("snapshot",) if d in ds.dims]).isel(time=slice(0, 0))

    def state_for(self, disc, scheme) -> dict:
        return carry(self.state, self.coarse, (disc, scheme))

    def settle(self, scheme) -> None:
        """The carried state solved again where the scheme needs it on the finer mesh (:meth:`Scheme.settle`)."""
        scheme.settle(self.time)

    def provenance(self, attrs: dict) -> dict:
        """The costs of all meshes so far (setup, time loop, CPU) summed; where the run was continued from, kept."""
        old, out = self.archive.attrs, dict(attrs)
        for key in ("setup_time", "wall_time", "cpu_time"):
            if key in old and key in out:
                out[key] = float(old[key]) + float(out[key])
        for key in ("history", "restarted_from", "restart_time", "restart_time_units"):
            if key in old:
                out[key] = old[key]
        return out


def carry(state: dict, coarse, fine) -> dict:
    """The run state ``state`` (:func:`~workbench.running.restart.capture`) of the discretisation and scheme
    ``coarse`` on the nested finer ones ``fine`` (module docs)."""
    from ..discrete.transfer import MeshInfo, Transfer

    (dc, scheme_c), (df, scheme_f) = coarse, fine
    order = dc.numerics.order
    move = Transfer(MeshInfo(dc.geometry, order), MeshInfo(df.geometry, order))
    ndof = dc.ndof

    def dofs(vector):
        nodes = vector.reshape(dc.dim, -1).T if move.P is not None else None
        return move.displacement(vector, nodes)

    def facets(values):
        return None if values is None else move.facets(values)

    s = state["scheme"]
    # (a Kelvin-Voigt body under error control: the step after a refinement is judged as a first step is, by
    # halving; a predictor from the coarse mesh's states charged it with the jump of the velocity onto the finer
    # mesh, an error no step shrinks, and the controller cut k to k_min. BDF2 then starts again, as at t = 0)
    history = s["history"][-1:] if dc.numerics.adaptive and dc.viscous is not None else s["history"]
    out = {**s, "u": dofs(s["u"]), "v": dofs(s["v"]), "beta": facets(s["beta"]),
           "history": [(t, dofs(u), facets(b)) for t, u, b in history], "extra": {}}
    out.pop("cache", None)  # (the finer scheme factors what it needs)
    points = _points(scheme_c, scheme_f) if "lam" in s["extra"] else None
    for key, value in s["extra"].items():
        if key in ("states", "lam"):  # the contact points' warm start: the nearest coarse point's
            nearest, ratio = points
            value = value[nearest] * (ratio if key == "lam" else 1)
        elif isinstance(value, np.ndarray) and value.ndim and value.shape[-1] == ndof:
            value = np.array([dofs(row) for row in value.reshape(-1, ndof)]).reshape(*value.shape[:-1], df.ndof)
        elif isinstance(value, list) and value and all(isinstance(v, np.ndarray) and v.size == ndof for v in value):
            value = [dofs(v) for v in value]
        out["extra"][key] = value
    return {**state, "scheme": out, "ndof": df.ndof_global}


def _points(coarse, fine):
    """(the nearest coarse contact point of each fine one, the ratio of their weights) for Model B's points."""
    from scipy.spatial import cKDTree

    a, b = coarse.nodes, fine.nodes
    nearest = cKDTree(a.positions()).query(fine.nodes.positions())[1]
    return nearest, b.w / a.w[nearest]


def run(make_job, model, numerics, execute_args: tuple):
    """One run from 0 to T whose mesh is refined where and when the estimate asks (module docs), or the
    continuation of one from its checkpoint. Returns the Dataset on the final mesh."""
    follow = Follow(numerics.space_tol, numerics.max_dofs, numerics.order, numerics.atol, numerics.edge_tol)
    segments, resume = follow.segments, None
    job, r = make_job(model), None
    if job.resume is not None:  # (a continuation: the first pass and the meshes before are in its archive)
        job.resume.archive = follow.resume(job.resume.archive, job.resume.state)
    else:
        job, r = _first_pass(make_job, model, follow, execute_args)
        if not isinstance(r, Refine):  # (met on the given mesh at every estimate time, or max_dofs)
            return r
    owner = None  # (the job of the last segment: its mesh's records, should the run stop before the next's begin)
    while True:
        try:  # (a stop signal from here on keeps the records so far: they were lost, an outside pass)
            if r is not None:
                # back to the last estimate time that met the tolerance on this mesh; if none did since the run came
                # to this mesh, to where it came from (the same state, carried onto a finer mesh still), or to the start
                if r.saved is not None:
                    owner = job
                    segments.append((job.disc, r.dataset, len(follow.refinements)))  # (its mesh: after so many)
                    resume = Carried(r, job)
                follow.refined(resume.time if resume is not None else 0.0)
                model, r = dataclasses.replace(model, geometry=r.geometry), None
                job = make_job(model, resume=resume)
            job.follow = follow
            ds = job.execute(*execute_args)
        except Refine as refine:
            r = refine
            continue
        except (Diverged, KeyboardInterrupt) as err:  # (what every mesh computed, on the last one; a stop signal's
            err = job.failed if isinstance(job.failed, Diverged) else err  # too, and a diverged run's it replaced)
            if not isinstance(err, (Diverged, Interrupted)) or err.dataset is None:  # (the last mesh's records alone
                raise _stopped_between(err, segments, follow, owner) from None  # were kept, an outside pass)
            with signals_held(drop=True):
                err.dataset = merge(segments + [(job.disc, err.dataset, None)], follow, job)
                if isinstance(err, Diverged):
                    finished(err.dataset, err)
            raise
        return _final(segments + [(job.disc, ds, None)], follow, job)


def _stopped_between(err, segments: list, follow: Follow, owner):
    """A stop signal between meshes (a finer mesh's steps not begun, or the first pass judged): Interrupted with the
    records of the meshes before, to the time the run went back to (a signal there lost every mesh's records, an
    outside pass); ``err`` itself where there are none (the run went back to the start)."""
    from ..discrete.world import stopped_by

    if not segments or owner is None or segments[-1][0] is not owner.disc or isinstance(err, Diverged):
        return err
    signal = err.signal if isinstance(err, Interrupted) else 2
    with signals_held(drop=True):
        follow.refinements = follow.refinements[:segments[-1][2]]  # (the refinement not run is not the archive's)
        # (no state to go on from: a pass's state at T, kept, was continued as a complete run that never refined)
        ds = without_state(merge(segments, follow, owner))
        message = (f"{ds.attrs['scene']}: {stopped_by(signal)} before a finer mesh's steps; the records to t = "
                   f"{float(ds.time[-1]):.6g} s are kept")
        ds.attrs.update(status="incomplete", failure=message, failure_type="Interrupted", space_stop="interrupted")
    return Interrupted(message, dataset=ds, signal=signal)


def _final(segments: list, follow: Follow, job, depth: int = 5) -> xr.Dataset:
    """The run's result, every mesh's records merged on the last, made with the stop signals dropped (the run is
    over) and kept for the command line (:func:`~workbench.discrete.world.finished`): a signal while the meshes were
    merged lost the run, or had the command write the last mesh's run alone (an outside pass)."""
    with signals_held(drop=True):
        out = _warned(merge(segments, follow, job), follow, depth)
        finished(out)
        return out


def _warned(ds: xr.Dataset, follow: Follow, depth: int = 4) -> xr.Dataset:
    """``ds``, with a warning when max_dofs kept the estimate above the tolerance (``depth``: the caller's frame,
    counted from here)."""
    if follow.full:
        warnings.warn(f"space_tol = {follow.tol:g} not met: the estimate is {ds.attrs['space_error_estimate']:.3g} at "
                      f"{ds.attrs['ndof']} dofs (max_dofs reached)", RuntimeWarning, stacklevel=depth)
    return ds


def _first_pass(make_job, model, follow: Follow, execute_args: tuple):
    """The whole run on the given mesh, watching: (the job, and its Dataset if the estimate met the tolerance at every
    estimate time (or the first refinement would exceed max_dofs), else the :class:`Refine` to go on from: back to the
    estimate time before the first that failed). Its largest norm becomes the scale of the tolerance: a body loaded
    from rest is not asked, at its first instants, for an error relative to its own small size (on Lee and Radok's
    Hertz that refined the mesh 14 times at the first step)."""
    follow.watching = True
    job = make_job(model)
    job.follow = follow
    try:
        ds = job.execute(*execute_args)
    except (Diverged, Interrupted) as err:  # (on the given mesh: that mesh's records, in the archive's layout)
        if err.dataset is not None:
            with signals_held(drop=True):
                err.dataset = merge([(job.disc, err.dataset, None)], follow, job)
        raise
    try:  # (a stop signal while the pass is judged, or the finer mesh made, keeps the pass: it was lost)
        follow.watching, follow.scale = False, follow.norm
        failed = [i for i, (e, displacement, _, _) in enumerate(follow.seen) if follow.too_large(e, displacement)]
        if failed:
            estimate, displacement, body, mesh = follow.seen[failed[0]]
            follow.refine(estimate, body, mesh, *follow.failing(estimate, displacement))
    except KeyboardInterrupt as err:
        raise _stopped_between(err, [(job.disc, ds, 0)], follow, job) from None
    saved = follow.kept[failed[0] - 1] if failed and failed[0] > 0 else None
    follow.seen, follow.kept = [], []
    if follow.geometry is None:
        return job, _final([(job.disc, ds, None)], follow, job, depth=6)
    return job, Refine(saved, ds, follow.geometry)


def merge(segments: list, follow: Follow, job) -> xr.Dataset:
    """The records of every mesh (``segments``: (discretisation, Dataset, the refinements that made its mesh; None
    for the last)) on the last mesh."""
    final_disc, final, _ = segments[-1]
    parts = [follow.onto(disc, ds, final_disc, final) for disc, ds, _ in segments[:-1]] + [(final, _snapshots(final))]
    timed = [name for name, v in final.data_vars.items() if "time" in v.dims]
    out = final.drop_vars(timed).drop_dims([d for d in ("time", "snapshot") if d in final.dims])
    time = np.concatenate([p.time.values for p, _ in parts])
    out = out.assign_coords(time=("time", time, final.time.attrs),
                            step=("time", np.concatenate([p.step.values for p, _ in parts]), final.step.attrs))
    for name in timed:
        out[name] = (final[name].dims, np.concatenate([_or_missing(p, name, final) for p, _ in parts]),
                     final[name].attrs)
    ndof = [disc.ndof_global for disc, _, _ in segments]
    per_record = np.repeat(ndof, [p.sizes["time"] for p, _ in parts]).astype(np.int64)
    if follow.earlier_ndof is not None:  # (a continued run: its archive's records were made on their own meshes)
        per_record[: len(follow.earlier_ndof)] = follow.earlier_ndof
    out["ndof"] = ("time", per_record, {"units": "1", "long_name": "the displacement dofs of the mesh each record was "
                                        "made on"})
    scale = follow.norm if follow.norm > 0 else 1.0
    out["space_error_estimate"] = out.space_error_estimate / scale
    out["space_error_estimate"].attrs.update(final.space_error_estimate.attrs)
    snaps = [shot for _, part_shots in parts for shot in part_shots]
    if snaps:  # (the fields and the final mesh's UGRID, as the recorder writes them)
        section = job.recorder.snapshot_dataset(snaps)
        out = out.drop_vars([n for n in section.variables if n in out.variables]).merge(section)
        made = [per_record[int(np.argmin(np.abs(time - t)))] for t, *_ in snaps]
        out["snapshot_ndof"] = ("snapshot", np.array(made, dtype=np.int64), {"units": "1", "long_name": "the "
                                "displacement dofs of the mesh each snapshot was made on (carried onto the final mesh)"})
        out = _snapshot_meshes(out, segments, follow)
    times, dofs = (list(c) for c in zip(*follow.refinements)) if follow.refinements else ([], [])
    out = out.assign_coords(refinement=("refinement", np.arange(len(times)), {"units": "1", "long_name": "refinement"}))
    out["refinement_time"] = ("refinement", np.array(times, dtype=float), {"units": "s", "long_name":
                              "the time each refinement went back to (the last estimate time that met space_tol on "
                              "the coarser mesh), from where the run went on on the finer mesh"})
    out["refinement_ndof"] = ("refinement", np.array(dofs, dtype=np.int64), {"units": "1", "long_name":
                              "the displacement dofs of the mesh after each refinement"})
    indicators = job.indicators if job.indicators is not None else np.zeros(final_disc.mesh.ne)
    if follow.earlier_indicators is not None and len(segments) == 1:  # (continued on the archive's last mesh: what
        indicators = np.maximum(indicators, follow.earlier_indicators)  # it met there before counts, as in one run)
    out["space_indicator"] = ("cell", np.sqrt(indicators) / scale, {"units": "1", "long_name": "the element's "
                              "largest error indicator on the final mesh (both parts), relative to the largest energy "
                              "norm of u"})
    if adapted_mesh(final_disc.geometry) is not None:  # (a continuation's too, where it refined no further: the
        out["adapted_mesh"] = ((), to_text(adapted_mesh(final_disc.geometry)),  # next continuation reads it there)
                               {"long_name": "the adapted mesh (netgen .vol text)"})
    largest = float(np.nanmax(out.space_error_estimate.values)) if out.sizes["time"] else float("nan")
    if "contact_edge_resolution" in out and np.isfinite(out.contact_edge_resolution.values).any():
        out.attrs["contact_edge_resolution"] = float(np.nanmax(out.contact_edge_resolution.values))
    out.attrs.update(space_error_estimate=largest, space_refinements=len(times), ndof=ndof[-1],
                     space_follow_json=json.dumps(follow.record()),
                     space_stop="max_dofs" if follow.full else "met")
    return out


def _snapshot_meshes(out: xr.Dataset, segments: list, follow: Follow) -> xr.Dataset:
    """``out`` with the mesh each snapshot was made on: ``snapshot_mesh(snapshot)`` names its UGRID topology
    (``"mesh"``, the final mesh, or ``"mesh_<j>"``, the mesh after j refinements, whose variables are added here or,
    for the snapshots of a continued archive, kept from it)."""
    earlier, meshes = follow.earlier_meshes
    names, meshes = [], dict(meshes)
    for i, (disc, ds, level) in enumerate(segments):
        if "snapshot" not in ds.dims:
            continue
        own = "mesh" if i == len(segments) - 1 else f"mesh_{level}"
        for t in ds.snapshot_time.values:
            made = [m for s, m in earlier if abs(s - t) <= 1e-9 * max(1.0, abs(t))]
            names.append(own if not made or made[0] == "mesh" else made[0])
        if own in names and own != "mesh":
            meshes.update(ugrid_mesh(own, disc.dim, disc.vertex_xyz, disc.fields.cells))
    used = {n: v for n, v in meshes.items() if any(n == m or n.startswith(m + "_") for m in set(names) - {"mesh"})}
    stale = [n for n in out.variables if re.fullmatch(r"mesh_\d+(_.*)?", n)]
    out = out.drop_vars(stale).assign(used)
    out["snapshot_mesh"] = ("snapshot", np.array(names, dtype=str), {"long_name": "the UGRID topology of the mesh "
                            "each snapshot was made on (its fields are carried onto the final mesh, 'mesh')"})
    return out


def _or_missing(part: xr.Dataset, name: str, final: xr.Dataset) -> np.ndarray:
    """``part[name]`` (a record variable), or NaN of its shape where that mesh's run did not record it."""
    if name in part:
        return part[name].values
    shape = (part.sizes["time"],) + final[name].shape[1:]
    return np.full(shape, np.nan)


def _onto(disc, ds: xr.Dataset, final_disc, final: xr.Dataset):
    """(the records of ``ds``, the snapshots of ``ds``) on ``final``'s mesh: the contact vertices and facet
    midpoints by position (NaN, or -1 for integers, where the point did not exist yet), the bonding field facet by
    facet, the snapshot fields by the nested prolongation."""
    from scipy.spatial import cKDTree

    from ..discrete.transfer import MeshInfo, Transfer

    order = disc.numerics.order
    move = Transfer(MeshInfo(disc.geometry, order), MeshInfo(final_disc.geometry, order))
    size = final_disc.geometry.size
    where = {}
    for dim, prefix in (("node", "node_"), ("midpoint", "midpoint_")):
        if dim not in ds.dims:
            continue
        coords = [c for c in ("x", "y", "z") if prefix + c in ds.coords]
        mine = np.column_stack([ds[prefix + c].values for c in coords])
        theirs = np.column_stack([final[prefix + c].values for c in coords])
        distance, index = cKDTree(mine).query(theirs)
        where[dim] = np.where(distance <= 1e-9 * size, index, -1)
    if "facet" in ds.dims:
        where["facet"] = move.facet_map if not move.identity else np.arange(ds.sizes["facet"])
    new = _new_nodes(move, disc, final_disc, where["node"]) if "node" in where else None
    records = {}
    for name, var in ds.data_vars.items():
        if "time" not in var.dims:
            continue
        data = var.values
        for axis, dim in enumerate(var.dims):
            if dim in where:
                data = _take(data, where[dim], axis)
                if dim == "node" and new is not None and name in INTERPOLATED:
                    at = [slice(None)] * data.ndim
                    at[axis] = new[0]
                    data[tuple(at)] = _interpolated(new[1], var.values, axis)
        records[name] = (var.dims, data)
    part = xr.Dataset(records, coords={"time": ds.time.values, "step": ("time", ds.step.values)})
    shots = []
    for t, u, stress, von_mises, _ in _snapshots(ds):
        u = move.displacement(u, u.reshape(disc.dim, -1).T if move.P is not None else None)
        edges = _edges(final_disc, u) if final_disc.numerics.order > 1 else None
        shots.append((t, u, move.cells(stress), move.cells(von_mises), edges))
    return part, shots


def _interpolated(weights: np.ndarray, values: np.ndarray, axis: int) -> np.ndarray:
    """``weights`` (new, coarse) applied along ``axis`` of ``values``; NaN only where a weighed value is (a clamped
    vertex's NaN pressure, weighing 0 at a new vertex away from it, would have made every new one NaN)."""
    nan = np.isnan(values)
    out = np.tensordot(weights, np.where(nan, 0.0, values), axes=([1], [axis]))
    out[np.tensordot(weights != 0, nan, axes=([1], [axis])) > 0] = np.nan
    return np.moveaxis(out, 0, axis)


#: The contact vertices' records that a finer mesh's new vertices take from the coarse mesh's P1 field on the contact
#: side (its nodal values interpolated): with the finer mesh's node_weight, sum w p is the coarse record's own force.
INTERPOLATED = ("contact_pressure", "contact_pressure_recovered", "u_contact")


def _new_nodes(move, disc, final_disc, index: np.ndarray):
    """(the final mesh's contact vertices that the coarse mesh did not have, the weights of the coarse contact vertices
    at them (new, coarse node)), or None where there are none or the meshes are not P1 (no vertex interpolation).
    On the contact side a new vertex lies on a coarse contact facet, so the coarse vertices off the side, left out
    here, weigh 0 there (on a curved side, where the new vertex moved onto the geometry, nearly 0). Left NaN, the
    coarse records had held the final mesh's weights for vertices they did not have: a force sum 34 % low
    (memory_slab, space_tol 0.1)."""
    missing = np.nonzero(index < 0)[0]
    if move.P is None or not missing.size:
        return None
    return missing, move.P[final_disc.vertex_numbers[missing]][:, disc.vertex_numbers].toarray()


def _snapshots(ds: xr.Dataset) -> list:
    """The snapshots of ``ds`` as the recorder keeps them: [(t, u dofs, stress, von Mises, edge values or None)]."""
    if "snapshot" not in ds.dims:
        return []
    edges = ds.u_edges.values if "u_edges" in ds else [None] * ds.sizes["snapshot"]
    return [(float(t), u, stress, vm, e) for t, u, stress, vm, e in zip(ds.snapshot_time.values, ds.u_dofs.values,
                                                                         ds.stress.values, ds.von_mises.values, edges)]


def _take(data: np.ndarray, index: np.ndarray, axis: int) -> np.ndarray:
    """``data`` at ``index`` along ``axis``, missing (-1) as NaN (or -1 for integers)."""
    out = np.take(data, np.maximum(index, 0), axis=axis)
    if np.any(index < 0):
        out = out if out.dtype.kind == "f" else (out.astype(float) if out.dtype.kind != "i" else out)
        missing = [slice(None)] * out.ndim
        missing[axis] = index < 0
        out[tuple(missing)] = np.nan if out.dtype.kind == "f" else -1
    return out


def _edges(disc, u: np.ndarray) -> np.ndarray:
    """The field ``u`` (dofs of ``disc``) at the edge midpoints, as the recorder takes them."""
    keep = disc.u.vec.FV().NumPy().copy()
    disc.u.vec.FV().NumPy()[:] = u
    try:
        return disc.fields.edge_values()
    finally:
        disc.u.vec.FV().NumPy()[:] = keep
