"""Model B's condensed solver on the contact points of smallest gap (``workbench.schemes.candidates``): where ``auto``
takes the coupled solver on a curved 3D side, the steps are first solved densely on the candidates, with the other
points checked exactly from the whole u; a step where one of them meets the foundation is the coupled solver's."""
import numpy as np
import pytest

import workbench
from workbench.discrete import discretisation, pardiso
from workbench.physics import unilateral
from workbench.physics.unilateral import COMPLIANT, RIGID, SEPARATED, STUCK
from workbench.schemes import candidates
from workbench.schemes.candidates import Candidates
from workbench.schemes.contact_nodes import ContactNodes
from workbench.schemes.memory_vi import MemoryVI
from workbench.schemes.step_operators import StepOperators

pytestmark = pytest.mark.skipif(not pardiso.available(), reason="the candidates are kept by PARDISO's factor")


#: The hemisphere's contact points at h_contact = 0.01 (11,865 dofs), the held apex among them; at most 287 touch.
POINTS = 767


@pytest.fixture(autouse=True)
def coupled_at_12k(monkeypatch):
    """``auto`` takes the coupled solver on the hemisphere at h_contact = 0.01, as from about h_contact = 0.006 (3D
    contact vertices beyond ``condensed_up_to``'s 1245 at 12k dofs, 2294 at 47k): the candidates' machinery on a
    mesh a test can afford. (Before its zone's wall was taken out of the contact side, that mesh had 1291 points.)"""
    from workbench.schemes import memory_vi

    monkeypatch.setattr(memory_vi, "condensed_up_to", lambda ndof, method: 400)


def _agree(a, b, tol=1e-9):
    """The two runs' displacements at the probes and contact pressures agree to ``tol`` of their largest values."""
    for name in ("u_probe", "contact_pressure"):
        x, y = a[name].values, b[name].values
        ok = np.isfinite(y)
        assert np.array_equal(np.isfinite(x), ok), name
        assert np.abs(x[ok] - y[ok]).max() <= tol * np.abs(y[ok]).max(), name


def test_the_candidates_solve_the_hemisphere_as_the_condensed_solver_with_a_fraction_of_the_coupled_solves():
    """The hemisphere at h_contact = 0.01 (767 contact vertices; `auto` takes the coupled solver, fixture): its 500
    points of smallest gap hold the whole zone (287 points at the full load). The run equals the condensed solver's
    on every point to 1e-9 (an exact solve on the same discrete problem). A step is one solve in two parts and the
    active set's dense solves (``linear_solves`` = 1 + ``iterations``, as the condensed solver counts them), with no
    conjugate gradient iteration; the coupled solver alone takes more."""
    kw = dict(h_contact=0.01, progress=False)
    assert Candidates.most(11865, "pardiso", 4) >= POINTS  # (the rule would take every point: 500 here)
    with pytest.MonkeyPatch.context() as fewer:
        fewer.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 500))
        auto = workbench.run("memory_hertz3d", **kw)
    assert auto.sizes["node"] == POINTS and auto.attrs["contact_solver_used"] == "coupled"
    assert auto.attrs["contact_candidates"] == 500 and auto.attrs["contact_candidates_missed"] == 0
    assert int(auto.n_rigid.values[-1]) == 287
    condensed = workbench.run("memory_hertz3d", contact_solver="condensed", **kw)
    _agree(auto, condensed)
    coupled = workbench.run("memory_hertz3d", contact_solver="coupled", **kw)
    assert coupled.attrs["contact_candidates"] == 0  # (asked by name: the coupled solver alone)
    assert int(auto.linear_iterations.sum()) == 0 and int(coupled.linear_iterations.sum()) > 0
    assert auto.linear_solves.values.tolist() == (1 + auto.iterations.values).tolist()


def test_a_zone_that_outgrows_the_candidates_is_solved_on_every_point(monkeypatch):
    """150 candidates hold the first load step's zone (115 points) and not the second's (181). The 766 points are
    few enough for the condensed solver (twice its rule's 1245, with the smaller of its two systems), so that step's
    factorization is made again keeping every point, and the run goes on condensed: equal to the condensed solver's
    to 1e-9, with no conjugate gradient iteration."""
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 150))
    kw = dict(h_contact=0.01, progress=False)
    auto = workbench.run("memory_hertz3d", **kw)
    assert auto.attrs["contact_candidates"] == POINTS - 1 and auto.attrs["contact_candidates_missed"] == 0
    assert auto.n_rigid.values.tolist() == [0, 115, 181, 239, 287] and int(auto.linear_iterations.sum()) == 0
    _agree(auto, workbench.run("memory_hertz3d", contact_solver="condensed", **kw))


