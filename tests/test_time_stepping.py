"""Second-order and error-controlled time stepping (BDF2, the trapezoid memory rule, rtol > 0).

References, each independent of the scheme under test: tp1's closed form; the exact-in-time
solution of the semi-discrete linear Kelvin-Voigt system by generalised eigenvectors
(workbench.references.modal_linear); the Model B rod's Volterra reference
(workbench.references.rod_memory); SciPy's Radau on the rod ODE (rod_ode); for the slab a
fixed-step BDF2 run at a step 20-200 times below the adaptive ones, interpolated by a cubic spline.
"""
import re

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from test_kelvin_voigt import CASES, dense

import workbench
from workbench.discrete import discretisation
from workbench.references import modal_linear, rod_ode, tp1_exact
from workbench.references.rod import rod_memory
from workbench.schemes import scheme_class
from workbench.schemes.stepping import StepTooSmall


def _rod_errors(ds, ref):
    """max over the run of |u(1, t) - u_ref| / max |u_ref| and of |beta - beta_ref| (beta: None without it)."""
    t = ds.time.values
    u_ref, b_ref = ref(t)
    eu = np.abs(ds.u_probe.isel(probe=-1, component=0).values - u_ref).max() / np.abs(u_ref).max()
    eb = np.abs(ds.beta.isel(facet=0).values - b_ref).max() if "beta" in ds else 0.0
    return eu, eb


def _first_step(rtol):
    """The first step of an adaptive run, as a user would pick it for the tolerance (it was not error-checked before
    issue 23; it is now: :func:`test_the_first_step_is_checked_like_every_other`)."""
    return 0.1 * (rtol / 1e-2) ** 0.5


# -- second order at fixed steps ------------------------------------------------------------------------------------

def test_bdf2_tp1_second_order_and_far_below_backward_euler(order_of):
    """tp1 (smooth: the truncation saturates): BDF2's order in k in [1.9, 2.1], and at k = 0.01 its error at
    least 20 x below backward Euler's."""
    ex = tp1_exact()
    ks = [0.04, 0.02, 0.01, 0.005]
    errs = [_rod_errors(workbench.run("tp1", scheme="bdf2", k=k, progress=False), ex)[0] for k in ks]
    be = _rod_errors(workbench.run("tp1", scheme="implicit", k=0.01, progress=False), ex)[0]
    assert 1.9 <= order_of(ks, errs) <= 2.1, errs
    assert errs[2] * 20 <= be, (errs[2], be)
    assert errs[-1] < 1e-5


@pytest.mark.parametrize("name", list(CASES))
def test_bdf2_linear_kelvin_voigt_order_two(name, order_of):
    """2D plane stress and 3D without contact: BDF2 is second order to the semi-discrete modal solution."""
    sc = workbench.scene(name, contact=False, adhesion=False, T=0.2, snapshots=(0.05, 0.1, 0.2), scheme="bdf2",
                         **CASES[name])
    d = discretisation.build(sc)
    F1 = d.u.vec.CreateVector()
    d.load_vector(1.0, F1)  # the load is t * F1
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    exact = modal_linear(dense(d.viscous.mat), dense(d.elastic.mat), np.array(F1.FV().NumPy()), free)
    # (pre-asymptotic above k = 0.005: local orders 1.2, 1.7, 2.3 from k = 0.04 on, measured)
    ks = [0.0025, 0.00125, 0.000625]
    errs = []
    for k in ks:
        ds = workbench.run(sc.with_(k=k), progress=False)
        errs.append(max(np.abs(ds.u_dofs.isel(snapshot=i).values - exact(float(t))).max()
                        for i, t in enumerate(ds.snapshot_time.values)))
    assert 1.9 <= order_of(ks, errs) <= 2.1, errs
    assert errs[-1] < 1e-5 * np.abs(exact(0.2)).max()


