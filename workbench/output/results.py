"""The result Dataset: its schema (one place), how a run fills it, and netCDF archiving.

Schema (docs/conventions.md, the result Dataset):

========================================  =====================================================
``time``                                  recorded times [s]; ``step`` holds the step index
``u_probe(time, probe, component)``       displacement at the probe points [m]
``u_contact(time, node, component)``      displacement at the contact-boundary vertices [m]
``beta(time, facet)``                     bonding field on the contact facets (if modelled)
``u_nodes(snapshot, vertex, component)``  whole displacement field at the snapshot times [m]
``stress(snapshot, cell, stress_component)``  P0 stress sigma_h = P_Q[...] [Pa]
``von_mises(snapshot, cell)``             von Mises norm of sigma_h [Pa]
``u_dofs(snapshot, dof)``                 the displacement dof vector (exact field reconstruction)
``cell_vertices(cell, corner)``           mesh connectivity, with ``vertex_x/y/z`` coordinates
``u_edges(snapshot, edge, component)``    order >= 2: the field at the edge midpoints (``edge_vertices``)
``state_*``, attribute ``state_json``     the full state at the last time, to continue the run (:mod:`.restart`)
========================================  =====================================================

Dataset attributes hold every scene parameter under its own name (expressions
as text, flags as 0/1, lists as JSON), the discretisation (``scheme``, ``h_max``,
``k_actual``, ``ndof``, ``nsteps``, ``cells``), cost (``wall_time``, ``cpu_time``),
``status`` ("complete" or "incomplete") with ``failure``, package versions and a
``history`` line. netCDF cannot hold dicts, bools or None as attributes, so the
schema stores only str, int, float.
"""
from __future__ import annotations

import functools
import json
import os
import time as _time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import xarray as xr

from ..values import to_plain
from . import invocation

COMPONENTS = ("x", "y", "z")
STRESS_COMPONENTS = {1: ("xx",), 2: ("xx", "yy", "xy"), 3: ("xx", "yy", "zz", "yz", "xz", "xy")}

