"""The banded Cholesky (RCM order) and MKL PARDISO's Cholesky solve the same systems as NGSolve's sparse Cholesky."""
import gc

import numpy as np
import pytest
import scipy.sparse as sp
import xarray as xr

import workbench
from workbench.discrete import discretisation, pardiso, solvers

SPARSE = "pardiso" if pardiso.available() else "sparsecholesky"  # (what auto takes for a wide band)


@pytest.mark.parametrize("name, kw", [("slab", dict(h=0.05)), ("block", dict(h=0.1)), ("tp1", dict(h=0.1)),
                                      ("slab", dict(h=0.1, order=2))])
def test_banded_matches_sparsecholesky(name, kw):
    d = discretisation.build(workbench.scene(name, **kw))
    rhs = np.random.default_rng(0).standard_normal(d.ndof)
    out = {}
    for method in ("banded", "sparsecholesky") + (("pardiso",) if pardiso.available() else ()):
        s = solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, method)
        out[method] = np.zeros(d.ndof)
        s.solve(rhs, out[method])
    free = np.array(d.fes.FreeDofs(), dtype=bool)
    assert np.all(out["banded"][~free] == 0)
    K = solvers.to_scipy(d.viscous.mat)
    for method, x in out.items():
        assert np.all(x[~free] == 0)
        assert np.allclose(x, out["sparsecholesky"], rtol=1e-9, atol=1e-12 * np.abs(x).max()), method
        assert np.abs((K @ x - rhs)[free]).max() < 1e-9 * np.abs(rhs).max(), method


def test_auto_takes_the_band_only_when_it_is_narrow_and_small(monkeypatch):
    """auto: the thin slab's narrow band is factored banded; a band that would need more than BAND_BYTES of storage
    (3D: it grows like n^(5/3); the P2 block at 118k dofs needed 2.2 GB, 4.6 GB peak) goes to the sparse factor."""
    d = discretisation.build(workbench.scene("slab", h=0.05))
    K = solvers.to_scipy(d.viscous.mat)
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    _, bandwidth = solvers.rcm(K, free)
    assert bandwidth == solvers.BandedCholesky(K, free).bandwidth  # (read from the permuted matrix itself)
    band = 8.0 * (bandwidth + 1) * free.size
    assert solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec).name == "banded"
    monkeypatch.setattr(solvers, "BAND_BYTES", 0.5 * band)
    assert solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec).name == SPARSE
    assert solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, "banded").name == "banded"  # asked for: kept
    monkeypatch.setattr(pardiso, "available", lambda: False)  # (no MKL: NGSolve's own factor)
    assert solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec).name == "sparsecholesky"


@pytest.mark.parametrize("name, kw", [("block", dict(h=0.05, order=2)), ("slab", dict(h=0.00625))])
def test_cg_solves_the_same_systems(name, kw):
    """solver = 'cg' (AMG-preconditioned CG on the rigid-body modes) solves K_A x = b as the sparse factor does, to
    its relative residual CG_TOL or to the round-off the direct solve itself reaches (the thin P1 slab: 1e-11 ||b||,
    measured); warm started from a nearby solution it needs fewer iterations."""
    d = discretisation.build(workbench.scene(name, **kw))
    rhs = np.random.default_rng(0).standard_normal(d.ndof)
    direct = solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, "sparsecholesky")
    cg = solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, "cg", fes=d.fes)
    a, b = np.zeros(d.ndof), np.zeros(d.ndof)
    direct.solve(rhs, a)
    cg.solve(rhs, b)
    free = np.array(d.fes.FreeDofs(), dtype=bool)
    assert np.all(b[~free] == 0)
    K = solvers.to_scipy(d.viscous.mat)
    floor = np.linalg.norm((K @ a - rhs)[free])
    assert np.linalg.norm((K @ b - rhs)[free]) <= max(1.01 * solvers.CG_TOL * np.linalg.norm(rhs[free]), 10 * floor)
    assert np.abs(a - b).max() < 1e-7 * np.abs(a).max()
    cold = cg.last_iterations
    cg.solve(rhs * (1 + 1e-4), b)  # out holds the last solution: the warm start
    assert cg.last_iterations < cold


