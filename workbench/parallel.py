"""One case on several processes: ``mpirun -np N workbench run SCENE ...`` with NGSolve's MPI.

Rank 0 builds the body's mesh and sends it out (netgen's ``Distribute``): it then holds no
cells (NGSolve's master), and ranks 1 ... N-1 hold a part each. Every rank builds the same
model on its part and runs the same time loop:

* the matrices are NGSolve's parallel matrices; u and v are kept *cumulated* (every copy
  of a dof shared by ranks holds its value), right-hand sides *distributed* (each rank
  holds its part of the sum);
* the contact side's traces act on each rank's own facets: T u needs u cumulated, and
  T^T (w p) is a distributed contribution, added with no communication;
* the solve is NGSolve's conjugate gradients preconditioned by BDDC (``solver = 'auto'``
  or ``'cg'``), warm started, or its sparse Cholesky factor gathered on rank 0
  (``'sparsecholesky'``);
* every decision the loop takes (the blow-up watchers, the step limit's re-check, its
  estimate, a solve that fails) is reduced over the ranks, so all ranks take it together.

Rank 0 also keeps a serial copy of the mesh with the discretisation's tables on it and no
matrices (its *shell*). At each record it gathers u (v too at the snapshots) in the serial
dof order and beta in the serial facet order, and records them with the serial code: the
archive, which rank 0 writes, has the serial run's layout and numbers to the solver's
tolerance (tests/test_parallel.py).

What runs: Model A's explicit scheme, P1 or P2, in 2D and 3D, on any body whose contact side
holds no pinned vertex; the archive, its plot and its VTK files are rank 0's. Refused by name
before any work (:func:`check`): the other schemes and Model B (they condense on the contact
dofs), the rod, higher orders, the banded and umfpack solvers. Restarts and checkpoints hold the
state in the serial order (:meth:`Shell.serial_state`), so a distributed run's archive goes on with
one process or with another number of ranks, and a one-process archive on several.

Started without mpirun (or with one process) nothing here is used: :data:`SERIAL` stands in,
and its reductions return their arguments.
"""
from __future__ import annotations

import functools
import os
import sys

import numpy as np

from .errors import ParameterError

#: The environment variables through which MPI launchers (MPICH's hydra and Intel MPI, Open MPI, MVAPICH) tell a
#: process how many were started.
SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "MV2_COMM_WORLD_SIZE")


def alone(environment=None) -> dict:
    """A copy of the environment (default: this process's) without an MPI launcher's variables: a process started
    from it runs alone (a study's worker), or under a launcher of its own."""
    environment = os.environ if environment is None else environment
    return {key: value for key, value in environment.items() if not key.startswith(("PMI_", "OMPI_", "MV2_", "PMIX_"))}


class Serial:
    """The stand-in for one process: every reduction returns its argument."""

    parallel = False
    rank, size, root = 0, 1, True

    @staticmethod
    def any(flag) -> bool:
        return bool(flag)

    @staticmethod
    def max(value) -> float:
        return value

    @staticmethod
    def sum(value) -> float:
        return value


SERIAL = Serial()


class World:
    """The ranks of one distributed case (mpi4py's COMM_WORLD) and the reductions the time loop takes."""

    parallel = True

    def __init__(self, comm):
        from mpi4py import MPI

        self.comm, self.MPI = comm, MPI
        self.rank, self.size = comm.rank, comm.size
        self.root = self.rank == 0

    def any(self, flag) -> bool:
        return bool(self.comm.allreduce(bool(flag), op=self.MPI.LOR))

    def max(self, value: float) -> float:
        """The largest over the ranks (a non-finite value on any rank gives inf: MPI's max of NaN is undefined)."""
        value = float(value)
        return self.comm.allreduce(value if np.isfinite(value) else np.inf, op=self.MPI.MAX)

    def sum(self, value: float) -> float:
        return self.comm.allreduce(float(value), op=self.MPI.SUM)

    def bcast(self, obj):
        return self.comm.bcast(obj, root=0)


@functools.lru_cache(maxsize=None)
def world():
    """The :class:`World` when this process is one of several started by an MPI launcher, else :data:`SERIAL`."""
    size = max(int(os.environ.get(name) or 1) for name in SIZE_VARIABLES)
    if size <= 1:
        return SERIAL
    try:
        from mpi4py import MPI
    except ImportError:
        raise ParameterError(f"started by an MPI launcher with {size} processes, but mpi4py is not installed: "
                             "pip install mpi4py (and an MPI, e.g. pip install mpich)") from None
    return World(MPI.COMM_WORLD) if MPI.COMM_WORLD.size > 1 else SERIAL


def abort_on_error() -> None:
    """In an exception handler on one of several MPI processes: print the traceback and end every rank (MPI_Abort);
    otherwise nothing. (A Python script gets the same from ``mpiexec -n N python -m mpi4py script.py``.)"""
    if not world.cache_info().currsize:  # (never asked for: no MPI in this process)
        return
    w = world()
    if not w.parallel:
        return
    import traceback

    traceback.print_exc()
    print(f"error: rank {w.rank} of {w.size} failed (above); ending every rank", file=sys.stderr, flush=True)
    w.comm.Abort(1)