#: (units, long_name) of every variable and coordinate the schema knows.
VARIABLES = {
    "time": ("s", "time"),
    "step": ("1", "time step index"),
    "u_probe": ("m", "displacement at probe points"),
    "u_contact": ("m", "displacement at contact-boundary vertices"),
    "beta": ("1", "bonding field on contact facets"),
    "u_nodes": ("m", "displacement at mesh vertices"),
    "u_dofs": ("m", "displacement degrees of freedom"),
    "stress": ("Pa", "stress, piecewise constant (P_Q projection)"),
    "von_mises": ("Pa", "von Mises norm of the stress"),
    "cell_vertices": ("1", "vertex indices of each cell"),
    "edge_vertices": ("1", "vertex indices of each mesh edge"),
    "u_edges": ("m", "displacement at the edge midpoints (elements of order >= 2)"),
    "snapshot_time": ("s", "time of the field snapshot"),
    "newton_iterations": ("1", "semismooth Newton iterations in the time step (all coupling passes)"),
    "cg_iterations": ("1", "conjugate gradient iterations of the time step's solve (solver = 'cg')"),
    "step_size": ("s", "accepted time step ending at this time (error-controlled steps)"),
    "error_estimate": ("1", "scaled local error estimate of the step (<= 1: within rtol, atol)"),
    "space_error_estimate": ("1", "a posteriori estimate of the error in space at the time, energy norm, relative to "
                             "the largest norm of u so far (space_tol > 0)"),
    "contact_edge_resolution": ("1", "the longest contact facet across the edge of the contact zone over the zone's "
                                "size (its measure to the power 1/(d-1)), at the estimate times (edge_tol > 0)"),
    "coupling_passes": ("1", "passes of the (u, beta) coupling iteration in the time step"),
    "iterations": ("1", "active-set iterations in the time step"),
    "linear_iterations": ("1", "conjugate gradient iterations on the active contact points in the time step "
                          "(contact_solver = 'coupled')"),
    "linear_solves": ("1", "linear solves in the time step (back-substitutions and active-set solves)"),
    "n_separated": ("1", "contact nodes separated (u_nu < 0)"),
    "n_stuck": ("1", "contact nodes at the layer surface below its yield limit (u_nu = 0)"),
    "n_compliant": ("1", "contact nodes in the compliant layer (0 < u_nu < gap)"),
    "n_rigid": ("1", "contact nodes at the rigid limit (u_nu = gap)"),
    "complementarity": ("m", "max over contact nodes of |s - prox(s + rho lam / w)|"),
    "contact_pressure": ("Pa", "contact pressure -sigma_nu at the contact vertices (lumped)"),
    "contact_state": ("1", "contact state: -1 clamped, 0 separated, 1 stuck, 2 compliant, 3 rigid"),
    "contact_pressure_recovered": ("Pa", "contact pressure averaged over each vertex's patch of the contact side by "
                                   "the nodal forces (sum F_j / sum w_j): smooth on unstructured meshes"),
    "component": ("1", "displacement component"),
    "probe": ("1", "probe index"),
    "node": ("1", "contact-boundary vertex index"),
    "facet": ("1", "contact facet index"),
    "stress_component": ("1", "stress tensor component"),
    "probe_x": ("m", "probe x"), "probe_y": ("m", "probe y"), "probe_z": ("m", "probe z"),
    "midpoint_x": ("m", "contact facet midpoint x (Model B on P2: its contact points besides the vertices)"),
    "midpoint_y": ("m", "contact facet midpoint y"),
    "midpoint_weight": ("m", "the midpoint's share of the contact side (Simpson: 2/3 of its facet)"),
    "contact_pressure_midpoint": ("Pa", "contact pressure at the facet midpoints (Model B on P2)"),
    "contact_state_midpoint": ("1", "contact state at the facet midpoints (as contact_state)"),
    "node_weight": ("m", "the contact vertex's share of the contact side, int phi_i da (m^2 in 3D; per unit "
                    "thickness in 2D): nodal force / node_weight = pressure"),
    "node_x": ("m", "contact vertex x"), "node_y": ("m", "contact vertex y"), "node_z": ("m", "contact vertex z"),
    "facet_x": ("m", "contact facet midpoint x"), "facet_y": ("m", "contact facet midpoint y"),
    "vertex_x": ("m", "vertex x"), "vertex_y": ("m", "vertex y"), "vertex_z": ("m", "vertex z"),
}


def _var(dims, data, name):
    units, long_name = VARIABLES[name]
    return xr.Variable(dims, data, attrs={"units": units, "long_name": long_name})


def attr_value(value):
    """A netCDF-safe attribute: bools as 0/1, None as '', containers as JSON text."""
    value = to_plain(value)
    if isinstance(value, bool):
        return int(value)
    if value is None:
        return ""
    if isinstance(value, (int, float, str, np.integer, np.floating)):
        return value
    return json.dumps(value)


def versions() -> dict:
    """The versions of the packages a run's numbers depend on, as attributes (``version_NAME``), and the digest of
    workbench's code (``version_workbench_code``, :func:`code_digest`)."""
    return dict(_versions(), version_workbench_code=code_digest())


@functools.lru_cache(maxsize=1)
def _versions() -> tuple:
    """Read once per process: the packages' metadata is read from disk (6 reads, 20 ms; 0.8 s of a 1000-step run with
    40 checkpoints), and the code that runs is the one this process imported, whatever is installed later."""
    import importlib.metadata as md

    out = []
    for pkg in ("workbench", "ngsolve", "numpy", "scipy", "xarray", "netCDF4"):
        try:
            out.append((f"version_{pkg}", md.version(pkg)))
        except md.PackageNotFoundError:
            out.append((f"version_{pkg}", "unknown"))
    return tuple(out)


def code_digest() -> str:
    """The sha256 (16 hex digits) of the package's source files, names and contents: which code made a result. The
    version number stays the same between releases, so a study resumed after a change to the code reused the cases
    of the code before without a word, and a restart went on across it (found by an outside pass); the cases are
    keyed by this digest, and a restart names it where it changed. 86 files, 11 ms, once per state of the files.

    The digest is of the files as they are when it is asked for; where they changed after this process imported
    workbench (their times or sizes differ from ``import workbench``'s), the code that runs may be either, and the
    digest ends in ``+changed``: no case of a study is then taken for a clean one's. It had named the files on disk
    at the first archive, edited after the import (an outside pass)."""
    import workbench

    now = workbench._source_stats()
    digest = _digest(now)
    return digest if now == workbench._SOURCES else f"{digest}+changed"


