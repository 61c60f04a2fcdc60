"""The adhesive pull gamma_nu beta^2 (-R(u_nu))_+ and the bonding law it comes with (Frémond; Chau et al. 2003).

Under tension (u_nu < 0) the glue pulls the surface back towards the foundation
with gamma_nu beta^2 times the truncated separation, R(s) = clip(s, -L, L); the
bonding field beta decays by the law of :class:`workbench.physics.bonding.BondingLaw`.
Both are built here from the scene's values (adhesion switched on).

Examples
--------
>>> import numpy as np
>>> from workbench.physics.ops import NP
>>> a = AdhesivePull(gamma_nu=2.0, L=0.3)
>>> a.normal(NP, np.array([-0.1, -0.5, 0.2]), np.ones(3)).round(6).tolist()  # -(gamma beta^2 (-R)_+)
[-0.2, -0.6, -0.0]
"""
from __future__ import annotations

from ..bonding import BondingLaw
from ..contact import ContactTerm


class AdhesivePull(ContactTerm):
    name, rank, side = "adhesion", 20, "tension"
    uses_beta = True

    def __init__(self, gamma_nu: float, L: float, sign: float = 1.0):
        """``sign = -1`` flips the pull (only to study the paper's Problem 2 curves, which match that sign)."""
        self.gamma_nu, self.L, self.sign = float(gamma_nu), float(L), float(sign)
        if self.sign != 1.0:
            self.name = "adhesion_flipped"  # says so in a run's terms

    @classmethod
    def from_values(cls, v):
        return cls(v["gamma_nu"], v["L"]) if v["adhesion"] else None

    def normal(self, ops, u_nu, beta):
        pull = self.gamma_nu * beta * beta * ops.pos(-ops.clip(u_nu, self.L))
        return -pull if self.sign == 1.0 else -self.sign * pull

    def normal_slope(self, ops, u_nu, beta):
        # d/du of -gamma beta^2 (-R(u))_+ : gamma beta^2 on -L < u < 0, zero elsewhere
        inside = ops.ifpos(-u_nu, ops.ifpos(u_nu + self.L, 1.0, 0.0), 0.0)
        return self.sign * self.gamma_nu * beta * beta * inside

    def kinks(self, u_nu, u_tau):
        return [u_nu, u_nu + self.L]  # the pull starts at contact and saturates at the bond length

    def max_slope(self, beta0):
        return self.gamma_nu * beta0 ** 2, 0.0


def bonding_law(v):
    """The bonding law of a scene with adhesion (None without)."""
    if not v["adhesion"]:
        return None
    return BondingLaw(v["gamma_nu"], v["eps_a"], v["L"], v["bonding_truncation"])
