"""NGSolve's parallel conjugate gradients alone, without workbench: does it run on N MPI processes here?

A Poisson problem on the unit square (or ``--cube``: the unit cube) distributed by netgen, solved by NGSolve's
CGSolver with BDDC (or ``--jacobi``: its local preconditioner) and by the sparse factor gathered on rank 0; rank 0
prints the iterations and the difference of the two solutions. On this machine (NGSolve 6.2.2608 from PyPI,
MPICH 5.0.2) 3 processes run (the square: 2 BDDC iterations, 54 Jacobi, both within 2e-12 of the factor; the
cube: 2 BDDC iterations), while on 4 the square with BDDC aborts with ``malloc(): unaligned tcache chunk detected``
and with Jacobi does not converge (500 iterations, the solution 1.2 off the factor's), and on 5 the cube aborts. workbench's distributed runs solve with the same CGSolver, so they are tested
on 2 and 3 processes and warn beyond (``workbench.parallel.TESTED_PROCESSES``).

    mpiexec -n 3 python studies/mpi_plain_ngsolve.py           # runs
    mpiexec -n 4 python studies/mpi_plain_ngsolve.py           # aborted here
    mpiexec -n 5 python studies/mpi_plain_ngsolve.py --cube    # aborted here
"""
from __future__ import annotations

import argparse

import ngsolve as ngs
from mpi4py import MPI
from ngsolve.krylovspace import CGSolver


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cube", action="store_true", help="the unit cube (maxh 0.2) instead of the square (maxh 0.1)")
    ap.add_argument("--jacobi", action="store_true", help="NGSolve's local (Jacobi) preconditioner, not BDDC")
    args = ap.parse_args()
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        if args.cube:
            from netgen.csg import unit_cube as geometry
        else:
            from netgen.geom2d import unit_square as geometry
        mesh = ngs.Mesh(geometry.GenerateMesh(maxh=0.2 if args.cube else 0.1).Distribute(comm))
    else:
        import netgen.meshing as nm

        mesh = ngs.Mesh(nm.Mesh.Receive(comm))
    fes = ngs.H1(mesh, order=1, dirichlet="left")
    u, v = fes.TnT()
    a = ngs.BilinearForm(ngs.grad(u) * ngs.grad(v) * ngs.dx)
    pre = ngs.Preconditioner(a, "local" if args.jacobi else "bddc")
    a.Assemble()
    f = ngs.LinearForm(v * ngs.dx).Assemble()
    x = ngs.GridFunction(fes)
    cg = CGSolver(a.mat, pre.mat, tol=1e-10, maxiter=500)
    x.vec.data = cg * f.vec
    y = x.vec.CreateVector()
    y.data = a.mat.Inverse(fes.FreeDofs(), inverse="sparsecholesky") * f.vec
    y -= x.vec
    difference = ngs.Norm(y)
    if comm.rank == 0:
        print(f"{comm.size} processes: CG {cg.iterations} iterations, |CG - factor| = {difference:.2e}", flush=True)


if __name__ == "__main__":
    main()
