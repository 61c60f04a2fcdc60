"""Model A's implicit steps on the contact candidates (``workbench.schemes.facet_candidates``): where ``auto`` takes
the coupled solver on a curved 3D side with a normal compliance, the steps are solved on the dofs of the facets of
smallest gap, with the compliance at every other quadrature point checked from the whole u; a step where it acts
there is the coupled solver's on the whole side, and so are the rest.

``auto`` takes the coupled solver from 2500 contact unknowns (``COUPLED_FROM_SCHUR``); these tests make it do so
from 100 (the fixture ``coupled_from_100``), so that meshes of a few thousand dofs take that path. Every run is
compared with the condensed solver on the same discrete problem (an exact dense Newton on every contact dof)."""
import numpy as np
import pytest
import scipy.sparse as sp

import workbench
from workbench.discrete import discretisation, pardiso
from workbench.discrete.condensation import ContactOperator, DenseSchur
from workbench.input.numerics import Numerics
from workbench.schemes import facet_candidates, step_operators
from workbench.schemes.candidates import Candidates
from workbench.schemes.facet_candidates import FacetCandidates
from workbench.schemes.step_operators import StepOperators

pytestmark = pytest.mark.skipif(not pardiso.available(), reason="the candidates are kept by PARDISO's factor")


ORIGINAL = Numerics.coupled_contact


@pytest.fixture
def coupled_from_100(monkeypatch):
    original = ORIGINAL

    def coupled_contact(self, unknowns, solver=None, schur=False, condensed_up_to=None):
        return original(self, unknowns, solver, schur, 100)

    monkeypatch.setattr(Numerics, "coupled_contact", coupled_contact)


@pytest.fixture
def own_factors(monkeypatch):
    """Each step operator factored on its own, as for a body whose A is no multiple of G. The hemisphere's A = tau G:
    its operators share one factor (``SharedFactor``), which keeps the candidates for all of them; that is turned
    off here."""
    monkeypatch.setattr(step_operators.SharedFactor, "of", classmethod(lambda cls, d, method: None))


@pytest.fixture
def factorizations(monkeypatch):
    """PARDISO's factorizations made, counted (one solver object may make its factorization again)."""
    made = []
    factor = pardiso.Factor
    monkeypatch.setattr(pardiso, "Factor", lambda *args, **kwargs: made.append(1) or factor(*args, **kwargs))
    return made


def _agree(a, b, tol):
    """The same time grid, and the contact displacements and pressures equal to ``tol`` of their largest values."""
    np.testing.assert_array_equal(a.time.values, b.time.values)
    for name in ("u_contact", "contact_pressure"):
        x, y = a[name].values, b[name].values
        ok = np.isfinite(y)
        assert np.array_equal(np.isfinite(x), ok), name
        assert np.abs(x[ok] - y[ok]).max() <= tol * np.abs(y[ok]).max(), name


def test_the_candidates_hold_the_zone_and_equal_the_condensed_solver(coupled_from_100, monkeypatch):
    """The hemisphere at h_contact = 0.02 (200 contact vertices, 86 in contact at the end), 52 backward Euler steps:
    150 candidates (fewer than the 199 the rule gives, so that the other points are checked at every step) hold the
    zone. Equal to the condensed solver to 1e-9 (measured 3e-12), with at most one inner iteration per Newton
    iteration on the run's own steps (the springs' systems are preconditioned by their exact inverse), where the
    coupled solver on the whole side takes several."""
    kw = dict(h_contact=0.02, progress=False)
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 150))
    auto = workbench.run("hertz3d", **kw)
    assert auto.attrs["contact_solver_used"] == "coupled"
    assert auto.attrs["contact_candidates"] == 150 and auto.attrs["contact_candidates_missed"] == 0
    assert int((auto.contact_pressure.values[-1] > 0).sum()) == 86
    _agree(auto, workbench.run("hertz3d", contact_solver="condensed", **kw), 1e-9)
    assert int(auto.linear_iterations[1:].sum()) <= int(auto.newton_iterations[1:].sum())  # (the landings' too)
    coupled = workbench.run("hertz3d", contact_solver="coupled", **kw)
    assert coupled.attrs["contact_candidates"] == 0  # (asked by name: the coupled solver on the whole side)
    assert int(coupled.linear_iterations.sum()) > 2 * int(auto.linear_iterations.sum())


