"""Check that ``plain_explicit.py`` solves the same discrete problem as ``workbench`` (to round-off).

Four checks, each printed:

1. Mesh: ``structured_mesh(nx, ny, W, H)`` has the vertices (same numbers,
   coordinates bit for bit) and triangles (same vertex sets) of
   ``ngsolve.meshes.MakeStructured2DMesh(quads=False, nx, ny, mapping=(W x, H y))``.
2. Matrices: K_A and K_G equal the package's assembled viscous and elastic matrices.
3. Quadrature: which Gauss rule NGSolve uses for the package's boundary forms.
   NGSolve's rule of order q on a segment is the ceil((q + 1) / 2)-point Gauss rule,
   and a symbolic linear form integrates with order 2 p (p = order of the test
   space). The experiment sets a random state (u_ν crossing 0 and ±L inside
   facets, so the integrands are nonsmooth and every rule gives a different
   value), assembles the package's contact form j (P1 test functions) and rate
   form (P0 test functions) and compares them with the n-point Gauss rule, n = 1..4.
4. Whole run: test problem 5 at h = 0.00625 (nx = 160, ny = 16), k = 0.001,
   1000 steps. Reports max |u_plain − u_workbench| / max |u| over all recorded
   probe values at (1, 0) and (1, H), the same for u at T (all dofs), and
   max |β_plain − β_workbench| over all steps and facets. Target: ≤ 1e-8.
   As a yardstick of round-off, the same numbers for the plain run against
   itself with E and a1 changed by one unit in the last place (K_A has
   condition number ~ 3e7 on this mesh, so entry-level round-off in the
   matrices moves the solution by ~ 1e-10 relative).

Command (from the repository root)::

    workbench run tp5 --h 0.00625 --k 0.001 -o /tmp/ref.nc --no-progress
    python studies/baseline/check_agreement.py --ref /tmp/ref.nc

Without ``--ref`` the workbench run is made first (the same command, into a
temporary file).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import plain_explicit as plain  # noqa: E402

TOL = 1e-8


def check_mesh(nx: int, ny: int, W: float, H: float) -> bool:
    """Compare the plain mesh with NGSolve's structured mesh; print and return the verdict."""
    from ngsolve.meshes import MakeStructured2DMesh

    mesh = MakeStructured2DMesh(quads=False, nx=nx, ny=ny, mapping=lambda x, y: (W * x, H * y))
    ngm = mesh.ngmesh
    ng_xy = np.array(ngm.Coordinates())[:, :2]
    ng_tri = np.array([[v.nr for v in el.vertices] for el in mesh.Elements()])
    xy, tri = plain.structured_mesh(nx, ny, W, H)
    same_xy = ng_xy.shape == xy.shape and np.array_equal(ng_xy, xy)
    same_tri = ng_tri.shape == tri.shape and np.array_equal(np.sort(ng_tri, axis=1), np.sort(tri, axis=1))
    # diagonal of the first square: the edge that is not axis-parallel
    first = ng_xy[ng_tri[0]]
    print(f"[mesh] {nx}x{ny}: vertices identical: {same_xy}, triangles identical (as vertex sets): {same_tri}; "
          f"NGSolve's first triangle {first.round(6).tolist()} (diagonal from lower-right to upper-left)")
    return same_xy and same_tri


def check_matrices(nx: int, ny: int) -> bool:
    """Compare K_A, K_G with the package's assembled matrices (relative max difference)."""
    from workbench.discrete import discretisation
    from workbench.input.scenes import scene
    from workbench.discrete.solvers import to_scipy

    sc = scene("tp5", nx=nx, ny=ny)
    d = discretisation.build(sc)
    v = sc.values
    xy, tri = plain.structured_mesh(nx, ny, v["width"], v["height"])
    E, nu = v["E"], v["nu"]
    ok = True
    for name, mat, (lam, two_mu) in (("K_A", d.viscous.mat, (v["a1"], v["a2"])),
                                      ("K_G", d.elastic.mat, (E * nu / (1 - nu * nu), E / (1 + nu)))):
        ours, theirs = plain.stiffness(xy, tri, lam, two_mu), to_scipy(mat)
        rel = abs(ours - theirs).max() / abs(theirs).max()
        print(f"[matrix] {name}: max |plain - workbench| / max |workbench| = {rel:.2e}")
        ok &= rel < 1e-13
    return ok


