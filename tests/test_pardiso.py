"""MKL PARDISO (ctypes): its factor, its Schur complements, and the condensed contact stiffness made inside one
factorization instead of one back-substitution per contact point, against dense linear algebra and the solves."""
import sys

import numpy as np
import pytest
import scipy.sparse as sp

import workbench
from workbench.discrete import condensation, discretisation, pardiso, solvers
from workbench.errors import ParameterError

needs_mkl = pytest.mark.skipif(not pardiso.available(), reason="MKL could not be loaded")


def _spd(n=400, seed=0):
    A = sp.random(n, n, 0.01, random_state=seed)
    return (A @ A.T + sp.diags(np.linspace(0.5, 3.0, n))).tocsr()


@needs_mkl
def test_factor_schur_complement_and_compliance_against_dense_algebra():
    A = _spd()
    dense_inverse = np.linalg.inv(A.toarray())
    rng = np.random.default_rng(1)
    b = rng.standard_normal((A.shape[0], 3))
    f = pardiso.Factor(A)
    assert np.abs(A @ f.solve(b) - b).max() < 1e-12 * np.abs(b).max()
    assert np.abs(A @ f.solve(b[:, 1]) - b[:, 1]).max() < 1e-12 * np.abs(b).max()  # (one right-hand side)
    keep = rng.choice(A.shape[0], 30, replace=False)  # (unsorted: the result is in this order)
    S = pardiso.schur_complement(A, keep)
    assert np.abs(S - np.linalg.inv(dense_inverse[np.ix_(keep, keep)])).max() < 1e-10 * np.abs(S).max()
    B = sp.random(20, A.shape[0], 0.05, random_state=2).tocsr()
    C = pardiso.compliance(A, B)
    reference = B @ dense_inverse @ B.T.toarray()
    assert np.abs(C - reference).max() < 1e-10 * np.abs(reference).max()


@needs_mkl
def test_a_factor_that_keeps_unknowns_last_gives_their_schur_complement_and_solves_in_parts():
    """Factor(A, keep): the Schur complement from the same factorization; forward gives the condensed load there;
    backward from any values there solves the other unknowns' equations; solve is A's solve."""
    A = _spd()
    n, dense = A.shape[0], A.toarray()
    rng = np.random.default_rng(3)
    keep = rng.choice(n, 25, replace=False)
    F = pardiso.Factor(A, keep)
    k = np.sort(keep)
    o = np.setdiff1d(np.arange(n), k)
    A_oo_inv_A_ok = np.linalg.solve(dense[np.ix_(o, o)], dense[np.ix_(o, k)])
    S = dense[np.ix_(k, k)] - dense[np.ix_(k, o)] @ A_oo_inv_A_ok
    assert np.array_equal(F.keep, k) and np.abs(F.schur - S).max() < 1e-10 * np.abs(S).max()
    b = rng.standard_normal((n, 2))
    assert np.abs(A @ F.solve(b) - b).max() < 1e-11 * np.abs(b).max()
    assert np.abs(A @ F.solve(b[:, 0]) - b[:, 0]).max() < 1e-11 * np.abs(b).max()
    y = F.forward(b[:, 0])
    condensed = b[k, 0] - dense[np.ix_(k, o)] @ np.linalg.solve(dense[np.ix_(o, o)], b[o, 0])
    assert np.abs(y[k] - condensed).max() < 1e-11 * np.abs(condensed).max()
    x_k = rng.standard_normal(k.size)  # any values there (a contact problem's): the others follow
    y[k] = x_k
    x = F.backward(y)
    assert np.abs(x[k] - x_k).max() < 1e-12 * np.abs(x_k).max()
    assert np.abs((A @ x - b[:, 0])[o]).max() < 1e-11 * np.abs(b).max()


