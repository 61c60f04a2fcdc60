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
dofs), restarts and checkpoints, the rod, higher orders, the banded and umfpack solvers.

Started without mpirun (or with one process) nothing here is used: :data:`SERIAL` stands in,
and its reductions return their arguments.
"""
from __future__ import annotations

import functools
import os

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

    @staticmethod
    def bcast(obj):
        return obj


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


def check(scene, model, *, restart=None, checkpoint=None) -> None:
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
    elif restart is not None or scene["checkpoint_every"]:
        why = "restart and checkpoint_every are not available on several processes"
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


class Shell:
    """Rank 0's serial view of a distributed discretisation (module docs): ``disc`` is a discretisation on the serial
    mesh without matrices; :meth:`gather` fills its u (and v, beta) from the ranks' parts.

    The serial order is found once: the local vertices by their coordinates among the serial mesh's (KD-tree, on
    rank 0), P2's edge dofs by their two vertices, the contact facets by their midpoints; only owned copies are sent.
    """

    def __init__(self, d, serial_mesh):
        self.w, self.local = world(), d
        comm = self.w.comm
        fes, mesh = d.fes, d.mesh
        order = d.scene["order"]
        dim = d.dim
        shell = serial_tree = None
        if self.w.root:
            from scipy.spatial import cKDTree

            from .discretisation import serial_shell

            shell = serial_shell(d.model, d.scene, serial_mesh)
            serial_tree = cKDTree(shell.vertex_xyz)
        numbers = _match(comm, d.vertex_xyz, serial_tree, "vertex")
        self.global_vertex = numbers
        self.disc = shell
        # the dofs of each local vertex (and P2 edge), by node; their serial counterparts on rank 0
        import ngsolve as ngs

        vdofs = d.vertex_dofs
        edges = np.zeros((0, 2), dtype=np.int64)
        edofs = np.zeros((0, dim), dtype=np.int64)
        if order > 1 and mesh.nedge:
            edges = np.sort(numbers[np.array([[v.nr for v in e.vertices] for e in mesh.edges], dtype=np.int64)],
                            axis=1)
            edofs = np.array([fes.GetDofNrs(ngs.NodeId(ngs.EDGE, e)) for e in range(mesh.nedge)],
                             dtype=np.int64).reshape(-1, dim)
        mine = owned(fes)
        if d.loads.point_force is not None:  # added once: where the serial run's vertex is owned
            target = self.w.bcast(shell.loads.point_vertex if self.w.root else None)
            hits = np.nonzero(numbers == target)[0] if target is not None else []
            here = len(hits) and mine[d.vertex_dofs[hits[0], 0]]
            d.loads.relocate_point_force(int(hits[0]) if here else None)
        local_dofs = np.concatenate([vdofs.ravel(), edofs.ravel()])
        keep = mine[local_dofs]
        self.send_dofs = local_dofs[keep]
        plans = comm.gather((numbers, edges, keep), root=0)
        if self.w.root:
            s = shell
            s_edge = {}
            if order > 1:
                s_edge = {tuple(sorted(v.nr for v in e.vertices)): e.nr for e in s.mesh.edges}
            targets = []
            for nums, edg, kp in plans:
                tv = s.vertex_dofs[nums].ravel()
                te = (np.array([s.fes.GetDofNrs(ngs.NodeId(ngs.EDGE, s_edge[tuple(p)])) for p in edg],
                               dtype=np.int64).ravel() if len(edg) else np.zeros(0, dtype=np.int64))
                targets.append(np.concatenate([tv, te])[kp])
            self.targets = np.concatenate(targets)
            self.counts = [len(t) for t in targets]
            if len(self.targets) != s.ndof or len(np.unique(self.targets)) != s.ndof:
                raise RuntimeError("the ranks' dofs do not cover the serial space once each")
        # beta: each contact facet lies on one rank; matched by its midpoint
        self.has_beta = d.beta is not None
        if self.has_beta:
            facet_tree = cKDTree(shell.facet_xyz) if self.w.root else None
            self.facet_targets = _match(comm, d.facet_xyz, facet_tree, "contact facet", gather_to_root=True)
            self.facet_counts = comm.gather(len(d.facet_xyz), root=0)

    def gather(self, velocity: bool = False) -> None:
        """u (and ``velocity``: v), beta of every rank into the shell on rank 0 (collective: every rank calls it)."""
        d = self.local
        for vec, target in ((d.u.vec, "u"), (d.v.vec, "v"))[: 2 if velocity else 1]:
            self._gather(vec.FV().NumPy()[self.send_dofs], self.counts if self.w.root else None,
                         None if not self.w.root else (getattr(self.disc, target).vec.FV().NumPy(), self.targets))
        if self.has_beta:
            beta = d.beta.vec.FV().NumPy()[d.beta_dofs]
            s = self.disc
            self._gather(beta, self.facet_counts if self.w.root else None,
                         None if not self.w.root else (s.beta.vec.FV().NumPy(), s.beta_dofs[self.facet_targets]))

    def _gather(self, local, counts, into) -> None:
        comm = self.w.comm
        local = np.ascontiguousarray(local, dtype=float)
        if into is None:
            comm.Gatherv(local, None, root=0)
            return
        buffer = np.empty(sum(counts))
        comm.Gatherv(local, (buffer, counts), root=0)
        array, where = into
        array[where] = buffer


def _match(comm, xyz, tree, what, gather_to_root=False):
    """The serial numbers of points (local vertex or facet coordinates), found on rank 0 in ``tree``; returned on every
    rank for its own points, or (``gather_to_root``) on rank 0 for all ranks' points in rank order."""
    everyone = comm.gather(np.asarray(xyz, dtype=float), root=0)
    found = None
    if comm.rank == 0:
        scale = max(float(np.ptp(tree.data, axis=0).max()), 1e-300) if len(tree.data) else 1.0
        found = []
        for points in everyone:
            if not len(points):
                found.append(np.zeros(0, dtype=np.int64))
                continue
            dist, index = tree.query(points)
            if np.any(dist > 1e-9 * scale):
                raise RuntimeError(f"a {what} of a rank has no serial counterpart")
            found.append(np.asarray(index, dtype=np.int64))
        if gather_to_root:
            return np.concatenate(found)
    if gather_to_root:
        return None
    return comm.scatter(found, root=0)


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
