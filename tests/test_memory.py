"""Model B: long memory, unilateral contact with a compliant layer, one variational inequality per step.

References: the rod with memory reduces to a scalar Volterra inequality, solved independently by
workbench.references.volterra (Prony kernel -> an ODE for the memory variables, SciPy DOP853 at rtol 1e-10);
the static elastic problem without memory and contact, assembled here from the plane-stress formula;
the constraint and complementarity conditions themselves.
"""
import ngsolve as ngs
import numpy as np
import pytest

import workbench
from workbench import ParameterError
from workbench.references import volterra
from workbench.study import Study

ROD = dict(a=1.0, moduli=[0.5], taus=[0.2], delta=lambda t: 0.3 * np.sin(2 * np.pi * t) - 0.05, T=1.0, ell=1.0,
           F=0.05, c=1.0, g=0.1)


@pytest.fixture(scope="module")
def rod_reference():
    return volterra.solve_prony(**ROD)


def test_rod_against_volterra(rod_reference, order_of):
    """memory_rod (same data as ROD) converges at first order in k through all four contact states."""
    t = np.linspace(0, 1, 201)
    assert set(np.unique(rod_reference.state(t))) == {0, 1, 2, 3}
    ks = [0.02, 0.01, 0.005]
    errs = []
    for k in ks:
        ds = workbench.run("memory_rod", k=k, progress=False)
        tt = ds.time.values
        errs.append(max(np.abs(ds.u_contact.values[:, 0, 0] - rod_reference.w(tt)).max(),
                        np.abs(ds.u_probe.isel(probe=1).values[:, 0] - rod_reference.u(tt, 0.5)).max()))
        assert set(np.unique(ds.contact_state.values)) == {0, 1, 2, 3}
        assert ds.complementarity.max() <= 1e-12
    assert order_of(ks, errs) >= 0.9 and errs[-1] < 1e-4


def test_prony_recursion_equals_quadrature():
    """An exponential kernel as Prony (O(1) recursion) and as an expression (O(n) quadrature): same to round-off."""
    for name, prony, kernel in (("memory_rod", ((0.5, 0.2),), dict(kernel="exp(-t/0.2)", kernel_E=0.5)),
                                ("memory_slab", ((-1000.0, 0.3, 0.5),),
                                 dict(kernel="exp(-t/0.5)", kernel_E=-1000.0, kernel_nu=0.3))):
        extra = dict(h=0.1, k=0.05) if name == "memory_slab" else {}
        a = workbench.run(name, prony=prony, progress=False, **extra)
        b = workbench.run(name, prony=(), progress=False, **kernel, **extra)
        scale = np.abs(a.u_contact.values).max()
        assert np.abs(a.u_contact.values - b.u_contact.values).max() <= 1e-12 * scale
        assert np.abs(a.stress.values - b.stress.values).max() <= 1e-9 * np.abs(a.stress.values).max()
        assert "memory" in a.attrs["terms"]


POWER_LAW = "(1 + t/0.05)**(-1.5)"  # no exact Prony form: a fit must really approximate it


@pytest.mark.parametrize("tol", [1e-3, 1e-6])
def test_exponential_sum_meets_its_bound(tol):
    """The fitted exponential sum of a power-law kernel is within the stated bound of b, checked here on points
    of its own (random and near 0, none of the fit's), and the bound it states is <= the tolerance asked."""
    from workbench.physics.kelvin_voigt import Scalar
    from workbench.physics.memory import GeneralKernel

    b = lambda t: (1 + np.asarray(t) / 0.05) ** -1.5  # noqa: E731
    fit = GeneralKernel(lambda t: b(t), Scalar(2.0)).exponential_sum(T=1.0, tol=tol)
    t = np.concatenate([np.random.default_rng(1).uniform(0, 1, 50000), np.geomspace(1e-9, 1e-2, 3000)])
    approx = sum(C.modulus * np.exp(-t / tau) for C, tau in fit.terms) / 2.0
    assert fit.fit["error"] <= tol and np.abs(approx - b(t)).max() <= 1.05 * fit.fit["error"] + 1e-14
    assert fit.base[0].modulus == 2.0 and len(fit.base[1]) == fit.fit["terms"] <= 32


