"""Curved contact sides and the Hertz benchmarks (issue 12).

References: Hertz's solution of a cylinder and of a sphere on a rigid flat (plane strain, E* = E / (1 - nu^2);
workbench.references.hertz, exact formulas) and Lee and Radok's for a Kelvin-Voigt body under a ramp load; the
energy of the boundary functional written here, independently of workbench.physics; the NGSolve form of j,
whose initial gap is the coordinate function y (the fast path takes it from its own quadrature points).
"""
import dataclasses
import re
import warnings

import numpy as np
import pytest

import workbench
from workbench.discrete import discretisation
from workbench.discrete.condensation import ContactOperator
from workbench.physics.ops import NP
from workbench.references import hertz


def _order(hs, errors):
    return float(np.polyfit(np.log(hs), np.log(errors), 1)[0])


def test_elastic_hertz_2d_in_the_signorini_limit():
    """Model B without memory, F = c = gap = 0, on the half-disc (plane strain), refined at the contact point: the
    pressure's L2 error against Hertz falls under refinement and is below 3 % on the finest mesh; the contact
    ends within one element of the analytic half-width; the contact force carries the load exactly (the held apex
    included, by its reaction)."""
    hcs, errors = [0.005, 0.0025, 0.00125], []
    for hc in hcs:
        r = hertz.profile(workbench.run("memory_hertz", h_contact=hc, progress=False))
        errors.append(r["l2"])
        assert r["a_last"] <= r["a"] <= r["a_next"] + 1e-12 and r["a"] - r["a_last"] <= hc
        assert r["force"] == pytest.approx(1.0, abs=1e-9)
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.03  # measured 1.9, 0.83, 0.50 %
    assert _order(hcs, errors) > 0.6  # measured 0.95


def test_hertz_profile_compares_only_a_hertz_problem_and_plane_stress_by_its_own_modulus():
    """``hertz.profile`` read E, nu and the load alone: a run with a Voigt matrix was compared with E's default (51 %
    "error" on the isotropic run's numbers), a compliant layer and a memory with elastic Hertz, a slab ended in a
    KeyError and t = 0 in a ZeroDivisionError. Each is refused by name. Plane stress is compared with its own
    modulus (E* = E; plane strain's is E / (1 - nu^2)), and meets Hertz as plane strain does."""
    E, nu = 2000.0, 0.3
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    voigt = [[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]]
    for values, said in ((dict(elastic_tensor=voigt), "elastic tensor is a matrix"),
                         (dict(gap=0.001, F=10.0, c=1e4), "compliant layer (gap = 0.001, F = 10, c = 10000)"),
                         (dict(prony=[[-500.0, 0.3, 0.5]]), "relaxation memory")):
        ds = workbench.run("memory_hertz", h_contact=0.01, progress=False, **values)
        with pytest.raises(workbench.ParameterError, match=f"^hertz.profile: the run's .*{re.escape(said)}"):
            hertz.profile(ds)
    with pytest.raises(workbench.ParameterError, match="it compares a run of hertz, hertz3d"):
        hertz.profile(workbench.run("memory_slab", h=0.25, T=0.2, progress=False))
    strain = workbench.run("memory_hertz", h_contact=0.005, progress=False)
    with pytest.raises(workbench.ParameterError, match=r"the load at t = 0 s is 0: nothing presses"):
        hertz.profile(strain.isel(time=[0]))
    stress = hertz.profile(workbench.run("memory_hertz", h_contact=0.005, plane="stress", progress=False))
    assert stress["a"] == pytest.approx(hertz.cylinder(stress["load"], 1.0, 1000.0, 0.0)[0])
    assert stress["a_last"] <= stress["a"] <= stress["a_next"] and stress["l2"] < 1.5 * hertz.profile(strain)["l2"]


def test_p2_signorini_hertz_archives_its_midpoint_forces():
    """Model B on P2 (2D) has contact points at the facet midpoints too: the archive carries their pressures,
    coordinates and Simpson weights, so the force balance closes from it (to 1e-9; the vertices alone carry about a
    third), the held apex's reaction counts only its own share (it had the adjacent midpoints' forces too: 1.019 x
    the load), and the pressure is within 3 % of Hertz (measured 2.4 %)."""
    ds = workbench.run("memory_hertz", h_contact=0.005, order=2, progress=False)
    assert ds.sizes["midpoint"] == ds.sizes["node"] - 1
    length = float(ds.node_weight.sum() + ds.midpoint_weight.sum())
    r = hertz.profile(ds)
    assert r["force"] == pytest.approx(1.0, abs=1e-9) and r["l2"] < 0.03
    assert abs(r["a_last"] - r["a"]) <= 0.005
    vertices = float(np.sum(ds.node_weight * ds.contact_pressure.isel(time=-1))) / (r["load"] / 2)
    assert 0.2 < vertices < 0.5
    assert length == pytest.approx(float(ds.midpoint_weight.sum()) * 1.5, rel=1e-12)  # Simpson: 1/3 vertices, 2/3 mid


