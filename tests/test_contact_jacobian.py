"""The implicit schemes' contact linearisation, and normal compliance with exponents m_nu != 1.

The condensed semismooth Newton (workbench.discrete.condensation) needs f(u_C) = j(beta, u, .)|_C and its
Jacobian df/du_C, which NGSolve derives from the IfPos integrand (AssembleLinearization). The
Jacobian is checked here against central finite differences of f itself (as NGSolve's own
tests/pytest/test_contact.py checks AssembleLinearization against Apply), at random states whose
quadrature points are, almost surely, away from the kinks of (.)_+, R and R*.

p_nu(r) = c_nu (r_+)^m_nu: the implicit scheme is checked for m_nu = 1.5, 2, 3 against the reduced
rod ODE (docs/models.md, Appendix A; scipy Radau, independent of the schemes) and against the explicit scheme
at a small step on the slab.
"""
import copy

import numpy as np
import pytest

import workbench
from workbench.discrete import discretisation
from workbench import references
from workbench.discrete.condensation import ContactOperator


def random_state(op, d, rng, scale):
    """Contact dofs spread over both sides of the kinks; beta random in (0.2, 1)."""
    u_C = rng.uniform(-scale, scale, op.size)
    if d.beta is not None:
        b = d.beta.vec.FV().NumPy()
        b[d.beta_dofs] = rng.uniform(0.2, 1.0, d.beta_dofs.size)
    return u_C


@pytest.mark.parametrize("name, overrides", [
    ("slab", dict(h=0.1, ny=1, c_nu=7.0, m_nu=1.0, gamma_nu=2.0, L=0.3, c_tau=3.0, gap=0.05)),
    ("slab", dict(h=0.1, ny=1, c_nu=7.0, m_nu=1.5, gamma_nu=2.0, L=0.3, c_tau=3.0)),
    ("slab", dict(h=0.1, ny=1, order=2, c_nu=7.0, m_nu=2.0, gamma_nu=2.0, L=0.3, c_tau=3.0, bonding_truncation="symmetric")),
    ("slab", dict(h=0.1, ny=1, c_nu=7.0, m_nu=3.0, adhesion=False)),
    ("block", dict(h=0.25, c_nu=7.0, m_nu=2.0, gamma_nu=2.0, L=0.3, c_tau=3.0)),
    ("rod", dict(h=0.25, c_nu=7.0, m_nu=1.5, gamma_nu=2.0, L=0.3)),
])
def test_contact_jacobian_equals_finite_differences(name, overrides):
    sc = workbench.scene(name, **overrides)
    d = discretisation.build(sc)
    op = ContactOperator(d)
    rng = np.random.default_rng(3)
    eps = 1e-7
    largest = 0.0
    for _ in range(4):
        u_C = random_state(op, d, rng, scale=0.5)
        J = op.jacobian(u_C)
        assert np.isfinite(J).all()
        fd = np.empty_like(J)
        for j in range(op.size):
            e = np.zeros(op.size)
            e[j] = eps
            fd[:, j] = (op.force(u_C + e) - op.force(u_C - e)) / (2 * eps)
        scale = max(np.abs(fd).max(), 1e-3)
        np.testing.assert_allclose(J, fd, rtol=0, atol=1e-6 * scale)
        largest = max(largest, np.abs(fd).max())
    assert largest > 1e-2  # the states exercise the terms


@pytest.mark.parametrize("name, overrides", [
    ("slab", dict(h=0.1, ny=1, order=2, c_nu=7.0, m_nu=2.0, gamma_nu=2.0, L=0.3, c_tau=3.0)),
    ("block", dict(h=0.25, c_nu=7.0, m_nu=2.0, gamma_nu=2.0, L=0.3, c_tau=3.0)),
])
def test_a_small_side_computes_with_dense_traces_as_with_sparse_ones(name, overrides):
    """A restricted contact side of few points and dofs (:data:`workbench.discrete.boundary.DENSE_TRACES`) keeps its
    traces dense, where SciPy's sparse products cost more in overhead than in work: its u_nu, u_tau, forces and
    Jacobians (dense and sparse) are the sparse traces' to round-off."""
    d = discretisation.build(workbench.scene(name, **overrides))
    op = ContactOperator(d)
    dense = op.side
    assert dense._dense is not None  # (the path the other tests of this module take)
    sparse = copy.copy(dense)
    sparse._dense = None
    rng = np.random.default_rng(5)
    for _ in range(3):
        u_C = random_state(op, d, rng, scale=0.5)
        for side in (dense, sparse):
            op.side = side
            side.result = (side.u_nu(u_C), side.u_tau(u_C), op.force(u_C), op.jacobian(u_C),
                           op.jacobian(u_C, dense=False).toarray())
        for a, b in zip(dense.result, sparse.result):
            assert a.shape == b.shape
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * max(np.abs(b).max(), 1.0))
        assert np.abs(sparse.result[3]).max() > 1e-2  # (the states exercise the terms)


