"""The serial order of a body distributed over MPI processes: where each rank's dofs, contact facets and contact
points stand in the one-process run, and rank 0's serial view of the body that records (:class:`Shell`).

Rank 0 keeps a serial copy of the mesh with the discretisation's tables on it and no matrices. At each record it
gathers u (v too at the snapshots) in the serial dof order and beta in the serial facet order, and records them with
the serial code; restarts and checkpoints hold a state in the same order (:meth:`Shell.serial_state`), so that an
archive goes on with any number of processes.
"""
from __future__ import annotations

import numpy as np

from ..discrete import discretisation
from .algebra import cumulate, owned


def serial_shell(d, mesh):
    """The tables of the distributed discretisation ``d`` on the serial ``mesh``, without its matrices: what rank 0
    records through."""
    shell = discretisation.Discretisation(d.model, d.scene, mesh,
                                          discretisation.vector_space(d.model.geometry, mesh, d.numerics.order),
                                          d.numerics)
    discretisation.assemble(shell, matrices=False)
    return shell


class Order:
    """Where each of this rank's items (dofs, contact facets, contact points) stands in the serial run's order: rank 0
    gathers values into that order (:meth:`gather`) and hands them back out of it (:meth:`scatter`).

    ``index``: the serial number of each local item; ``send``: which local items to send when gathering (a dof shared
    by ranks is sent by its owner alone; default all); ``size``: the serial count.
    """

    def __init__(self, comm, index: np.ndarray, send=None, size: int | None = None, what: str = "item"):
        self.comm, self.index = comm, np.asarray(index, dtype=np.int64)
        self.send = send
        sent = self.index if send is None else self.index[send]
        everyone = comm.gather(sent, root=0)
        failed = False
        if comm.rank == 0:
            self.targets = np.concatenate(everyone)
            self.counts = [len(t) for t in everyone]
            self.size = len(self.targets) if size is None else size
            failed = len(self.targets) != self.size or len(np.unique(self.targets)) != self.size
        if comm.bcast(failed, root=0):  # (every rank raises: one alone would leave the others waiting)
            raise RuntimeError(f"the ranks' {what}s do not cover the serial run's once each")

    def gather(self, local: np.ndarray):
        """The values of every rank's items in the serial order, on rank 0 (None elsewhere); collective."""
        values = np.ascontiguousarray(local if self.send is None else local[self.send], dtype=float)
        if self.comm.rank != 0:
            self.comm.Gatherv(values, None, root=0)
            return None
        buffer = np.empty(sum(self.counts))
        self.comm.Gatherv(values, (buffer, self.counts), root=0)
        out = np.empty(self.size)
        out[self.targets] = buffer
        return out

    def pick(self, serial: np.ndarray) -> np.ndarray:
        """This rank's values of ``serial`` (in the serial order, known to this rank: e.g. read from an archive)."""
        return np.asarray(serial)[self.index]


