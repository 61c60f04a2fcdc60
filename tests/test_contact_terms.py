"""The contact-boundary functional j(beta, u, .) is the derivative of an energy (beta fixed).

For fixed beta, j(beta, u, w) = d/de Phi(u + e w) at e = 0 with
Phi(u) = int_Gamma3 c_nu/(m+1) ((u_nu - g)_+)^(m+1) + gamma beta^2 phi_L(u_nu) + c_tau beta psi_L(|u_tau|) da,
phi_L(s) = 0 (s >= 0), s^2/2 (-L <= s < 0), L^2/2 - L (s + L) (s < -L),
psi_L(r) = r^2/2 (r <= L), L r - L^2/2 (r > L).
Phi is written here independently of workbench.physics and integrated with
ngsolve.Integrate; the assembled vector must match its central differences.
u is chosen piecewise linear with regime changes (0, -L, |u_tau| = L) only at
vertices, so both sides integrate polynomials exactly.
"""
import ngsolve as ngs
import numpy as np
import pytest

import workbench
from workbench.discrete import discretisation

U_NU = [0.2, 0.1, 0.0, -0.1, -0.3, -0.45, -0.6, -0.3, 0.0, 0.05, 0.0]  # at x = 0, 0.1, ..., 1
U_TAU = [0.0, 0.1, 0.3, 0.4, 0.5, 0.3, 0.1, -0.3, -0.5, -0.3, 0.0]


def energy(u, beta, sc):
    v = sc.values
    n = ngs.specialcf.normal(2)
    u_nu = ngs.InnerProduct(u, n)
    u_tau = u - u_nu * n
    L, gam = v["L"], v["gamma_nu"]
    pen = ngs.IfPos(u_nu - v["gap"], u_nu - v["gap"], 0)
    phi = ngs.IfPos(u_nu, 0, ngs.IfPos(-L - u_nu, L * L / 2 - L * (u_nu + L), u_nu * u_nu / 2))
    r = ngs.sqrt(ngs.InnerProduct(u_tau, u_tau) + 1e-30)
    psi = ngs.IfPos(r - L, L * r - L * L / 2, r * r / 2)
    density = v["c_nu"] / (v["m_nu"] + 1) * pen ** (v["m_nu"] + 1) + gam * beta * beta * phi + v["c_tau"] * beta * psi
    mesh = u.space.mesh
    return ngs.Integrate(density, mesh, ngs.BND, order=8, definedon=mesh.Boundaries("bottom"))


def set_state(d):
    uvec = d.u.vec.FV().NumPy()
    xs = d.node_xyz[:, 0]
    idx = np.rint(xs * 10).astype(int)
    uvec[d.node_dofs[:, 1]] = -np.asarray(U_NU)[idx]  # nu = (0, -1): u_nu = -u_y
    uvec[d.node_dofs[:, 0]] = np.asarray(U_TAU)[idx]
    rng = np.random.default_rng(1)
    b = d.beta.vec.FV().NumPy()
    b[d.beta_dofs] = rng.uniform(0.2, 1.0, d.beta_dofs.size)


@pytest.mark.parametrize("gap", [0.0, 0.1])
def test_contact_vector_is_energy_gradient(gap):
    sc = workbench.scene("slab", h=0.1, ny=1, c_nu=7.0, gamma_nu=2.0, L=0.3, c_tau=3.0, gap=gap)
    assert sc.terms == ("compliance", "adhesion", "glue")
    d = discretisation.build(sc)
    set_state(d)
    d.contact_form.Assemble()
    j = np.array(d.contact_form.vec.FV().NumPy())
    rng = np.random.default_rng(2)
    probe = ngs.GridFunction(d.fes)
    for _ in range(3):
        w = rng.standard_normal(d.ndof)
        eps = 1e-6
        vals = []
        for sign in (1, -1):
            probe.vec.FV().NumPy()[:] = d.u.vec.FV().NumPy() + sign * eps * w
            vals.append(energy(probe, d.beta, sc))
        fd = (vals[0] - vals[1]) / (2 * eps)
        assert j @ w == pytest.approx(fd, rel=1e-6, abs=1e-9)
    assert np.abs(j).max() > 0.01  # the state exercises the terms (nodal forces ~ h x traction)


def contact_force_y(sc, u_y):
    """y-component of the contact force on the body (-j) at the contact nodes, for uniform u_y."""
    d = discretisation.build(sc)
    d.u.vec.FV().NumPy()[d.node_dofs[:, 1]] = u_y
    d.contact_form.Assemble()
    return -d.contact_form.vec.FV().NumPy()[d.node_dofs[:, 1]]


def test_adhesive_pull_points_back_and_compliance_pushes_out():
    """Lifted off (tension): the glue pulls down; pressed in: the foundation pushes up."""
    sc = workbench.scene("slab", h=0.1, ny=1, c_nu=5.0, gamma_nu=1.0)
    assert np.all(contact_force_y(sc, +0.1) < 0)
    assert np.all(contact_force_y(sc, -0.1) > 0)
    no_glue = sc.with_(adhesion=False)
    assert np.all(contact_force_y(no_glue, +0.1) == 0)  # no foundation force when separated


def test_run_signs_2d():
    """Pulled up, adhesion lowers the uplift; pushed down, compliance lowers the penetration."""
    up = dict(h=0.05, k=0.002, T=0.3, traction_top="(0, 1)", gamma_nu=5.0, L=1.0)
    tip = lambda ds: float(ds.u_probe.isel(time=-1, probe=-1).sel(component="y"))  # noqa: E731
    assert tip(workbench.run("slab", **up, progress=False)) < tip(workbench.run("slab", **up, adhesion=False, progress=False))
    down = dict(h=0.05, k=0.002, T=0.3, traction_top="(0, -1)", c_nu=5.0, adhesion=False)
    with_c = workbench.run("slab", **down, progress=False)
    without = workbench.run("slab", **down, contact=False, progress=False)
    assert tip(without) < tip(with_c) < 0


def test_undeclared_terms_are_not_assembled():
    """A scene assembles only what it declares: no beta field without adhesion, no boundary form without contact."""
    d = discretisation.build(workbench.scene("slab", h=0.1, adhesion=False))
    assert d.beta is None and d.rate_form is None and d.contact_form is not None
    d = discretisation.build(workbench.scene("slab", h=0.1, adhesion=False, contact=False))
    assert d.contact_form is None
    ds = workbench.run("slab", h=0.1, k=0.01, T=0.05, adhesion=False, progress=False)
    assert "beta" not in ds and ds.attrs["terms"] == "compliance"