@functools.lru_cache(maxsize=4)
def _digest(stats: tuple) -> str:
    """The digest of the files ``stats`` lists (:func:`code_digest`), read once for each state of them."""
    import hashlib
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for name, _, _ in stats:
        try:
            h.update(name.encode() + b"\0" + (root / name).read_bytes() + b"\0")
        except OSError:
            continue
    return h.hexdigest()[:16]


class Recorder:
    """Collects a run's records by time and builds the Dataset.

    What it records of the state comes from ``observer`` (the scheme's,
    :class:`workbench.schemes.base.Observer`). The time loop offers every step's end time
    (:meth:`record`, the loop's callback); the recorder keeps
    t0, T, the ``record_times`` if given, else every step thinned to at most about
    ``max_records`` records (one whenever a (T / max_records)-long stretch has passed,
    whatever the step sizes; with ``every_step``, for error-controlled runs whose short
    steps are where things happen: every step, halved to every other one whenever
    ``max_records`` are reached), and whole fields at the ``snapshots`` times (which the
    step controller lands on exactly) and at T. A diagnostic that a record does not give
    (a run continued with another solver: ``cg_iterations``) is NaN there.
    """

    def __init__(self, disc, observer, T: float, snapshots=(), record_times=None, max_records: int = 2000,
                 every_step: bool = False):
        self.disc, self.observer = disc, observer
        self.T = float(T)
        self.tol = 1e-9 * self.T  # (relative: T = 1e-9 s kept a snapshot at every step within 1e-9 s)
        self.snapshot_times = sorted({float(t) for t in snapshots} | {self.T})
        self.record_times = None if record_times is None else np.sort(np.asarray(record_times, dtype=float))
        self.spacing = self.T / max_records
        # every_step (error-controlled runs): every step, and beyond max_records every other one of those kept
        self.every_step, self.max_records, self.stride = every_step, max_records, 1
        self.last = -np.inf
        self.times, self.steps = [], []
        self.u_probe, self.u_contact, self.beta = [], [], []
        self.extra, self.node_extra = {}, {}  # per-record diagnostics, per-contact-node values
        self.point_extra, self.points, self.weights = {}, {}, None  # per other contact point; their coordinates
        self.snaps = []  # (time, u_dofs, stress, von_mises)
        self.step = -1

    def _wanted(self, t: float, final: bool) -> bool:
        if final or self.step == 0:
            return True
        if self.record_times is not None:
            i = np.searchsorted(self.record_times, t - self.tol)
            return i < len(self.record_times) and abs(self.record_times[i] - t) <= self.tol
        if self.every_step:
            return self.step % self.stride == 0
        return t - self.last >= self.spacing * (1 - 1e-9)

    def _decimate(self) -> None:
        """Keep every other record (the first and last kept) and record every other step from now on."""
        keep = list(range(0, len(self.times) - 1, 2)) + [len(self.times) - 1]
        for seq in [self.times, self.steps, self.u_probe, self.u_contact, self.beta,
                    *self.extra.values(), *self.node_extra.values(), *self.point_extra.values()]:
            if seq:
                seq[:] = [seq[i] for i in keep]
        self.stride *= 2

    def record(self, t: float, final: bool = False, control=None) -> None:
        """Offer the state at time t (the loop calls this after every step and after ``start``); ``control``:
        scalars of the step controller (an adaptive run's step size and error estimate)."""
        self.take(t, *self.due(t, final), control=control)

    def due(self, t: float, final: bool = False) -> tuple:
        """(whether the state at t is recorded, whether its whole field is kept): the schedule, advanced by the offer
        of time t (a distributed run gathers the state to rank 0 only then, :mod:`workbench.parallel`)."""
        self.step += 1
        return self._wanted(t, final), any(abs(t - s) <= self.tol for s in self.snapshot_times)

    def take(self, t: float, wanted: bool, snapshot: bool, control=None) -> None:
        """Record the state at t as :meth:`due` said. Everything is evaluated before any list grows, and a record cut
        short is taken back: an interrupt inside the contact pressure's evaluation left the lists of unequal lengths,
        and the whole run was lost with "its steps are kept" (found by an outside pass)."""
        if wanted:
            row = self._row(t, control)
            sizes = self._sizes()
            try:
                self._append(t, row)
            except BaseException:  # (KeyboardInterrupt between two appends: the records as they were)
                self._truncate(sizes)
                raise
            if self.every_step and len(self.times) > self.max_records:
                self._decimate()
        if snapshot:
            self.snapshot(t)

    def _row(self, t: float, control) -> dict:
        """The values recorded at t, evaluated (nothing of the recorder's changed)."""
        d, scheme = self.disc, self.observer
        u = d.u.vec.FV().NumPy()
        return dict(u_probe=d.fields.probe_values(), u_contact=u[d.node_dofs],
                    beta=None if d.beta is None else d.beta.vec.FV().NumPy()[d.beta_dofs].copy(),
                    extra=scheme.diagnostics() | (control or {}),
                    nodes={key: np.asarray(arr) for key, arr in scheme.node_values(t).items()},
                    weights=(scheme.node_weights(), scheme.contact_points()) if self.weights is None else None,
                    points={key: np.asarray(arr) for key, arr in scheme.point_values(t).items()})

    def _append(self, t: float, row: dict) -> None:
        self.last = t
        self.times.append(t)
        self.steps.append(self.step)
        self.u_probe.append(row["u_probe"])
        self.u_contact.append(row["u_contact"])
        if row["beta"] is not None:
            self.beta.append(row["beta"])
        n = len(self.times)
        # (a run continued from an archive made with another solver, e.g. on another number of MPI processes,
        # gives other diagnostics: cg_iterations. A column is NaN at the records that did not give it)
        for key, val in row["extra"].items():
            column = self.extra.setdefault(key, [])
            column.extend([np.nan] * (n - 1 - len(column)))
            column.append(val)
        for column in self.extra.values():
            column.extend([np.nan] * (n - len(column)))
        # (per node or point: NaN at the records that did not give it, as a continued archive of an older code that
        # recorded no contact pressure; its columns were shorter than time's, and the continuation failed at its end)
        for table, values in ((self.node_extra, row["nodes"]), (self.point_extra, row["points"])):
            for key, arr in values.items():
                column = table.setdefault(key, [])
                column.extend([np.full(np.shape(arr), np.nan)] * (n - 1 - len(column)))
                column.append(arr)
            for column in table.values():
                column.extend([np.full(np.shape(column[-1]), np.nan)] * (n - len(column)))
        if row["weights"] is not None:
            self.weights, self.points = row["weights"]

    def _sizes(self) -> dict:
        """The length of every per-record list, and the last time (:meth:`_truncate` goes back to them)."""
        lists = {"times": self.times, "steps": self.steps, "u_probe": self.u_probe, "u_contact": self.u_contact,
                 "beta": self.beta}
        for prefix, table in (("extra", self.extra), ("nodes", self.node_extra), ("points", self.point_extra)):
            lists |= {f"{prefix} {k}": v for k, v in table.items()}
        return {"last": self.last, "lengths": {name: len(v) for name, v in lists.items()},
                "extra": set(self.extra), "nodes": set(self.node_extra), "points": set(self.point_extra)}

    def _truncate(self, sizes: dict) -> None:
        self.last = sizes["last"]
        for table, kept in ((self.extra, sizes["extra"]), (self.node_extra, sizes["nodes"]),
                            (self.point_extra, sizes["points"])):
            for key in set(table) - kept:
                del table[key]
        lengths = sizes["lengths"]
        for name, seq in (("times", self.times), ("steps", self.steps), ("u_probe", self.u_probe),
                          ("u_contact", self.u_contact), ("beta", self.beta)):
            del seq[lengths[name]:]
        for prefix, table in (("extra", self.extra), ("nodes", self.node_extra), ("points", self.point_extra)):
            for key, seq in table.items():
                del seq[lengths[f"{prefix} {key}"]:]

    def state(self) -> dict:
        """What the record schedule carries from step to step (the records themselves are the Dataset)."""
        return {"step": self.step, "last": self.last, "stride": self.stride}

    def resume(self, ds: xr.Dataset, state: dict) -> None:
        """Go on from the records of ``ds`` (an archive of this run) and the schedule ``state`` (:meth:`state`).

        The snapshots kept are those at this run's snapshot times: an archive's final field at its own T is
        dropped when the run now goes beyond it (as a run straight to the new T would not store it).
        """
        self.step, self.last, self.stride = int(state["step"]), float(state["last"]), int(state["stride"])
        self.times, self.steps = list(ds.time.values), list(ds.step.values)
        self.u_probe, self.u_contact = list(ds.u_probe.values), list(ds.u_contact.values)
        self.beta = list(ds.beta.values) if "beta" in ds else []
        self.extra = {n: list(v.values) for n, v in ds.data_vars.items() if v.dims == ("time",)}
        self.node_extra = {n: list(v.values) for n, v in ds.data_vars.items() if v.dims == ("time", "node")}
        self.point_extra = {n: list(v.values) for n, v in ds.data_vars.items() if v.dims == ("time", "midpoint")}
        self.snaps = []
        for i, t in enumerate(ds.snapshot_time.values if "snapshot_time" in ds.coords else []):
            if any(abs(t - s) <= self.tol for s in self.snapshot_times):
                edges = ds.u_edges.values[i] if "u_edges" in ds else None
                self.snaps.append((float(t), ds.u_dofs.values[i], ds.stress.values[i], ds.von_mises.values[i], edges))

    def snapshot(self, t: float) -> None:
        """Keep the whole field: u, the P0 stress sigma_h = P_Q[...] and its von Mises norm."""
        from ..physics.kelvin_voigt import stress_and_von_mises

        d = self.disc
        parts = [(tensor, d.fields.cell_strains(vector)) for tensor, vector in self.observer.stress_parts()]
        stress, vm = stress_and_von_mises(parts, d.dim)
        edges = d.fields.edge_values() if d.numerics.order > 1 else None
        self.snaps.append((t, d.u.vec.FV().NumPy().copy(), stress, vm, edges))

    def dataset(self, attrs: dict) -> xr.Dataset:
        """The Dataset of everything recorded so far (``attrs`` already netCDF-safe)."""
        d = self.disc
        dim = d.dim
        comp = list(COMPONENTS[:dim])
        probes = np.asarray(d.scene["probes"], dtype=float).reshape(-1, dim)
        n = len(self.times)
        coords = {
            "time": _var("time", np.asarray(self.times, dtype=float), "time"),
            "step": _var("time", np.asarray(self.steps, dtype=np.int64), "step"),
            "component": _var("component", comp, "component"),
            "probe": _var("probe", np.arange(len(probes)), "probe"),
            "node": _var("node", np.arange(len(d.node_dofs)), "node"),
        }
        for c in range(dim):
            coords[f"probe_{COMPONENTS[c]}"] = _var("probe", probes[:, c], f"probe_{COMPONENTS[c]}")
            coords[f"node_{COMPONENTS[c]}"] = _var("node", d.node_xyz[:, c], f"node_{COMPONENTS[c]}")
        if dim > 1:
            coords["node_weight"] = _var("node", d.node_weights if self.weights is None else self.weights,
                                         "node_weight")
            coords["node_weight"].attrs["units"] = "m" if dim == 2 else "m^2"
        shape = (0, len(probes), dim)
        data = {
            "u_probe": _var(("time", "probe", "component"), np.stack(self.u_probe) if n else np.empty(shape), "u_probe"),
            "u_contact": _var(("time", "node", "component"),
                              np.stack(self.u_contact) if n else np.empty((0, len(d.node_dofs), dim)), "u_contact"),
        }
        if d.beta is not None:
            coords["facet"] = _var("facet", np.arange(len(d.beta_dofs)), "facet")
            for axis in d.geometry.facet_axes or (0,):
                coords[f"facet_{COMPONENTS[axis]}"] = _var("facet", d.facet_xyz[:, axis], f"facet_{COMPONENTS[axis]}")
            data["beta"] = _var(("time", "facet"), np.stack(self.beta) if n else np.empty((0, len(d.beta_dofs))),
                                "beta")
        for key, vals in self.extra.items():
            data[key] = _var("time", np.asarray(vals), key)
        # (no record at all: a run continued on a finer mesh that stopped at its first step)
        for key, arrs in self.node_extra.items():
            data[key] = _var(("time", "node"), np.stack(arrs) if arrs else np.empty((0, len(d.node_dofs))), key)
        for key, values in self.points.items():
            coords[key] = _var("midpoint", values, key)
        midpoints = len(next(iter(self.points.values()))) if self.points else 0
        for key, arrs in self.point_extra.items():
            data[key] = _var(("time", "midpoint"), np.stack(arrs) if arrs else np.empty((0, midpoints)), key)
        if self.snaps:
            self._snapshot_variables(coords, data)
        return xr.Dataset(data | stored_mesh(d.scene), coords=coords, attrs=attrs)

    def snapshot_dataset(self, snaps: list) -> xr.Dataset:
        """The snapshot section of a Dataset (the fields and the mesh) for ``snaps`` [(t, u dofs, stress, von Mises,
        edge values or None)] on this recorder's mesh (a run whose mesh followed its solution carries its earlier
        snapshots onto the last mesh)."""
        coords, data = {}, {}
        self._snapshot_variables(coords, data, snaps)
        return xr.Dataset(data, coords=coords)

    def _snapshot_variables(self, coords: dict, data: dict, snaps: list | None = None) -> None:
        """The whole fields at the snapshot times, on the mesh (UGRID: its topology, and where each field lives)."""
        d = self.disc
        dim = d.dim
        snaps = self.snaps if snaps is None else snaps
        coords["snapshot_time"] = _var("snapshot", np.array([s[0] for s in snaps]), "snapshot_time")
        coords["stress_component"] = _var("stress_component", list(STRESS_COMPONENTS[dim]), "stress_component")
        for name, var in ugrid_mesh("mesh", dim, d.vertex_xyz, d.fields.cells).items():
            (coords if name.startswith("vertex_") else data)[name] = var
        data["u_dofs"] = _var(("snapshot", "dof"), np.stack([s[1] for s in snaps]), "u_dofs")
        vd = d.vertex_dofs
        data["u_nodes"] = _var(("snapshot", "vertex", "component"), np.stack([s[1][vd] for s in snaps]), "u_nodes")
        data["stress"] = _var(("snapshot", "cell", "stress_component"), np.stack([s[2] for s in snaps]), "stress")
        data["von_mises"] = _var(("snapshot", "cell"), np.stack([s[3] for s in snaps]), "von_mises")
        if snaps[0][4] is not None:  # order >= 2: the field at the edge midpoints too
            data["edge_vertices"] = _var(("edge", "end"), d.fields.edges[0], "edge_vertices")
            data["u_edges"] = _var(("snapshot", "edge", "component"), np.stack([s[4] for s in snaps]), "u_edges")
        for name, location in (("u_nodes", "node"), ("stress", UGRID_CELLS[dim][2]), ("von_mises", UGRID_CELLS[dim][2])):
            data[name].attrs.update(mesh="mesh", location=location)  # the fields on the mesh say where they live