def test_a_shared_factor_made_again_for_a_grown_zone_serves_every_operator(monkeypatch):
    """As above with the trapezoid rule and a relaxation tensor that is a multiple of A: the operators (t = 0's, the
    run's own, the landings') share K_A's factorization. Where the zone outgrows the candidates in one of them, that
    factorization is made again keeping every point, and each other operator takes it up at its next step instead of
    solving on a factor that no longer keeps its candidates: two factorizations in all, no conjugate gradient
    iteration, equal to the condensed solver with a factor per operator to 1e-9."""
    from workbench.schemes import step_operators

    made = []
    Factor = pardiso.Factor
    monkeypatch.setattr(pardiso, "Factor", lambda *args, **kwargs: made.append(1) or Factor(*args, **kwargs))
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 150))
    kw = dict(h_contact=0.01, k=0.1, memory_rule="trapezoid", prony=[[-300.0, 0.3, 0.5]], progress=False)
    auto = workbench.run("memory_hertz3d", **kw)
    assert auto.attrs["contact_candidates"] == POINTS - 1 and auto.attrs["contact_candidates_missed"] == 0
    assert len(made) == 2 and int(auto.linear_iterations.sum()) == 0
    monkeypatch.setattr(step_operators.SharedFactor, "of_memory", classmethod(lambda cls, d, method, trapezoid: None))
    _agree(auto, workbench.run("memory_hertz3d", contact_solver="condensed", **kw))


def test_a_zone_that_outgrows_what_the_condensed_solver_affords_is_handed_to_the_coupled_solver(monkeypatch):
    """As above, where every point is more than the condensed solver affords (its rule made to allow 100): the step
    that outgrows the candidates is solved again by the coupled solver, and so are the rest. The run still equals the
    condensed solver's, to the coupled solver's tolerance (1e-7 of the pressures, as tests/test_coupled_contact.py
    has it; measured 1.3e-8)."""
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 150))
    monkeypatch.setattr(candidates, "dense_points", lambda ndof, method, backsubs: 100)
    kw = dict(h_contact=0.01, progress=False)
    auto = workbench.run("memory_hertz3d", **kw)
    assert auto.attrs["contact_candidates"] == 150 and auto.attrs["contact_candidates_missed"] == 1
    assert auto.n_rigid.values.tolist() == [0, 115, 181, 239, 287]
    _agree(auto, workbench.run("memory_hertz3d", contact_solver="condensed", **kw), tol=1e-7)
    # (t = 0 and the first step on the candidates, the rest by the coupled solver's conjugate gradients)
    assert auto.linear_iterations.values[:2].max() == 0 and auto.linear_iterations.values[2:].min() > 0


def test_a_zone_that_outgrows_the_candidates_with_few_steps_left_goes_to_the_coupled_solver(monkeypatch):
    """Every point's dense work is worth it only against the coupled solver's steps left (``Candidates._grows``): at
    106k dofs the zone outgrew 2286 candidates in the last of 4 steps, and solving on all 6410 points took the run
    to 25.0 s, against 14.6 s for the coupled solver alone. Here that work made to cost more than the 3 steps left
    after the miss: the coupled solver takes over, equal to the condensed solver to its tolerance; with the work
    as it is, every point (the test above)."""
    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 150))
    kw = dict(h_contact=0.01, progress=False)
    monkeypatch.setattr(Candidates, "growth", 200.0)  # (8 x (766 / 863)^3 = 5.6 back-substitutions: now 140 > 60)
    auto = workbench.run("memory_hertz3d", **kw)
    assert auto.attrs["contact_candidates"] == 150 and auto.attrs["contact_candidates_missed"] == 1
    _agree(auto, workbench.run("memory_hertz3d", contact_solver="condensed", **kw), tol=1e-7)


def test_the_candidates_with_a_compliant_layer_memory_and_a_load_at_t0():
    """Unlike the Signorini ramp: the full load from t = 0, a compliant layer (gap 0.002, F = 5, c = 1e4: stuck,
    compliant and rigid points) and a Prony memory. Against the condensed solver, to 1e-9."""
    kw = dict(h_contact=0.01, load="10", gap=0.002, F=5.0, c=1e4, prony=[[200.0, 0.3, 0.5]], progress=False)
    auto = workbench.run("memory_hertz3d", **kw)
    assert auto.attrs["contact_candidates"] > 0 and auto.attrs["contact_candidates_missed"] == 0
    assert int(auto.n_compliant.values[-1]) > 0 and int(auto.n_rigid.values[-1]) > 0
    _agree(auto, workbench.run("memory_hertz3d", contact_solver="condensed", **kw))