def test_rigid_body_modes_are_exact():
    """The modes are in the kernel of the unconstrained stiffness (2D: 3, 3D: 6)."""
    import ngsolve as ngs

    for name in ("slab", "block"):
        sc = workbench.scene(name, h=0.1, order=2)
        m = sc.model_of()
        mesh = m.geometry.mesh()
        fes = ngs.VectorH1(mesh, order=2)
        B = solvers.rigid_body_modes(fes)
        K = solvers.to_scipy(discretisation.stiffness(fes, m.viscous, m.geometry.dim).mat)
        assert B.shape[1] == (3 if name == "slab" else 6)
        assert np.abs(K @ B).max() < 1e-9 * np.abs(K).max() * np.abs(B).max()


@pytest.mark.parametrize("name, kw", [("block", dict(scheme="bdf2", T=0.03, k=0.01, order=2)),
                                      ("memory_block", dict(T=0.2, k=0.1, order=1))])
def test_auto_takes_cg_for_a_large_3d_implicit_run_with_its_contact_on_the_whole_body(monkeypatch, name, kw):
    """Beyond FACTOR_BYTES in 3D, auto resolves the implicit schemes' solver to cg, and their contact to the coupled
    solver (which needs no factor): the run agrees with the factored one to the solvers' tolerances; with
    contact_solver = 'condensed' auto keeps the factor (measured: the P2 block at 270963 dofs, BDF2, 10 steps, ran in
    3.1 GB where the sparse factor alone passes 5 GB)."""
    kw = dict(h=0.1, contact_solver="auto", progress=False, **kw)
    direct = workbench.run(name, **kw)
    monkeypatch.setattr(solvers, "FACTOR_BYTES", 1.0)
    d = discretisation.build(workbench.scene(name, **{k: v for k, v in kw.items() if k != "progress"}))
    assert d.step_solver() == "cg"
    condensed = {k: v for k, v in kw.items() if k not in ("progress", "contact_solver")} | {"contact_solver": "condensed"}
    assert discretisation.build(workbench.scene(name, **condensed)).step_solver() == "auto"
    ds = workbench.run(name, **kw)
    assert ds.attrs["contact_solver_used"] == "coupled"
    assert np.abs(ds.u_probe - direct.u_probe).max() < 1e-7 * np.abs(direct.u_probe).max()


def test_auto_takes_cg_for_a_large_3d_explicit_run_only(monkeypatch):
    """auto resolves to cg for the explicit scheme in 3D when the sparse factor would exceed FACTOR_BYTES; the run
    then agrees with the direct solver (u at the probes to 1e-9), records its iterations, and estimates k_crit with
    LOBPCG (agreeing with Lanczos to 1e-6); the implicit schemes with the condensed contact solver refuse cg by name
    (with the coupled one they take it: tests/test_coupled_contact.py, and auto takes it for them beyond
    FACTOR_BYTES, above)."""
    kw = dict(order=2, h=0.1, T=0.01, k=0.002, c_nu=100.0)
    direct = workbench.run("block", progress=False, **kw)
    monkeypatch.setattr(solvers, "FACTOR_BYTES", 1.0)
    assert solvers.choose("auto", 3, direct.attrs["ndof"], True) == "cg"
    assert solvers.choose("auto", 3, direct.attrs["ndof"], False) == "auto"
    ds = workbench.run("block", progress=False, **kw)
    assert direct.attrs["linear_solver"] == SPARSE and ds.attrs["linear_solver"] == "cg"
    assert np.abs(ds.u_probe - direct.u_probe).max() < 1e-9 * np.abs(direct.u_probe).max()
    assert abs(ds.attrs["k_crit"] / direct.attrs["k_crit"] - 1) < 1e-6
    assert ds.cg_iterations[0] == 0 and (ds.cg_iterations[1:] > 0).all()
    with pytest.raises(workbench.ParameterError, match="solver = 'cg'"):
        workbench.scene("block", scheme="implicit", solver="cg", contact_solver="condensed")
    # asked for on the rod (one rigid mode; tp3's end moves: the lifted solve), it agrees with the band
    rods = [workbench.run("tp3", solver=s, T=0.5, progress=False) for s in ("cg", "banded")]
    assert rods[0].attrs["linear_solver"] == "cg"
    assert np.abs(rods[0].u_contact - rods[1].u_contact).max() < 1e-9 * np.abs(rods[1].u_contact).max()


