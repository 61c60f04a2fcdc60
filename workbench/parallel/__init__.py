"""One case on several processes: ``mpiexec -n N workbench run SCENE ...`` with NGSolve's MPI.

Parallelism is a property of the data here: a body distributed over the processes is a
:class:`DistributedDiscretisation`, which carries its :class:`World` (the communicator and its
reductions) and overrides the few methods of :class:`workbench.discrete.discretisation.Discretisation` that
depend on where the data lives (the solver of K_A, the step limit's operators, the dofs a rank
counts, the state gathered into and scattered from the serial order, the recorder). The time loop,
the step limit, restarts and the schemes call those methods and never ask how many processes run.

Rank 0 builds the body's mesh and sends it out (netgen's ``Distribute``): it then holds no
cells (NGSolve's master), and ranks 1 ... N-1 hold a part each. Every rank builds the same
model on its part and runs the same time loop:

* the matrices are NGSolve's parallel matrices; u and v are kept *cumulated* (every copy
  of a dof shared by ranks holds its value), right-hand sides *distributed* (each rank
  holds its part of the sum) (:mod:`.algebra`);
* the contact side's traces act on each rank's own facets: T u needs u cumulated, and
  T^T (w p) is a distributed contribution, added with no communication;
* the solve is NGSolve's conjugate gradients preconditioned by BDDC (``solver = 'auto'``
  or ``'cg'``), warm started, or its sparse Cholesky factor gathered on rank 0
  (``'sparsecholesky'``);
* every decision the loop takes (the blow-up watchers, the step limit's re-check, its
  estimate, a solve that fails) is reduced over the ranks, so all ranks take it together.

Rank 0 also keeps a serial view of the body (:mod:`.order`): the archive, which rank 0 writes,
has the serial run's layout and numbers to the solver's tolerance (tests/test_parallel.py).

What runs: the schemes registered as ``distributed`` (:data:`workbench.input.numerics.SCHEMES`: all of
them), with fixed or error-controlled steps, P1 or P2, in 2D and 3D; the Hertz bodies' held apex too (its
reaction is summed over the ranks and gathered to rank 0 at each record,
:meth:`workbench.schemes.base.Observer.record_vectors`). The archive, its plot and its VTK files are rank 0's.
The implicit schemes solve their step operator like K_A and their contact problem on rank 0's serial view, the
other ranks serving its solves (:mod:`.contact`). Refused by name before any work (:func:`check`): adaptive
meshes, the rod, higher orders, the banded and umfpack solvers. Restarts and checkpoints hold the state in the
serial order, so a distributed run's archive goes on with one process or with another number of ranks, and a
one-process archive on several.

Started without a launcher (or with one process) :func:`world` is :data:`workbench.discrete.world.SERIAL`
and :func:`discretise` builds the one-process discretisation.
"""
from __future__ import annotations

import functools
import os
import sys
import time
import warnings

import numpy as np

from ..discrete import discretisation
from ..discrete.world import SERIAL, Serial, launched
from ..errors import ParameterError
from ..input.numerics import SCHEMES
from .algebra import DistributedOperators, DistributedSolver, owned
from .contact import DistributedExchange
from .order import GatheringRecorder, Shell


class World(Serial):
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

    def allgather(self, obj) -> list:
        return self.comm.allgather(obj)


#: The most processes the tests run (2 and 3). On 4 and 5 NGSolve 6.2.2608's parallel CG aborted with heap corruption
#: on this machine for some meshes, also in a plain NGSolve script (the unit square with BDDC or Jacobi on 4, the unit
#: cube on 5), so a run beyond this count is warned about (:func:`check`).
TESTED_PROCESSES = 3


#: Set, unless the user set them, before this process starts MPI. MPICH's ranks poll for messages while they wait
#: (rank 0 building the mesh, a rank waiting at a reduction): MPIR_CVAR_CH4_PROGRESS_THROTTLE polls less while no
#: message comes, which leaves the cores to the ranks that compute. Measured on 2 cores with ``mpiexec -n N
#: workbench run block --h 0.1`` (one run each, default against throttled): T = 0.01, N = 3, another process busy:
#: 14.3-30.2 s against 11.1 s; idle: 7.5-7.9 s against 6.4-6.9 s; T = 0.1, N = 2, idle: 7.3-8.1 s against 5.7-6.2 s.
#: Other MPIs ignore the name.
MPI_ENVIRONMENT = {"MPIR_CVAR_CH4_PROGRESS_THROTTLE": "1"}


@functools.lru_cache(maxsize=None)
def world():
    """The :class:`World` when this process is one of several started by an MPI launcher, else
    :data:`workbench.discrete.world.SERIAL`."""
    size = launched()
    if size <= 1:
        return SERIAL
    for name, value in MPI_ENVIRONMENT.items():  # (read by MPI_Init, which importing mpi4py.MPI calls)
        os.environ.setdefault(name, value)
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
    time.sleep(0.5)  # (the launcher forwards the output asynchronously: an abort at once lost it on a loaded machine)
    w.comm.Abort(1)


