"""Plain NumPy/SciPy implementation of the paper's explicit scheme PV^hk on the 2D slab.

A speed and correctness baseline written independently of ``workbench``:
nothing here imports the package or NGSolve. It solves Model A of
``docs/models.md`` (Chau–Fernández–Shillor–Sofonea 2003, test problem 5 by
default) with the fully discrete scheme of the paper (eqs. 6.9–6.12 / 7.1–7.4).

Problem
-------
Slab Ω = (0, W) × (0, H), plane stress, clamped (u = 0) on x = 0, traction f2(t)
on the top y = H, contact side Γ3 = {y = 0} with outward normal ν = (0, −1), so
u_ν = −u_y (positive = penetration). Material σ = A ε(u̇) + G ε(u) with

    G ε = E ν / (1 − ν²) tr(ε) I + E / (1 + ν) ε,        A ε = a1 tr(ε) I + a2 ε.

Scheme (P1 displacement, β piecewise constant on the contact facets), step n,
k_n = t_n − t_{n−1}:

    (A ε(v_n), ε(w)) = (f_n, w) − (G ε(u_{n−1}), ε(w)) − j(β_{n−1}, u_{n−1}, w)   ∀ w
    u_n = u_{n−1} + k_n v_n
    β_n = clip(β_{n−1} − k_n P_B[(γ β_{n−1} R_b(u_{n−1,ν})² − ε_a)_+], 0, 1)

    j(β, u, w) = ∫_Γ3 [c_ν (u_ν)_+ − γ β² (−R(u_ν))_+] w_ν da,    R(s) = clip(s, −L, L),

with the "tension" bonding truncation R_b(s) = (−R(s))_+ (debonding only under
tension; ``--truncation symmetric`` gives R_b = R) and P_B the facet mean.
Problem-5 data (defaults): c_ν = 1, γ = 0.3, L = 0.3, ε_a = 0, β0 = 1, T = 1,
f2(t) = (−10 sin 50t, −sin 50t) on the whole top edge, u0 = 0.

Discretisation
--------------
* Mesh: nx × ny squares, each cut into the triangles (i, i+1, i+nx+1) and
  (i+1, i+nx+2, i+nx+1) (row-major vertex numbers), i.e. along the diagonal from
  the lower-right to the upper-left corner. This is exactly the mesh of
  ``ngsolve.meshes.MakeStructured2DMesh(quads=False, nx, ny, mapping=(W x, H y))``
  (checked in ``check_agreement.py``), with the same vertex numbers; the dof of
  (vertex v, component c) is v + c nv, as in NGSolve's VectorH1.
* K_A, K_G: constant-strain elements, area B^T D B, assembled with vectorised
  NumPy into SciPy COO -> CSR. The clamped dofs are eliminated once; the reduced
  system is renumbered by reverse Cuthill–McKee and K_A is factored once by
  LAPACK's banded Cholesky (``dpbtrf``); each step is one ``dpbtrs``.
  Measured with ``studies/baseline/bench_solvers.py`` (nx = 160, ny = 16,
  5440 unknowns, RCM bandwidth 35, one BLAS thread, 2 shared cores): one
  banded solve 0.19–0.21 ms (factor 196k entries, factorisation 7 ms);
  ``splu`` 0.8–1.4 ms depending on the column ordering (factor 326k–385k
  nonzeros, 17–54 ms); ``factorized`` 1.4 ms (SuperLU here: no scikit-umfpack).
  So banded Cholesky is the default (``--solver splu`` for comparison): a thin
  slab has a narrow band, and a band solve streams one contiguous array with
  no index indirection. ``dpbtrs`` is called directly (SciPy's
  ``cho_solve_banded`` wraps the same routine; its per-call checks cost a
  few µs, within the timing noise here).
* Boundary terms: evaluated every step from the contact-node values of u_ν by
  the same quadrature rules as NGSolve's default for the package's forms
  (``workbench`` assembles them as symbolic linear forms, whose integration
  order is 2 × the order of the test space): the contact force j with the
  2-point Gauss rule on each facet (test space P1, order 2), the facet mean P_B
  of the debonding rate with the 1-point midpoint rule (test space P0,
  order 0). Both integrands are nonsmooth (kinks where u_ν = 0, ±L), so no
  low-order rule is exact for them; ``--contact-points`` / ``--rate-points``
  choose other Gauss rules to measure the effect.
* Load: g(t) times the consistent top-edge vector ∫_top φ_i ds (precomputed).

Output (``--out``, .npz): ``time``; ``u_probe(time, probe, component)`` at the
probe vertices (1, 0) and (1, H) with ``probe_xy``; ``beta(time, facet)`` with
``facet_x`` (midpoints, left to right); ``u_final(vertex, component)``,
``vertex_xy``; ``loop_time`` and ``setup_time`` (s). The script prints the time
of its time loop.

Command (from the repository root)::

    python studies/baseline/plain_explicit.py --nx 160 --ny 16 --k 0.001 --out /tmp/plain.npz
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack
from scipy.sparse.csgraph import reverse_cuthill_mckee

#: NGSolve's points and weights on [0, 1] of its default segment rules (orders 0-1, 2-3, 4-5),
#: copied bit for bit so that the boundary terms agree to round-off with the package's.
GAUSS = {
    1: (np.array([0.5]), np.array([1.0])),
    2: (np.array([0.21132486540518713, 0.7886751345948129]), np.array([0.5, 0.5])),
    3: (np.array([0.1127016653792583, 0.5, 0.8872983346207417]),
        np.array([0.27777777777777635, 0.4444444444444444, 0.27777777777777635])),
}


def gauss_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The n-point Gauss–Legendre rule on [0, 1] (points, weights)."""
    if n in GAUSS:
        return GAUSS[n]
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