@pytest.mark.skipif(not pardiso.available(), reason="needs MKL")
def test_mixed_precision_solves_to_the_double_factor():
    """solver = 'mixed': conjugate gradients in double precision on PARDISO's factor in single precision. On the
    hemisphere's K (3D and graded, the ill-conditioned kind) a random load, a load on 50 surface points (whose true
    residual stalls at 3e-12, above MIXED_TOL: it is accepted below CG_TOL, not iterated on to the limit) and a warm
    start agree with the double factor to 1e-9, each in at most 6 iterations (measured 3), to a true residual below
    CG_TOL. The single factor alone is 1e-4-1e-3 off: without the iterations it fails."""
    d = discretisation.build(workbench.scene("memory_hertz3d", h_contact=0.01))
    mixed = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "mixed")
    exact = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "pardiso")
    assert isinstance(mixed, solvers.MixedPrecision) and mixed.iterative and mixed.warm_start
    K = solvers.to_scipy(d.elastic.mat)
    free = np.array(d.fes.FreeDofs(), dtype=bool)
    rng = np.random.default_rng(3)
    points = np.zeros(d.ndof)
    points[d.vertex_dofs[:50, 2]] = 1.0
    for rhs in (rng.standard_normal(d.ndof), points):
        x, y = np.zeros(d.ndof), np.zeros(d.ndof)
        exact.solve(rhs, x)
        mixed.solve(rhs, y)
        assert 1 <= mixed.last_iterations <= 6
        assert np.all(y[~free] == 0)
        assert np.abs(y - x).max() < 1e-9 * np.abs(x).max()
        assert np.linalg.norm((K @ y - rhs)[free]) <= solvers.CG_TOL * np.linalg.norm(rhs[free])
        single = np.zeros(d.ndof)
        single[free] = mixed.factor.solve(rhs[free])
        assert np.abs(single - x).max() > 1e-6 * np.abs(x).max()  # (what the iterations buy)
        y[free] += 1e-3 * np.abs(x).max() * rng.standard_normal(free.sum())  # a guess near the solution
        mixed.solve(rhs, y)
        assert mixed.last_iterations <= 6 and np.abs(y - x).max() < 1e-9 * np.abs(x).max()


@pytest.mark.skipif(not pardiso.available(), reason="needs MKL")
@pytest.mark.parametrize("size", [1e-40, 1e40])
def test_mixed_precision_solves_loads_outside_single_precisions_range(size):
    """Single precision holds 1e-38-3e38: a Newton correction's load of 1e-26 gained 12 digits below it and divided
    by zero (the slab's BDF2 under error control, rtol = 1e-3). Each preconditioning is scaled into range: loads of
    1e-40 and 1e40 solve as the double factor does, to 1e-9, within 6 iterations."""
    d = discretisation.build(workbench.scene("slab", h=0.1))
    mixed = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "mixed")
    exact = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "pardiso")
    rhs = size * np.random.default_rng(5).standard_normal(d.ndof)
    x, y = np.zeros(d.ndof), np.zeros(d.ndof)
    exact.solve(rhs, x)
    mixed.solve(rhs, y)
    assert np.isfinite(y).all() and np.abs(x).max() > 0
    assert np.abs(y - x).max() < 1e-9 * np.abs(x).max() and mixed.last_iterations <= 6
    if size < 1.0:  # the run that found it, against the double factor's (measured 2.9e-12)
        kw = dict(scheme="bdf2", rtol=1e-3, T=0.05, progress=False)
        a, b = (workbench.run("slab", solver=solver, **kw) for solver in ("mixed", "pardiso"))
        assert a.sizes["time"] == b.sizes["time"]
        assert float(abs(a.u_probe - b.u_probe).max()) < 1e-9 * float(abs(b.u_probe).max())


@pytest.mark.skipif(not pardiso.available(), reason="needs MKL")
def test_mixed_preconditions_the_coupled_solve_by_the_compliance_of_its_own_factorization(monkeypatch):
    """With solver = 'mixed', the single factorization keeps the contact dofs last, and their Schur complement, in
    single precision, gives S approximately: the coupled solve's conjugate gradients take it as preconditioner
    (memory_block at h = 0.1: 84 iterations against 346 with the diagonal; at h = 0.05 126 against 758, and 239
    back-substitutions against 916; the hemisphere at h_contact = 0.01, 13 against 54). The displacements agree with
    the condensed solver on the double factor to 1e-9 (measured 7e-11)."""
    from workbench.discrete import condensation

    kw = dict(h=0.1, T=0.4, k=0.1, progress=False)
    exact = workbench.run("memory_block", solver="pardiso", contact_solver="condensed", **kw)
    runs = {}
    for preconditioned in (True, False):
        if not preconditioned:
            monkeypatch.setattr(condensation.SchurOperator, "preconditioner", lambda self, U, D: None)
        runs[preconditioned] = ds = workbench.run("memory_block", solver="mixed", contact_solver="coupled", **kw)
        assert ds.attrs["linear_solver"] == "mixed"
        assert np.abs(ds.u_probe - exact.u_probe).max() < 1e-9 * np.abs(exact.u_probe).max()
    assert runs[True].linear_iterations.sum() < 0.5 * runs[False].linear_iterations.sum()


