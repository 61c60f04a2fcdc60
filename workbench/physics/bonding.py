"""The bonding law beta' = -(gamma_nu beta R(u_nu)^2 - eps_a)_+ (Frémond; no rebonding).

Two conventions for R in the debonding rate (SPEC, "Bonding-law convention"):
``symmetric`` is eq. (3.7) as printed, R(s) = clip(s, -L, L), which also
debonds under compression; ``tension`` is R_t(s) = (-R(s))_+, which debonds only
when the surface is pulled away (the paper's simulations behave so).

Examples
--------
>>> import ngsolve as ngs
>>> mesh = ngs.Mesh(ngs.unit_square.GenerateMesh(maxh=1))
>>> rate = debonding_rate(ngs.CF(1.0), ngs.CF(0.2), gamma_nu=1.0, eps_a=0.0, L=0.3, truncation="tension")
>>> float(rate(mesh(0.1, 0.1)))
0.0
"""
from __future__ import annotations

from .contact import positive_part, truncate


def bonding_truncation(u_nu, L: float, convention: str):
    """R(u_nu) (``symmetric``) or R_t(u_nu) = (-R(u_nu))_+ (``tension``)."""
    if convention == "symmetric":
        return truncate(u_nu, L)
    if convention == "tension":
        return positive_part(-truncate(u_nu, L))
    raise ValueError(f"bonding_truncation = {convention!r}; allowed: 'tension' | 'symmetric'")


def debonding_rate(beta, u_nu, gamma_nu: float, eps_a: float, L: float, truncation: str):
    """-beta' = (gamma_nu beta R(u_nu)^2 - eps_a)_+ >= 0."""
    r = bonding_truncation(u_nu, L, truncation)
    return positive_part(gamma_nu * beta * r * r - eps_a)