@pytest.mark.slow
def test_elastic_hertz_3d_in_the_signorini_limit():
    """The hemisphere (its quarter): the pressure's L2 error against Hertz's sphere falls under refinement, the
    contact radius lies within one element of a, the force carries the load."""
    hcs, errors = [0.04, 0.02], []
    for hc in hcs:
        r = hertz.profile(workbench.run("memory_hertz3d", h_contact=hc, progress=False))
        errors.append(r["l2"])
        assert abs(r["a_last"] - r["a"]) <= hc
        assert r["force"] == pytest.approx(1.0, abs=1e-9)
    assert errors[1] < 0.8 * errors[0] and errors[1] < 0.15


def test_normal_compliance_approaches_the_signorini_pressure():
    """Model A, an almost elastic body (tau = 1e-3 s): as c_nu grows the penetration falls as 1/c_nu and the pressure
    approaches Hertz's profile."""
    cs, pens, errors = [1e5, 1e6, 1e7], [], []
    for c in cs:
        ds = workbench.run("hertz", h_contact=0.0025, c_nu=c, tau=1e-3, k=0.05, progress=False)
        r = hertz.profile(ds)
        u_nu = -ds.u_contact.isel(time=-1).sel(component="y").values
        pens.append(float((u_nu - ds.node_y.values).max()))
        errors.append(r["l2"])
        assert r["force"] == pytest.approx(1.0, abs=1e-6)
    assert -1.1 < _order(cs, pens) < -0.85  # measured -0.95
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.03  # measured 0.36, 0.063, 0.0092


def test_viscoelastic_hertz_follows_lee_radok():
    """Kelvin-Voigt with A = tau G (tau = 0.2 s) under the ramp P = 10 t: the contact half-width a(t) follows Lee
    and Radok's a(t)^2 = (4 R / pi) int J*(t - s) dP(s): the last vertex in contact lies within two elements of a at
    every recorded time once a spans 10 elements (a vertex carries a force as soon as one quadrature point beside
    it touches: up to an element beyond the edge), and within 3 % once it spans 35 (BDF2, c_nu = 1e7; measured:
    0.4 to 2.4 % beyond a)."""
    ds = workbench.run("hertz", h_contact=0.00125, c_nu=1e7, tau=0.2, k=0.02, scheme="bdf2", snapshots=(),
                       progress=False)
    checked = 0
    for t in ds.time.values[1:]:
        a = hertz.lee_radok(t, rate=10.0, R=1.0, E=1000.0, nu=0.3, tau=0.2, body="cylinder")
        r = hertz.profile(ds, t)
        if a >= 10 * 0.00125:  # the contact's last vertex lies within two elements (as there: a_next - a_last) of a
            assert abs(r["a_last"] - a) <= 2 * (r["a_next"] - r["a_last"]) and r["a_next"] > a, (t, r["a_last"], a)
        if a >= 35 * 0.00125:  # ... which is within 3 % of a beyond 35 elements
            assert abs(r["a_last"] / a - 1) < 0.03, (t, r["a_last"], a)
            checked += 1
    assert checked >= 30
    # the lag behind the elastic contact is what is measured: at t = 0.25 the elastic a is 26 % larger
    assert hertz.cylinder(2.5, 1.0, 1000.0, 0.3)[0] > 1.2 * hertz.lee_radok(0.25, 10.0, 1.0, 1000.0, 0.3, 0.2)