@pytest.mark.parametrize("name, kw", [("memory_block", dict(T=0.2, k=0.1)), ("block", dict(scheme="bdf2", T=0.03,
                                                                                             k=0.01))])
def test_auto_takes_mixed_where_only_the_single_factor_fits(monkeypatch, name, kw):
    """Beyond FACTOR_BYTES in 3D auto takes 'mixed' (PARDISO's factor in single precision, half the memory) where
    that fits, and 'cg' where not, or without MKL; the run on 'mixed' solves its contact on the whole body and agrees
    with the factored one to 1e-9 (measured 1e-11). Given by name with the condensed contact solver, 'mixed' is
    refused as 'cg' is."""
    kw = dict(h=0.1, progress=False, **kw)
    direct = workbench.run(name, **kw)
    n = direct.attrs["ndof"]
    double = solvers.sparse_factor_bytes(3, n, "auto")
    monkeypatch.setattr(solvers, "FACTOR_BYTES", 0.75 * double)  # (the double factor too large, the single not)
    taken = "mixed" if pardiso.available() else "cg"
    assert solvers.choose("auto", 3, n, True) == taken and solvers.choose("auto", 3, n, False) == "auto"
    ds = workbench.run(name, **kw)
    assert ds.attrs["linear_solver"] == taken and ds.attrs["contact_solver_used"] == "coupled"
    assert np.abs(ds.u_probe - direct.u_probe).max() < 1e-9 * np.abs(direct.u_probe).max()
    monkeypatch.setattr(solvers, "FACTOR_BYTES", 0.4 * double)  # (neither fits)
    assert solvers.choose("auto", 3, n, True) == "cg"
    monkeypatch.setattr(solvers, "FACTOR_BYTES", 0.75 * double)
    monkeypatch.setattr(pardiso, "available", lambda: False)
    assert solvers.choose("auto", 3, n, True) == "cg"
    with pytest.raises(workbench.ParameterError, match="solver = 'mixed' \\(iterative\\)"):
        workbench.scene(name, solver="mixed", contact_solver="condensed", **{k: kw[k] for k in ("scheme",) if k in kw})


def test_model_a_implicit_archives_record_the_linear_solver_the_steps_took(tmp_path):
    """Model A's implicit schemes factor at their first step; the archive still says which solver it was (default
    arguments: the rod's band; asked for: PARDISO or NGSolve's factor on the block), also after netCDF."""
    assert workbench.run("tp1", scheme="implicit", progress=False).attrs["linear_solver"] == "banded"
    ds = workbench.run("block", scheme="bdf2", h=0.2, T=0.05, solver=SPARSE, progress=False)
    ds.to_netcdf(tmp_path / "b.nc")
    with xr.open_dataset(tmp_path / "b.nc") as back:
        assert back.attrs["linear_solver"] == SPARSE


def test_the_free_block_is_scipys_cut():
    """free_block against SciPy's own indexing, on a random sparse matrix with free dofs in and out of order."""
    rng = np.random.default_rng(3)
    K = sp.random(40, 40, density=0.2, random_state=4, format="csr")
    for free in (np.sort(rng.choice(40, 25, replace=False)), rng.permutation(40)[:30]):
        block = solvers.free_block(K, free)
        assert block.shape == (free.size, free.size)
        assert np.array_equal(block.toarray(), K[free][:, free].toarray())


@pytest.mark.parametrize("name, kw", [("block", dict(scheme="bdf2", h=0.1, T=0.03, k=0.01)),
                                      ("memory_slab", dict(h=0.1, T=0.2, k=0.1, memory_rule="trapezoid",
                                                           prony=[[-1000.0, 0.2, 0.5]])),
                                      ("memory_slab", dict(h=0.1, T=0.2, k=0.1, memory_rule="trapezoid",
                                                           prony=[[-1000.0, 0.2, 0.5]], contact_solver="coupled"))],
                         ids=["bdf2", "vi", "vi, coupled"])