@needs_mkl
def test_every_multiple_of_a_shared_factor_reads_one_stiffness_and_compliance_unformed():
    """Scaled.kept for two multiples c of one factor: c S and S^-1 / c (S the Schur complement from dense algebra),
    read through blocks, rows, products and the diagonal of the same two arrays, none formed per multiple; the dense
    products (BLAS's symmetric one with the multiple as its alpha) and the springs' factor on a multiple equal those
    on the matrix formed."""
    from workbench.discrete.springs import SpringsFactor

    A = _spd()
    n, dense = A.shape[0], A.toarray()
    keep = np.sort(np.random.default_rng(5).choice(np.arange(1, n), 30, replace=False))
    o = np.setdiff1d(np.arange(1, n), keep)
    S = dense[np.ix_(keep, keep)] - dense[np.ix_(keep, o)] @ np.linalg.solve(dense[np.ix_(o, o)],
                                                                             dense[np.ix_(o, keep)])
    base, found = solvers.PardisoCholesky(A, np.arange(1, n)), {}
    (S2, G2, _), (S5, G5, _) = (solvers.Scaled(base, c, found).kept(keep) for c in (2.0, 5.0))
    assert S2.base is S5.base and G2.base is G5.base  # (one stiffness and one compliance for every multiple)
    x, rows = np.cos(np.arange(30.0)), np.array([3, 7, 11])
    for c, Sc, Gc in ((2.0, S2, G2), (5.0, S5, G5)):
        stiffness, compliance = c * S, np.linalg.inv(S) / c
        for got, want in ((Sc, stiffness), (Gc, compliance)):
            scale = np.abs(want).max()
            assert np.abs(got @ x - want @ x).max() < 1e-10 * scale * np.abs(x).sum()
            assert np.abs(got[np.ix_(rows, rows)] - want[np.ix_(rows, rows)]).max() < 1e-10 * scale
            assert np.abs(got[rows] - want[rows]).max() < 1e-10 * scale
            assert np.abs(got.diagonal() - want.diagonal()).max() < 1e-10 * scale
        schur = condensation.DenseSchur(Sc, Gc)
        assert np.abs(schur.apply(x) - compliance @ x).max() < 1e-10 * np.abs(compliance @ x).max()
        J, R = sp.diags(np.linspace(1.0, 2.0, 20) * np.abs(stiffness).max()).tocsr(), np.arange(20)
        r = np.sin(np.arange(20.0))
        got = SpringsFactor(J, R, Gc, whole=True).solver()(r)
        want = SpringsFactor(J, R, compliance, whole=True).solver()(r)
        assert np.abs(got - want).max() < 1e-10 * np.abs(want).max()
    with pytest.raises(TypeError, match="forming c A whole"):
        np.asarray(S2)


@needs_mkl
def test_pardiso_condenses_inside_its_own_factorization_when_asked_first_and_splits_a_solve():
    """PardisoCholesky asked for the condensed stiffness before any solve keeps the contact dofs last: the stiffness
    equals the separate Schur complement (the route once the factor exists, which then has no split), and the split
    solve gives z at C and u from values at C."""
    from workbench.schemes.contact_nodes import ContactNodes

    d = discretisation.build(workbench.scene("memory_block", h=0.25))
    discretisation.assemble(d)
    C = ContactNodes(d).C[::-1].copy()  # (not in the dofs' order)
    kept = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "pardiso")
    plain = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "pardiso")
    r = np.random.default_rng(4).standard_normal(d.ndof)
    r[d.dirichlet_dofs] = 0.0
    z = np.zeros(d.ndof)
    plain.solve(r, z)  # (factored now: its condensed stiffness is the separate Schur complement)
    S, reference = kept.condensed_stiffness(C), plain.condensed_stiffness(C)
    assert plain.split(C) is None and kept.split(C[::-1]) is None
    assert np.abs(S - reference).max() < 1e-10 * np.abs(reference).max()
    split = kept.split(C)
    z_C = split.free_displacement(r)
    assert np.abs(z_C - z[C]).max() < 1e-10 * np.abs(z).max()
    u_C = z_C + 0.1 * np.abs(z).max() * np.sin(np.arange(C.size))
    u = np.zeros(d.ndof)
    split.expand(u_C, u)
    K = solvers.to_scipy(d.elastic.mat)
    others = np.setdiff1d(kept.free, C)  # (their equations hold; at C the difference is the force holding u_C)
    assert np.array_equal(u[C], u_C) and np.abs((K @ u - r)[others]).max() < 1e-9 * np.abs(r).max()
    whole = np.zeros(d.ndof)
    kept.solve(r, whole)  # (a whole solve through the kept factor)
    assert np.abs(whole - z).max() < 1e-10 * np.abs(z).max()