def test_the_trapezoid_rules_landing_steps_share_one_plain_operator(monkeypatch):
    """The trapezoid rule puts part of the memory into the step's operator, so a run meets one per step size: t = 0's
    (K_A), its own (k = 0.1) and the landings' on the snapshots off the grid (0.2 to 0.25 to 0.3: two steps of 0.05,
    which differ in their last bits and share one operator). Where the relaxation tensor is no multiple of A (its
    Poisson ratio 0.25 against A's 0.3), each has a factor of its own, and the factorization keeps the candidates
    for the run's own operator alone; the others' steps are the coupled solver's on a plain factor until one has served
    ``RENT_STEPS`` steps (made 3 here: the landings' third step of four), when its factorization is made again
    keeping them. Against the condensed solver, to the coupled solver's tolerance (1e-7 of the pressures). Before,
    the run factored four operators, each keeping the candidates."""
    built, requests = [], []
    build, operator = MemoryVI._build, Candidates.operator
    monkeypatch.setattr(MemoryVI, "_build", lambda self, w, keep: built.append((w, keep)) or build(self, w, keep))
    monkeypatch.setattr(Candidates, "operator", lambda self, solver, again=False: requests.append(again) or
                        operator(self, solver, again))
    monkeypatch.setattr(StepOperators, "RENT_STEPS", 3)
    kw = dict(h_contact=0.01, k=0.1, memory_rule="trapezoid", prony=[[-300.0, 0.25, 0.5]], progress=False)
    auto = workbench.run("memory_hertz3d", **kw)
    assert auto.attrs["contact_candidates"] > 0 and auto.attrs["contact_candidates_missed"] == 0
    assert [keep for _, keep in built] == [False, True, False] and built[0][0] == (0.0,)
    assert requests == [False, True]
    # (the coupled solver's conjugate gradients: in the landings' first two steps alone)
    assert np.allclose(auto.time.values[auto.linear_iterations.values > 0], [0.25, 0.3], rtol=0, atol=1e-12)
    _agree(auto, workbench.run("memory_hertz3d", contact_solver="condensed", **kw), tol=1e-7)


def test_a_relaxation_tensor_that_is_a_multiple_of_A_shares_one_factor_for_every_step_size(monkeypatch):
    """With C = f A (the Poisson ratio of A), the trapezoid rule's operators K_A + w K_C are (1 + w f) K_A: K_A's one
    factorization, keeping the candidates, serves every one (``SharedFactor.of_memory``). The run of the test above
    meets three operators, and one under error control (``rtol = 1e-3``) more: each asks for the candidates once,
    none is made again, every step is theirs (no conjugate gradient iteration), one factorization in all. Equal to
    1e-9 to the condensed solver with a factor per operator (both solve the inequality densely; with a factor per
    operator the auto run's landings would be the coupled solver's, to its tolerance)."""
    from workbench.schemes import step_operators

    made, requests = [], []
    Factor, operator = pardiso.Factor, Candidates.operator
    monkeypatch.setattr(pardiso, "Factor", lambda *args, **kwargs: made.append(1) or Factor(*args, **kwargs))
    monkeypatch.setattr(Candidates, "operator", lambda self, solver, again=False: requests.append(again) or
                        operator(self, solver, again))
    kw = dict(h_contact=0.01, k=0.1, memory_rule="trapezoid", prony=[[-300.0, 0.3, 0.5]], progress=False)
    for extra, operators in ((dict(), 3), (dict(rtol=1e-3, T=0.6), 5)):
        made.clear(), requests.clear()
        auto = workbench.run("memory_hertz3d", **kw, **extra)
        assert auto.attrs["contact_candidates"] > 0 and auto.attrs["contact_candidates_missed"] == 0
        assert len(made) == 1 and len(requests) >= operators and not any(requests)
        assert not auto.linear_iterations.values.any()
        with monkeypatch.context() as own:
            own.setattr(step_operators.SharedFactor, "of_memory", classmethod(lambda cls, d, method, trapezoid: None))
            _agree(auto, workbench.run("memory_hertz3d", contact_solver="condensed", **kw, **extra))