# --------------------------------------------------------------------------- mesh and matrices


def structured_mesh(nx: int, ny: int, W: float, H: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of the structured slab mesh.

    Parameters
    ----------
    nx, ny : int
        Squares along x and y.
    W, H : float
        Width and height of the slab.

    Returns
    -------
    xy : ndarray, shape (nv, 2)
        Vertex coordinates, vertex j + i (nx + 1) at (W j / nx, H i / ny).
    tri : ndarray, shape (2 nx ny, 3)
        Counter-clockwise triangles, the two of each square in turn.
    """
    j, i = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1))
    # same arithmetic as netgen: the unit-square point j / nx first, then the mapping
    xy = np.column_stack([W * (j.ravel() / nx), H * (i.ravel() / ny)])
    jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
    base = (ii * (nx + 1) + jj).ravel()
    lower = np.column_stack([base, base + 1, base + nx + 1])
    upper = np.column_stack([base + 1, base + nx + 2, base + nx + 1])
    tri = np.stack([lower, upper], axis=1).reshape(-1, 3)
    return xy, tri


def stiffness(xy: np.ndarray, tri: np.ndarray, lam: float, two_mu: float) -> sp.csr_matrix:
    """P1 stiffness of the isotropic tensor ε -> lam tr(ε) I + two_mu ε.

    Parameters
    ----------
    xy, tri : ndarray
        Mesh (see :func:`structured_mesh`).
    lam, two_mu : float
        Moduli of the tensor (plane-stress G or viscosity A).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (2 nv, 2 nv)
        K[a, b] = ∫ (C ε(φ_b)) : ε(φ_a) dx with dof(v, c) = v + c nv.
    """
    nv = xy.shape[0]
    p = xy[tri]  # (ne, 3, 2)
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    area = 0.5 * np.abs(det)
    # gradients of the barycentric coordinates: the rows of the inverse Jacobian, and their negative sum
    gx1, gy1 = d2[:, 1] / det, -d2[:, 0] / det
    gx2, gy2 = -d1[:, 1] / det, d1[:, 0] / det
    gx = np.column_stack([-gx1 - gx2, gx1, gx2])  # (ne, 3)
    gy = np.column_stack([-gy1 - gy2, gy1, gy2])
    ne = tri.shape[0]
    # B: (ne, 3 Voigt rows eps11, eps22, 2 eps12) x (6 local dofs: x of vertices 0-2, then y)
    B = np.zeros((ne, 3, 6))
    B[:, 0, :3] = gx
    B[:, 1, 3:] = gy
    B[:, 2, :3] = gy
    B[:, 2, 3:] = gx
    # eps(u):eps(w) = e11 e11' + e22 e22' + (2 e12)(2 e12')/2 in Voigt notation with engineering shear
    D = np.array([[lam + two_mu, lam, 0.0], [lam, lam + two_mu, 0.0], [0.0, 0.0, 0.5 * two_mu]])
    Ke = area[:, None, None] * np.einsum("eki,kl,elj->eij", B, D, B)
    dofs = np.concatenate([tri, tri + nv], axis=1)  # (ne, 6) global dofs in the local order
    rows = np.repeat(dofs, 6, axis=1).ravel()
    cols = np.tile(dofs, (1, 6)).ravel()
    return sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=(2 * nv, 2 * nv)).tocsr()


# --------------------------------------------------------------------------- linear solvers


class BandedCholesky:
    """Banded Cholesky (LAPACK ``dpbtrf``/``dpbtrs``) of an SPD matrix already in a banded order.

    Parameters
    ----------
    K : scipy.sparse matrix
        SPD, ordered so that its bandwidth is small (reverse Cuthill–McKee).
    """

    name = "banded"

    def __init__(self, K: sp.spmatrix):
        K = sp.triu(K).tocoo()
        self.bandwidth = bw = int(np.max(K.col - K.row))
        ab = np.zeros((bw + 1, K.shape[0]))
        ab[bw + K.row - K.col, K.col] = K.data  # LAPACK upper band storage
        factor, info = lapack.dpbtrf(ab, lower=0, overwrite_ab=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"dpbtrf: info = {info} (matrix not positive definite)")
        self.factor = factor

    def solve(self, b: np.ndarray) -> np.ndarray:
        """K^-1 b (LAPACK directly: scipy's cho_solve_banded wrapper costs more than the solve here)."""
        x, info = lapack.dpbtrs(self.factor, b, lower=0)
        return x


class SuperLU:
    """SciPy's ``splu`` (SuperLU with COLAMD column ordering), for comparison.

    Parameters
    ----------
    K : scipy.sparse matrix
    """

    name = "splu"

    def __init__(self, K: sp.spmatrix):
        from scipy.sparse.linalg import splu  # imported only when asked for: it adds to the start-up time

        self.lu = splu(sp.csc_matrix(K))
        self.bandwidth = -1

    def solve(self, b: np.ndarray) -> np.ndarray:
        """K^-1 b."""
        return self.lu.solve(b)


SOLVERS = {"banded": BandedCholesky, "splu": SuperLU}


# --------------------------------------------------------------------------- the scheme


class Slab:
    """The scheme's constant data on the reduced (free, RCM-ordered) dof vector.

    Parameters
    ----------
    args : argparse.Namespace
        Geometry, material, contact and discretisation parameters (see :func:`parse`).
    """

    def __init__(self, args):
        nx, ny, W, H = args.nx, args.ny, args.W, args.H
        self.xy, self.tri = xy, tri = structured_mesh(nx, ny, W, H)
        nv = self.nv = xy.shape[0]
        E, nu = args.E, args.nu
        K_G = stiffness(xy, tri, E * nu / (1.0 - nu * nu), E / (1.0 + nu))
        K_A = stiffness(xy, tri, args.a1, args.a2)

        # eliminate the clamp x = 0 (u = 0 there for all time), then order the rest for a narrow band
        clamped = np.nonzero(xy[:, 0] == 0.0)[0]
        free = np.setdiff1d(np.arange(2 * nv), np.concatenate([clamped, clamped + nv]))
        K_A, K_G = K_A[free][:, free], K_G[free][:, free]
        perm = reverse_cuthill_mckee(K_A.tocsr(), symmetric_mode=True)
        self.dofs = free[perm]  # reduced position p holds global dof dofs[p]
        self.K_G = K_G[perm][:, perm].tocsr()
        self.solver = SOLVERS[args.solver](K_A[perm][:, perm])
        position = np.full(2 * nv, -1)
        position[self.dofs] = np.arange(self.dofs.size)

        # contact side y = 0: vertices 0..nx from left to right, facet f between vertices f and f + 1,
        # u_nu = -u_y. The clamped corner (0, 0) has no reduced position: its u_nu stays 0, its force is dropped.
        xb = xy[: nx + 1, 0]
        contact_y = position[np.arange(nx + 1) + nv]
        self.contact_free = contact_y >= 0
        self.contact_pos = contact_y[self.contact_free]
        self.facet_x = 0.5 * (xb[:-1] + xb[1:])
        # j: P1 interpolation to the --contact-points Gauss points of each facet, weights times facet length
        p, w = gauss_rule(args.contact_points)
        self.phi0, self.phi1 = 1.0 - p, p  # the left and right node's shape functions at the points
        self.weights = np.diff(xb)[:, None] * w[None, :]  # (facet, point)
        # P_B: the facet mean by the --rate-points rule (weights sum to 1 on [0, 1])
        pr, self.rate_w = gauss_rule(args.rate_points)
        self.rate_phi0, self.rate_phi1 = 1.0 - pr, pr

        # load: g(t) times the consistent top-edge vectors int_top phi_i ds (both components)
        top = ny * (nx + 1) + np.arange(nx + 1)
        xt = xy[top, 0]
        m = np.zeros(nx + 1)
        m[:-1] += 0.5 * np.diff(xt)
        m[1:] += 0.5 * np.diff(xt)
        self.load_x, self.load_y = position[top], position[top + nv]  # only the corner (0, H) is clamped
        keep = self.load_x >= 0
        self.load_x, self.load_y, self.load_m = self.load_x[keep], self.load_y[keep], m[keep]

        # probes at vertices (1, 0) and (1, H): reduced positions of (x, y) components
        probe_v = np.array([nx, ny * (nx + 1) + nx])
        self.probe_xy = xy[probe_v]
        self.probe_pos = np.stack([position[probe_v], position[probe_v + nv]], axis=1)  # (probe, component)

    def full_field(self, u: np.ndarray) -> np.ndarray:
        """The reduced vector ``u`` as (vertex, component) values, zero on the clamp."""
        full = np.zeros(2 * self.nv)
        full[self.dofs] = u
        return full.reshape(2, self.nv).T


def march(slab: Slab, args) -> dict:
    """Run the explicit scheme PV^hk from u0 = 0, β0 over the uniform grid of step ≤ k.

    Parameters
    ----------
    slab : Slab
    args : argparse.Namespace

    Returns
    -------
    dict
        Arrays for the .npz file (see the module docstring).
    """
    n_steps = max(1, math.ceil(args.T / args.k - 1e-9))
    grid = np.linspace(0.0, args.T, n_steps + 1)  # the same grid as workbench's time_grid
    c_nu, gamma, L, eps_a = args.c_nu, args.gamma_nu, args.L, args.eps_a
    tension = args.truncation == "tension"
    nf = slab.facet_x.size
    u = np.zeros(slab.dofs.size)
    beta = np.full(nf, args.beta0)
    u_probe = np.zeros((n_steps + 1, 2, 2))
    beta_rec = np.zeros((n_steps + 1, nf))
    beta_rec[0] = beta
    phi0, phi1, weights = slab.phi0, slab.phi1, slab.weights
    rphi0, rphi1, rate_w = slab.rate_phi0, slab.rate_phi1, slab.rate_w
    minus_K_G, solve = -slab.K_G, slab.solver.solve
    cpos, cfree = slab.contact_pos, slab.contact_free
    lx, ly, lm, ppos = slab.load_x, slab.load_y, slab.load_m, slab.probe_pos
    u_nu = np.zeros(cfree.size)  # at the contact nodes; 0 at the clamped corner
    nodal = np.zeros(cfree.size)

    start = time.perf_counter()
    for n in range(1, n_steps + 1):
        t, k = grid[n], grid[n] - grid[n - 1]
        # rhs = F(t_n) - K_G u_{n-1} - j(beta_{n-1}, u_{n-1}, .), traction f2(t) = (-10 sin 50t, -sin 50t)
        rhs = minus_K_G @ u
        g = math.sin(50.0 * t)
        rhs[lx] += (-10.0 * g) * lm
        rhs[ly] += (-g) * lm
        u_nu[cfree] = -u[cpos]
        left, right = u_nu[:-1, None], u_nu[1:, None]
        # j at the quadrature points (facet, point): c (s)_+ - gamma beta^2 (-R(s))_+, (-R(s))_+ = min((-s)_+, L)
        s = left * phi0 + right * phi1
        pull = np.minimum(np.maximum(-s, 0.0), L)
        force = (c_nu * np.maximum(s, 0.0) - (gamma * beta * beta)[:, None] * pull) * weights
        # -j(w) with w_nu = -w_y: +sum_q weight_q force_q phi_i(q) on the y dof of node i
        from_left, from_right = force @ phi0, force @ phi1  # each facet's share for its left / right node
        nodal[0], nodal[-1] = from_left[0], from_right[-1]
        np.add(from_left[1:], from_right[:-1], out=nodal[1:-1])
        rhs[cpos] += nodal[cfree]
        # P_B of the debonding rate at (beta_{n-1}, u_{n-1}), before u moves
        r = np.minimum(np.maximum(left * rphi0 + right * rphi1, -L), L)
        rb = np.maximum(-r, 0.0) if tension else r
        rate = np.maximum((gamma * beta)[:, None] * rb * rb - eps_a, 0.0) @ rate_w
        u += k * solve(rhs)
        beta = np.minimum(np.maximum(beta - k * rate, 0.0), 1.0)
        u_probe[n] = u[ppos]
        beta_rec[n] = beta
    loop_time = time.perf_counter() - start
    if not np.all(np.isfinite(u)):
        raise FloatingPointError("the explicit scheme blew up (k above its stability limit?)")
    return dict(time=grid, u_probe=u_probe, probe_xy=slab.probe_xy, beta=beta_rec, facet_x=slab.facet_x,
                u_final=slab.full_field(u), vertex_xy=slab.xy, loop_time=loop_time)


def parse(argv=None) -> argparse.Namespace:
    """Command-line options (defaults: test problem 5 at nx = 160, ny = 16, k = 0.001)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add = ap.add_argument
    add("--nx", type=int, default=160), add("--ny", type=int, default=16)
    add("--W", type=float, default=1.0), add("--H", type=float, default=0.1)
    add("--E", type=float, default=1000.0), add("--nu", type=float, default=0.3)
    add("--a1", type=float, default=30.0), add("--a2", type=float, default=20.0)
    add("--c-nu", dest="c_nu", type=float, default=1.0)
    add("--gamma-nu", dest="gamma_nu", type=float, default=0.3)
    add("--L", type=float, default=0.3), add("--eps-a", dest="eps_a", type=float, default=0.0)
    add("--beta0", type=float, default=1.0)
    add("--truncation", choices=("tension", "symmetric"), default="tension")
    add("--T", type=float, default=1.0), add("--k", type=float, default=0.001)
    add("--solver", choices=tuple(SOLVERS), default="banded")
    add("--contact-points", type=int, default=2, help="Gauss points per facet for j (workbench/NGSolve: 2)")
    add("--rate-points", type=int, default=1, help="Gauss points per facet for P_B (workbench/NGSolve: 1)")
    add("--out", default=None, help="write the results to this .npz file")
    add("--quiet", action="store_true")
    return ap.parse_args(argv)


def main(argv=None) -> dict:
    """Set up, march, write; print setup and loop times."""
    args = parse(argv)
    t0 = time.perf_counter()
    slab = Slab(args)
    setup_time = time.perf_counter() - t0
    out = march(slab, args)
    out["setup_time"] = setup_time
    if args.out:
        np.savez(args.out, **out)
    if not args.quiet:
        print(f"plain_explicit: {2 * slab.nv} dofs ({slab.dofs.size} free), {out['time'].size - 1} steps, "
              f"solver {slab.solver.name} (bandwidth {slab.solver.bandwidth}); "
              f"setup {setup_time:.4f} s, loop_time {out['loop_time']:.4f} s")
    return out


if __name__ == "__main__":
    main()
