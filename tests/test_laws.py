"""Every contact law (workbench.physics.laws), whatever file it comes from: its two evaluations agree, its slopes are
the derivatives of its tractions, and its declared largest slope bounds them.

Each law writes its tractions once (workbench.physics.ops): as NGSolve coefficient functions (the model's definition,
the integrand of j) and as NumPy arrays at the contact quadrature points (the time loop). For random states:

* NumPy tractions = the NGSolve integrand evaluated at the same points (to round-off);
* NumPy slopes = central finite differences of the NumPy tractions, away from the kinks;
* |slope| <= max_slope(beta0) on states with beta <= beta0 (the explicit scheme's stability limit uses it);
* the sum of the laws (workbench.physics.contact.Contact): its largest normal slope is the largest central finite
  difference of the summed traction, terms on the same side of u_nu = 0 adding (the two pulls at u_nu -> -L).

And the contact side (workbench.discrete.boundary): T^T (w p(T u)) equals NGSolve's assembled boundary linear form of the
same law (to round-off), for P1 and P2 in 2D and 3D, so the quadrature points are NGSolve's own.
"""
import ngsolve as ngs
import numpy as np
import pytest

import workbench
from workbench.discrete import discretisation
from workbench.physics.ops import NGS, NP
from workbench.physics.laws import LAWS

VALUES = dict(contact=True, adhesion=True, c_nu=7.0, m_nu=1.7, gap=0.05, gamma_nu=2.0, eps_a=0.0, L=0.3, beta0=1.0,
              bonding_truncation="tension", c_tau=3.0, gamma_p=5.0, q_p=2.5)


def laws():
    out = [law.from_values(VALUES) for law in LAWS]
    assert all(t is not None for t in out), "every law is active with VALUES"
    return out