def test_a_run_of_many_steps_affords_more_candidates():
    """16 steps (T / k) afford four back-substitutions' worth of candidates: at 12k dofs more than the 767 contact
    vertices, so every point is one and none is checked. Under error control, the same. Both against the condensed
    solver, to 1e-9 (measured 5e-13 with error control, 295 steps and a memory: 8.1 s against 29.0 s for the coupled
    solver alone)."""
    for kw in (dict(k=0.0625), dict(rtol=1e-2)):
        kw |= dict(h_contact=0.01, progress=False)
        auto = workbench.run("memory_hertz3d", **kw)
        assert auto.attrs["contact_candidates"] == auto.sizes["node"] - 1  # (all but the held apex)
        assert auto.attrs["contact_solver_used"] == "coupled" and int(auto.linear_iterations.sum()) == 0
        condensed = workbench.run("memory_hertz3d", contact_solver="condensed", **kw)
        assert auto.sizes["time"] == condensed.sizes["time"]
        _agree(auto, condensed)


def test_a_flat_side_has_no_candidates():
    """memory_block's side lies on the foundation everywhere (every gap 0): the gaps do not tell where it touches
    first, and the coupled solver runs alone."""
    nodes = ContactNodes(discretisation.build(workbench.scene("memory_block", h=0.1)))
    assert Candidates.of(nodes, "pardiso") is None
    assert Candidates.choose(np.zeros(nodes.size), nodes.size // 2) is None


@pytest.mark.parametrize("given", [True, False], ids=["compliance given", "formed from S_inv"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_states_system_on_the_forces_is_the_one_on_the_positions(seed, given):
    """ContactNodes solves a state's system on the unknown forces with the compliance where they are fewer than the
    unknown positions (with the stiffness): the same (s, lam) to round-off, for every state, with F, c and g. The
    compliance is the caller's (the candidates') or, for the condensed solver, S_inv's inverse formed once."""
    nodes = ContactNodes(discretisation.build(workbench.scene("memory_slab", h=0.05)))
    nodes.layer = unilateral.Layer(F=0.3, c=50.0, g=0.01)
    m, rng = nodes.size, np.random.default_rng(seed)
    X = rng.standard_normal((m, m))
    stiffness = X @ X.T + m * np.eye(m)
    states = rng.choice([SEPARATED] * 5 + [STUCK, COMPLIANT, RIGID], size=m)  # (mostly separated: the forces fewer)
    free = rng.standard_normal(m) * 0.01
    s0, lam0 = nodes.layer.solve_states(stiffness, free, nodes.w, states)
    if given:
        nodes.compliance = np.linalg.inv(stiffness)
    s1, lam1 = nodes._state_solution(stiffness, free, states)
    assert given or nodes._inverse[0] is stiffness  # (formed, and kept for this S_inv)
    assert np.count_nonzero((states == STUCK) | (states == RIGID) | (states == COMPLIANT)) < \
        np.count_nonzero((states == SEPARATED) | (states == COMPLIANT))  # (the forces' system was the one solved)
    assert np.abs(s1 - s0).max() <= 1e-10 * np.abs(s0).max()
    assert np.abs(lam1 - lam0).max() <= 1e-10 * np.abs(lam0).max()
    assert np.all(lam1[states == SEPARATED] == 0.0) and np.all(s1[states == RIGID] == 0.01)


def test_a_contact_tol_the_candidates_do_not_read_is_said(monkeypatch):
    """Where ``auto`` took the coupled solver and solves on candidates first, each active set on them is solved
    exactly: contact_tol acts only if the zone outgrows them. It was recorded and ignored without a word (the
    hemisphere at 47k dofs: 34 back-substitutions at every contact_tol; an outside pass, December 2026). The
    warning says so, with the candidates planned (``contact_candidates_planned``); none without contact_tol."""
    import re
    import warnings

    monkeypatch.setattr(Candidates, "most", classmethod(lambda cls, ndof, method, steps: 500))
    with pytest.warns(RuntimeWarning, match=re.escape("contact_tol = 1e-07 acts only if the contact zone outgrows "
                                                      "the 500 candidate points")):
        ds = workbench.run("memory_hertz3d", h_contact=0.01, contact_tol=1e-7, progress=False)
    assert ds.attrs["contact_candidates_planned"] == 500 and ds.attrs["contact_solver_used"] == "coupled"
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert workbench.run("memory_hertz3d", h_contact=0.01, progress=False).attrs["contact_candidates"] == 500
