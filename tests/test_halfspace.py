"""The half-space model of the contact compliance S = B K^-1 B^T (workbench/schemes/halfspace.py) and the zone
prediction built on it.

References: Boussinesq's loaded circle (Johnson, Contact Mechanics, 3.2) for the kernel with mirror images; the
body's own S, formed column by column with back-substitutions, for the model with images and the held apex; the
coupled solver without the prediction, and the condensed solver, for the solutions (the discrete problem is the
same, so they agree to the solvers' tolerance).
"""
import numpy as np
import pytest

import workbench
from workbench.schemes.coupled_contact import CoupledActiveSet
from workbench.schemes.halfspace import HalfSpace


@pytest.mark.parametrize("on_planes", [False, True], ids=["cell centres", "points on the planes"])
def test_mirror_images_load_the_whole_circle(on_planes):
    """A uniform pressure p on a circle of radius A, modelled as its quarter x, y >= 0 with mirrors on x = 0 and
    y = 0: the quarter's points and their images must lower the surface as the whole circle does, 2 p A at the centre
    and 4 p A / pi at the rim (in units of (1 - nu^2) / E). With points on the planes, each carries the share of
    its patch inside the quarter (half on a plane, a quarter at the origin), as a mesh of the quarter gives it.
    Without the mirrors the centre sinks by about a quarter of that."""
    A, h, p = 1.0, 1.0 / 20, 3.0
    g = np.arange(0.0 if on_planes else h / 2, A + h, h)
    X, Y = np.meshgrid(g, g)
    inside = X ** 2 + Y ** 2 <= A ** 2
    x = np.column_stack([X[inside], Y[inside], np.zeros(inside.sum())])
    w = np.full(len(x), h * h)
    w[x[:, 0] == 0] /= 2
    w[x[:, 1] == 0] /= 2
    rim = np.array([[A, 0.0, 0.0]])  # (a probe only, its force 0)
    points, w = np.vstack([x, rim]), np.concatenate([w, [w.min()]])
    force = np.concatenate([p * w[:-1], [0.0]])
    deflection = HalfSpace(points, w, mirrors=(0, 1)).compliance(np.arange(len(points))) @ force
    centre = int(np.argmin(np.linalg.norm(x, axis=1)))
    assert deflection[centre] == pytest.approx(2 * p * A, rel=0.01)
    assert deflection[-1] == pytest.approx(4 * p * A / np.pi, rel=0.01)
    alone = HalfSpace(points, w).compliance(np.arange(len(points))) @ force
    assert alone[centre] < 0.35 * deflection[centre]


def _capture_schur(monkeypatch):
    """The coupled active set's operator S and contact points, as the last solve of a run left them."""
    seen = {}
    solve = CoupledActiveSet.solve

    def capture(self, schur, *args, **kwargs):
        seen.update(schur=schur, active=self)
        return solve(self, schur, *args, **kwargs)

    monkeypatch.setattr(CoupledActiveSet, "solve", capture)
    return seen


def test_images_and_the_held_apex_model_the_hemispheres_compliance(monkeypatch):
    """S of the Hertz hemisphere (its quarter, the apex held; h_contact = 0.02) formed column by column, against
    the scaled model c G~ on the 76 points in contact at the full load: the generalised eigenvalues of (S, c G~)
    lie in a narrow band (measured 1.06-5.1) where the plain half-space's span a factor 87 (0.90-78.6; with the
    images alone 1.06-45.8: the held apex is most of the difference)."""
    seen = _capture_schur(monkeypatch)
    monkeypatch.setattr(CoupledActiveSet, "predict", False)
    workbench.run("memory_hertz3d", h_contact=0.02, contact_solver="coupled", progress=False)
    schur, active = seen["schur"], seen["active"]
    U = np.nonzero(active.nodes.lam > 0)[0]
    assert U.size > 50
    S = np.zeros((U.size, U.size))
    for j, i in enumerate(U):
        e = np.zeros(active.nodes.lam.size)
        e[i] = 1.0
        S[:, j] = schur.apply(e)[U]
    S = 0.5 * (S + S.T)
    local = 1.0 / schur.stiffness[U]

    def spread(half):
        G = half.compliance(U) * half.scale(U, local)
        values = np.linalg.eigvals(np.linalg.solve(G, S)).real
        return values.min(), values.max()

    low, high = spread(active.halfspace)
    assert active.halfspace.mirrors == (0, 1) and active.halfspace.held is not None
    assert 0.8 < low and high < 6.5
    plain_low, plain_high = spread(HalfSpace(active.halfspace.x, active.halfspace.w))
    assert plain_high / plain_low > 50