@pytest.mark.slow
def test_memory_trapezoid_second_order_without_state_changes(order_of):
    """Model B rod, the contact state fixed (compliant all the time): the trapezoid rule is second order to the
    Volterra reference, the rectangle rule first order."""
    sc = workbench.scene("memory_rod", delta="0.18+0.04*sin(2*pi*t)")
    ref = rod_memory(sc)
    ks = [0.02, 0.01, 0.005]
    orders = {}
    for rule in ("rectangle", "trapezoid"):
        errs = []
        for k in ks:
            ds = workbench.run(sc, memory_rule=rule, k=k, progress=False)
            assert set(np.unique(ds.contact_state.values)) == {2}  # compliant: no state change
            t = ds.time.values
            errs.append(np.abs(ds.u_probe.isel(probe=-1, component=0).values - ref(t, x=1.0)[0]).max())
        orders[rule] = order_of(ks, errs)
        if rule == "trapezoid":
            assert errs[-1] < 1e-7, errs
    assert orders["trapezoid"] >= 1.9 and 0.9 <= orders["rectangle"] <= 1.1, orders


@pytest.mark.parametrize("memory", [{}, dict(prony=(), kernel="exp(-t/0.2)*(1+t)", kernel_E=0.5)],
                         ids=["prony", "general kernel"])