@pytest.mark.parametrize("body", ["cylinder", "sphere"])
@pytest.mark.parametrize("load", ["10*t", "5 + 10*t + 20*t^2"])
def test_lee_radoks_kelvin_voigt_pressure_carries_the_load(body, load):
    """The Kelvin-Voigt reference (A = tau G): its pressure's resultant is the load at every time (2 int_0^a p dx for
    the cylinder, int_0^a 2 pi r p dr for the sphere, by x = a sin(theta), exact for the edge's inverse root), a(t)
    is lee_radok's under a ramp, and tau -> 0 gives Hertz's. Loads at t = 0 and curving too."""
    from workbench.expressions import parse

    P = parse(load, name="load", allowed=("t",))
    theta = np.linspace(0.0, np.pi / 2, 200_001)[:-1]
    for t in (0.05, 0.3, 1.0):
        a, p = hertz.kelvin_voigt(lambda s: float(P(t=s)), t, 1.0, 1000.0, 0.3, 0.2, body)
        x = a * np.sin(theta)
        dx = a * np.cos(theta) * (theta[1] - theta[0])
        resultant = np.sum(p(x) * dx) * 2 if body == "cylinder" else np.sum(2 * np.pi * x * p(x) * dx)
        assert resultant == pytest.approx(float(P(t=t)), rel=1e-4), (t, resultant)
        if load == "10*t":
            assert a == pytest.approx(hertz.lee_radok(t, 10.0, 1.0, 1000.0, 0.3, 0.2, body), rel=1e-10)
    elastic = (hertz.cylinder if body == "cylinder" else hertz.sphere)(float(P(t=1.0)), 1.0, 1000.0, 0.3)
    a, p = hertz.kelvin_voigt(lambda s: float(P(t=s)), 1.0, 1.0, 1000.0, 0.3, 1e-9, body)
    assert a == pytest.approx(elastic[0], rel=1e-6) and p(0.5 * a) == pytest.approx(elastic[1](0.5 * a), rel=1e-6)
    with pytest.raises(workbench.ParameterError, match="shrinks before t = 1 s"):
        hertz.kelvin_voigt(lambda s: 10.0 * np.sin(np.pi * s), 1.0, 1.0, 1000.0, 0.3, 0.2, body)


def test_a_kelvin_voigt_run_is_compared_with_lee_and_radoks_pressure():
    """profile() of a viscous hertz run compares it with Lee and Radok's pressure for A = tau G, not with the
    elastic body's at the load then: at tau = 0.2 (BDF2, c_nu = 1e7, h_contact = 0.0025) 0.78 % within 0.9 a, where
    the elastic reference said 16 % and a contact radius 30 % off (a helper's pass, December 2026). A viscous
    tensor that is no multiple of the elastic one is refused by name."""
    ds = workbench.run("hertz", tau=0.2, h_contact=0.0025, c_nu=1e7, k=0.01, scheme="bdf2", snapshots=(),
                       progress=False)
    r = hertz.profile(ds)
    assert r["tau"] == pytest.approx(0.2) and r["l2_within"] == 0.9 and r["l2"] < 0.015
    assert r["a"] == pytest.approx(hertz.lee_radok(1.0, 10.0, 1.0, 1000.0, 0.3, 0.2), rel=1e-10)
    assert abs(r["a_last"] - r["a"]) < 2 * 0.0025 < r["a_next"] - r["a"] + 2 * 0.0025  # (within an element or two)
    assert r["force"] == pytest.approx(1.0, abs=1e-9)
    other = workbench.run("hertz", a1=1.0, a2=30.0, k=0.5, progress=False)
    with pytest.raises(workbench.ParameterError, match="no multiple of its elastic one"):
        hertz.profile(other)


def test_curved_adhesion_debonds_only_where_pulled_away():
    """The half-disc glued (beta0 = 1, tension truncation), pressed and then pulled (load = 10 sin(2 pi t)): beta stays
    in [0, 1], decreases on a facet only in a step where its midpoint was pulled away (u_nu < 0), and does decrease
    (the pull debonds); while the load presses, facets not pulled keep beta0."""
    ds = workbench.run("hertz", adhesion=True, gamma_nu=50.0, L=0.05, c_nu=1e5, tau=0.05, h_contact=0.005, k=0.01,
                       load="10*sin(2*pi*t)", scheme="implicit", progress=False)
    beta = ds.beta.values
    assert np.all((beta >= 0) & (beta <= 1))
    # u_nu at the facet midpoints: the mean of the facet's two vertices (the contact side is a graph over x)
    x = ds.node_x.values
    order = np.argsort(x)
    u_nu = -ds.u_contact.sel(component="y").values[:, order]
    mid_x = 0.5 * (x[order][1:] + x[order][:-1])
    mid_u = 0.5 * (u_nu[:, 1:] + u_nu[:, :-1])
    facet = np.array([int(np.argmin(np.abs(mid_x - fx))) for fx in ds.facet_x.values])
    assert np.allclose(mid_x[facet], ds.facet_x.values, atol=1e-12)
    pulled = mid_u[:, facet] < 0  # (time, facet)
    drop = np.diff(beta, axis=0) < 0
    assert drop.any() and (pulled[:-1] | pulled[1:])[drop].all()
    pressing = ds.time.values <= 0.5  # load >= 0: the facets that move towards the foundation keep beta0
    never = ~pulled[pressing].any(axis=0)
    assert never.any() and np.all(beta[pressing][:, never] == 1.0)


