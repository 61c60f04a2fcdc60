"""Model B: long memory, unilateral contact with a compliant layer, one variational inequality per step.

References: the rod with memory reduces to a scalar Volterra inequality, solved independently by
workbench.volterra (Prony kernel -> an ODE for the memory variables, SciPy DOP853 at rtol 1e-10);
the static elastic problem without memory and contact, assembled here from the plane-stress formula;
the constraint and complementarity conditions themselves.
"""
import ngsolve as ngs
import numpy as np
import pytest

import workbench
from workbench import ParameterError, volterra
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


def test_memory_slab_coupled_refinement():
    """Coupled k = 0.4 h against the finest case: order >= 0.9 in ||u - u_ref||_V (measured 0.91 over 5 levels)."""
    st = Study("memory_slab", h=[0.2, 0.1, 0.05, 0.025], k_over_h=0.4, n_compare=4, workers=2)
    st.run(progress=False)
    st.assert_order(1.0, tol=0.1, norm="error_V", at_least=True)


@pytest.mark.parametrize("overrides, message", [
    (dict(gap=-0.1), "0 <= gap"), (dict(F=-1), "0 <= F"), (dict(c=-1), "0 <= c"),
    (dict(kernel="exp(-x)"), "unknown name 'x'"), (dict(prony="(100, 0.3, 0)"), "tau_i > 0"),
    (dict(prony="(100, 0.3, -1)"), "tau_i > 0"), (dict(kernel="exp(-t)", kernel_E=5.0), "not both"),
    (dict(scheme="explicit"), "does not apply to a Model B scene"), (dict(prony="(100, 0.3)"), "(E_i, nu_i, tau_i)"),
    (dict(order=2), "order must be 1"),
])
def test_bad_model_b_input(overrides, message):
    with pytest.raises(ParameterError) as err:
        workbench.run("memory_slab", progress=False, **overrides)
    assert message in str(err.value)


def test_block_3d_regimes():
    """memory_block (3D, coarse): all contact regimes at T, u_nu <= gap, complementarity at round-off."""
    ds = workbench.run("memory_block", h=0.125, k=0.05, progress=False)
    last = ds.isel(time=-1)
    assert all(int(last[n]) > 0 for n in ("n_separated", "n_compliant", "n_rigid"))
    assert float((-ds.u_contact.sel(component="z")).max()) <= ds.attrs["gap"] * (1 + 1e-12)
    assert float(ds.complementarity.max()) <= 1e-10