def check_quadrature(nx: int = 10, ny: int = 2, seed: int = 0) -> tuple[int, int]:
    """Find by experiment the Gauss rules NGSolve uses for the package's contact and rate forms.

    Returns
    -------
    (n_contact, n_rate) : tuple of int
        Points per facet of the rule that reproduces each form to round-off.
    """
    import ngsolve as ngs
    from workbench.discrete import discretisation
    from workbench.input.scenes import scene

    for order in range(5):
        ir = ngs.IntegrationRule(ngs.SEGM, order)
        print(f"[quadrature] NGSolve IntegrationRule(SEGM, {order}): {len(ir.points)} points "
              f"{[p[0] for p in ir.points]}")
    sc = scene("tp5", nx=nx, ny=ny)
    d = discretisation.build(sc)
    v = sc.values
    rng = np.random.default_rng(seed)
    u = d.u.vec.FV().NumPy()
    u[:] = rng.normal(scale=0.4, size=u.size)  # |u_nu| ~ L: both kinks (0 and -L) fall inside facets
    u[d.dirichlet_dofs] = 0.0
    b = d.beta.vec.FV().NumPy()
    b[d.beta_dofs] = rng.uniform(0.5, 1.0, size=d.beta_dofs.size)
    d.contact_form.Assemble()
    d.rate_form.Assemble()
    order = np.argsort(d.node_xyz[:, 0])
    y_dofs = d.node_dofs[order, 1]
    j_ref = d.contact_form.vec.FV().NumPy()[y_dofs]
    forder = np.argsort(d.facet_xyz[:, 0])
    rate_ref = (d.rate_form.vec.FV().NumPy()[d.beta_dofs] / d.facet_measure)[forder]
    beta = b[d.beta_dofs][forder]
    xb = d.node_xyz[order, 0]
    u_nu = -u[y_dofs]
    g, L, c = v["gamma_nu"], v["L"], v["c_nu"]
    found = {}
    for n in range(1, 5):
        p, w = plain.gauss_rule(n)
        hf = np.diff(xb)
        s = u_nu[:-1, None] * (1 - p) + u_nu[1:, None] * p
        f = c * np.maximum(s, 0) - g * beta[:, None] ** 2 * np.maximum(-np.clip(s, -L, L), 0)
        j = np.zeros(xb.size)  # j on w_y = -(j on w_nu)
        j[:-1] -= (f * (1 - p) * w).sum(1) * hf
        j[1:] -= (f * p * w).sum(1) * hf
        rb = np.maximum(-np.clip(s, -L, L), 0)
        rate = (np.maximum(g * beta[:, None] * rb * rb - v["eps_a"], 0) * w).sum(1)
        ej = np.abs(j - j_ref).max() / np.abs(j_ref).max()
        er = np.abs(rate - rate_ref).max() / np.abs(rate_ref).max()
        print(f"[quadrature] {n}-point Gauss: contact form j rel. diff {ej:.2e}, rate form P_B rel. diff {er:.2e}")
        if ej < 1e-13:
            found.setdefault("contact", n)
        if er < 1e-13:
            found.setdefault("rate", n)
    print(f"[quadrature] NGSolve uses: {found.get('contact')}-point Gauss for j (P1 test space, order 2), "
          f"{found.get('rate')}-point (midpoint) for P_B (P0 test space, order 0)")
    return found.get("contact"), found.get("rate")