class Shell:
    """Rank 0's serial view of a distributed discretisation (module docs): ``disc`` is a discretisation on the serial
    mesh without matrices; :meth:`gather` fills its u (and v, beta) from the ranks' parts.

    The serial order is found once (:class:`Order`): the local vertices by their coordinates among the serial mesh's
    (KD-tree, on rank 0), P2's edge dofs by their two vertices, the contact facets and the contact side's quadrature
    points by their coordinates.
    """

    def __init__(self, d, serial_mesh):
        import ngsolve as ngs

        self.w, self.local = d.world, d
        comm = self.w.comm
        fes, mesh, dim = d.fes, d.mesh, d.dim
        shell = serial_shell(d, serial_mesh) if self.w.root else None
        self.disc = shell
        numbers = _serial_numbers(comm, d.vertex_xyz, shell.vertex_xyz if shell else None, "vertex")
        mine = owned(fes)
        if d.loads.point_force is not None:  # added once: where the serial run's vertex is owned
            target = self.w.bcast(shell.loads.point_vertex if self.w.root else None)
            hits = np.nonzero(numbers == target)[0] if target is not None else []
            here = len(hits) and mine[d.vertex_dofs[hits[0], 0]]
            d.loads.relocate_point_force(int(hits[0]) if here else None)
        # the dofs of each local vertex (and P2 edge) and their serial counterparts, found on rank 0
        edges = np.zeros((0, 2), dtype=np.int64)
        edofs = np.zeros((0, dim), dtype=np.int64)
        if d.numerics.order > 1 and mesh.nedge:
            edges = np.sort(numbers[np.array([[v.nr for v in e.vertices] for e in mesh.edges], dtype=np.int64)],
                            axis=1)
            edofs = np.array([fes.GetDofNrs(ngs.NodeId(ngs.EDGE, e)) for e in range(mesh.nedge)],
                             dtype=np.int64).reshape(-1, dim)
        self.local_dofs = np.concatenate([d.vertex_dofs.ravel(), edofs.ravel()])
        plans = comm.gather((numbers, edges), root=0)
        serial_dofs = None
        if self.w.root:
            edge_of = ({tuple(sorted(v.nr for v in e.vertices)): e.nr for e in shell.mesh.edges}
                       if d.numerics.order > 1 else {})
            serial_dofs = []
            for nums, edg in plans:
                te = (np.array([shell.fes.GetDofNrs(ngs.NodeId(ngs.EDGE, edge_of[tuple(p)])) for p in edg],
                               dtype=np.int64).ravel() if len(edg) else np.zeros(0, dtype=np.int64))
                serial_dofs.append(np.concatenate([shell.vertex_dofs[nums].ravel(), te]))
        self.dofs = Order(comm, comm.scatter(serial_dofs, root=0), send=mine[self.local_dofs],
                          size=shell.ndof if shell else None, what="dof")
        self.facets = self.points = None
        if d.beta is not None:  # each contact facet lies on one rank
            self.facets = Order(comm, _serial_numbers(comm, d.facet_xyz, shell.facet_xyz if shell else None,
                                                      "contact facet"), what="contact facet")
        if d.side is not None:  # and so does each contact point (the step limit's envelope is kept per point)
            self.points = Order(comm, _serial_points(comm, d.side, shell.side if shell else None),
                                what="contact point")

    def gather(self, velocity: bool = False) -> None:
        """u (and ``velocity``: v), beta of every rank into the shell on rank 0 (collective: every rank calls it)."""
        d, s = self.local, self.disc
        for name in ("u", "v")[: 2 if velocity else 1]:
            full = self.dofs.gather(getattr(d, name).vec.FV().NumPy()[self.local_dofs])
            if s is not None:
                getattr(s, name).vec.FV().NumPy()[:] = full
        if self.facets is not None:
            beta = self.facets.gather(d.beta.vec.FV().NumPy()[d.beta_dofs])
            if s is not None:
                s.beta.vec.FV().NumPy()[s.beta_dofs] = beta

    def serial_state(self, state: dict, layout: dict):
        """A scheme's state (:meth:`workbench.schemes.base.Scheme.state`) in the serial order, on rank 0 (None
        elsewhere): u, v, beta and the arrays of its ``extra`` that ``layout`` names ("dof" or "point": a contact
        point's); collective."""
        out = dict(state)
        out["u"], out["v"] = (self.dofs.gather(np.asarray(state[k])[self.local_dofs]) for k in ("u", "v"))
        if state["beta"] is not None:
            out["beta"] = self.facets.gather(state["beta"])
        out["extra"] = dict(state["extra"])
        for key, where in layout.items():
            if key in state["extra"] and where != "root" and not _none(state["extra"][key]):  # (root: held in the
                # serial order on rank 0 already)
                out["extra"][key] = self._gathered(where, np.asarray(state["extra"][key]))
        out["history"] = [(t, self._gathered("dof", np.asarray(u)), None if b is None else self.facets.gather(b))
                          for t, u, b in state["history"]]
        return out if self.w.root else None

    def local_state(self, state: dict, layout: dict) -> dict:
        """This rank's part of a scheme's state in the serial order (:meth:`serial_state`; every rank has it)."""
        out = dict(state)
        out["u"], out["v"] = (self._local_dofs(state[k]) for k in ("u", "v"))
        if state["beta"] is not None:
            out["beta"] = self.facets.pick(state["beta"])
        out["history"] = [(t, self._local_dofs(u), None if b is None else self.facets.pick(b))
                          for t, u, b in state["history"]]
        out["extra"] = dict(state["extra"])
        for key, where in layout.items():
            if key in state["extra"] and where != "root" and not _none(state["extra"][key]):
                out["extra"][key] = self._picked(where, np.asarray(state["extra"][key]))
        return out

    def _picked(self, where: str, value: np.ndarray) -> np.ndarray:
        """This rank's part of an array of a scheme's state in the serial order (a 2D array: per row)."""
        if value.ndim == 2:
            return np.array([self._picked(where, row) for row in value])
        return self._local_dofs(value) if where == "dof" else self._order(where).pick(value)

    def _gathered(self, where: str, value: np.ndarray):
        """An array of a scheme's state (per local dof or per point; a 2D array: per row) in the serial order, on
        rank 0; collective."""
        order = self._order(where)
        if value.ndim == 2:  # (several dof vectors: Model B's memory histories)
            rows = [self._gathered(where, row) for row in value]
            return np.array(rows) if self.w.root else None
        return order.gather(value[self.local_dofs] if where == "dof" else value)

    def _order(self, where: str) -> Order:
        return {"dof": self.dofs, "point": self.points, "facet": self.facets}[where]

    def _local_dofs(self, serial) -> np.ndarray:
        out = np.zeros(self.local.ndof)
        out[self.local_dofs] = self.dofs.pick(serial)
        return out