@needs_mkl
@pytest.mark.parametrize("name, kw", [("memory_block", dict(h=0.2, solver="pardiso")),
                                      ("block", dict(h=0.2, scheme="bdf2", T=0.1, solver="pardiso")),
                                      ("memory_rod", dict(solver="pardiso")),
                                      ("rod", dict(solver="pardiso", T=0.5, scheme="implicit"))])
def test_runs_that_solve_in_parts_equal_runs_with_two_solves_a_step(monkeypatch, name, kw):
    """Model B and Model A (bdf2), and the rods' moving clamp, condensed on PARDISO's factor: one solve in two parts
    a step against z and u by two whole solves (the split switched off), and the back-substitutions counted."""
    runs, expanded, expand = {}, [], solvers.SplitSolve.expand
    monkeypatch.setattr(solvers.SplitSolve, "expand", lambda self, u_C, out: expanded.append(1) or expand(self, u_C, out))
    for split in (True, False):
        if not split:
            monkeypatch.setattr(solvers.PardisoCholesky, "split", lambda self, C: None)
        runs[split] = workbench.run(name, contact_solver="condensed", progress=False, **kw)
    a, b = runs[True], runs[False]
    assert len(expanded) >= a.sizes["time"] - 1  # (every step split; Model A's u(0) is given)
    for v in ("u_contact", "contact_pressure", "u_probe"):
        if v in b:
            assert np.nanmax(np.abs(a[v] - b[v])) <= 1e-9 * max(float(np.nanmax(np.abs(b[v]))), 1e-300), v
    if "linear_solves" in b:  # (Model B: one back-substitution fewer a step)
        assert int(b.linear_solves.sum() - a.linear_solves.sum()) == a.sizes["time"]


@needs_mkl
def test_a_singular_matrix_is_refused_by_name():
    A = sp.diags([1.0, 0.0, 1.0]).tocsr()
    with pytest.raises(RuntimeError, match="PARDISO"):
        pardiso.Factor(A)


@needs_mkl
@pytest.mark.parametrize("name, kw", [("memory_hertz3d", {}), ("memory_hertz", dict(order=2)), ("slab", {})])
def test_the_condensed_stiffness_equals_the_one_made_by_back_substitutions(name, kw):
    """P1 vertices (dofs C) and P2 traces (B), with the banded and the PARDISO factor."""
    from workbench.schemes.contact_nodes import ContactNodes

    d = discretisation.build(workbench.scene(name, **kw))
    discretisation.assemble(d)
    if name == "slab":
        from workbench.discrete.condensation import ContactOperator

        C, B = ContactOperator(d).C, None
    else:
        nodes = ContactNodes(d)
        C, B = nodes.C, nodes.B
    for method in ("banded", "pardiso"):
        s = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, method)
        inside = s.condensed_stiffness(C, B)
        by_solves = condensation.CondensedSystem._by_solves(s, d.ndof, C, 64, B)
        assert inside.shape == by_solves.shape and inside.shape[0] > 10
        assert np.abs(inside - by_solves).max() < 1e-8 * np.abs(by_solves).max(), method


@needs_mkl
def test_a_run_with_pardiso_equals_the_run_with_ngsolves_factor():
    """The 3D hemisphere's Signorini run, condensed, with auto (PARDISO's factor and Schur complement) and with
    NGSolve's factor and one back-substitution per contact point."""
    runs = {s: workbench.run("memory_hertz3d", contact_solver="condensed", solver=s, progress=False)
            for s in ("auto", "sparsecholesky")}
    assert runs["auto"].attrs["linear_solver"] == "pardiso"
    a, b = (runs[s].contact_pressure.values for s in ("auto", "sparsecholesky"))
    assert np.abs(a - b).max() < 1e-7 * np.abs(b).max()


def test_without_mkl_pardiso_is_refused_before_any_work_and_auto_keeps_ngsolves_factor(monkeypatch):
    monkeypatch.setattr(pardiso, "available", lambda: False)
    with pytest.raises(ParameterError, match="solver = 'pardiso' needs Intel MKL"):
        workbench.run("memory_hertz3d", solver="pardiso", progress=False)
    with pytest.raises(ParameterError, match="solver = 'mixed' needs Intel MKL"):
        workbench.run("memory_hertz3d", solver="mixed", progress=False)  # (its factor is PARDISO's too)
    ds = workbench.run("memory_hertz3d", progress=False)
    assert ds.attrs["linear_solver"] == "sparsecholesky"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/maps")