def check(scene, model, numerics) -> None:
    """Refuse, by name and before any work, what does not run distributed (module docs)."""
    w = world()
    if not w.parallel:
        return
    why = None
    if not SCHEMES[numerics.scheme].distributed:
        runs = ", ".join(repr(n) for n, e in SCHEMES.items() if e.distributed)
        why = (f"scheme = {numerics.scheme!r} (Model {model.kind}): only the scheme(s) {runs} run on several processes "
               "(the others are registered as one-process only)")
    elif numerics.solver not in ("auto", "cg", "sparsecholesky"):
        why = (f"solver = {numerics.solver!r}: on several processes the solver is 'cg' (conjugate gradients "
               "with BDDC; 'auto' takes it) or 'sparsecholesky' (the factor gathered on rank 0)")
    elif model.geometry.dim == 1:
        why = "the rod (1D) does not run on several processes"
    elif numerics.order > 2:
        why = (f"order = {numerics.order}: on several processes the displacement is P1 or P2 (the edge dofs of higher "
               "orders depend on the edges' orientation on each rank)")
    elif numerics.space_tol > 0:
        why = f"space_tol = {numerics.space_tol:g}: adaptive refinement runs on one process"
    if why:
        raise ParameterError(f"{scene.name} on {w.size} MPI processes: {why}; run it with one process")
    if w.size > TESTED_PROCESSES and numerics.solver in ("auto", "cg") and w.root:
        import ngsolve

        warnings.warn(f"{w.size} MPI processes with solver = 'cg': NGSolve's parallel conjugate gradients (NGSolve "
                      f"{ngsolve.__version__} here) aborted with heap corruption ('malloc(): unaligned tcache chunk') "
                      f"on 4 and 5 processes on the reference machine, also in a plain NGSolve script "
                      f"(studies/mpi_plain_ngsolve.py); {TESTED_PROCESSES} processes or fewer are tested, and "
                      f"solver = 'sparsecholesky' ran on 4",
                      RuntimeWarning, stacklevel=3)


def discretise(model, scene, numerics):
    """The discretisation of a model on the processes this one runs with: one process, or this rank's part of a body
    distributed over several (:class:`DistributedDiscretisation`)."""
    w = world()
    if not w.parallel:
        d = discretisation.build(model, scene, numerics)
        outside = discretisation.probes_outside(d)
    else:
        d = DistributedDiscretisation(model, scene, numerics, w)
        outside = w.bcast(discretisation.probes_outside(d.shell.disc) if w.root else None)  # (rank 0's serial mesh)
    if outside:  # (before any factorization: the first record's point evaluation failed on it)
        raise ParameterError(outside)
    return d


class DistributedDiscretisation(discretisation.Discretisation):
    """This rank's part of a body distributed over MPI processes (module docs), with rank 0's serial view
    (``shell``, :class:`workbench.parallel.order.Shell`)."""

    def __init__(self, model, scene, numerics, world_):
        self.world = world_
        import ngsolve as ngs

        geometry = model.geometry
        if world_.root:  # rank 0 keeps the serial mesh for its shell and sends the parts out
            serial_mesh = geometry.mesh()
            mesh = ngs.Mesh(serial_mesh.ngmesh.Copy().Distribute(world_.comm))
        else:
            import netgen.meshing as nm

            serial_mesh, mesh = None, ngs.Mesh(nm.Mesh.Receive(world_.comm))
        fes = discretisation.vector_space(geometry, mesh, numerics.order)
        self.conjugate_gradients = numerics.solver in ("auto", "cg")
        if self.conjugate_gradients:
            _vertex_wirebasket(fes, geometry.dim, mesh.nv)
        super().__init__(model, scene, mesh, fes, numerics)
        self.viscous_pre = None
        discretisation.assemble(self, preconditioner="bddc" if self.conjugate_gradients else None)
        self.shell = Shell(self, serial_mesh)

    @property
    def ndof_global(self) -> int:
        return self.fes.ndofglobal

    def owned(self):
        return owned(self.fes)

    def viscous_solver(self, iterative: bool = True):
        """NGSolve's CG with BDDC, or the sparse factor gathered on rank 0 (``solver = 'sparsecholesky'``)."""
        method = "cg" if self.conjugate_gradients else "sparsecholesky"
        return DistributedSolver(self.viscous.mat, self.viscous_pre, self.fes.FreeDofs(), self.u.vec, method)

    def step_solver(self) -> str:
        return "cg" if self.conjugate_gradients else "sparsecholesky"

    def step_factor(self, M):
        """An implicit step's operator M: CG preconditioned by K_A's BDDC (M = a0 K_A + K_G, or Model B's K_A plus
        a memory part, is spectrally equivalent to K_A), or the sparse factor gathered on rank 0."""
        return DistributedSolver(M, self.viscous_pre, self.fes.FreeDofs(), self.u.vec, self.step_solver())

    def exchange(self):
        return DistributedExchange(self)

    def springs(self, solver):
        return DistributedOperators(self, solver)

    def gather_state(self, state: dict, layout: dict):
        return self.shell.serial_state(state, layout)

    def scatter_state(self, state: dict, layout: dict) -> dict:
        return self.shell.local_state(state, layout)

    def recording(self, make, observer=None):
        """Every rank sends its part at the record times of rank 0's recorder, which records the serial view."""
        return GatheringRecorder(self.shell, make(self.shell.disc) if self.world.root else None, observer)


def _vertex_wirebasket(fes, dim: int, nv: int) -> None:
    """BDDC's coarse problem on the vertex dofs only: every other dof (P2: the edges') an interface dof. With the
    default wirebasket, vertices and edges, the coarse problem of P2 is the whole system, factored on rank 0 (the P2
    block at 271k dofs on 3 processes: 5.1 GB on rank 0, 2 CG iterations); with the vertices alone rank 0 holds
    0.6 GB and every rank under 1 GB, at 77 iterations (studies/bench_mpi.py)."""
    import ngsolve as ngs

    per = fes.ndof // dim  # (each component's block: its vertex dofs first)
    for c in range(dim):
        fes.SetCouplingType(ngs.IntRange(c * per + nv, (c + 1) * per), ngs.COUPLING_TYPE.INTERFACE_DOF)