def _none(value) -> bool:
    """Whether a state's array is an empty list of dof vectors (Model B without memory), the same on every rank (an
    empty array may be rank 0's part of a dof vector: it holds no cells)."""
    return isinstance(value, list) and not value


def _serial_numbers(comm, xyz, serial_xyz, what, group=None, serial_group=None):
    """The serial number of each of this rank's points (vertex, facet midpoint, contact point coordinates): found on
    rank 0 by a KD-tree over ``serial_xyz`` (given there), to 1e-9 of the body's size. With ``group`` (per point) and
    ``serial_group`` the match must lie in the same group: two facets' quadrature points may share coordinates (the
    3D rule of P1 has them at the edge midpoints), one facet's do not."""
    everyone = comm.gather((np.asarray(xyz, dtype=float), group), root=0)
    found, failed = None, False
    if comm.rank == 0:
        from scipy.spatial import cKDTree

        tree = cKDTree(serial_xyz)
        scale = max(float(np.ptp(serial_xyz, axis=0).max()), 1e-300) if len(serial_xyz) else 1.0
        k = 1 if serial_group is None else min(16, len(serial_xyz))
        found = []
        for points, groups in everyone:
            index = np.zeros(0, dtype=np.int64)
            if len(points):
                dist, near = tree.query(points, k=k)
                dist, near = dist.reshape(len(points), k), near.reshape(len(points), k)
                fits = dist <= 1e-9 * scale
                if serial_group is not None:
                    fits &= serial_group[near] == np.asarray(groups)[:, None]
                failed |= not fits.any(axis=1).all()
                index = near[np.arange(len(points)), np.argmax(fits, axis=1)]
            found.append(np.asarray(index, dtype=np.int64))
    if comm.bcast(failed, root=0):  # (every rank raises: one alone would leave the others waiting)
        raise RuntimeError(f"a {what} of a rank has no serial counterpart")
    return comm.scatter(found, root=0)


def _serial_points(comm, side, serial_side):
    """The serial number of each of this rank's contact points: its facet found by the facet's centroid (the mean of
    its points), then the point by its coordinates among that facet's."""
    def centroids(s):
        out = np.zeros((len(s.facets), s.dim))
        np.add.at(out, s.element, s.xyz)
        return out / np.bincount(s.element, minlength=len(s.facets))[:, None]

    serial_centroids = centroids(serial_side) if serial_side is not None else None
    facet = _serial_numbers(comm, centroids(side), serial_centroids, "contact facet")
    return _serial_numbers(comm, side.xyz, serial_side.xyz if serial_side is not None else None, "contact point",
                           group=facet[side.element],
                           serial_group=serial_side.element if serial_side is not None else None)


class GatheringRecorder:
    """The recorder of a distributed run: at the times the schedule of rank 0's ``recorder`` (a
    :class:`workbench.output.results.Recorder` of the shell with the scheme's observer of the shell; None on the other
    ranks) takes, every rank sends its part of u (and of v at the snapshots) and of beta, and rank 0 records the
    shell with the serial code."""

    def __init__(self, shell: Shell, recorder=None, observer=None):
        self.shell, self.recorder, self.w, self.observer = shell, recorder, shell.w, observer

    def record(self, t: float, final: bool = False, control=None) -> None:
        due = self.w.bcast(self.recorder.due(t, final) if self.w.root else None)
        if not any(due):
            return
        self.shell.gather(velocity=due[1])
        if self.observer is not None:  # (what the serial view's observer reads besides the state)
            shell = self.shell
            if due[1]:  # (a snapshot: the stress's other dof vectors, e.g. the memory's)
                vectors = [shell.dofs.gather(v[shell.local_dofs]) for v in self.observer.snapshot_vectors()]
                if self.w.root:
                    self.recorder.observer.gathered = vectors
            parts = self.observer.record_vectors(t)  # (each rank's part of a sum: summed over the ranks first)
            work = shell.local.u.vec.CreateVector() if parts else None
            vectors = [shell.dofs.gather(cumulate(work, v)[shell.local_dofs]) for v in parts]
            if self.w.root:
                self.recorder.observer.gathered_record = vectors or None
        if self.w.root:
            self.recorder.take(t, *due, control=control)

    @property
    def times(self) -> list:
        """The recorded times (rank 0's; the others keep none)."""
        return self.recorder.times if self.recorder is not None else []

    @property
    def extra(self) -> dict:
        """The scalar records by name (rank 0's; the others keep none)."""
        return self.recorder.extra if self.recorder is not None else {}

    def dataset(self, attrs: dict):
        """The Dataset (on rank 0)."""
        return self.recorder.dataset(attrs)

    def state(self) -> dict:
        """The record schedule (rank 0's; the others keep none)."""
        return self.recorder.state() if self.w.root else {}

    def resume(self, ds, state: dict) -> None:
        if self.w.root:
            self.recorder.resume(ds, state)