#: UGRID names by dimension: (cell connectivity role, the shape of the cells, the location of cell data).
UGRID_CELLS = {1: ("edge_node_connectivity", "", "edge"), 2: ("face_node_connectivity", "", "face"),
               3: ("volume_node_connectivity", "tetrahedron", "volume")}


def stored_mesh(scene) -> dict:
    """``{"stored_mesh": its text}`` where the scene's mesh is a file made from a Python object (an OCC geometry, a
    netgen mesh) in the cache folder, which may be cleared: a restart, or :func:`workbench.running.restart.
    archived_scene`, writes it again from the archive (:func:`workbench.input.meshes.restore`). Else ``{}``."""
    from ..input.meshes import is_stored

    path = scene.values.get("mesh")
    if not isinstance(path, str) or not is_stored(path):
        return {}
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError):  # (the cache cleared during the run: the archive cannot keep it)
        return {}
    return {"stored_mesh": xr.Variable((), text, attrs={
        "long_name": "the mesh file the run's mesh (given as a Python object) was stored in, in the cache folder "
                     "(netgen .vol text): a continuation writes it again where that file is gone"})}


def ugrid_mesh(name: str, dim: int, vertex_xyz: np.ndarray, cells: np.ndarray) -> dict:
    """The variables of one mesh by the UGRID conventions: the topology variable ``name``, the vertices and the
    cells (0-based). A reader of UGRID (e.g. xugrid, ParaView's UGRID reader) finds them from the topology.

    The body's mesh is ``"mesh"`` with ``vertex_x/y/z(vertex)`` and ``cell_vertices(cell, corner)``; any other
    ``name`` (the coarser meshes of an adapted run's snapshots) prefixes its variables and dimensions:
    ``mesh_1_vertex_x(mesh_1_vertex)``, ``mesh_1_cell_vertices(mesh_1_cell, corner)``.

    Examples
    --------
    >>> import numpy as np
    >>> out = ugrid_mesh("mesh_1", 2, np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), np.array([[0, 1, 2]]))
    >>> sorted(out), out["mesh_1"].attrs["node_coordinates"]
    (['mesh_1', 'mesh_1_cell_vertices', 'mesh_1_vertex_x', 'mesh_1_vertex_y'], 'mesh_1_vertex_x mesh_1_vertex_y')
    """
    pre, role, shape, location = ("" if name == "mesh" else f"{name}_"), *UGRID_CELLS[dim]
    out = {}
    for c in range(dim):
        units, long_name = VARIABLES[f"vertex_{COMPONENTS[c]}"]
        out[f"{pre}vertex_{COMPONENTS[c]}"] = xr.Variable(f"{pre}vertex", vertex_xyz[:, c],
                                                          {"units": units, "long_name": long_name})
    units, long_name = VARIABLES["cell_vertices"]
    out[f"{pre}cell_vertices"] = xr.Variable((f"{pre}cell", "corner"), cells, {
        "units": units, "long_name": long_name, "cf_role": role, "start_index": 0})
    attrs = {"cf_role": "mesh_topology", "long_name": "the body's mesh (UGRID 1.0 topology)",
             "topology_dimension": dim, "node_coordinates": " ".join(f"{pre}vertex_{c}" for c in COMPONENTS[:dim]),
             role: f"{pre}cell_vertices", f"{location}_dimension": f"{pre}cell"}
    if shape:
        attrs["volume_shape_type"] = f"{name}_volume_shape"
        out[f"{name}_volume_shape"] = xr.Variable(f"{pre}cell", np.zeros(len(cells), np.int8), attrs={
            "cf_role": "volume_shape_type", "long_name": "the shape of each cell", "units": "1",
            "flag_values": np.int8(0), "flag_meanings": "tetrahedron"})
    out[name] = xr.Variable((), np.int32(0), attrs=attrs)
    return out