def _energy(sc, d, u, beta):
    """Phi(u) at the side's quadrature points, written here: c_nu/2 ((u_nu - y)_+)^2 + gamma beta^2 phi_L(u_nu)."""
    side = d.side
    u_nu = side.u_nu(u)
    r = u_nu - side.xyz[:, 1] - sc["gap"]
    L, gam = sc["L"], sc["gamma_nu"]
    phi = np.where(u_nu >= 0, 0.0, np.where(u_nu < -L, L * L / 2 - L * (u_nu + L), u_nu * u_nu / 2))
    b = beta[side.element]
    return float(np.sum(side.weights * (sc["c_nu"] / 2 * np.maximum(r, 0) ** 2 + gam * b * b * phi)))


def test_contact_functional_on_a_curved_side_is_its_energy_gradient():
    """On the half-disc's curved side (gap g0 = y): the fast path's j equals the NGSolve form's (whose gap is the
    coordinate function y), j is the gradient of the energy (central differences), and the implicit schemes'
    Jacobian is j's derivative."""
    sc = workbench.scene("hertz", h=0.2, h_contact=0.02, adhesion=True, c_nu=7.0, gamma_nu=2.0, L=0.05)
    d = discretisation.build(sc)
    assert d.side.gap0 is not None and d.side.gap0.max() > 0.04  # (the contact zone: gap up to 0.046 R)
    rng = np.random.default_rng(3)
    u = d.u.vec.FV().NumPy()
    y = d.vertex_xyz[:, 1]
    u[d.vertex_dofs[:, 1]] = -(y + rng.uniform(-0.08, 0.03, y.size))  # in and out of contact, pulled here and there
    beta = rng.uniform(0.2, 1.0, d.beta_dofs.size)
    d.beta.vec.FV().NumPy()[d.beta_dofs] = beta
    d.contact_form.Assemble()
    form = d.contact_form.vec.FV().NumPy().copy()
    m = d.model
    fast = d.side.integrate(m.contact.normal(NP, d.side.u_nu(u), beta[d.side.element], d.side.gap0))
    np.testing.assert_allclose(fast, form, rtol=1e-12, atol=1e-14 * np.abs(form).max())
    assert np.abs(form).max() > 1e-4
    for _ in range(3):
        w = rng.standard_normal(d.ndof)
        eps = 1e-7
        fd = (_energy(sc, d, u + eps * w, beta) - _energy(sc, d, u - eps * w, beta)) / (2 * eps)
        assert fast @ w == pytest.approx(fd, rel=1e-6, abs=1e-10)
    op = ContactOperator(d)
    u_C = u[op.C].copy()
    J = op.jacobian(u_C)
    dv = rng.standard_normal(u_C.size) * 1e-9
    np.testing.assert_allclose(J @ dv, op.force(u_C + dv) - op.force(u_C), rtol=1e-4, atol=1e-12)


def test_a_study_refines_the_contact_zone():
    """A Study sweeps h_contact (a refinement axis; the finest is named as the reference) on the Hertz body: the fields of
    non-nested meshes with curved sides are compared over the cells' overlaps (a fine point just outside a coarser
    faceted side takes its nearest cell), and the displacement's energy-norm error falls (measured 1.30e-3, 1.09e-3;
    the body beyond the zone keeps h = 0.1. Compared by interpolation, as before, 8.7e-4 and 4.4e-4: the
    interpolation's own change of the coarse field, test_study.py)."""
    st = workbench.Study("memory_hertz", sweep={"h_contact": [0.01, 0.005, 0.0025]}, workers=0, n_compare=2,
                         reference="finest")
    ds = st.run(progress=False)
    assert ds.attrs["reference_case"].endswith("h_contact=0.0025")
    err = ds.error_V.sel(h_contact=[0.01, 0.005]).values.ravel()
    assert np.isfinite(err).all() and err[1] < 0.9 * err[0]
    assert ds.attrs["transfer"].startswith("cell overlaps (meshes not nested)")