def test_exponential_kernel_runs_match_the_quadrature_at_flat_cost():
    """memory_slab with a power-law kernel. Rectangle rule: the exponential-sum run is within the fit's error of
    the O(n) quadrature (the same rule with the exact kernel). Both rules: it equals the run with the fitted
    terms given as an ordinary Prony series (32 stiffness matrices; the fitted run shares one). (The trapezoid
    rule integrates a Prony term exactly against piecewise-linear u and a general kernel by the product trapezoid
    rule, so there the two differ by O(k^2).) It records the terms and the bound, keeps no history of u and
    applies the memory with one matvec per step, whatever the number of terms."""
    from workbench.discrete import discretisation
    from workbench.schemes import scheme_class

    kernel = dict(prony=(), kernel=POWER_LAW, kernel_E=-1000.0, kernel_nu=0.3, h=0.1, k=0.02)
    for rule in ("rectangle", "trapezoid"):
        fitted = workbench.run("memory_slab", memory_rule=rule, kernel_approximation="exponentials", kernel_tol=1e-8,
                               progress=False, **kernel)
        u = fitted.u_contact.values
        scale = np.abs(u).max()
        assert fitted.attrs["kernel_terms"] >= 8 and fitted.attrs["kernel_fit_error"] <= 1e-8
        if rule == "rectangle":
            exact = workbench.run("memory_slab", memory_rule=rule, progress=False, **kernel)
            assert np.abs(exact.u_contact.values - u).max() <= 1e-7 * scale
        terms = workbench.scene("memory_slab", kernel_approximation="exponentials", kernel_tol=1e-8,
                                **kernel).model_of().memory
        prony = [(-1000.0 * c, 0.3, tau) for c, (_, tau) in zip(terms.base[1], terms.terms)]
        plain = workbench.run("memory_slab", memory_rule=rule, progress=False, **dict(kernel, prony=prony, kernel="0"))
        assert np.abs(plain.u_contact.values - u).max() <= 1e-10 * scale
    sc = workbench.scene("memory_slab", kernel_approximation="exponentials", **kernel)
    sch = scheme_class("vi")(discretisation.build(sc))
    calls = []
    sch.memory._add_matvec = lambda K, H, out: calls.append(K)
    sch.start(0.0)
    sch.accept(0.0)
    for n in range(3):
        sch.step(n * 0.02, (n + 1) * 0.02)
        sch.accept((n + 1) * 0.02)
    assert sch.memory.kind == "prony" and len(sch.memory.histories) == fitted.attrs["kernel_terms"]
    assert len(calls) == 3  # (one matvec a step: no stored u_j, whatever the number of terms)


def test_static_elastic_recovered():
    """No memory, nothing touching (pulled up): each step is the static plane-stress solution."""
    ds = workbench.run("memory_slab", prony=(), h=0.1, k=0.25, traction_top="(0, 30*t)", progress=False)
    assert np.all(ds.contact_state.values[-1][ds.contact_state.values[-1] >= 0] == 0)
    mesh = ngs.Mesh(ngs.meshes.MakeStructured2DMesh(quads=False, nx=20, ny=10, mapping=lambda x, y: (2 * x, y)).ngmesh)
    fes = ngs.VectorH1(mesh, order=1, dirichlet="left")
    u, w = fes.TnT()
    E, nu = 1000.0, 0.3
    eps = lambda f: 0.5 * (ngs.Grad(f) + ngs.Grad(f).trans)  # noqa: E731
    sigma = lambda e: E / (1 - nu ** 2) * ((1 - nu) * e + nu * ngs.Trace(e) * ngs.Id(2))  # noqa: E731
    a = ngs.BilinearForm(ngs.InnerProduct(sigma(eps(u)), eps(w)) * ngs.dx).Assemble()
    f = ngs.LinearForm(30.0 * w[1] * ngs.ds("top")).Assemble()
    g = ngs.GridFunction(fes)
    g.vec.data = a.mat.Inverse(fes.FreeDofs(), inverse="umfpack") * f.vec
    np.testing.assert_allclose(ds.u_dofs.isel(snapshot=-1).values, g.vec.FV().NumPy(), rtol=0, atol=1e-10)