def check(scene, model) -> None:
    """Refuse, by name and before any work, what does not run distributed (module docs)."""
    w = world()
    if not w.parallel:
        return
    why = None
    if model.kind != "A" or scene["scheme"] != "explicit":
        why = (f"scheme = {scene['scheme']!r} (Model {model.kind}): only Model A's explicit scheme runs on "
               "several processes (the others condense on the contact dofs, one solve per contact dof)")
    elif scene["solver"] not in ("auto", "cg", "sparsecholesky"):
        why = (f"solver = {scene['solver']!r}: on several processes the solver is 'cg' (conjugate gradients "
               "with BDDC; 'auto' takes it) or 'sparsecholesky' (the factor gathered on rank 0)")
    elif model.geometry.pins_contact:
        why = f"the {scene.geometry} body holds contact vertices (its apex): not on several processes"
    elif scene.dim == 1:
        why = "the rod (1D) does not run on several processes"
    elif scene["order"] > 2:
        why = (f"order = {scene['order']}: on several processes the displacement is P1 or P2 (the edge dofs of higher "
               "orders depend on the edges' orientation on each rank)")
    if why:
        raise ParameterError(f"{scene.name} on {w.size} MPI processes: {why}; run it with one process")


def conjugate_gradients(scene) -> bool:
    """Whether a distributed run solves with BDDC-preconditioned CG (``solver = auto | cg``; else the factor gathered on
    rank 0)."""
    return world().parallel and scene["solver"] in ("auto", "cg")


def distribute(geometry):
    """(the mesh part of this rank, the whole serial mesh on rank 0 (None elsewhere))."""
    import netgen.meshing as nm
    import ngsolve as ngs

    w = world()
    if w.root:
        serial = geometry.mesh()
        return ngs.Mesh(serial.ngmesh.Copy().Distribute(w.comm)), serial
    return ngs.Mesh(nm.Mesh.Receive(w.comm)), None


def status(vector, distributed: bool) -> None:
    """Mark an NGSolve vector written through NumPy as distributed (a rank's part of a sum) or cumulated."""
    import ngsolve as ngs

    s = ngs.la.PARALLEL_STATUS
    vector.SetParallelStatus(s.DISTRIBUTED if distributed else s.CUMULATED)


def cumulate(vector, values: np.ndarray) -> np.ndarray:
    """Values per local dof that are a rank's part of a sum, summed over the ranks that share each dof (through
    ``vector``, an NGSolve vector of the space used as work space)."""
    arr = vector.FV().NumPy()
    arr[:] = values
    status(vector, True)
    vector.Cumulate()
    return arr.copy()


def owned(fes) -> np.ndarray:
    """True at the local dofs this rank owns (each shared dof has one owner): sums over owned dofs count each once."""
    pardofs = fes.ParallelDofs()
    if pardofs is None:
        return np.ones(fes.ndof, dtype=bool)
    return np.array(pardofs.MasterDofs(), dtype=bool)


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

        self.w, self.local = world(), d
        comm = self.w.comm
        fes, mesh, dim = d.fes, d.mesh, d.dim
        shell = None
        if self.w.root:
            from .discretisation import serial_shell

            shell = serial_shell(d.model, d.scene, serial_mesh)
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
        if d.scene["order"] > 1 and mesh.nedge:
            edges = np.sort(numbers[np.array([[v.nr for v in e.vertices] for e in mesh.edges], dtype=np.int64)],
                            axis=1)
            edofs = np.array([fes.GetDofNrs(ngs.NodeId(ngs.EDGE, e)) for e in range(mesh.nedge)],
                             dtype=np.int64).reshape(-1, dim)
        self.local_dofs = np.concatenate([d.vertex_dofs.ravel(), edofs.ravel()])
        plans = comm.gather((numbers, edges), root=0)
        serial_dofs = None
        if self.w.root:
            edge_of = ({tuple(sorted(v.nr for v in e.vertices)): e.nr for e in shell.mesh.edges}
                       if d.scene["order"] > 1 else {})
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
            if key in state["extra"]:
                order, value = self._order(where), np.asarray(state["extra"][key])
                out["extra"][key] = order.gather(value[self.local_dofs] if where == "dof" else value)
        if state["history"]:
            raise NotImplementedError("a distributed scheme keeps no history of accepted states")
        return out if self.w.root else None

    def local_state(self, state: dict, layout: dict) -> dict:
        """This rank's part of a scheme's state in the serial order (:meth:`serial_state`; every rank has it)."""
        out = dict(state)
        out["u"], out["v"] = (self._local_dofs(state[k]) for k in ("u", "v"))
        if state["beta"] is not None:
            out["beta"] = self.facets.pick(state["beta"])
        out["extra"] = dict(state["extra"])
        for key, where in layout.items():
            if key in state["extra"]:
                value = state["extra"][key]
                out["extra"][key] = self._local_dofs(value) if where == "dof" else self._order(where).pick(value)
        return out

    def _order(self, where: str) -> Order:
        return {"dof": self.dofs, "point": self.points, "facet": self.facets}[where]

    def _local_dofs(self, serial) -> np.ndarray:
        out = np.zeros(self.local.ndof)
        out[self.local_dofs] = self.dofs.pick(serial)
        return out


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
    :class:`workbench.results.Recorder` of the shell; None on the other ranks) takes, every rank sends its part of u
    (and of v at the snapshots) and of beta, and rank 0 records the shell with the serial code, through a copy of the
    scheme that reads the shell."""

    def __init__(self, shell: Shell, recorder=None):
        self.shell, self.recorder, self.w = shell, recorder, shell.w

    def record(self, t: float, scheme, final: bool = False, control=None) -> None:
        due = self.w.bcast(self.recorder.due(t, final) if self.w.root else None)
        if not any(due):
            return
        self.shell.gather(velocity=due[1])
        if self.w.root:
            import copy

            view = copy.copy(scheme)
            view.d = self.shell.disc
            self.recorder.take(t, view, *due, control=control)

    def dataset(self, attrs: dict):
        """The Dataset (on rank 0)."""
        return self.recorder.dataset(attrs)

    def state(self) -> dict:
        """The record schedule (rank 0's; the others keep none)."""
        return self.recorder.state() if self.w.root else {}

    def resume(self, ds, state: dict) -> None:
        if self.w.root:
            self.recorder.resume(ds, state)