@pytest.mark.slow
def test_both_model_a_schemes_on_a_curved_body():
    """The rocker of docs/examples (a curved sole, adhesion, compliance): only the part of the sole that touches has
    a foundation spring, so the explicit scheme's limit for the springs that act (the run's k_crit_min, 2.5 x the
    bound with the spring on the whole sole, measured) lets it run at twice that bound, in agreement with the
    implicit scheme at a small step; a step above the limit the state reaches stops the run with the steps so far,
    and one above the limit at the start is refused before work."""
    from pathlib import Path

    from workbench.discrete import stability
    from workbench.errors import StepLimitExceeded, StepTooLarge

    toml = Path(__file__).resolve().parents[1] / "docs" / "examples" / "rocker.toml"
    sc = workbench.scene(str(toml), T=0.2, c_nu=1e3)
    assert sc.body.curved
    bound = stability.critical_step(sc).k_crit
    ref = workbench.run(sc, scheme="implicit", k=1e-4, snapshots=(), progress=False)
    ds = workbench.run(sc, scheme="explicit", k=2.0 * bound, snapshots=(), progress=False)
    assert ds.attrs["k_crit_min"] > 2.0 * bound and ds.attrs["k_crit"] >= ds.attrs["k_crit_min"]
    tip = lambda d: d.u_probe.isel(time=-1).values  # noqa: E731
    assert np.abs(tip(ds) - tip(ref)).max() < 0.01 * np.abs(tip(ref)).max()  # measured 0.68 %
    with pytest.raises(StepLimitExceeded) as err:
        workbench.run(sc, scheme="explicit", k=1.5 * ds.attrs["k_crit_min"], snapshots=(), progress=False)
    partial = err.value.dataset
    assert partial.attrs["status"] == "incomplete" and partial.sizes["time"] > 2
    assert "contact state changed" in str(err.value) and "scheme = 'implicit'" in str(err.value)
    with pytest.raises(StepTooLarge):
        workbench.run(sc, scheme="explicit", k=1.5 * ds.attrs["k_crit"], progress=False)




@pytest.mark.slow
def test_the_contact_zone_follows_the_parameter():
    """contact_zone sets the part of the curved side that is the contact boundary (refined with h_contact): the
    contact vertices lie within contact_zone x radius of the apex and reach its edge; a smaller zone has fewer
    vertices and, while it holds Hertz's contact radius, the same answer (force exact, pressure within 1 % of the
    default zone's error); a load whose contact radius nears the zone's edge is warned about by name."""
    runs = {z: workbench.run("memory_hertz3d", h_contact=0.02, contact_zone=z, progress=False) for z in (0.3, 0.24)}
    for z, ds in runs.items():
        r = np.hypot(ds.node_x.values, ds.node_y.values)
        assert r.max() <= z * 1.0 + 1e-9 and r.max() > z - 0.02
    assert runs[0.24].sizes["node"] < 0.8 * runs[0.3].sizes["node"]
    errors = [hertz.profile(ds)["l2"] for ds in runs.values()]
    assert abs(errors[1] - errors[0]) < 0.01 and hertz.profile(runs[0.24])["force"] == pytest.approx(1.0, abs=1e-9)
    with pytest.warns(RuntimeWarning, match="increase contact_zone"):
        workbench.run("memory_hertz3d", h_contact=0.04, contact_zone=0.2, progress=False)
    with pytest.raises(workbench.ParameterError, match="contact_zone"):
        workbench.scene("memory_hertz3d", contact_zone=0.95)


@pytest.mark.parametrize("name", ["memory_hertz3d", "hertz", "hertz3d"])
def test_the_contact_side_is_the_curved_side_within_the_zone_alone(name):
    """Every contact vertex lies on the curved side (the circle or sphere of radius R about (0, R) or (0, 0, R)),
    within contact_zone R of the axis, and the weights add up to that cap's length or area. The hemisphere's side
    once took in the wall of the refined zone, inside the body (76 of its 203 vertices at the defaults, z up to
    0.15 R): a glue pulled there with 45 % of the load (a helper's pass, December 2026)."""
    ds = workbench.run(name, k=0.5, progress=False)
    R, zone, dim = 1.0, 0.3, 3 if name.endswith("3d") else 2
    x, y = ds.node_x.values, ds.node_y.values
    centre = (x ** 2 + (ds.node_z.values - R) ** 2 + y ** 2) if dim == 3 else (x ** 2 + (y - R) ** 2)
    assert np.abs(np.sqrt(centre) - R).max() < 1e-9
    assert np.hypot(x, y if dim == 3 else 0.0).max() <= zone * R + 1e-12
    theta = np.arcsin(zone)
    cap = np.pi * R ** 2 * (1 - np.cos(theta)) / 2 if dim == 3 else R * theta  # (the quarter cap; the half arc)
    assert ds.node_weight.values.sum() == pytest.approx(cap, rel=0.01)