def test_slab_regimes_and_constraint():
    """memory_slab at T: separated, compliant and rigid nodes all occur; u_nu <= gap; complementarity ~ 0."""
    ds = workbench.run("memory_slab", progress=False)
    last = ds.isel(time=-1)
    for count in ("n_separated", "n_compliant", "n_rigid"):
        assert int(last[count]) > 0, count
    u_nu = -ds.u_contact.sel(component="y").values
    assert u_nu.max() <= ds.attrs["gap"] * (1 + 1e-12)
    assert float(ds.complementarity.max()) <= 1e-10
    assert float(ds.linear_solves[1:].mean()) <= 5
    p = last.contact_pressure.values
    state = last.contact_state.values
    assert np.all(p[state == 0] == 0) and np.all(p[state == 3] >= ds.attrs["F"] + ds.attrs["c"] * ds.attrs["gap"] - 1e-9)


@pytest.mark.parametrize("overrides", [dict(c=0.0), dict(F=0.0), dict(gap=0.0)])
def test_limits(overrides):
    """c = 0 (rigid-plastic layer), F = 0 (pure compliance), gap = 0 (Signorini): constraints hold exactly."""
    ds = workbench.run("memory_slab", h=0.1, k=0.05, progress=False, **overrides)
    u_nu = -ds.u_contact.sel(component="y").values
    assert u_nu.max() <= ds.attrs["gap"] + 1e-14
    assert float(ds.complementarity.max()) <= 1e-10
    if overrides.get("gap") == 0.0:
        assert int(ds.n_compliant.max()) == 0


@pytest.mark.slow
def test_memory_slab_coupled_refinement():
    """Coupled k = 0.4 h against the finest case: order >= 0.9 in ||u - u_ref||_V (measured 0.91). The finest case as
    the reference overstates the order (its own error is not small against the others'): the extrapolated reference
    (the default here) measures 0.74 on the same cases, asserted >= 0.6 (docs/reproduction.md). (h = 0.2 ... 0.025
    had k = 0.08 ... 0.01, whose grids share t = 1 alone: that is refused now, docs/conventions.md.)"""
    hs = [0.25, 0.125, 0.0625, 0.03125]  # (k = 0.1 ... 0.0125: grids that nest, compared at four times)
    st = Study("memory_slab", h=hs, k_over_h=0.4, n_compare=4, workers=2, reference="finest")
    st.run(progress=False)
    st.assert_order(1.0, tol=0.1, norm="error_V", at_least=True)
    extrapolated = Study("memory_slab", h=hs, k_over_h=0.4, n_compare=4, workers=2)
    extrapolated.run(progress=False)
    assert extrapolated.dataset.attrs["reference"].startswith("auto: extrapolated")
    extrapolated.assert_order(1.0, tol=0.4, norm="error_V", at_least=True)


@pytest.mark.parametrize("overrides, message", [
    (dict(gap=-0.1), "0 <= gap"), (dict(F=-1), "0 <= F"), (dict(c=-1), "0 <= c"),
    (dict(kernel="exp(-x)"), "unknown name 'x'"), (dict(prony="(100, 0.3, 0)"), "tau_i > 0"),
    (dict(prony="(100, 0.3, -1)"), "tau_i > 0"), (dict(kernel="exp(-t)", kernel_E=5.0), "not both"),
    (dict(scheme="explicit"), "does not apply to a Model B scene"), (dict(prony="(100, 0.3)"), "(E_i, nu_i, tau_i)"),
    (dict(order=3), "order 1, or 2 on a 2D body"),
])
def test_bad_model_b_input(overrides, message):
    with pytest.raises(ParameterError) as err:
        workbench.run("memory_slab", progress=False, **overrides)
    assert message in str(err.value)