def test_a_zone_that_outgrows_the_candidates_is_solved_on_every_dof(coupled_from_100, monkeypatch, factorizations):
    """40 candidates do not hold the zone. The side's 199 contact dofs are few enough for dense work on them all
    (``whole``), so the step where the compliance first acts beyond the candidates is solved again on every dof,
    its factorization made again keeping them, and so are the rest of the run's steps, in both of its operators
    (two step sizes), which share that factorization (A = tau G): two in all. Equal to the condensed solver to
    1e-9."""
    kw = dict(h_contact=0.02, progress=False)
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 40))
    auto = workbench.run("hertz3d", **kw)
    assert auto.attrs["contact_candidates"] == 199 and auto.attrs["contact_candidates_missed"] == 0
    assert np.unique(np.diff(auto.time.values).round(9)).size == 2 and len(factorizations) == 2
    assert int(auto.linear_iterations[1:].sum()) <= int(auto.newton_iterations[1:].sum())
    _agree(auto, workbench.run("hertz3d", contact_solver="condensed", **kw), 1e-9)


def test_a_zone_that_outgrows_what_is_affordable_goes_to_the_coupled_solver(coupled_from_100, monkeypatch):
    """As above, where every dof is more than is affordable (the rule made to allow 50, twice that below 199): the
    step where the
    compliance first acts beyond the candidates is solved again on the whole side by the coupled solver, and so are
    the rest. Still equal to the condensed solver, to the coupled solver's tolerance (1e-7 of the pressures, as
    tests/test_coupled_contact.py has it; measured 1e-10)."""
    kw = dict(h_contact=0.02, progress=False)
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 40))
    monkeypatch.setattr(facet_candidates, "dense_points", lambda ndof, method, backsubs: 50)
    auto = workbench.run("hertz3d", **kw)
    assert auto.attrs["contact_candidates"] == 40 and auto.attrs["contact_candidates_missed"] == 1
    _agree(auto, workbench.run("hertz3d", contact_solver="condensed", **kw), 1e-7)


@pytest.mark.parametrize("kw", [dict(h_contact=0.02, scheme="bdf2", k=0.05, T=0.6, load="4 * t"),
                                dict(order=2, h_contact=0.04, c_nu=1e7, tau=1e-3, k=0.1, T=0.3, snapshots=())],
                         ids=["BDF2, another load", "P2, stiff compliance"])
def test_the_candidates_with_bdf2_and_on_p2(coupled_from_100, monkeypatch, kw):
    """Unlike the first test: BDF2 (its first step by backward Euler, then its own operator) under a load rising
    without a kink, with 120 candidates; and P2 elements with a stiff compliance (the candidates' dofs include the
    edges'; the rule's count covers every contact dof there, so none is checked; no snapshot off the grid, so that
    every step is the candidates'). Against the condensed solver to 1e-8."""
    if "order" not in kw:
        monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 120))
    kw = kw | dict(progress=False)
    auto = workbench.run("hertz3d", **kw)
    assert auto.attrs["contact_candidates"] > 0 and auto.attrs["contact_candidates_missed"] == 0
    _agree(auto, workbench.run("hertz3d", contact_solver="condensed", **kw), 1e-8)


@pytest.fixture
def asked(monkeypatch):
    """150 candidates, and the requests for their operator, in order (``again``: the factorization made anew)."""
    requests = []
    operator = FacetCandidates.operator

    def counted(self, solver, again=False):
        requests.append(again)
        return operator(self, solver, again)

    monkeypatch.setattr(FacetCandidates, "operator", counted)
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 150))
    return requests