def _run(**overrides):
    return workbench.run("memory_hertz3d", contact_solver="coupled", progress=False, **overrides)


def _same_pressures(a, b, tol=1e-7):
    scale = float(np.nanmax(np.abs(b.contact_pressure)))
    assert float(np.nanmax(np.abs(a.contact_pressure - b.contact_pressure))) <= tol * scale


def test_more_points_than_half_the_dense_limit_are_predicted_on_clusters_first(monkeypatch):
    """The model on every point is solved at once only up to half the points a dense factor is allowed
    (``HalfSpace.largest``): beyond, its active set factored a block of every point each iteration (3085 points at
    47k dofs: 2.7 s of a 6.5 s run), where the clusters' zone and its neighbours give the same steps (4.5 s). Here
    the hemisphere's 200 points against a limit of 300: the clusters first, the pressures those of the run without
    a prediction."""
    from workbench.schemes import halfspace

    monkeypatch.setattr(HalfSpace, "largest_for", classmethod(lambda cls, ndof, method, backsubs=2.0: 300))
    clustered = []
    on_clusters = halfspace.ZonePrediction._on_clusters
    monkeypatch.setattr(halfspace.ZonePrediction, "_on_clusters",
                        lambda self, *args: clustered.append(1) or on_clusters(self, *args))
    predicted = _run(h_contact=0.02)
    assert predicted.sizes["node"] == 200 and len(clustered) >= 4
    monkeypatch.setattr(CoupledActiveSet, "predict", False)
    _same_pressures(predicted, _run(h_contact=0.02))


@pytest.mark.parametrize("bounds", [None, (150, 150)], ids=["points", "clusters first"])
def test_the_predicted_zone_cuts_the_back_substitutions(monkeypatch, bounds):
    """The hemisphere at h_contact = 0.02 (200 contact points) from rest to the full load, with and without each
    step's zone predicted on the model: the same pressures for about two thirds of the back-substitutions
    (measured: 70 against 90). With at most 150 points factored the prediction first solves on clusters of points
    and then on the points near the clusters in contact: 70 against 93."""
    if bounds is not None:
        monkeypatch.setattr(HalfSpace, "bounds", bounds)
    predicted = _run(h_contact=0.02)
    monkeypatch.setattr(CoupledActiveSet, "predict", False)
    plain = _run(h_contact=0.02)
    _same_pressures(predicted, plain)
    assert int(predicted.linear_solves.sum()) < 0.8 * int(plain.linear_solves.sum())


def test_the_prediction_meets_a_compliant_layer():
    """A layer with a gap, a yield force and a hardening (all four states met) on the hemisphere: the coupled solver
    with the prediction gives the condensed solver's pressures and states."""
    layer = dict(h_contact=0.02, gap=0.002, F=5.0, c=1e4)
    coupled = _run(**layer)
    condensed = workbench.run("memory_hertz3d", contact_solver="condensed", progress=False, **layer)
    _same_pressures(coupled, condensed)
    np.testing.assert_array_equal(coupled.contact_state.values, condensed.contact_state.values)
    assert set(np.unique(coupled.contact_state.values)) == {0, 1, 2, 3}