def test_memory_trapezoid_second_order_across_variable_steps(memory, order_of):
    """The trapezoid memory rule stays second order when the steps vary: steps alternating k and 2k (the ratio
    error control may take), refined by halving, against the Volterra reference at T, for a Prony term (its internal
    variable) and a general kernel (the product quadrature over the stored history). Measured: 2.01 and 2.02."""
    sc = workbench.scene("memory_rod", delta="0.18+0.04*sin(2*pi*t)", memory_rule="trapezoid", **memory)
    T, x = float(sc["T"]), float(sc["length"])
    exact = float(np.ravel(rod_memory(sc)(np.array([T]), x)[0])[0])
    ns, errs = [20, 40, 80], []
    for n in ns:
        grid = np.concatenate([[0.0], np.cumsum(np.tile([1.0, 2.0], n // 2))])
        grid *= T / grid[-1]
        d = discretisation.build(sc.model_of(), sc)
        s = scheme_class("vi")(d)
        s.preflight(float(np.diff(grid).max()))
        s.start(0.0)
        s.accept(0.0)
        for t0, t1 in zip(grid[:-1], grid[1:]):
            s.step(t0, t1)
            s.accept(t1)
        errs.append(abs(float(np.ravel(d.u(d.mesh(x)))[0]) - exact))
    assert order_of([1.0 / n for n in ns], errs) >= 1.9, errs


# -- error control: the tolerance as the accuracy knob ---------------------------------------------------------------

TOLERANCES = [1e-2, 1e-3, 1e-4, 1e-5]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["tp1", "tp2"])
@pytest.mark.parametrize("scheme", ["implicit", "bdf2"])
def test_achieved_error_follows_the_tolerance_on_the_rods(name, scheme):
    """The achieved error (u relative to max |u|, and beta) falls monotonically with rtol and stays below
    10 x rtol; it is at least 0.1 x rtol except where the whole BDF2 run is a dozen steps (rtol >= 1e-3 on
    these smooth rods: the step is limited by BDF2's step-ratio bound, not by the error)."""
    ref = tp1_exact() if name == "tp1" else (lambda s: (lambda t: s(t, x=1.0)))(rod_ode(workbench.scene(name)))
    achieved = []
    for rtol in TOLERANCES:
        ds = workbench.run(name, scheme=scheme, k=_first_step(rtol), rtol=rtol, progress=False)
        achieved.append(max(_rod_errors(ds, ref)))
        if scheme == "implicit" or rtol <= 1e-4:
            assert 0.1 * rtol <= achieved[-1] <= 10 * rtol, (rtol, achieved)
        else:
            assert achieved[-1] <= 10 * rtol and ds.attrs["accepted_steps"] <= 15
    assert all(a > b for a, b in zip(achieved, achieved[1:])), achieved


@pytest.mark.parametrize("first", [0.01, None])
def test_the_first_step_is_checked_like_every_other(first):
    """A rod driven back and forth (tension, then compression into the compliance), BDF2 at rtol = 1e-5 with the
    documented first step 0.01 (and with no k given: the scene's): the error was 27 x rtol, all of it from the
    unchecked first step (studies/first_step.py: 2.7e-4 at rtol 1e-4, 1e-5 and 1e-6 alike). The first step is now
    judged by two half steps and shortened; against the rod's ODE (Radau) the error is 0.22 x rtol, as with a
    small first step."""
    rtol = 1e-5
    sc = workbench.scene("rod", T=1.0, h=0.1, delta="0.3*sin(2*pi*t)", scheme="bdf2", rtol=rtol,
                         **({} if first is None else {"k": first}))
    ds = workbench.run(sc, progress=False)
    ref = (lambda s: (lambda t: s(t, x=1.0)))(rod_ode(sc))
    err = _rod_errors(ds, ref)[0]
    assert 0.1 * rtol <= err <= rtol, err
    k1 = float(ds.time.values[1] - ds.time.values[0])
    assert k1 < sc["k"] / 4 and ds.attrs["rejected_steps"] >= 1, (k1, sc["k"])


SLAB = dict(E=1000, nu=0.3, a1=30, a2=20, c_nu=100, gamma_nu=20, eps_a=1e-3, L=0.3, c_tau=10,
            bonding_truncation="symmetric", traction_top="(0, 5*t*ifpos(x - 0.5, 1, 0))", order=2, h=0.05,
            T=1.0, probes=[(1.0, 0.0)])


@pytest.fixture(scope="module")
def slab_reference():
    """The held-out slab of issue 11 (on h = 0.05 here; the benchmark uses 0.025): fixed BDF2, k = 5e-4."""
    ds = workbench.run("slab", **SLAB, scheme="bdf2", k=5e-4, progress=False)
    u = ds.u_probe.isel(probe=-1, component=1).values
    return CubicSpline(ds.time.values, u), CubicSpline(ds.time.values, ds.beta.values, axis=0), np.abs(u).max()


@pytest.mark.slow
# (backward Euler's steps grow like 1/rtol: 416 at 3e-2, 1616 at 1e-2, 5414 at 3e-3, 16,124 at 1e-3, which took 80 s
# of the suite; 3e-2 and 1e-2, a factor of 3 in rtol for the error to fall by, achieve 2.0 and 2.2 x rtol in 10 s)
@pytest.mark.parametrize("scheme, tolerances", [("bdf2", TOLERANCES[:3]), ("implicit", [3e-2, 1e-2])])
def test_achieved_error_follows_the_tolerance_on_the_slab(slab_reference, scheme, tolerances):
    """Debonding slab with contact, glue and a load on half the top: the tip error and the beta error within
    [0.1, 10] x rtol, falling with it; the Dataset records every step size and estimate."""
    u_ref, b_ref, scale = slab_reference
    achieved = []
    for rtol in tolerances:
        ds = workbench.run("slab", **SLAB, scheme=scheme, k=_first_step(rtol), rtol=rtol, progress=False)
        t = ds.time.values
        eu = np.abs(ds.u_probe.isel(probe=-1, component=1).values - u_ref(t)).max() / scale
        eb = np.abs(ds.beta.values - b_ref(t)).max()
        achieved.append(max(eu, eb))
        assert 0.1 * rtol <= achieved[-1] <= 10 * rtol, (rtol, eu, eb)
        k, est = ds.step_size.values, ds.error_estimate.values
        assert ds.attrs["accepted_steps"] == len(t) - 1  # every step recorded
        assert np.isnan(k[0]) and np.allclose(k[1:], np.diff(t), rtol=1e-9, atol=1e-15)
        assert np.nanmax(est) <= 1.0 and np.isfinite(est[3:]).all()  # accepted steps are within the tolerance
    assert all(a > b for a, b in zip(achieved, achieved[1:])), achieved


@pytest.mark.slow
def test_memory_tolerance_rectangle_rule():
    """Model B rod through all four contact states ('vi', rectangle rule): achieved error within [0.1, 10] x rtol,
    falling with it. (The trapezoid rule's estimate is conservative: its achieved error is 0.01-0.07 x rtol.)"""
    sc = workbench.scene("memory_rod")
    ref = rod_memory(sc)
    t = np.linspace(0, 1, 201)
    scale = np.abs(ref(t, x=1.0)[0]).max()
    achieved = []
    for rtol in TOLERANCES[:3]:
        ds = workbench.run(sc, k=_first_step(rtol), rtol=rtol, progress=False)
        tt = ds.time.values
        achieved.append(np.abs(ds.u_probe.isel(probe=-1, component=0).values - ref(tt, x=1.0)[0]).max() / scale)
        assert 0.1 * rtol <= achieved[-1] <= 10 * rtol, (rtol, achieved)
    assert all(a > b for a, b in zip(achieved, achieved[1:])), achieved


# -- rejection, events, the stop -------------------------------------------------------------------------------------

def _state_equal(a, b):
    for key in ("u", "v", "beta"):
        if a[key] is None:
            assert b[key] is None
        else:
            assert np.array_equal(a[key], b[key]), key
    assert a["k_last"] == b["k_last"] and a["u_scale"] == b["u_scale"]
    assert len(a["history"]) == len(b["history"])
    for (ta, ua, ba), (tb, ub, bb) in zip(a["history"], b["history"]):
        assert ta == tb and np.array_equal(ua, ub) and (ba is None or np.array_equal(ba, bb))
    for key, value in a["extra"].items():
        assert np.array_equal(np.asarray(value), np.asarray(b["extra"][key])), key


@pytest.mark.parametrize("name, scheme, extra", [
    ("slab", "bdf2", dict(SLAB, h=0.1)),
    ("memory_rod", "vi", dict(memory_rule="trapezoid")),
    ("memory_rod", "vi", dict(kernel="exp(-t/0.2)*(1+t)", kernel_E=0.5, prony=())),
])
def test_a_rejected_step_leaves_the_state_bitwise_as_before(name, scheme, extra):
    """state() -> step -> restore() gives back every array bit for bit, and the step redone from it is bit for
    bit the step taken the first time (nothing hidden survives a rejection)."""
    sc = workbench.scene(name, scheme=scheme, **extra)
    disc = discretisation.build(sc.model_of(), sc)
    s = scheme_class(scheme)(disc)
    s.preflight(0.05)
    s.start(0.0)
    s.accept(0.0)
    t = 0.0
    for k in (0.05, 0.05, 0.03):  # some history (BDF2 and the quadratic predictor use it)
        s.step(t, t + k)
        t += k
        s.accept(t)
    before = s.state()
    s.step(t, t + 0.2)
    first = s.state()
    assert not np.array_equal(first["u"], before["u"])
    s.restore(before)
    _state_equal(s.state(), before)
    s.step(t, t + 0.2)
    _state_equal(s.state(), first)


@pytest.mark.slow
def test_contact_switch_is_not_stepped_over():
    """The rod end reaches the foundation at t = 0.37 exactly (delta = 0.1 (t - 0.37), nothing else acts before):
    an adaptive run ends a step within k_min of it, both schemes; with the tolerance alone it would not."""
    sc = workbench.scene("rod", delta="0.1*(t - 0.37)", u0="-0.037", adhesion=False, c_nu=10, k=0.01, rtol=1e-3,
                         scheme="implicit")
    for scheme in ("implicit", "bdf2"):
        ds = workbench.run(sc, scheme=scheme, progress=False)
        t = ds.time.values
        assert np.abs(t - 0.37).min() <= sc["k_min"], (scheme, t[np.argsort(np.abs(t - 0.37))[:3]])
        i = np.argmin(np.abs(t - 0.37))
        assert ds.step_size.values[i + 1] < 0.5 * ds.step_size.values[i - 1] or ds.attrs["rejected_steps"] > 0
    # a debonding onset: tp1-like rod whose end is pulled off, gamma beta R^2 reaching eps_a at a known time
    ref = rod_ode(workbench.scene("rod", delta="-0.5*t", gamma_nu=3.0, eps_a=0.05, L=1.0))
    t = np.linspace(0, 1, 20001)
    drive = 3.0 * ref(t, x=1.0)[1] * np.clip(ref(t, x=1.0)[0], -1, 0) ** 2 - 0.05
    onset = t[np.argmax(drive > 0)]
    ds = workbench.run("rod", delta="-0.5*t", gamma_nu=3.0, eps_a=0.05, L=1.0, scheme="bdf2", k=0.01, rtol=1e-3,
                       progress=False)
    assert np.abs(ds.time.values - onset).min() <= 2e-4 + 1e-12, onset


def test_k_below_k_min_stops_clearly_and_keeps_the_run():
    """Error control that needs a step below k_min stops with StepTooSmall naming k_min and the time, and the
    Dataset of what was computed comes with it, marked incomplete."""
    with pytest.raises(StepTooSmall, match="k_min") as info:
        workbench.run("tp3", scheme="implicit", k=0.05, rtol=1e-6, k_min=0.02, progress=False)
    # (the step tried may lie above k_min: the one asked for next is said too, below it)
    asked = float(re.search(r"asks for ([0-9.e+-]+) s next", str(info.value)).group(1))
    assert asked < 0.02
    ds = info.value.dataset
    assert ds.attrs["status"] == "incomplete" and ds.attrs["failure_type"] == "StepTooSmall"
    assert ds.sizes["time"] >= 1 and "step_size" in ds


@pytest.mark.parametrize("scheme, rtol", [("implicit", 1e-2), ("implicit", 1e-3), ("bdf2", 1e-3)])
def test_a_load_that_kinks_is_landed_on_and_its_tolerance_delivered(scheme, rtol):
    """A ramp held from t = 0.3 (the rod's end, ``ifpos(t - 0.3, 0.3, t)``) stopped error control at k_min there: the
    step across the kink was judged per unit of elapsed time, which grows as the step falls (backward Euler at every
    rtol, BDF2 at 1e-4; an outside pass, December 2026). The load's kinks are landed on and the steps after each are
    charged to it: the run completes, a step ends on 0.3, and the achieved error against fixed BDF2 steps of 1e-4 s
    at the run's own times is within 3 rtol (measured 0.43, 0.60 and 0.14 rtol). The rigid motion of a free rod,
    which every step reproduces, takes few steps."""
    delta = "-0.6*ifpos(t-0.3, 0.3, t)"
    ds = workbench.run("rod", h=0.05, scheme=scheme, rtol=rtol, delta=delta, progress=False)
    assert ds.attrs["status"] == "complete" and np.min(np.abs(ds.time.values - 0.3)) < 1e-12
    times = np.round(ds.time.values, 9)
    grid = np.unique(np.round(np.concatenate([np.arange(0.0, 1.0 + 1e-12, 1e-4), times]), 9))
    ref = workbench.run("rod", h=0.05, scheme="bdf2", rtol=0, times=grid.tolist(), record_times=list(times),
                        delta=delta, progress=False)
    u, exact = ds.u_probe.values, ref.u_probe.sel(time=ds.time.values, method="nearest").values
    assert np.abs(u - exact).max() <= 3 * rtol * np.abs(exact).max()
    free = workbench.run("rod", h=0.05, scheme=scheme, rtol=rtol, contact=False, adhesion=False,
                         delta="-0.6*ifpos(t-0.37, 0.37, t)", progress=False)
    assert free.attrs["status"] == "complete" and free.attrs["nsteps"] < 60


@pytest.mark.parametrize("scheme, rtol", [("implicit", 1e-2), ("bdf2", 1e-3)])
def test_the_prescribed_motion_is_no_time_error(scheme, rtol):
    """The rod's end moved by delta = 0.03 sin(20 pi t): the step meets delta at its end exactly, and a free rod moves
    rigidly with it, which every step reproduces. The predictor missed by delta's curvature, which the estimate read
    as error (an outside pass, December 2026): a free rod took 5068 BDF2 steps at rtol 1e-3 to T = 1 and 5801
    backward Euler steps at 1e-2 to T = 0.3, 6503 and 5467 in contact. That miss, spread by the step's operator, is
    left out of the estimate now (``prescribed_response``): the free rod takes the steps that follow the load
    (``load_error``; 253 and 27 measured), and in contact and glued the error against fixed BDF2 steps of 1e-4 s is
    within rtol in 1071 and 65 steps (0.25 and 0.40 rtol measured)."""
    delta, T = "0.03*sin(20*pi*t)", 1.0 if scheme == "bdf2" else 0.3
    free = workbench.run("rod", h=0.05, scheme=scheme, rtol=rtol, T=T, delta=delta, contact=False, adhesion=False,
                         progress=False)
    assert free.attrs["nsteps"] < (400 if scheme == "bdf2" else 60)
    assert np.abs(free.u_probe.values[..., 0] - 0.03 * np.sin(20 * np.pi * free.time.values)[:, None]).max() < 1e-12
    ds = workbench.run("rod", h=0.05, scheme=scheme, rtol=rtol, T=T, delta=delta, progress=False)
    times = ds.time.values[np.concatenate([[True], np.diff(ds.time.values) > 1e-7])]  # (landing on the contact's
    base = np.arange(0.0, T + 1e-12, 1e-4)  # kinks takes steps down to 1e-8 s: times too close to be told apart)
    base = base[np.min(np.abs(base[:, None] - times[None, :]), axis=1) > 1e-7]
    ref = workbench.run("rod", h=0.05, scheme="bdf2", rtol=0, T=T, times=np.union1d(base, times).tolist(),
                        record_times=list(times), delta=delta, progress=False)
    exact = ref.u_probe.sel(time=times, method="nearest").values
    assert np.abs(ds.u_probe.sel(time=times).values - exact).max() <= rtol * np.abs(exact).max()
    assert ds.attrs["nsteps"] < (2000 if scheme == "bdf2" else 200)


def test_only_the_loads_are_landed_on_and_resolved_not_a_kernels_lag():
    """The times error control lands on and the loads it resolves are the model's loads in t (the rod's end here),
    not every expression in t of the scene: a memory kernel's t is a lag, and its kink at 0.37 is no time."""
    sc = workbench.scene("memory_rod", kernel="exp(-abs(t - 0.37))", kernel_E=0.5, prony=(),
                         delta="-0.05 + 0.2*ifpos(t - 0.3, 0.3, t)")
    loads = sc.model_of().loads.in_time()
    assert [str(e) for e in loads] == [str(sc["delta"])] and loads[0].kinks(1.0) == pytest.approx([0.3])
    ds = workbench.run(sc, rtol=1e-3, progress=False)
    assert ds.attrs["status"] == "complete" and np.min(np.abs(ds.time.values - 0.3)) < 1e-12
    assert np.min(np.abs(ds.time.values - 0.37)) > 1e-12  # (the kernel's kink is not landed on)


def test_steps_resolve_the_loads_that_drive_a_body_without_an_error_estimate():
    """A rod moved by 0.2 t - 0.05 + 0.03 sin(20 pi t) is free most of the time, where Model B's estimate is round-off
    (its rigid motion is exact at any step): its steps grew to 0.375 s and stepped over whole contact episodes, and
    the error stayed at 6.5e-3 from rtol = 1e-3 to 1e-5 (an outside pass, December 2026). A step must now follow the
    loads to 10 rtol of their size (``AdaptiveSteps.load_error``): against fixed trapezoid steps of 1e-4 s at the
    run's own times the error is within rtol and falls with it (measured 1.5e-5 and 3.2e-6)."""
    delta = "0.2*t-0.05+0.03*sin(20*pi*t)"
    errors = []
    for rtol in (1e-3, 1e-4):
        ds = workbench.run("memory_rod", memory_rule="trapezoid", rtol=rtol, delta=delta, progress=False)
        times = ds.time.values
        base = np.arange(0.0, ds.attrs["T"] + 1e-12, 1e-4)
        base = base[np.min(np.abs(base[:, None] - times[None, :]), axis=1) > 1e-7]
        ref = workbench.run("memory_rod", memory_rule="trapezoid", rtol=0, times=np.union1d(base, times).tolist(),
                            record_times=list(times), delta=delta, progress=False)
        exact = ref.u_probe.sel(time=times, method="nearest").values
        errors.append(float(np.abs(ds.u_probe.values - exact).max() / np.abs(exact).max()))
        assert errors[-1] <= rtol, (rtol, errors[-1])
    assert errors[1] < errors[0] / 3


def test_error_control_refused_for_the_explicit_scheme():
    with pytest.raises(workbench.ParameterError, match="rtol"):
        workbench.run("tp1", scheme="explicit", rtol=1e-3, progress=False)


def test_a_kink_is_charged_against_its_share_of_the_tolerance():
    """A step inside which a share of the boundary switched law is judged by err / share when that is below the
    error per unit elapsed time (a kink's first-order error is made once); steps without crossings are not."""
    from workbench.schemes.base import crossed_fraction
    from workbench.schemes.stepping import AdaptiveSteps

    steps = AdaptiveSteps(1.0, 0.01, rtol=1e-3, atol=1e-9, k_min=1e-9, k_max=1.0, order=2, t0=0.0)
    steps.t = 0.5
    steps.next()  # the step (0.5, 0.51): per unit elapsed time x 51
    assert steps.per_unit_step(0.02) == pytest.approx(0.02 * 51)
    assert steps.per_unit_step(0.02, crossed=0.1) == pytest.approx(0.2)
    assert steps.per_unit_step(1e-4, crossed=1e-4) == pytest.approx(1e-4 * 51)  # a tiny share: no relief
    # the predictor of the next `order` steps is drawn through the kink: their estimates are charged to it as well
    assert steps.judge(0.02, None, crossed=0.1)
    for _ in range(2):
        steps.next()
        assert steps.per_unit_step(0.02) == pytest.approx(0.2)
        assert steps.judge(0.02, None)
    steps.next()
    assert steps.per_unit_step(0.02) > 1.0  # three steps on: per unit elapsed time again
    before = [(np.array([1.0, 1.0, -1.0, 1.0]), np.array([1.0, 1.0, 1.0, 2.0]))]
    after = [(np.array([-1.0, 1.0, -2.0, -1.0]), None)]
    assert crossed_fraction(before, after) == pytest.approx(3 / 5)


@pytest.mark.slow
def test_bdf2_steps_reuse_their_factorisations(monkeypatch):
    """BDF2's matrix a0 K_A + K_G depends on the step and the step ratio. An error-controlled run shortens a free step
    (by < 19 %) so that a0 lies on the grid 2^(j/4), and so meets the same few matrices again: on the slab (h = 0.1,
    rtol 1e-3) at most 15 % of the solves factor a matrix (measured 9 %; 21 % on the grid 2^(j/8), 43 % without a
    grid)."""
    import math

    from workbench.discrete import discretisation, solvers
    from workbench.schemes.bdf2 import BDF2

    scheme = BDF2(discretisation.build(workbench.scene("tp1", h=0.1)))
    scheme.history = [(0.0, None, None), (0.03, None, None)]  # k' = 0.03
    for k in (0.01, 0.0212, 0.029, 0.05, 0.0601):  # (0.0212: k / k' = 0.71, the largest cut)
        ks = scheme.admissible_step(k)
        a0 = (0.03 + 2 * ks) / ((0.03 + ks) * ks)
        assert 0.81 * k <= ks <= k and abs(4 * math.log2(a0) - round(4 * math.log2(a0))) < 1e-9
    calls = []
    factor = solvers.factor
    monkeypatch.setattr(solvers, "factor", lambda *a, **kw: calls.append(1) or factor(*a, **kw))
    ds = workbench.run("slab", **dict(SLAB, h=0.1), scheme="bdf2", rtol=1e-3, k=_first_step(1e-3), progress=False)
    assert len(calls) <= 0.15 * (ds.attrs["accepted_steps"] + ds.attrs["rejected_steps"]), (len(calls), ds.attrs)


def test_round_off_at_a_kink_is_not_an_event():
    """A contact point that sits on its kink flips sign at round-off (Model B's stuck points after a condensed solve:
    s = 1e-21 ... 1e-19 of either sign): that is no kink crossed. Unit: such flips beside a real value give no event,
    a real crossing still does. Run: memory_slab under error control takes the same steps with the condensed solver
    as with the coupled one, whose values there are exactly 0 (before, the condensed run landed on the flips: 53
    accepted and 15 rejected steps against 48 and 0)."""
    from workbench.schemes.base import crossed_fraction, first_crossing

    before, after, w = np.array([1e-20, -3e-21, 1.0]), np.array([-2e-20, 4e-21, 0.5]), np.ones(3)
    assert first_crossing(before, after, w, 0.25) is None and crossed_fraction([(before, w)], [(after, w)]) == 0.0
    assert first_crossing(before, np.array([-2e-20, 4e-21, -1.0]), w, 0.25) == pytest.approx(0.5)
    runs = [workbench.run("memory_slab", h=0.25, rtol=1e-2, T=0.4, contact_solver=c, progress=False)
            for c in ("condensed", "coupled")]
    assert [r.attrs["rejected_steps"] for r in runs] == [0, 0]
    assert runs[0].attrs["accepted_steps"] == runs[1].attrs["accepted_steps"]
    np.testing.assert_allclose(runs[0].step_size.values, runs[1].step_size.values, rtol=1e-9)