@needs_mkl
def test_one_unknown_left_to_eliminate_is_condensed_without_mkls_schur_complement(tmp_path):
    """MKL's Schur complement with one unknown outside the kept ones reads memory it never wrote: the rod at
    h = 0.5 (two free dofs, one kept) crashed its process (a segmentation fault, nothing written), every time with
    glibc's MALLOC_PERTURB_ filling fresh memory, now and then without. It is condensed densely; a factor asked to
    keep that many is refused by name. Each in a process of its own with MALLOC_PERTURB_, against dense algebra."""
    import os
    import subprocess

    code = ("import numpy as np, scipy.sparse as sp\n"
            "from workbench.discrete import pardiso\n"
            "for n, m in ((2, 1), (3, 2), (9, 8)):\n"
            "    A = (sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n)) + 0.5 * sp.eye(n)).tocsr()\n"
            "    keep = np.arange(n - m, n)\n"
            "    S = pardiso.schur_complement(A, keep)\n"
            "    exact = np.linalg.inv(np.linalg.inv(A.toarray())[np.ix_(keep, keep)])\n"
            "    assert np.abs(S - exact).max() < 1e-12, (n, m)\n"
            "print('ok')\n")
    env = dict(os.environ, MALLOC_PERTURB_="165")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env)
    assert out.returncode == 0 and out.stdout.strip() == "ok", (out.returncode, out.stderr[-2000:])
    run = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "tp1", "--h", "0.5", "--set", "scheme=implicit",
                          "--threads", "1", "--no-progress", "-o", str(tmp_path / "tp1.nc")],
                         capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode == 0 and (tmp_path / "tp1.nc").is_file(), (run.returncode, run.stderr[-2000:])
    A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(3, 3)).tocsr() + sp.eye(3)
    with pytest.raises(ValueError, match="keep at most n - 2"):
        pardiso.Factor(A, keep=np.array([1, 2]))


def test_import_workbench_does_not_load_mkl():
    """MKL is loaded at its first use in a run, so importing workbench leaves a user's process (and an MKL it may
    load later, with its own threading) as it was."""
    import subprocess

    code = "import workbench; print('libmkl' in open('/proc/self/maps').read())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


@needs_mkl
@pytest.mark.parametrize("name, kw", [("memory_block", dict(h=0.05)), ("block", dict(h=0.05)),
                                      ("memory_hertz3d", dict(h_contact=0.01))],
                         ids=["P1 block", "P2 block", "hemisphere"])
def test_the_factor_estimate_auto_decides_by_bounds_pardisos_own_count(name, kw):
    """The memory ``auto`` weighs before it factors (``cg`` beyond FACTOR_BYTES) is that of the factor it would take:
    PARDISO's, whose analysis counts its nonzeros. The estimate must bound the count without overstating it more than
    2.5x (NGSolve's estimate, which auto used before, overstates it 2.3-3.8x: auto gave up the factor at 150k dofs
    where PARDISO's fits up to 240k)."""
    d = discretisation.build(workbench.scene(name, **kw))
    discretisation.assemble(d)
    K = solvers.to_scipy(d.elastic.mat).tocsr()
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    actual = 8.0 * pardiso.Factor(K[free][:, free]).nonzeros
    estimate = solvers.sparse_factor_bytes(3, d.ndof, "auto")
    assert actual <= estimate <= 2.5 * actual, (actual, estimate)
    assert solvers.sparse_factor_bytes(3, d.ndof, "sparsecholesky") > 2.0 * actual
    assert solvers.choose("auto", 3, 200_000, True) == "auto"  # (a factor of about 1.5 GB: kept)
    assert solvers.choose("auto", 3, 300_000, True) == "mixed"  # (about 2.6 GB; in single precision 1.3 GB)
    assert solvers.choose("auto", 3, 700_000, True) == "cg"  # (about 3.5 GB in single precision)