def test_a_body_the_half_space_does_not_model_drops_the_prediction(monkeypatch):
    """memory_block (clamped, loaded down on one half and up on the other, a compliant layer): the model's active
    set cycles, and after two such steps the prediction is dropped for the run: the same back-substitutions as
    without it, one by one."""
    seen = _capture_schur(monkeypatch)
    block = dict(h=0.125, k=0.05, T=0.5)
    predicted = workbench.run("memory_block", contact_solver="coupled", progress=False, **block)
    assert seen["active"].prediction.dropped
    monkeypatch.setattr(CoupledActiveSet, "predict", False)
    plain = workbench.run("memory_block", contact_solver="coupled", progress=False, **block)
    np.testing.assert_array_equal(predicted.linear_solves.values, plain.linear_solves.values)


def test_the_start_keeps_the_last_forces_where_the_zone_stays():
    """The active set's start from a prediction: the predicted states always; the last forces where they are not 0
    (exact for the last step, their product kept); the model's forces on the added points only where the zone grows
    by many (at least 10 points and more than 10 % of the zone), else 0 there (the conjugate gradients find a few
    points' forces in an iteration or two)."""
    from types import SimpleNamespace

    from workbench.physics.unilateral import RIGID, SEPARATED

    def start(zone, predicted, n=400):
        states = np.where(np.arange(n) < zone, RIGID, SEPARATED)
        lam = np.where(states == RIGID, 1.0, 0.0)
        new = np.where(np.arange(n) < predicted, RIGID, SEPARATED)
        got_states, got = CoupledActiveSet._start(SimpleNamespace(added_from=CoupledActiveSet.added_from), states,
                                                  lam, new, np.full(n, 2.0))
        np.testing.assert_array_equal(got_states, new)
        np.testing.assert_array_equal(got[:zone], 1.0)  # (the zone that stays: the last forces)
        return got[zone:predicted]

    assert np.all(start(40, 45) == 0.0)  # 5 points added: fewer than 10
    assert np.all(start(40, 60) == 2.0)  # 20 added to 40
    assert np.all(start(200, 212) == 0.0)  # 12 added to 200: 6 %
    assert np.all(start(0, 35) == 2.0)  # from rest


def test_the_models_factor_is_updated_exactly():
    """ModelFactor: a set of points that loses and gains a few points (and changes a few D) a call is solved through
    the base factor by low-rank corrections, to round-off against a dense solve of its own matrix, with a new base
    factor only once the changes pass ``rebase`` of the set."""
    from workbench.schemes.halfspace import ModelFactor

    rng = np.random.default_rng(3)
    x = np.c_[rng.random((300, 2)), np.zeros(300)]
    half = HalfSpace(x, np.full(300, 1e-3), mirrors=(0, 1), held=np.zeros(3))
    factors, c = ModelFactor(half), 2.5
    U, D = np.sort(rng.choice(300, 150, replace=False)), np.zeros(150)
    for _ in range(20):
        U2 = np.union1d(np.delete(U, rng.choice(U.size, 1)), rng.choice(np.setdiff1d(np.arange(300), U), 2))
        D2 = np.where(np.isin(U2, U), np.interp(U2, U, D), 0.0)
        D2[rng.choice(U2.size, 1)] = rng.random()  # (a compliant point's layer)
        A = c * half.compliance(U2) + np.diag(D2)
        r = rng.random((U2.size, 2))
        assert np.abs(A @ factors(U2, D2, c)(r) - r).max() <= 1e-10 * np.abs(r).max()
        # (only the points changed now keep their columns: a set drifting around its base holds no more)
        assert sum(map(len, factors._columns)) <= factors.rebase * U2.size
        U, D = U2, D2
    assert 2 <= factors.factorizations <= 6  # (4 changes a call against 0.125 x 150: a new base every 4-5 calls)