def test_recovered_pressure_against_hertz_3d():
    """The patch-recovered pressure (contact_pressure_recovered) of the hemisphere against Hertz's: the same resultant
    as the nodal forces, and smoother and closer than the lumped one on the unstructured surface mesh (measured at
    h_contact = 0.02: spread of p / p_Hertz inside 0.8 a 6.2 % -> 2.3 %, peak +10.8 % -> +1.6 %, L2 10.2 % -> 5.8 %)."""
    ds = workbench.run("memory_hertz3d", h_contact=0.02, progress=False)
    lumped, recovered = (hertz.profile(ds, variable=v) for v in ("contact_pressure", "contact_pressure_recovered"))
    assert abs(recovered["force"] - lumped["force"]) < 1e-12 and abs(lumped["force"] - 1) < 1e-9
    p0 = hertz.sphere(lumped["load"], 1.0, 1000.0, 0.3)[1](0.0)

    def spread_and_peak(r):
        inner = (r["x"] > 0) & (r["x"] < 0.8 * r["a"])
        return float(np.std(r["p"][inner] / r["p_hertz"][inner])), float(np.max(r["p"][r["x"] > 0]) / p0 - 1)

    (s_l, peak_l), (s_r, peak_r) = spread_and_peak(lumped), spread_and_peak(recovered)
    assert s_r < 0.5 * s_l and abs(peak_r) < 0.03 < abs(peak_l)
    assert recovered["l2"] < 0.7 * lumped["l2"]
    outside = ds.contact_pressure.isel(time=-1).values <= 0  # (no pressure leaks out of the contact zone)
    assert np.all(ds.contact_pressure_recovered.isel(time=-1).values[outside] <= 0)


def test_recovered_pressure_keeps_a_uniform_pressure():
    """A flat body pressed uniformly: every patch average of a constant is that constant."""
    d = discretisation.build(workbench.scene("memory_hertz3d", h_contact=0.04))
    w = d.node_weights
    p = np.full(len(w), 7.0)
    np.testing.assert_allclose(d.pressure_recovery(p, w), 7.0, rtol=1e-13)
    p[0] = np.nan  # a clamped vertex stays unknown
    assert np.isnan(d.pressure_recovery(p, w)[0])


