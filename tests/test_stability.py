"""Stability of the explicit scheme, its predicted step limit, and the stable implicit scheme.

The slab of the stability issue: E = 1000, nu = 0.3, a1 = 30, a2 = 20, c_nu = 100,
gamma_nu = 20, L = 0.3 (the paper's tp4/tp5 geometry and loads). Linearised
stability of forward Euler on the elastic and contact terms gives
k_crit = 2 / lambda_max(K_A^-1 (K_G + springs)) (workbench.stability).
References for the implicit scheme: the explicit scheme itself at a step far
below k_crit (a different scheme, so not a self-comparison).
"""
import warnings

import numpy as np
import pytest

import workbench
from workbench import stability
from workbench.results import far_facet
from workbench.stability import StepTooLarge

STIFF = dict(c_nu=100.0, gamma_nu=20.0, L=0.3)


def test_explicit_refused_above_k_crit():
    with pytest.raises(StepTooLarge) as err:
        workbench.run("tp5", k=0.01, progress=False, **STIFF)
    msg = str(err.value)
    assert "k_crit = 0.000697" in msg and "scheme = 'implicit'" in msg and "allow_unstable" in msg


def test_k_crit_matches_issue_figures():
    """~7e-4 while the foundation spring acts, ~3e-3 for the adhesive spring alone; no better with refinement."""
    k_found = [stability.critical_step(workbench.scene("tp5", h=h, **STIFF)).k_crit for h in (0.025, 0.0125)]
    k_adh = stability.critical_step(workbench.scene("tp5", contact=False, **STIFF)).k_crit
    assert 5e-4 < k_found[1] < 9e-4 and 2.5e-3 < k_adh < 4e-3
    assert k_found[1] <= k_found[0]


@pytest.mark.parametrize("name, overrides", [
    ("tp5", dict(STIFF, h=0.025, T=0.3)),                    # foundation spring in compression
    ("tp4", dict(contact=False, gamma_nu=20.0, h=0.025, T=0.3)),  # adhesive spring in tension
])
def test_predicted_k_crit_brackets_onset(name, overrides):
    """Stable just below the predicted k_crit, unstable (detected and stopped) at twice it."""
    k_crit = stability.critical_step(workbench.scene(name, **overrides)).k_crit
    ds = workbench.run(name, k=0.95 * k_crit, progress=False, **overrides)
    assert ds.attrs["status"] == "complete" and np.abs(ds.u_contact).max() < 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        with pytest.raises(workbench.Diverged) as err:
            workbench.run(name, k=2.0 * k_crit, allow_unstable=True, progress=False, **overrides)
    assert err.value.dataset.attrs["stability_override"] == 1
    assert err.value.dataset.attrs["status"] == "incomplete"


def tip(ds):
    return ds.u_probe.isel(probe=-1).sel(component="y").values


def beta_far(ds):
    return far_facet(ds.beta).values


@pytest.fixture(scope="module")
def explicit_reference():
    """The paper's scheme at k = 2.5e-4 (k_crit / 3) on the same mesh."""
    rt = np.round(np.arange(0, 1.0001, 0.02), 10)
    return workbench.run("tp4", k=0.00025, h=0.025, progress=False, record_times=rt, **STIFF), rt


def test_implicit_matches_fine_explicit(explicit_reference):
    """Implicit at k = 0.01 (14 x k_crit) agrees with explicit at k = 0.00025 within 2% (tip and beta(1, 0) at T)."""
    ref, rt = explicit_reference
    ds = workbench.run("tp4", scheme="implicit", k=0.01, h=0.025, progress=False, record_times=rt, **STIFF)
    assert abs(tip(ds)[-1] - tip(ref)[-1]) <= 0.02 * abs(tip(ref)[-1])
    assert abs(beta_far(ds)[-1] - beta_far(ref)[-1]) <= 0.02 * beta_far(ref)[-1]
    assert 1 <= ds.newton_iterations[1:].max() <= 10 and "k_crit" not in ds.attrs


def test_implicit_first_order(explicit_reference, order_of):
    """Observed order in k of the implicit scheme (tip + beta(1, 0), max over t) is >= 0.9."""
    ref, rt = explicit_reference
    ks = [0.02, 0.01, 0.005]
    errs = []
    for k in ks:
        ds = workbench.run("tp4", scheme="implicit", k=k, h=0.025, progress=False, record_times=rt, **STIFF)
        errs.append(np.abs(tip(ds) - tip(ref)).max() + np.abs(beta_far(ds) - beta_far(ref)).max())
    assert order_of(ks, errs) >= 0.9
    assert errs[-1] < 0.01 * np.abs(tip(ref)).max()


def test_implicit_rod_against_exact():
    """The implicit scheme on tp1 (exact solution) and tp3 (ODE) is first order and close."""
    from workbench.references import rod_ode, tp1_exact

    for name, ref in (("tp1", tp1_exact()), ("tp3", rod_ode(workbench.scene("tp3")))):
        errs = []
        for k in (0.02, 0.01):
            ds = workbench.run(name, scheme="implicit", k=k, progress=False)
            u, b = ref(ds.time.values, x=1.0)
            errs.append(np.abs(ds.u_contact.isel(node=0, component=0).values - u).max())
        assert 0.85 < np.log2(errs[0] / errs[1]) < 1.15 and errs[1] < 3e-4
