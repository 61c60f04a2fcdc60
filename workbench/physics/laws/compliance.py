"""Normal compliance p_nu(u_nu) = c_nu ((u_nu - g)_+)^m_nu: the foundation's push against penetration.

Examples
--------
>>> import numpy as np
>>> from workbench.physics.ops import NP
>>> t = NormalCompliance(c_nu=2.0, m_nu=2.0, gap=0.1)
>>> t.normal(NP, np.array([0.0, 0.3]), None).round(12).tolist(), t.normal_slope(NP, np.array([0.0, 0.3]), None).round(12).tolist()
([0.0, 0.08], [0.0, 0.8])
"""
from __future__ import annotations

from ..contact import ContactTerm


class NormalCompliance(ContactTerm):
    name, rank = "compliance", 10
    gapped = True

    def __init__(self, c_nu: float, m_nu: float = 1.0, gap: float = 0.0, L: float = 1.0):
        self.c_nu, self.m_nu, self.gap, self.L = float(c_nu), float(m_nu), float(gap), float(L)

    @classmethod
    def from_values(cls, v):
        if not v["contact"] or v["c_nu"] <= 0:
            return None
        return cls(v["c_nu"], v["m_nu"], v["gap"], v["L"])

    def normal(self, ops, u_nu, beta):
        s = u_nu - self.gap
        return self.c_nu * (ops.pos(s) if self.m_nu == 1 else ops.pow_pos(s, self.m_nu))

    def normal_slope(self, ops, u_nu, beta):
        s = u_nu - self.gap
        if self.m_nu == 1:
            return self.c_nu * ops.ifpos(s, 1.0, 0.0)
        return self.c_nu * self.m_nu * ops.pow_pos(s, self.m_nu - 1.0)

    def kinks(self, u_nu, u_tau):
        return [u_nu - self.gap]  # where the foundation starts to push

    def max_slope(self, beta0):
        # unbounded for m_nu > 1; the slope at a penetration of L (the bond length) stands for it
        return self.c_nu * self.m_nu * (self.L ** (self.m_nu - 1.0) if self.m_nu != 1 else 1.0), 0.0