def brief(value, head: int = 3, tail: int = 2) -> str:
    """The repr of a value for a ``history`` line: a long sequence (a study's record times) by its ends and count.

    Examples
    --------
    >>> brief([0.0, 0.1])
    '[0.0, 0.1]'
    >>> brief(np.linspace(0.0, 1.0, 1001))
    '[0.0, 0.001, 0.002, ..., 0.999, 1.0] (1001 values)'
    """
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        items = [v.item() if isinstance(v, np.generic) else v for v in value]  # 0.5, not np.float64(0.5)
        if len(items) > head + tail + 1:
            ends = [repr(v) for v in items[:head]] + ["..."] + [repr(v) for v in items[-tail:]]
            return f"[{', '.join(ends)}] ({len(items)} values)"
        return repr(items if isinstance(value, list) else tuple(items))
    return repr(value.item() if isinstance(value, np.generic) else value)

#: Units of the non-parameter attributes a run writes.
ATTR_UNITS = {"h_max": "m", "k_actual": "s", "k_crit": "s", "k_crit_min": "s", "setup_time": "s", "wall_time": "s",
              "cpu_time": "s", "ndof": "1", "nsteps": "1", "steps_taken": "1", "threads": "1",
              "memory_peak_mb": "MB", "contact_candidates": "1", "contact_candidates_missed": "1"}