@pytest.mark.parametrize("scene", ["memory_hertz3d", "memory_hertz"])
def test_a_vertex_pressed_by_round_off_is_not_in_the_recovered_zone(scene):
    """A vertex whose lumped pressure is round-off (2e-12 of a peak of 200, or 0, or -4e-12: which one depends on the
    number of MPI processes) took its patch's average where positive, 73 Pa of a peak of 243 on a mesh body, and
    moved its neighbours' averages: the recovered pressure differed between 1 and 2 processes by 30 % of its peak (an
    outside pass, December 2026). Pressures within 1e-9 of the peak are round-off: the three give the same."""
    d = discretisation.build(workbench.scene(scene, h_contact=0.04 if scene == "memory_hertz3d" else 0.01))
    xyz = d.node_xyz
    w, r = d.node_weights, np.hypot(xyz[:, 0], xyz[:, 1]) if d.dim == 3 else np.abs(xyz[:, 0])
    a = np.sort(r)[len(r) // 3]  # (a third of the vertices in contact)
    p = np.where(r < a, 200.0 * np.sqrt(np.clip(1 - (r / a) ** 2, 0, None)), 0.0)
    edge = np.argmin(np.where(r >= a, r, np.inf))  # (the first vertex out of contact)
    runs = []
    for tiny in (2e-12, 0.0, -4e-12):
        q = p.copy()
        q[edge] = tiny
        runs.append(d.pressure_recovery(q, w))
    for other in runs[1:]:
        assert np.abs(other - runs[0]).max() <= 1e-9 * 200.0
    assert abs(runs[0][edge]) <= 1e-9 * 200.0


def _graded_half_disc():
    """The 2D Hertz body at h_contact = 0.01 with the elements near the apex bisected twice: facets of 0.0025 beside
    facets of 0.005 and 0.01 along the contact side (the steps an adapted mesh has)."""
    from workbench.input.geometry import on_mesh
    from workbench.running import adapt

    sc = workbench.scene("memory_hertz", h_contact=0.01)
    body = sc.model_of().geometry
    for radius in (0.08, 0.04):
        mesh = body.mesh()
        near = np.array([min(np.hypot(*mesh[v].point) for v in el.vertices) < radius for el in mesh.Elements()])
        body = on_mesh(body, adapt.refine(mesh, near))
    return discretisation.build(dataclasses.replace(sc.model_of(), geometry=body), sc)


def _lumped(d, pressure):
    """F_j / w_j for a pressure p(x) on the contact side, F_j = int p phi_j da by 4-point Gauss on each facet (not
    by the hats' centroids the recovery uses), w_j = int phi_j da."""
    index = {int(v): i for i, v in enumerate(d.vertex_numbers)}
    F, w = np.zeros(len(index)), np.zeros(len(index))
    s, g = np.polynomial.legendre.leggauss(4)
    s, g = (s + 1) / 2, g / 2
    for el in d.mesh.Boundaries(d.contact_name).Elements():
        (a, b) = [np.array(d.mesh[v].point) for v in el.vertices]
        ia, ib = (index[v.nr] for v in el.vertices)
        length = np.linalg.norm(b - a)
        x = a[0] + s * (b[0] - a[0])
        F[ia] += length * np.sum(g * pressure(x) * (1 - s))
        F[ib] += length * np.sum(g * pressure(x) * s)
        w[ia] += length / 2
        w[ib] += length / 2
    return F / w, w


def test_recovered_pressure_is_second_order_on_a_graded_contact_side():
    """2D: a lumped pressure is the pressure's mean over its hat, at the vertex only to first order where the facets
    beside it differ in size. The recovery's linear fit at the hats' centroids is exact for a linear pressure on the
    graded side (every vertex it fits), and for Hertz's own profile its error is below a third of the patch
    average's, which is first order there."""
    from workbench.discrete.pressure import Recovery

    d = _graded_half_disc()
    x = d.node_xyz[:, 0]
    lumped, w = _lumped(d, lambda x: 10.0 + 30.0 * x)
    fitted, operator = d.pressure_recovery.fit
    assert fitted.sum() > 0.8 * len(x)
    np.testing.assert_allclose((operator @ lumped)[fitted], (10.0 + 30.0 * x)[fitted], rtol=1e-12)

    a = 0.2  # (a smooth Hertz-like profile whose edge lies beyond the side: the fit everywhere but the ends)
    profile = lambda x: 50.0 * np.sqrt(np.maximum(1.0 - (x / (2 * a)) ** 2, 0.0))  # noqa: E731
    lumped, w = _lumped(d, profile)
    averaged = Recovery(d.mesh, d.contact_name, d.vertex_numbers)(lumped, w)
    inner = x < 0.25
    err_fit = np.abs(d.pressure_recovery(lumped, w) - profile(x))[inner].max()
    err_average = np.abs(averaged - profile(x))[inner].max()
    assert err_fit < err_average / 3, (err_fit, err_average)


def test_memory_hertz_default_mesh_meets_hertz_within_one_percent():
    """The 2D Signorini Hertz scene at its default mesh (the scene's defaults only): the recovered pressure within 1 %
    of Hertz's in L2 and at the peak, the contact's last vertex within one element of Hertz's a (measured 0.90 %,
    -0.16 %, 2.0 % inside a with elements of 2.5 %)."""
    ds = workbench.run("memory_hertz", progress=False)
    r = hertz.profile(ds, variable="contact_pressure_recovered")
    p0 = hertz.cylinder(r["load"], 1.0, 1000.0, 0.3)[1](0.0)
    x, p = r["x"], r["p"]
    assert r["l2"] <= 0.01
    assert abs(float(np.max(p[x > 0])) / p0 - 1) <= 0.01
    assert r["a_last"] <= r["a"] < r["a_next"] and r["a"] - r["a_last"] <= r["a_next"] - r["a_last"]


def test_the_held_apex_reaction_from_the_matrices_rows_is_the_whole_residuals(monkeypatch):
    """Model A's pressure at the held apex is the support's reaction, K_A v + K_G u - f at its normal dof, taken from
    the matrices' rows there (cut once) instead of two whole products per record: at every record equal, to
    round-off, to that entry of the whole residual (NGSolve's products, as a distributed run still forms it)."""
    from workbench.schemes.model_a import KelvinVoigtObserver

    kw = dict(h_contact=0.01, k=0.05, T=0.5, progress=False)
    rows = workbench.run("hertz", **kw)
    monkeypatch.setattr(KelvinVoigtObserver, "_residual_at", lambda self, t, dofs: self.record_vectors(t)[0][dofs])
    whole = workbench.run("hertz", **kw)
    apex = int(np.argmin(np.abs(rows.node_x.values)))
    p, q = rows.contact_pressure.values, whole.contact_pressure.values
    assert p[-1, apex] > 0.5 * p[-1].max()  # (the apex carries about the peak pressure)
    assert np.abs(p - q).max() <= 1e-12 * np.abs(q).max()


@pytest.mark.parametrize("scene, values, said", [
    ("hertz", dict(gap=0.001), "gap = 0.001"),
    ("memory_hertz", dict(F=30.0, c=1e4, gap=0.01), "gap = 0.01, F = 30, c = 10000"),
    ("memory_hertz", dict(load="-5"), "load = -5 pulls (down to -5 N)"),
    ("hertz", dict(load="ifpos(t-0.2506,ifpos(0.2518-t,-5,10*t),10*t)", k=0.0004, T=0.3),
     "load = ifpos(t-0.2506,ifpos(0.2518-t,-5,10*t),10*t) pulls (down to -5 N)"),
])
def test_a_hertz_body_whose_held_apex_would_carry_force_is_warned_about(scene, values, said):
    """The Hertz scenes hold their apex at u_nu = 0 against the rigid motion of a body pressed by a force. With a gap,
    Model B's layer or a pull, the contact would move it, and the hold carried a force instead, silently (an outside
    pass, December 2026: gap = 0.001 on ``hertz``, the apex held 19 % of the load while its neighbours crossed the gap;
    ``memory_hertz`` pulled by 5 N, the apex held the body alone with a Signorini pressure of -1993 Pa). A warning
    says so; at the scenes' own values, none. A pull of 1.2 ms between two switches fell between the 201 times the
    load was first sampled at (an outside pass): it is sampled finely and beside its kinks."""
    import warnings

    with pytest.warns(RuntimeWarning, match=re.escape(f"{scene}: {said}: the apex is held at u_nu = 0")):
        ds = workbench.run(scene, h=0.2, h_contact=0.02, **(dict(T=0.5, k=0.25) | values), progress=False)
    apex = int(np.argmin(np.abs(ds.node_x.values)))
    force = ds.node_weight.values * ds.contact_pressure.isel(time=-1).values
    assert abs(force[apex]) > 0.05 * abs(force.sum())  # (what the hold carries: the reason for the warning)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        workbench.run(scene, h=0.2, h_contact=0.02, T=0.5, k=0.25, progress=False)


def test_tau_scales_the_elastic_tensor_given():
    """``tau`` makes the viscous tensor tau G. Given G as ``elastic_tensor``, a1 and a2 were made from the default E
    and nu instead: for the plane-strain tensor of E = 2000, A was half of tau G, and u 18 % off at t = 0.1 (an
    outside pass, December 2026). Now the viscous tensor is tau times the tensor given, and the run equals the one
    with E = 2000 to round-off."""
    lam, mu = 2000 * 0.3 / (1.3 * 0.4), 2000 / 2.6
    C = [[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]]
    kw = dict(h=0.2, h_contact=0.02, T=0.2, k=0.05, progress=False)
    a = workbench.run("hertz", elastic_tensor=C, **kw)
    b = workbench.run("hertz", E=2000.0, **kw)
    A = workbench.scene("hertz", elastic_tensor=C)["viscous_tensor"]
    np.testing.assert_allclose(np.array(A, dtype=float), 0.05 * np.array(C), rtol=1e-12)
    assert np.abs(a.u_probe.values - b.u_probe.values).max() <= 1e-10 * np.abs(b.u_probe.values).max()


def test_an_h_contact_coarser_than_h_is_said_to_do_nothing():
    """h_contact above h meshes the zone at h (the mesh takes the smaller size: the same vertices for 0.1, 0.2, 0.4 at
    h = 0.1), and a study of it ran without a word (found by an outside pass): it is warned about."""
    counts = {hc: workbench.scene("hertz", h=0.1, h_contact=hc).model_of().geometry.vertex_count() for hc in (0.1, 0.2)}
    assert counts[0.1] == counts[0.2]
    with pytest.warns(RuntimeWarning, match=r"h_contact = 0.2 is coarser than h = 0.1, and the mesh takes the smaller"):
        workbench.run("hertz", h=0.1, h_contact=0.2, T=0.1, k=0.05, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        workbench.run("hertz", h=0.1, h_contact=0.05, T=0.1, k=0.05, progress=False)