def test_trapezoid_steps_that_make_the_operator_indefinite_are_refused(monkeypatch):
    """A Prony term that takes three times A's stiffness away (memory_slab: E = 1000, a term of -3000 with A's
    Poisson ratio, tau = 0.5): the trapezoid rule's step operator is (1 - 3 w(k)) K_A, w(k) = tau (1 - (1 - e^-x)/x),
    x = k / tau, definite for k below 1.41 s (x = 2.82, the root of (1 - e^-x)/x = 1/3). Steps up to 1.3 s run; 1.5 s
    is refused before any work, naming k, or k_max under error control, and the longest step allowed. The bound is
    the factorization's own: with the check taken out, a step of 1.5 s fails in the factorization (indefinite). The
    rectangle rule (operator K_A) takes any step."""
    from workbench.running import preflight

    kw = dict(h=0.2, memory_rule="trapezoid", prony=[[-3000.0, 0.3, 0.5]], T=3.0, snapshots=(), progress=False)
    assert workbench.run("memory_slab", k=1.3, **kw).attrs["status"] == "complete"
    for extra, name in ((dict(k=1.5), "k = 1.5"), (dict(rtol=1e-3, k_max=1.5), "k_max = 1.5")):
        with pytest.raises(ParameterError) as err:
            workbench.run("memory_slab", **kw, **extra)
        assert str(err.value).startswith(name) and "steps below 1.4 s" in str(err.value), str(err.value)
    assert workbench.run("memory_slab", **(kw | dict(memory_rule="rectangle", k=1.5))).attrs["status"] == "complete"
    monkeypatch.setattr(preflight, "trapezoid_steps", lambda *args: None)
    with pytest.raises(Exception, match="positive definite|not positive|singular"):
        workbench.run("memory_slab", k=1.5, **kw)


def test_block_3d_regimes():
    """memory_block (3D, coarse): all contact regimes at T, u_nu <= gap, complementarity at round-off."""
    ds = workbench.run("memory_block", h=0.125, k=0.05, progress=False)
    last = ds.isel(time=-1)
    assert all(int(last[n]) > 0 for n in ("n_separated", "n_compliant", "n_rigid"))
    assert float((-ds.u_contact.sel(component="z")).max()) <= ds.attrs["gap"] * (1 + 1e-12)
    assert float(ds.complementarity.max()) <= 1e-10


LOADED_ROD = dict(ROD, delta=lambda t: 0.3 + 0.1 * np.sin(2 * np.pi * t))


def test_rod_loaded_at_t0_against_volterra(order_of):
    """delta(0) = 0.3 > gap = 0.1: at t = 0 the end already sits on the rigid limit. u(0) is the solution of the
    inclusion at t = 0 (no memory yet), recorded with its state; the whole history converges at first order in k
    to the independent Volterra solution of the same data."""
    ref = volterra.solve_prony(**LOADED_ROD)
    assert int(ref.state(np.array([0.0]))[0]) == volterra.RIGID
    errs, ks = [], [0.02, 0.01, 0.005]
    for k in ks:
        ds = workbench.run("memory_rod", k=k, delta="0.3 + 0.1*sin(2*pi*t)", progress=False)
        first = ds.isel(time=0)
        assert float(first.time) == 0.0
        assert int(first.contact_state.values[0]) == volterra.RIGID and int(first.n_rigid) == 1
        assert float(first.u_contact.values[0, 0]) == pytest.approx(float(ref.w(np.array([0.0]))[0]), abs=1e-14)
        assert float(first.contact_pressure.values[0]) == pytest.approx(-float(ref.sigma(np.array([0.0]))[0]),
                                                                         rel=1e-12)
        assert float(first.complementarity) <= 1e-14
        t = ds.time.values
        errs.append(np.abs(ds.u_contact.values[:, 0, 0] - ref.w(t)).max())
    assert errs[-1] > 1e-7 and order_of(ks, errs) >= 0.9 and errs[-1] < 1e-3


