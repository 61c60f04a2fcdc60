"""The local error estimates of error-controlled steps against the true local error of a scalar ODE.

For u' = -u (exact e^-t) a step of backward Euler or variable-step BDF2 from exact
history values has the local error l = u_n - e^-t_n; the schemes estimate it as
C / (1 + C) (u_n - predictor) from :meth:`error_constant`. The ratio estimate / l must
tend to 1 as the steps shrink (at the same step ratios), whatever the ratios.
"""
import math

import numpy as np
import pytest

from workbench.schemes.base import ErrorControlled
from workbench.schemes.bdf2 import BDF2


class _Stub:
    """Just the history and error constants of a scheme class, without a discretisation."""

    def __init__(self, cls, times):
        self.cls = cls
        self.history = [(t, np.array([math.exp(-t)]), None) for t in times]

    def estimate(self, t, u_n, order):
        pred = ErrorControlled.predictor(self, t, order)[0][0]
        c = self.cls.error_constant(self, t, order)
        return c / (1 + c) * (u_n - pred)


def _be(t1, k):  # (u_n - u_{n-1}) / k = -u_n
    return math.exp(-t1) / (1 + k)


def _bdf2(t2, t1, k):  # a0 u_n + a1 u_{n-1} + a2 u_{n-2} = -u_n
    w = k / (t1 - t2)
    a0, a1, a2 = (1 + 2 * w) / ((1 + w) * k), -(1 + w) / k, w * w / ((1 + w) * k)
    return -(a1 * math.exp(-t1) + a2 * math.exp(-t2)) / (a0 + 1)


@pytest.mark.parametrize("ratios", [(1.0, 1.0), (2.0, 0.5), (0.3, 1.7)])
def test_backward_euler_estimate_tends_to_local_error(ratios):
    out = []
    for k in (1e-2, 1e-3):
        t1 = 0.4
        t0 = t1 - k / ratios[0]
        stub = _Stub(ErrorControlled, [t0, t1])
        u_n = _be(t1, k)
        out.append(stub.estimate(t1 + k, u_n, 1) / (u_n - math.exp(-(t1 + k))))
    assert abs(out[1] - 1) < 0.02 and abs(out[1] - 1) < abs(out[0] - 1) + 1e-3, out


@pytest.mark.parametrize("ratios", [(1.0, 1.0), (2.0, 0.5), (0.4, 1.6)])
def test_bdf2_estimate_tends_to_local_error(ratios):
    out = []
    for k in (1e-2, 1e-3):
        t1 = 0.4
        t2 = t1 - k / ratios[0]
        t3 = t2 - k / ratios[0] / ratios[1]
        stub = _Stub(BDF2, [t3, t2, t1])
        u_n = _bdf2(t2, t1, k)
        out.append(stub.estimate(t1 + k, u_n, 2) / (u_n - math.exp(-(t1 + k))))
    assert abs(out[1] - 1) < 0.05 and abs(out[1] - 1) < abs(out[0] - 1) + 1e-3, out
