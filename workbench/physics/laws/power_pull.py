"""A power-law adhesive pull: p_nu = -gamma_p beta^2 L ((-R(u_nu))_+ / L)^q_p (adds to the linear pull).

The example of a law added in its own file: this class, its two parameters and
the rule that a scene with adhesion and gamma_p > 0 declares it are all there
is; the model builder finds it (:mod:`workbench.physics.laws`), the explicit
scheme's stability limit takes its largest slope, the implicit schemes its
slope. With q_p = 1 it is the linear adhesive pull with gamma_nu = gamma_p; a
larger q_p makes the glue soft for small separations and stiff near the bond
length L (as for cohesive laws with a hardening branch).

Examples
--------
>>> import numpy as np
>>> from workbench.physics.ops import NP
>>> p = PowerLawPull(gamma_p=2.0, q_p=2.0, L=0.3)
>>> p.normal(NP, np.array([-0.15, -0.6, 0.1]), np.ones(3)).round(6).tolist()
[-0.15, -0.6, -0.0]
"""
from __future__ import annotations

from ...values import Param
from ..contact import ContactTerm


class PowerLawPull(ContactTerm):
    name, rank, side = "power_pull", 25, "tension"
    uses_beta = True
    parameters = (
        Param("gamma_p", 0.0, "Pa/m", "power-law adhesive pull: -gamma_p beta^2 L ((-R(u_nu))_+ / L)^q_p "
              "(0: not modelled)", lower=0.0),
        Param("q_p", 2.0, "1", "exponent of the power-law adhesive pull", lower=1.0, upper=10.0),
    )

    def __init__(self, gamma_p: float, q_p: float, L: float):
        self.gamma_p, self.q_p, self.L = float(gamma_p), float(q_p), float(L)

    @classmethod
    def from_values(cls, v):
        if not v["adhesion"] or v.get("gamma_p", 0.0) <= 0:
            return None
        return cls(v["gamma_p"], v["q_p"], v["L"])

    def normal(self, ops, u_nu, beta):
        s = ops.pos(-ops.clip(u_nu, self.L)) / self.L  # in [0, 1]
        return -self.gamma_p * beta * beta * self.L * ops.pow_pos(s, self.q_p)

    def normal_slope(self, ops, u_nu, beta):
        s = ops.pos(-ops.clip(u_nu, self.L)) / self.L
        inside = ops.ifpos(-u_nu, ops.ifpos(u_nu + self.L, 1.0, 0.0), 0.0)
        return self.gamma_p * beta * beta * self.q_p * ops.pow_pos(s, self.q_p - 1.0) * inside

    def kinks(self, u_nu, u_tau):
        return [u_nu, u_nu + self.L]  # the pull starts at contact and saturates at the bond length

    def max_slope(self, beta0):
        return self.q_p * self.gamma_p * beta0 ** 2, 0.0