@pytest.mark.parametrize("contact_solver", ["condensed", "coupled"])
def test_slab_loaded_at_t0_against_independent_qp(contact_solver):
    """memory_slab with the load already on at t = 0: u(0) minimises the static energy
    1/2 u.K u - f.u + sum_i w_i psi(s_i) subject to s_i = -u_y <= gap at the contact vertices.
    Reference: that program over all dofs, assembled here independently of workbench (plane-stress
    stiffness, traction and nodal weights from NGSolve forms) and solved by SciPy's L-BFGS-B with
    s_i = p_i - q_i, 0 <= p_i <= gap, q_i >= 0 (psi(s) = F s_+ + c/2 s_+^2 becomes the smooth
    F p + c/2 p^2: at the minimum p_i q_i = 0, since lowering both lowers psi and keeps s)."""
    from scipy.optimize import minimize

    load = "(0, -60*(0.5 + t)*ifpos(x - 1, 1, -0.25))"
    ds = workbench.run("memory_slab", h=0.25, k=0.25, traction_top=load, snapshots="0", progress=False,
                       contact_solver=contact_solver)
    mesh = ngs.Mesh(ngs.meshes.MakeStructured2DMesh(quads=False, nx=8, ny=4, mapping=lambda x, y: (2 * x, y)).ngmesh)
    fes = ngs.VectorH1(mesh, order=1, dirichlet="left")
    u, w = fes.TnT()
    E, nu, F, c, g = 1000.0, 0.3, ds.attrs["F"], ds.attrs["c"], ds.attrs["gap"]
    eps = lambda f: 0.5 * (ngs.Grad(f) + ngs.Grad(f).trans)  # noqa: E731
    sigma = lambda e: E / (1 - nu ** 2) * ((1 - nu) * e + nu * ngs.Trace(e) * ngs.Id(2))  # noqa: E731
    K = ngs.BilinearForm(ngs.InnerProduct(sigma(eps(u)), eps(w)) * ngs.dx).Assemble()
    traction = -30.0 * ngs.IfPos(ngs.x - 1, 1, -0.25)
    f = ngs.LinearForm(traction * w[1] * ngs.ds("top")).Assemble()
    p1 = ngs.H1(mesh, order=1)
    weights = ngs.LinearForm(p1.TestFunction() * ngs.ds("bottom")).Assemble().vec.FV().NumPy()
    rows, cols, vals = K.mat.COO()
    Kd = np.zeros((fes.ndof, fes.ndof))
    np.add.at(Kd, (np.asarray(rows), np.asarray(cols)), np.asarray(vals))
    nv = mesh.nv
    xy = np.array(mesh.ngmesh.Coordinates())
    free = np.array(fes.FreeDofs(), dtype=bool)
    contact = [i for i in range(nv) if abs(xy[i, 1]) < 1e-12 and free[i]]
    y_dof = np.array([nv + i for i in contact])  # VectorH1 P1: x-components first, then y
    others = np.array([d for d in np.nonzero(free)[0] if d not in set(y_dof)])
    fv, wc = f.vec.FV().NumPy(), weights[contact]
    n, m = others.size, len(contact)

    def full(z):
        x = np.zeros(fes.ndof)
        x[others] = z[:n]
        x[y_dof] = -(z[n:n + m] - z[n + m:])  # u_y = -s, s = p - q
        return x

    def energy_and_grad(z):
        x = full(z)
        r = Kd @ x - fv
        p = z[n:n + m]
        val = 0.5 * x @ (Kd @ x) - fv @ x + wc @ (F * p + 0.5 * c * p * p)
        gp = -r[y_dof] + wc * (F + c * p)
        return val / E, np.concatenate([r[others], gp, r[y_dof]]) / E

    bounds = [(None, None)] * n + [(0.0, g)] * m + [(0.0, None)] * m
    res = minimize(energy_and_grad, np.zeros(n + 2 * m), jac=True, bounds=bounds, method="L-BFGS-B",
                   options=dict(maxiter=100000, maxfun=100000, ftol=1e-16, gtol=1e-13, maxcor=60))
    u_ref = full(res.x)
    u0 = ds.u_dofs.isel(snapshot=0).values if float(ds.snapshot_time[0]) == 0.0 else None
    first = ds.isel(time=0)
    s_ref = -u_ref[y_dof]
    got = -first.u_contact.sel(component="y").values
    order = np.argsort(ds.node_x.values)
    got_by_x = dict(zip(np.round(ds.node_x.values, 12), got))
    s_got = np.array([got_by_x[round(xy[i, 0], 12)] for i in contact])
    assert np.abs(s_ref).max() > 0.2 * g  # the load at t = 0 really presses the body in
    np.testing.assert_allclose(s_got, s_ref, rtol=0, atol=1e-6 * g)
    states = first.contact_state.values[order]
    assert (states > 0).any() and int(first.n_separated) < len(contact)
    assert u0 is None or np.abs(u0 - u_ref).max() <= 1e-6 * np.abs(u_ref).max()