def test_updated_factors_find_what_fresh_factors_find(monkeypatch):
    """The hemisphere at h_contact = 0.02 with the model's factors updated (the default) and redone for every set
    (``rebase = 0``): the same pressures and, but for round-off in the conjugate gradients, the same
    back-substitutions."""
    from workbench.schemes.halfspace import ModelFactor

    updated = _run(h_contact=0.02)
    monkeypatch.setattr(ModelFactor, "rebase", 0.0)
    fresh = _run(h_contact=0.02)
    _same_pressures(updated, fresh, 1e-9)
    assert abs(int(updated.linear_solves.sum()) - int(fresh.linear_solves.sum())) <= 2


def test_an_active_set_that_wanders_gives_up_its_scale(monkeypatch):
    """A compliant layer on the hemisphere at h_contact = 0.01: at the first scale rho the active set wanders among
    nearly the same states without settling (all 60 iterations of the first step); it is given up once 10
    iterations bring no new low in the states changed, and the scale that settles (rho / 100) starts the next
    steps. Measured: 118 back-substitutions in the first step against 247 with the scale held to the end, and 20-22
    in each later step (256, 267, 259, 246 when every step began at rho); the same pressures."""
    layer = dict(h_contact=0.01, gap=0.002, F=5.0, c=1e4)
    given_up = _run(**layer)
    monkeypatch.setattr(CoupledActiveSet, "stall", CoupledActiveSet.max_iterations)
    held = _run(**layer)
    _same_pressures(given_up, held)
    first, later = int(given_up.linear_solves[1]), given_up.linear_solves.values[2:]
    assert first < 0.6 * int(held.linear_solves[1])
    assert later.max() <= 40


def test_the_condensed_active_set_gives_up_a_wandering_scale_too(monkeypatch):
    """The same layer, condensed: at rho its active set wandered for all 50 iterations of each step and fell to
    projected Gauss-Seidel (82.7 s of an 88.9 s run); now the scale is given up and the next one settles (measured:
    35, 6, 5, 5 iterations, 2.8 s, the same pressures bit for bit), with no Gauss-Seidel at all."""
    from workbench.schemes.contact_nodes import ContactNodes

    def no_gauss_seidel(*args, **kwargs):
        raise AssertionError("projected Gauss-Seidel was not needed")

    monkeypatch.setattr(ContactNodes, "_gauss_seidel_states", no_gauss_seidel)
    ds = workbench.run("memory_hertz3d", contact_solver="condensed", h_contact=0.01, gap=0.002, F=5.0, c=1e4,
                       progress=False)
    assert int(ds.iterations.values[2:].max()) <= 10


def test_blocks_cut_and_extended_equal_the_compliance_computed_afresh():
    """HalfSpace.block on a run of point sets that grow by a few points (the storage of the block before last then
    takes the next one), lose some, come back, and jump: every block equals the compliance computed afresh, and the
    block the caller got last stays intact while the next one is built."""
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.random(400), rng.random(400), np.zeros(400)])
    half = HalfSpace(x, np.full(400, 1e-4), mirrors=(0, 1), held=np.zeros(3))
    fresh = HalfSpace(x, np.full(400, 1e-4), mirrors=(0, 1), held=np.zeros(3))
    sets = [np.arange(0, 200), np.arange(0, 210), np.arange(0, 215), np.arange(0, 222), np.arange(5, 222),
            np.arange(0, 230), np.arange(0, 230), np.arange(0, 120), np.r_[0:100, 150:260], np.arange(300, 400)]
    reused, last = 0, None
    for U in sets:
        kept = None if last is None else last.copy()
        spare = half._store
        G = half.block(U)
        reused += spare is not None and G.base is spare
        np.testing.assert_allclose(G, fresh.compliance(U), rtol=1e-13, atol=0)
        if kept is not None:
            np.testing.assert_array_equal(last, kept)  # (the last block, still read by its caller)
        scaled = half.block(U, 2.0)
        np.testing.assert_allclose(scaled, 2.0 * fresh.compliance(U), rtol=1e-13, atol=0)
        last = G
    assert reused >= 2  # (the storage was taken over, not only allocated)