@pytest.mark.parametrize("scheme", ["implicit", "bdf2"])
def test_the_candidates_are_kept_for_the_runs_own_step_alone(coupled_from_100, asked, own_factors, scheme):
    """Where each step operator has a factor of its own (``own_factors``), a fixed-step run meets other step operators
    besides its own (k after k): here the landing on a snapshot off the grid (0.12 to 0.13 to 0.14, two steps of
    0.01), and with BDF2 its first step (backward Euler) and the step after each change of size. Each of those
    serves a step or two, so the factorization keeps the candidates for the run's own operator alone (keeping them
    costs about twice a plain factorization, and their compliance's inverse more), and the other steps are the
    coupled solver's on the whole side. One operator asked for its candidates, the others' steps with more inner
    iterations than Newton iterations (back-substitutions), and the run equal to the condensed solver to 1e-8."""
    kw = dict(h_contact=0.02, scheme=scheme, k=0.02, T=0.3, snapshots=(0.13,), progress=False)
    auto = workbench.run("hertz3d", **kw)
    assert auto.attrs["contact_candidates"] == 150 and auto.attrs["contact_candidates_missed"] == 0
    assert asked == [False]
    k = np.diff(auto.time.values)
    own = np.isclose(k, 0.02) & (np.isclose(np.r_[0.0, k[:-1]], 0.02) if scheme == "bdf2" else True)
    assert 0 < (~own).sum() < own.sum()
    newton, inner = auto.newton_iterations.values[1:], auto.linear_iterations.values[1:]
    assert (inner[own] <= newton[own]).all() and (inner[~own] > newton[~own]).all()
    _agree(auto, workbench.run("hertz3d", contact_solver="condensed", **kw), 1e-8)


def test_an_operator_that_keeps_serving_gets_the_candidates_too(coupled_from_100, asked, own_factors):
    """With a factor per step operator (``own_factors``): six snapshots halfway between the points of a grid of 0.02: each
    is landed on and left by a step of 0.01, whose operator then serves 12 steps in all. The first nine are the
    coupled solver's; at the tenth (``RENT_STEPS``) its factorization is made again keeping the candidates (the
    second request), and that step and the last two are theirs. Equal to the condensed solver to 1e-8."""
    kw = dict(h_contact=0.02, k=0.02, T=0.4, snapshots=tuple(0.05 + 0.06 * j for j in range(6)), progress=False)
    auto = workbench.run("hertz3d", **kw)
    assert StepOperators.RENT_STEPS == 10 and asked == [False, True]
    landing = np.nonzero(np.isclose(np.diff(auto.time.values), 0.01))[0]
    assert landing.size == 12
    newton, inner = auto.newton_iterations.values[1:], auto.linear_iterations.values[1:]
    assert (inner[landing[:9]] > newton[landing[:9]]).all() and (inner[landing[9:]] <= newton[landing[9:]]).all()
    _agree(auto, workbench.run("hertz3d", contact_solver="condensed", **kw), 1e-8)


def test_operators_that_share_a_factor_all_keep_the_candidates(coupled_from_100, asked, factorizations):
    """The hemisphere's A = tau G, so every step operator is a multiple of K_G, and K_G's one factorization, which
    keeps the candidates, serves them all (``SharedFactor``). BDF2 with fixed steps and a landing off the grid meets
    five operators: each asks for the candidates once, none makes a factorization again, and every step is theirs
    (at most one inner iteration per Newton iteration). Under error control, one operator per step size, the same.
    Both equal to the condensed solver to 1e-8, whose operators share one factor too."""
    kw = dict(h_contact=0.02, scheme="bdf2", k=0.02, T=0.3, snapshots=(0.13,), progress=False)
    for extra, operators in ((dict(), 5), (dict(rtol=1e-2), 10)):
        asked.clear(), factorizations.clear()
        auto = workbench.run("hertz3d", **kw, **extra)
        assert auto.attrs["contact_candidates"] == 150 and auto.attrs["contact_candidates_missed"] == 0
        assert len(factorizations) == 1 and len(asked) >= operators and not any(asked)
        assert (auto.linear_iterations.values[1:] <= auto.newton_iterations.values[1:]).all()
        factorizations.clear()
        _agree(auto, workbench.run("hertz3d", contact_solver="condensed", **kw, **extra), 1e-8)
        assert len(factorizations) == 1