@pytest.mark.slow
@pytest.mark.parametrize("memory", [dict(), dict(prony=(), kernel="exp(-t/0.2)", kernel_E=0.5)],
                         ids=["prony", "general kernel"])
def test_rod_study_against_volterra_reference(memory):
    """`workbench study memory_rod --reference ode`: the reference of a Model B rod is the Volterra solver
    (Prony: ODE; general kernel: Richardson-extrapolated product trapezoid rule), order 1 in k."""
    st = Study("memory_rod", k=[0.02, 0.01, 0.005], reference="ode", workers=0, **memory)
    ds = st.run(progress=False)
    st.assert_order(1.0, tol=0.1, along="k", max_error=2e-3)
    assert "beta" not in ds and np.isfinite(ds.error_probe.values).all()


@pytest.mark.slow
def test_memory_benchmark_still_runs():
    """studies/bench_memory.py drives MemoryVI by hand (start, then steps, as the time loop does): its --help and a
    tiny run work against today's scheme protocol, and both kernels report a cost per step and the linear solves."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "studies" / "bench_memory.py"
    p = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True)
    assert p.returncode == 0 and "--steps" in p.stdout, p.stderr
    p = subprocess.run([sys.executable, str(script), "--h", "0.5", "--steps", "12", "--k", "0.01"], capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout.splitlines()[-1])
    for memory in ("prony", "kernel"):
        assert out[memory]["ms_per_step"]["10"] > 0 and out[memory]["mean_solves"] >= 1


@pytest.mark.slow
def test_model_b_with_p2_elements():
    """Model B on P2 (2D): the constraint and the layer's law at the P2 nodes of the contact side (vertices and facet
    midpoints, Simpson-lumped). At the P1 rate h (the estimate is O(h)), P2 is more accurate: memory_slab against a
    P2 run at h = 0.025, the displacement's energy-norm error falls at order >= 0.8 for both, P2's below P1's
    (measured to h = 0.0125: orders 0.82 (P1) and 1.05 (P2), P2 3.5-5.6 x smaller); complementarity to round-off;
    P2 in 3D is refused by name."""
    st = Study("memory_slab", h=[0.2, 0.1, 0.05], order=[1, 2], k=[0.05], workers=2, reference={"h": 0.025, "order": 2})
    ds = st.run(progress=False)
    err = ds.error_V.squeeze()
    assert (err.sel(order=2) < 0.5 * err.sel(order=1)).all()
    for order in (1, 2):
        rate = float(ds.observed_order.sel(norm="error_V", along="h", order=order).squeeze())
        assert rate > 0.8, (order, rate)
    run = workbench.run("memory_slab", h=0.1, order=2, progress=False)
    assert run.complementarity.max() < 1e-12 and run.attrs["status"] == "complete"
    with pytest.raises(ParameterError, match="order 1, or 2 on a 2D body"):
        workbench.scene("memory_block", order=2)


def test_a_general_kernels_state_holds_the_stored_displacements_alone():
    """The quadrature memory's state (restart state, and what a rejected step is redone from) holds u_0 ... u_{n-1}
    for its n + 1 times and nothing more. It once copied the buffer's next row too, memory never written: NaN
    patterns there made a rejected step's state compare unequal to itself at random, and went into the archives.
    The buffer's unwritten rows are made NaN here, so that copy would show."""
    from workbench.discrete import discretisation
    from workbench.schemes import scheme_class

    sc = workbench.scene("memory_rod", scheme="vi", kernel="exp(-t/0.2)*(1+t)", kernel_E=0.5, prony=())
    d = discretisation.build(sc.model_of(), sc)
    s = scheme_class("vi")(d)
    s.preflight(0.05)
    s.start(0.0)
    s.accept(0.0)
    s.memory.stored[:] = np.nan
    before, t = [], 0.0
    for k in (0.05, 0.05, 0.03):
        before.append(d.u.vec.FV().NumPy().copy())
        s.step(t, t + k)
        t += k
        s.accept(t)
    extra = s.state()["extra"]
    assert len(extra["times"]) == 4 and np.array_equal(extra["stored"], np.array(before))
    s.restore(s.state())
    assert np.array_equal(s.state()["extra"]["stored"], np.array(before))