def test_a_scheme_frees_the_factor_it_drops_before_it_factors_the_next(monkeypatch, name, kw):
    """Where a factored operator is large, a scheme holds only as many as fit FACTOR_BYTES together (factors_kept), and
    drops the least recently used one, with its own references to it, before it factors the next: BDF2 factors its
    backward-Euler start and then its own operator, Model B's vi (trapezoid rule) the operator of u(0) and then the
    steps' (its relaxation tensor no multiple of A, whose operators would share one factor). With one kept, no
    earlier factor is alive when the next is made (measured: BDF2 on the P2 block at 271k dofs peaked at 5.67 GB
    holding both, 3.36 GB now); with the default cache one is. The coupled solver's remembered products hold their
    operator weakly, so they keep no dropped factor alive. The results are the same. A finished run frees its
    factors as it returns (a cycle through the scheme kept them until the garbage collector ran: a session's next
    run of memory_hertz3d at 47k dofs peaked at 1219 MB against 873 MB)."""
    import weakref

    made, alive_at = [], []
    factor = solvers.factor

    def tracked(*args, **kwargs):
        alive_at.append(sum(ref() is not None for ref in made))  # (no gc.collect: the run does not call it either)
        out = factor(*args, **kwargs)
        made.append(weakref.ref(out))
        return out

    monkeypatch.setattr(solvers, "factor", tracked)
    gc.disable()  # (what a run leaves in a reference cycle stays alive, with its factors, until the collector runs)
    try:
        cached = workbench.run(name, progress=False, **kw)
        assert all(ref() is None for ref in made)  # (the run's scheme freed as it returns: no cycle holds it)
    finally:
        gc.enable()
    assert len(made) == 2 and alive_at == [0, 1]
    made.clear(), alive_at.clear()
    monkeypatch.setattr(solvers, "factors_kept", lambda *args: 1)
    ds = workbench.run(name, progress=False, **kw)
    assert len(made) == 2 and alive_at == [0, 0]
    assert np.abs(ds.u_probe - cached.u_probe).max() <= 1e-12 * np.abs(cached.u_probe).max()
    assert solvers.factors_kept(3, 200_000, "auto", 4) == (1 if pardiso.available() else 4)  # (1.5 GB each)


def test_a_body_with_A_tau_G_factors_K_G_once_for_every_step_size(monkeypatch):
    """hertz3d has A = tau G, so each implicit step operator a0 K_A + K_G is (a0 tau + 1) K_G. Under error control,
    BDF2's steps take many sizes; one factorization of K_G serves them all (SharedFactor), where before each size had
    its own: with the coupled solver (solves alone), and with the condensed solver, whose condensed stiffness and
    solve in parts around the contact dofs come from that one factorization, scaled. The run takes the same steps
    and equals the one with a factor per operator to round-off (K_A is assembled, not tau K_G: measured 4e-14 of u
    and 2e-12 of the pressures). Not shared: a body whose A is no multiple of G, an iterative solver."""
    from workbench.schemes import step_operators
    from workbench.schemes.implicit_euler import ImplicitEuler

    made, inside = [], []  # (the solvers made; PARDISO's factorizations and condensed stiffnesses, made inside one)
    factor, Factor, schur = solvers.factor, pardiso.Factor, pardiso.schur_complement
    monkeypatch.setattr(solvers, "factor", lambda *args, **kwargs: made.append(1) or factor(*args, **kwargs))
    monkeypatch.setattr(pardiso, "Factor", lambda *args, **kwargs: inside.append(1) or Factor(*args, **kwargs))
    monkeypatch.setattr(pardiso, "schur_complement", lambda *args: inside.append(1) or schur(*args))
    of = step_operators.SharedFactor.of
    for contact_solver in ("coupled", "condensed"):
        kw = dict(h_contact=0.05, scheme="bdf2", rtol=1e-2, T=0.3, contact_solver=contact_solver, progress=False)
        made.clear(), inside.clear()
        monkeypatch.setattr(step_operators.SharedFactor, "of", of)
        shared = workbench.run("hertz3d", **kw)
        assert len(made) == 1 and len(inside) <= 1, contact_solver
        made.clear()
        monkeypatch.setattr(step_operators.SharedFactor, "of", classmethod(lambda cls, d, method: None))
        own = workbench.run("hertz3d", **kw)
        assert len(made) > 5 and shared.sizes["time"] == own.sizes["time"]
        for name in ("u_probe", "contact_pressure"):
            x, y = shared[name].values, own[name].values
            assert np.nanmax(np.abs(x - y)) <= 1e-10 * np.nanmax(np.abs(y)), (contact_solver, name)
    monkeypatch.undo()
    assert ImplicitEuler(discretisation.build(workbench.scene("block", h=0.25))).shared is None  # (A no multiple)
    hertz3d = discretisation.build(workbench.scene("hertz3d", h_contact=0.05, solver="cg"))
    assert ImplicitEuler(hertz3d).shared is None  # (an iterative solver)