def provenance(scene, extra: dict, call: str = "", terms=None) -> dict:
    """Dataset attributes: CF conventions, every scene parameter with its units (``NAME_units``), the
    discretisation, cost, versions and a ``history`` line with the full command or call."""
    from ..input.parameters import PARAMETERS

    attrs = {"Conventions": "CF-1.10 UGRID-1.0", "title": f"workbench run of scene {scene.name}: {scene.description}",
             "scene": scene.name, "base_scene": scene.base, "geometry": scene.geometry,
             "description": scene.description, "model": scene.model,
             "terms": ",".join(scene.terms if terms is None else terms) or "none"}
    attrs |= {k: attr_value(v) for k, v in scene.values.items()}
    attrs["parameters_json"] = json.dumps(scene.plain(), sort_keys=True)
    attrs["set_by_user_json"] = json.dumps(sorted(scene.set_by_user))
    attrs |= {k: attr_value(v) for k, v in extra.items()}
    for k in list(scene.values) + list(extra):
        unit = PARAMETERS[k].unit if k in PARAMETERS else ATTR_UNITS.get(k)
        if unit:
            attrs[f"{k}_units"] = unit
    attrs |= versions()
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    launcher = f"mpiexec -n {extra['mpi_processes']} " if int(extra.get("mpi_processes", 1)) > 1 else ""
    attrs["history"] = f"{stamp} {launcher}{invocation.get() or call or 'workbench.run(' + repr(scene.name) + ')'}"
    return attrs