ROD_PUSHED = dict(h=0.1, T=1.0, c_nu=5.0, gamma_nu=0.3, L=0.3, delta="0.2*sin(pi*t)", u0="0")


@pytest.mark.parametrize("m", [1.5, 2.0, 3.0])
def test_implicit_rod_with_power_compliance_matches_ode(m):
    """Rod pressed into the foundation (delta = 0.2 sin(pi t)): implicit backward Euler is O(k) against
    the reduced ODE with p_nu(r) = 5 r_+^m; the explicit scheme at the same k agrees as closely."""
    sc = workbench.scene("rod", m_nu=m, **ROD_PUSHED)
    ref = references.rod_ode(sc)
    errors = {}
    for scheme in ("implicit", "explicit"):
        for k in (0.01, 0.005):
            ds = workbench.run(sc, k=k, scheme=scheme, progress=False)
            u_end = ds.u_probe.sel(component="x").isel(probe=-1).values
            errors[scheme, k] = float(np.max(np.abs(u_end - ref(ds.time.values, x=1.0)[0])))
    assert max(errors.values()) > 1e-6  # the comparison is not with itself
    for scheme in ("implicit", "explicit"):
        assert errors[scheme, 0.005] < 2e-3
        assert 1.7 < errors[scheme, 0.01] / errors[scheme, 0.005] < 2.3  # first order
    # the end really penetrates, so the power law acts
    assert float(ref(np.array([0.5]), x=1.0)[0][0]) > 0.05


@pytest.mark.parametrize("m", [1.5, 2.0, 3.0])
def test_implicit_slab_with_power_compliance_matches_explicit(m):
    """Slab pressed down: implicit at k = 2e-3 against the explicit scheme at k = 2.5e-4 (a different
    scheme, well inside its stability limit): the tip and the contact side agree to the O(k) error."""
    common = dict(h=0.05, T=0.3, c_nu=50.0, m_nu=m, traction_top="(0, -2*t)", gamma_nu=0.3)
    imp = workbench.run("slab", k=2e-3, scheme="implicit", progress=False, **common)
    exp = workbench.run("slab", k=2.5e-4, scheme="explicit", progress=False, **common)
    a = imp.u_contact.sel(component="y").isel(time=-1).values
    b = exp.u_contact.sel(component="y").isel(time=-1).values
    assert np.max(-b) > 1e-3  # penetration: the compliance acts
    assert np.max(np.abs(a - b)) < 0.02 * np.max(np.abs(b))
    assert imp.newton_iterations.max() <= 10


def test_condensed_system_is_the_dense_schur_complement():
    """S0^{-1} = ((M^{-1})_CC)^{-1} built with the factored M equals the inverse of the dense (M^{-1})_CC, and the
    condensed Newton solves the full system M u + j(u) = r (checked on the assembled dense matrices)."""
    from workbench.discrete import solvers
    from workbench.discrete.condensation import CondensedNewton, CondensedSystem

    sc = workbench.scene("slab", h=0.1, ny=2, c_nu=50.0, gamma_nu=2.0, c_tau=3.0)
    d = discretisation.build(sc)
    op = ContactOperator(d)
    K = (solvers.to_scipy(d.viscous.mat) / 0.01 + solvers.to_scipy(d.elastic.mat)).toarray()
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    Minv = np.zeros_like(K)
    Minv[np.ix_(free, free)] = np.linalg.inv(K[np.ix_(free, free)])
    M = d.viscous.mat.CreateMatrix()
    M.AsVector().data = (1 / 0.01) * d.viscous.mat.AsVector() + d.elastic.mat.AsVector()
    solver = solvers.factor(M, d.fes.FreeDofs(), d.u.vec)
    cs = CondensedSystem(solver, d.ndof, op.C)
    dense = np.linalg.inv(Minv[np.ix_(op.C, op.C)])
    np.testing.assert_allclose(cs.S0_inv, dense, rtol=1e-9, atol=1e-9 * np.abs(dense).max())
    # the condensed Newton reproduces the full nonlinear solve
    rng = np.random.default_rng(4)
    r = np.zeros(d.ndof)
    r[free] = rng.standard_normal(free.size) * 0.5
    z = Minv @ r
    u_C = z[op.C].copy()
    newton = CondensedNewton(cs, op)
    f_C = newton.solve(u_C, z[op.C].copy(), 0.0)
    u = z.copy()
    f_full = np.zeros(d.ndof)
    f_full[op.C] = f_C
    u -= Minv @ f_full
    assert np.abs(u[op.C] - u_C).max() <= 1e-10 * np.abs(u_C).max()
    residual = K[np.ix_(free, free)] @ u[free] + f_full[free] - r[free]
    assert np.abs(residual).max() <= 1e-8 * np.abs(r).max()
    assert newton.iterations >= 1 and np.abs(f_C).max() > 1e-3  # the contact really acts