@pytest.mark.parametrize("term", laws(), ids=lambda t: t.name)
def test_numpy_and_ngsolve_evaluations_agree(term):
    mesh = ngs.Mesh(ngs.unit_square.GenerateMesh(maxh=0.5))
    rng = np.random.default_rng(0)
    points = mesh(rng.uniform(0.05, 0.95, 40), rng.uniform(0.05, 0.95, 40))
    u_nu_cf, beta_cf = 0.8 * (ngs.x - 0.5), 0.2 + 0.8 * ngs.y
    u_tau_cf = ngs.CF((0.9 * (ngs.y - 0.4),))
    u_nu = np.asarray(u_nu_cf(points)).ravel()
    beta = np.asarray(beta_cf(points)).ravel()
    u_tau = np.asarray(u_tau_cf(points)).reshape(-1, 1)
    p_np, p_cf = term.normal(NP, u_nu, beta), term.normal(NGS, u_nu_cf, beta_cf)
    assert (p_np is None) == (p_cf is None)
    if p_np is not None:
        np.testing.assert_allclose(p_np, np.asarray(p_cf(points)).ravel(), rtol=1e-13, atol=1e-15)
    q_np, q_cf = term.tangential_traction(NP, u_tau, beta), term.tangential_traction(NGS, u_tau_cf, beta_cf)
    assert (q_np is None) == (q_cf is None)
    if q_np is not None:
        np.testing.assert_allclose(q_np.ravel(), np.asarray(q_cf(points)).ravel(), rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("term", laws(), ids=lambda t: t.name)
def test_slopes_are_derivatives_and_bounded(term):
    rng = np.random.default_rng(1)
    u_nu = rng.uniform(-0.6, 0.6, 200)
    u_tau = rng.uniform(-0.6, 0.6, (200, 2))
    beta = rng.uniform(0.1, 1.0, 200)
    eps = 1e-7
    normal, tangential = term.max_slope(1.0)
    if term.normal(NP, u_nu, beta) is not None:
        fd = (term.normal(NP, u_nu + eps, beta) - term.normal(NP, u_nu - eps, beta)) / (2 * eps)
        slope = np.broadcast_to(term.normal_slope(NP, u_nu, beta), u_nu.shape)
        np.testing.assert_allclose(slope, fd, rtol=1e-5, atol=1e-6)
        assert np.abs(slope).max() > 0
        # the compliance with m_nu > 1 has no largest slope: its stand-in is the slope at a penetration of L
        within = u_nu - VALUES["gap"] <= VALUES["L"] if term.name == "compliance" else np.ones_like(u_nu, bool)
        assert np.all(np.abs(slope[within]) <= normal * (1 + 1e-12))
    if term.tangential_traction(NP, u_tau, beta) is not None:
        J = term.tangential_slope(NP, u_tau, beta)
        for c in range(2):
            e = np.zeros(2)
            e[c] = eps
            fd = (term.tangential_traction(NP, u_tau + e, beta) - term.tangential_traction(NP, u_tau - e, beta)) / (2 * eps)
            np.testing.assert_allclose(J[:, :, c], fd, rtol=1e-5, atol=1e-6)
        assert np.linalg.norm(J, 2, axis=(1, 2)).max() <= tangential * (1 + 1e-12)


def test_max_slope_of_the_sum_is_the_slope_of_the_summed_law():
    """Contact.max_slope = max over u_nu of |d/du (sum of p_nu)| at beta = beta0, by finite differences.

    Compliance (u_nu > gap) and the pulls (-L < u_nu < 0) act on opposite sides; the linear pull (gamma_nu) and the
    power-law pull (q_p gamma_p at the bond length) are steepest together at u_nu -> -L, so there the slopes add.
    """
    from workbench.physics.contact import Contact

    contact = Contact(laws())
    L, gap = VALUES["L"], VALUES["gap"]
    u_nu = np.linspace(-0.6, gap + L, 200001)  # the compliance stands in by its slope at a penetration of L
    beta = np.full_like(u_nu, VALUES["beta0"])
    eps = 1e-9
    fd = (contact.normal(NP, u_nu + eps, beta) - contact.normal(NP, u_nu - eps, beta)) / (2 * eps)
    normal, tangential = contact.max_slope(VALUES["beta0"])
    expected = VALUES["gamma_nu"] + VALUES["q_p"] * VALUES["gamma_p"]
    assert normal == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(np.abs(fd).max(), normal, rtol=1e-3)
    assert tangential == pytest.approx(VALUES["c_tau"] * VALUES["beta0"])


@pytest.mark.parametrize("name, order", [("slab", 1), ("slab", 2), ("block", 1), ("block", 2)])
def test_contact_side_integrates_like_ngsolve(name, order):
    """T^T (w p(T u, beta)) = NGSolve's LinearForm of the same integrand (its default rule), every law at once."""
    sc = workbench.scene(name, h=0.25 if name == "block" else 0.1, order=order, **{k: v for k, v in VALUES.items()
                                                                                   if k != "c_tau" or True})
    d = discretisation.build(sc)
    rng = np.random.default_rng(2)
    u = d.u.vec.FV().NumPy()
    u[:] = rng.uniform(-0.3, 0.3, u.size)
    beta = d.beta.vec.FV().NumPy()
    beta[d.beta_dofs] = rng.uniform(0.2, 1.0, d.beta_dofs.size)
    d.contact_form.Assemble()
    ref = d.contact_form.vec.FV().NumPy().copy()
    side, contact = d.side, d.model.contact
    bq = beta[d.beta_dofs][side.element]
    mine = side.integrate(contact.normal(NP, side.u_nu(u), bq), contact.tangential_traction(NP, side.u_tau(u), bq))
    assert np.abs(ref).max() > 1e-3
    np.testing.assert_allclose(mine, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    # and the bonding rate at the facet midpoints = NGSolve's form with P0 test functions
    d.rate_form.Assemble()
    rate_ref = d.rate_form.vec.FV().NumPy()[d.beta_dofs] / d.facet_measure
    rs = d.rate_side
    rate = np.empty(d.beta_dofs.size)
    rate[rs.element] = d.model.bonding.rate(NP, beta[d.beta_dofs][rs.element], rs.u_nu(u))
    np.testing.assert_allclose(rate, rate_ref, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("term", laws(), ids=lambda t: t.name)
def test_every_jump_of_a_slope_is_a_declared_kink(term):
    """A law declares its kinks (:meth:`ContactTerm.kinks`): wherever its normal or tangential slope jumps between
    two neighbouring states on a fine line through the states (a change ten times those on either side: a steep but
    continuous slope, as of a power law at its start, is no jump), one of its kink functions changes sign there (an
    error-controlled run lands on those zeros; a kink it did not declare would be stepped over)."""
    s = np.linspace(-0.7, 0.7, 14001)
    beta = np.full(s.size, 0.8)
    u_tau = np.stack([0.9 * s], axis=-1)  # |u_tau| passes L = 0.3 too
    slopes = [term.normal_slope(NP, s, beta) * np.ones_like(s)]
    if term.tangential:
        slopes.append(term.tangential_slope(NP, u_tau, beta)[:, 0, 0])
    kinks = term.kinks(s, u_tau)
    declared = np.zeros(s.size - 1, dtype=bool)
    for k in kinks:
        declared |= np.sign(k[:-1]) != np.sign(k[1:])
    for slope in slopes:
        change = np.abs(np.diff(slope))
        beside = np.maximum(np.r_[0.0, change[:-1]], np.r_[change[1:], 0.0])
        jumps = (change > 1e-6 * (np.abs(slope).max() + 1e-300)) & (change > 10 * beside)
        assert not (jumps & ~declared).any(), (term.name, s[:-1][jumps & ~declared][:5])
    assert kinks or not any((np.abs(np.diff(sl)) > 0).any() for sl in slopes), f"{term.name} declares no kink"


def test_an_adaptive_run_lands_on_the_kink_a_new_law_declares():
    """A law of a user's own, with a kink no built-in law has (a foundation that stiffens at the penetration d), run
    with error control on a rod pushed into it: the run ends a step at its kink (u_nu = d to 1e-7 of d at some
    record), because the law says where it is; the same law without the declaration is stepped over (no record
    within 30 x that)."""
    import dataclasses

    from workbench.physics.contact import Contact, ContactTerm

    class Stiffening(ContactTerm):
        name, rank, gapped = "stiffening", 15, True

        def __init__(self, c, c2, d):
            self.c, self.c2, self.d = c, c2, d

        def normal(self, ops, u_nu, beta):
            return self.c * ops.pos(u_nu) + self.c2 * ops.pos(u_nu - self.d)

        def normal_slope(self, ops, u_nu, beta):
            return self.c * ops.ifpos(u_nu, 1.0, 0.0) + self.c2 * ops.ifpos(u_nu - self.d, 1.0, 0.0)

        def max_slope(self, beta0):
            return self.c + self.c2, 0.0

        def kinks(self, u_nu, u_tau):
            return [u_nu, u_nu - self.d]

    class Undeclared(Stiffening):
        def kinks(self, u_nu, u_tau):
            return []

    sc = workbench.scene("rod", delta="0.2*t", u0="0", adhesion=False, scheme="implicit", k=0.01, rtol=1e-3,
                         snapshots=())
    d = 0.03
    misses = []
    for law in (Stiffening, Undeclared):
        model = dataclasses.replace(sc.model_of(), contact=Contact([law(1.0, 10.0, d)]))
        ds = workbench.run(sc, model=model, progress=False)
        # (the history names the model given and its law's values: it had left model= out, an outside pass)
        assert f"model=<ModelA, terms stiffening: {law.__name__}(c=1.0, c2=10.0, d=0.03)>" in ds.attrs["history"]
        u_nu = ds.u_contact.isel(node=0, component=0).values  # (the rod's end: u_nu = u)
        assert u_nu.max() > 1.5 * d  # the run passes the kink
        misses.append(np.abs(u_nu - d).min())
    assert misses[0] <= 1e-7 * d and misses[1] > 30 * misses[0], misses