def compare_runs(ref_path: str, n_contact: int, n_rate: int) -> bool:
    """Run the plain script with the found rules and compare it with the workbench archive."""
    import workbench

    ds = workbench.load(ref_path)
    h, k = float(ds.attrs["h"]), float(ds.attrs["k"])
    nx, ny = (int(c) for c in str(ds.attrs["cells"]).split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "plain.npz"
        plain.main(["--nx", str(nx), "--ny", str(ny), "--k", repr(k), "--contact-points", str(n_contact),
                    "--rate-points", str(n_rate), "--out", str(out)])
        p = dict(np.load(out))
    assert np.array_equal(p["time"], ds["time"].values), "time grids differ"

    px, py = ds["probe_x"].values, ds["probe_y"].values
    worst_u = 0.0
    scale = 0.0
    for i, (x, y) in enumerate(p["probe_xy"]):
        j = int(np.nonzero((np.abs(px - x) < 1e-12) & (np.abs(py - y) < 1e-12))[0][0])
        ref = ds["u_probe"].values[:, j, :]
        diff = np.abs(p["u_probe"][:, i, :] - ref).max()
        scale = max(scale, np.abs(ref).max())
        worst_u = max(worst_u, diff)
        print(f"[run] probe ({x:g}, {y:g}): max |u| = {np.abs(ref).max():.6f}, max |u_plain - u_wb| = {diff:.3e}")
    rel_u = worst_u / scale

    # u at T: every dof (workbench's u_dofs are (vertex v, component c) -> v + c nv, as plain's layout)
    nv = ds.sizes["vertex"]
    assert np.array_equal(np.column_stack([ds["vertex_x"].values, ds["vertex_y"].values]), p["vertex_xy"])
    last = int(np.argmin(np.abs(ds["snapshot_time"].values - ds["time"].values[-1])))
    u_T_ref = ds["u_dofs"].values[last].reshape(2, nv).T
    rel_T = np.abs(p["u_final"] - u_T_ref).max() / np.abs(u_T_ref).max()

    forder = np.argsort(ds["facet_x"].values)
    assert np.allclose(ds["facet_x"].values[forder], p["facet_x"], rtol=0, atol=1e-12)
    beta_ref = ds["beta"].values[:, forder]
    diff_beta = np.abs(p["beta"] - beta_ref).max()
    drop = (1.0 - beta_ref).max()

    print(f"[run] tp5, {nx}x{ny}, {ds.attrs['ndof']} dofs, {p['time'].size - 1} steps:")
    print(f"[run]   u probes (1,0), (1,H), all steps: max |u_plain - u_wb| / max |u| = {rel_u:.3e}")
    print(f"[run]   u at T, all dofs:                max |u_plain - u_wb| / max |u| = {rel_T:.3e}")
    print(f"[run]   beta, all steps and facets:       max |beta_plain - beta_wb|     = {diff_beta:.3e} "
          f"(largest debonding 1 - beta = {drop:.3e}, relative {diff_beta / drop:.3e})")
    # round-off yardstick: the plain run against itself with E and a1 moved by one unit in the last place.
    # cond(K_A) ~ 3e7 here, so a change of the matrices at round-off level moves the solution by ~1e-10.
    base = plain.main(["--nx", str(nx), "--ny", str(ny), "--k", repr(k), "--quiet"])
    ulp = float(np.finfo(float).eps)
    moved = plain.main(["--nx", str(nx), "--ny", str(ny), "--k", repr(k), "--quiet",
                        "--E", repr(1000.0 * (1 + ulp)), "--a1", repr(30.0 * (1 - ulp))])
    yard_u = np.abs(base["u_probe"] - moved["u_probe"]).max() / np.abs(base["u_probe"]).max()
    yard_b = np.abs(base["beta"] - moved["beta"]).max()
    print(f"[run]   yardstick, plain vs plain with E, a1 changed by 1 ulp: u probes {yard_u:.3e}, beta {yard_b:.3e}")
    ok = rel_u <= TOL and rel_T <= TOL and diff_beta <= TOL
    print(f"[run] agreement to {TOL:g}: {'PASS' if ok else 'FAIL'}")
    return ok


def main(argv=None) -> int:
    """Run the checks; exit status 0 when all pass."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ref", help="workbench archive of `workbench run tp5 --h 0.00625 --k 0.001` (made if absent)")
    args = ap.parse_args(argv)
    ok = check_mesh(160, 16, 1.0, 0.1) & check_mesh(3, 2, 1.0, 0.1)
    ok &= check_matrices(160, 16)
    n_contact, n_rate = check_quadrature()
    ok &= (n_contact, n_rate) == (2, 1)
    with tempfile.TemporaryDirectory() as tmp:
        ref = args.ref
        if ref is None:
            ref = str(Path(tmp) / "ref.nc")
            subprocess.run(["workbench", "run", "tp5", "--h", "0.00625", "--k", "0.001", "-o", ref, "--no-progress"],
                           check=True)
        ok &= compare_runs(ref, n_contact or 2, n_rate or 1)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
