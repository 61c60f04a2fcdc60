"""The bonding law beta' = -(gamma_nu beta R_b(u_nu)^2 - eps_a)_+ (Frémond; no rebonding), with its time updates.

Two conventions for R_b (docs/choices.md): ``symmetric`` is eq. (3.7) as printed,
R(s) = clip(s, -L, L), which also debonds under compression; ``tension`` is
R_t(s) = (-R(s))_+, which debonds only when the surface is pulled away (the
paper's simulations behave so).

The law knows its two time updates: the paper's forward step (clipped to [0, 1])
and the exponential step of the implicit schemes (exact for frozen u_nu, never
leaving [0, beta_old]), and when a step resolves debonding: its fastest time
scale is 1 / (gamma_nu L^2 beta0), resolved when k gamma_nu L^2 beta0 <= 0.1.

Examples
--------
>>> import numpy as np
>>> from workbench.physics.ops import NP
>>> law = BondingLaw(gamma_nu=1.0, eps_a=0.0, L=0.3, truncation="tension")
>>> law.rate(NP, np.array([1.0, 1.0]), np.array([0.2, -0.2])).round(6).tolist()  # compression: no debonding
[0.0, 0.04]
>>> round(float(law.exponential_step(np.array([1.0]), np.array([0.09]), 0.5)[0]), 12)  # exp(-0.045)
0.955997481833
"""
from __future__ import annotations

import numpy as np


class BondingLaw:
    def __init__(self, gamma_nu: float, eps_a: float, L: float, truncation: str = "tension"):
        if truncation not in ("tension", "symmetric"):
            raise ValueError(f"bonding_truncation = {truncation!r}; allowed: 'tension' | 'symmetric'")
        self.gamma_nu, self.eps_a, self.L, self.truncation = float(gamma_nu), float(eps_a), float(L), truncation

    #: k gamma_nu L^2 beta0 at or below this resolves the fastest debonding (measured, docs/schemes.md).
    RESOLVED = 0.1

    def r(self, ops, u_nu):
        """R_b(u_nu): R (symmetric) or R_t = (-R)_+ (tension)."""
        R = ops.clip(u_nu, self.L)
        return R if self.truncation == "symmetric" else ops.pos(-R)

    def rate(self, ops, beta, u_nu):
        """-beta' = (gamma_nu beta R_b(u_nu)^2 - eps_a)_+ >= 0."""
        r = self.r(ops, u_nu)
        return ops.pos(self.gamma_nu * beta * r * r - self.eps_a)

    @staticmethod
    def forward_step(beta, rate, k):
        """The paper's update beta - k rate, kept in [0, 1]."""
        return np.clip(beta - k * rate, 0.0, 1.0)

    def exponential_step(self, beta, r2, k):
        """beta at t + k solving beta' = -(gamma beta r2 - eps_a)_+ exactly with r2 frozen.

        Where gamma beta r2 > eps_a the solution decays to b* = eps_a / (gamma r2) without
        crossing it: beta_new = b* + (beta - b*) exp(-k gamma r2); elsewhere beta is unchanged.
        """
        rate = self.gamma_nu * r2
        active = rate * beta > self.eps_a
        with np.errstate(divide="ignore", invalid="ignore"):
            b_star = np.where(active, self.eps_a / np.where(rate > 0, rate, 1.0), beta)
        new = np.where(active, b_star + (beta - b_star) * np.exp(-k * rate), beta)
        return np.clip(new, 0.0, 1.0)

    def kinks(self, beta, u_nu) -> list:
        """Functions of the state whose zeros are the law's kinks, at the facets: the onset of debonding (gamma_nu
        beta R_b(u_nu)^2 = eps_a) and beta reaching 0 (NumPy)."""
        from .ops import NP

        r = self.r(NP, u_nu)
        return [self.gamma_nu * beta * r * r - self.eps_a, beta]

    def fastest_rate(self, beta0: float) -> float:
        """1 / (the shortest debonding time scale) = gamma_nu L^2 beta0."""
        return self.gamma_nu * self.L ** 2 * beta0

    def resolved(self, k: float, beta0: float) -> bool:
        """Whether a step k resolves the fastest debonding (k gamma_nu L^2 beta0 <= 0.1)."""
        return k * self.fastest_rate(beta0) <= self.RESOLVED