def write(ds: xr.Dataset, path) -> Path:
    """Write ``ds`` to netCDF atomically (:func:`workbench.output.files.atomic_write`).

    A path that cannot be written and can be known so before writing (a folder, a device, /proc, a folder without
    permission, a name too long) is a ParameterError; a failure while writing (a full disk) an OSError naming
    ``path``, ``ds`` untouched."""
    from ..errors import ParameterError
    from .files import atomic_write, check_output

    if not isinstance(ds, xr.Dataset):
        raise ParameterError(f"workbench.write: give the xarray Dataset of a run or a study, got {type(ds).__name__}")
    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise ParameterError(f"workbench.write: path = {path!r}: give a file name")
    check_output(path, "workbench.write: path")  # (a folder, a device, /proc, no permission: named before writing)
    return atomic_write(path, lambda tmp: ds.to_netcdf(tmp, engine="netcdf4"))


def load(path) -> xr.Dataset:
    """Read an archive written by :func:`write` (fully into memory, file closed).

    Examples
    --------
    >>> import tempfile, workbench
    >>> ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    >>> p = write(ds, tempfile.mkdtemp() + "/tp1.nc")
    >>> xr.testing.assert_identical(load(p), ds)
    """
    from ..errors import ParameterError

    if isinstance(path, (str, os.PathLike)):
        path = Path(path).expanduser()  # (~ as xarray reads it)
    if not isinstance(path, (str, os.PathLike)) or not Path(path).is_file():
        raise ParameterError(f"workbench.load: {str(path)!r} is not an archive file" +
                             (" (no such file)" if isinstance(path, (str, os.PathLike)) else ""))
    try:
        with xr.open_dataset(path, engine="netcdf4", decode_times=False, decode_timedelta=False) as ds:
            return ds.load()
    except (OSError, ValueError, RuntimeError) as err:
        raise ParameterError(f"workbench.load: {str(path)!r} cannot be read as a netCDF archive ({type(err).__name__})") \
            from None


class Clock:
    """Wall and CPU time of a block."""

    def __enter__(self):
        self.wall0, self.cpu0 = _time.perf_counter(), _time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = self.elapsed()

    def elapsed(self) -> tuple:
        """(wall, cpu) seconds since the block began (inside it: so far)."""
        return _time.perf_counter() - self.wall0, _time.process_time() - self.cpu0


def far_facet(beta: xr.DataArray) -> xr.DataArray:
    """The bonding field on the contact facet farthest along x (the slab's (1, 0); the rod's only facet).

    Examples
    --------
    >>> import workbench
    >>> ds = workbench.run("tp4", h=0.1, k=0.05, T=0.1, progress=False)
    >>> round(float(far_facet(ds.beta).facet_x), 3)
    0.95
    """
    return beta.isel(facet=int(np.argmax(beta.facet_x.values)))