def test_none_where_the_side_is_flat_glued_the_solver_condensed_or_the_steps_controlled(coupled_from_100, monkeypatch):
    """No candidates on a flat side (the block), with a glue (its forces act on the whole bonded side), under error
    control where each step operator is factored on its own (it changes with the step: a factorization that keeps
    the candidates would be paid for a few steps each), or where ``auto`` condenses the contact problem (the
    hemisphere's 200 vertices, under its own rule: the fixture's 100 undone)."""
    block = workbench.run("block", h=0.25, T=0.1, k=0.05, scheme="implicit", contact_solver="coupled", progress=False)
    assert block.attrs["contact_candidates"] == 0
    d = discretisation.build(workbench.scene("slab", h=0.1, c_tau=1.0))
    assert FacetCandidates.of(d, ContactOperator(d), "pardiso", True) is None
    d = discretisation.build(workbench.scene("hertz3d", h_contact=0.02, scheme="bdf2", rtol=1e-2, T=0.3))
    op = ContactOperator(d)
    assert FacetCandidates.of(d, op, "pardiso", True) is None and FacetCandidates.of(d, op, "pardiso", True, True)
    monkeypatch.setattr(Numerics, "coupled_contact", ORIGINAL)
    hemisphere = workbench.run("hertz3d", h_contact=0.02, T=0.1, progress=False)
    assert hemisphere.attrs["contact_solver_used"] == "condensed" and hemisphere.attrs["contact_candidates"] == 0


def test_the_chosen_facets_close_over_their_dofs():
    """On the hemisphere's side: the chosen points are exactly those whose traces lie within the chosen dofs, those
    dofs number at most ``most``, and no point left out has a smaller gap than every chosen one has (the facets go
    in order of gap)."""
    d = discretisation.build(workbench.scene("hertz3d", h_contact=0.02))
    side = ContactOperator(d).side
    T = sp.csr_matrix(side.T_nu)
    for most in (30, 150, 199):
        cols, points = FacetCandidates.choose(T, side.element, side.gap0, most)
        assert 0 < cols.size <= most
        inside = np.zeros(T.shape[1], dtype=bool)
        inside[cols] = True
        within = np.array([inside[T[i].indices[T[i].data != 0]].all() for i in range(T.shape[0])])
        assert np.array_equal(np.nonzero(within)[0], points)
        left = np.setdiff1d(np.arange(T.shape[0]), points)
        if left.size:
            facet_gap = np.full(side.element.max() + 1, np.inf)
            np.minimum.at(facet_gap, side.element, side.gap0)
            assert facet_gap[side.element[left]].min() >= facet_gap[side.element[points]].min()


def test_the_dense_schur_is_the_compliance_of_the_factor_that_keeps_the_dofs():
    """DenseSchur from a condensed stiffness S: its products are S^-1 x, its blocks S^-1's, its stiffness S's
    diagonal; against a dense inverse of a random SPD matrix."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((30, 30))
    S = A @ A.T + 30 * np.eye(30)
    dense = DenseSchur(S)
    x = rng.standard_normal(30)
    np.testing.assert_allclose(dense.apply(x), np.linalg.solve(S, x), rtol=1e-12, atol=1e-14)
    G, whole = dense.springs_compliance(np.array([2, 5, 11]), np.ones(3))
    assert whole
    np.testing.assert_allclose(G, np.linalg.inv(S), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(dense.stiffness, np.diag(S))
