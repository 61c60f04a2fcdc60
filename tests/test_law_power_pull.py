"""The power-law adhesive pull (workbench/physics/laws/power_pull.py), a law added in its own file.

p_nu = -gamma_p beta^2 L ((-R(u_nu))_+ / L)^q_p. References, independent of workbench:

* q_p = 1 is the linear adhesive pull with gamma_nu = gamma_p: a rod with gamma_nu = 0 and gamma_p = g equals the
  rod with gamma_nu = g and no power pull (the same physics through two laws);
* the rod with the power pull beside the linear one reduces (docs/models.md) to
  A' + A = gamma_nu beta^2 (-R)_+ + gamma_p beta^2 L ((-R)_+ / L)^q_p with R = R(A + delta), and
  beta' = -gamma_nu beta R^2 (delta constant, u0 = delta, the end in tension): integrated here by SciPy's Radau;
  the explicit and implicit schemes converge to it at first order in k.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import workbench

ROD = dict(h=0.1, T=1.0, delta="-0.15", u0="-0.15", L=0.3, gamma_nu=0.3, c_nu=1.0)


def test_declared_by_the_scene_and_recorded():
    sc = workbench.scene("rod", gamma_p=2.0, q_p=3.0, **ROD)
    assert sc.terms == ("compliance", "adhesion", "power_pull")
    assert "power_pull" not in workbench.scene("rod", **ROD).terms  # gamma_p = 0: not modelled


def test_q1_is_the_linear_pull():
    """With no debonding in either (eps_a above every gamma beta R^2), the two laws give the same run."""
    rest = {k: v for k, v in ROD.items() if k != "gamma_nu"}
    a = workbench.run("rod", k=0.01, gamma_nu=0.0, gamma_p=0.7, q_p=1.0, eps_a=1.0, progress=False, **rest)
    b = workbench.run("rod", k=0.01, gamma_nu=0.7, eps_a=1.0, progress=False, **rest)
    assert np.all(b.beta.values == 1.0) and np.abs(b.u_probe.values + 0.15).max() > 0.01
    np.testing.assert_allclose(a.u_probe.values, b.u_probe.values, rtol=0, atol=1e-12)


def reduced_ode(gamma_p, q_p, gamma_nu, L, delta, T):
    """A' + A = gamma_nu beta^2 (-R)_+ + gamma_p beta^2 L ((-R)_+ / L)^q_p (both pulls; the end stays in tension, so
    the compliance does not act), beta' = -gamma_nu beta R^2 (tension truncation, R < 0 here)."""
    def rhs(t, y):
        A, beta = y
        end = min(max(delta + A, -L), L)
        pull = gamma_nu * beta ** 2 * max(-end, 0.0) + gamma_p * beta ** 2 * L * (max(-end, 0.0) / L) ** q_p
        return [-A + pull, -gamma_nu * beta * end * end]

    sol = solve_ivp(rhs, (0.0, T), [0.0, 1.0], method="Radau", rtol=1e-11, atol=1e-13, dense_output=True)
    return lambda t: delta + sol.sol(t)[0]


@pytest.mark.parametrize("scheme", ["explicit", "implicit"])
def test_rod_against_its_reduced_ode(scheme, order_of):
    gamma_p, q_p = 2.0, 2.5
    ref = reduced_ode(gamma_p, q_p, ROD["gamma_nu"], ROD["L"], -0.15, ROD["T"])
    ks, errs = [0.02, 0.01, 0.005], []
    for k in ks:
        ds = workbench.run("rod", k=k, scheme=scheme, gamma_p=gamma_p, q_p=q_p, progress=False, **ROD)
        end = ds.u_probe.isel(probe=-1, component=0).values
        errs.append(np.abs(end - ref(ds.time.values)).max())
    assert errs[-1] < 2e-4 and 0.9 < order_of(ks, errs) < 1.15
    assert abs(float(ref(1.0)) + 0.15) > 0.01  # the pull really moves the end
