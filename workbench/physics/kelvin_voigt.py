"""Kelvin–Voigt material sigma = A eps(u') + G eps(u): linear tensors A (viscous) and G (elastic).

A tensor is a function from a strain to a stress. Isotropic tensors are
``lam tr(eps) I + two_mu eps``; plane stress, 3D and the rod's scalar moduli are
special choices of (lam, two_mu). A user may pass any linear function of the strain.

Examples
--------
>>> lam, two_mu = plane_stress_moduli(E=1000.0, nu=0.3)
>>> round(lam, 3), round(two_mu, 3)
(329.67, 769.231)
"""
from __future__ import annotations

import ngsolve as ngs


def plane_stress_moduli(E: float, nu: float) -> tuple[float, float]:
    """(lam, two_mu) of the plane-stress elasticity: E nu / (1 - nu^2), E / (1 + nu)."""
    return E * nu / (1.0 - nu * nu), E / (1.0 + nu)


def lame_moduli(E: float, nu: float) -> tuple[float, float]:
    """(lam, two_mu) of 3D isotropic elasticity: E nu / ((1 + nu)(1 - 2 nu)), E / (1 + nu)."""
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (1.0 + nu)


def isotropic(lam: float, two_mu: float):
    """The isotropic tensor eps -> lam tr(eps) I + two_mu eps (any dimension)."""

    def tensor(eps):
        dim = eps.dims[0]
        return lam * ngs.Trace(eps) * ngs.Id(dim) + two_mu * eps

    return tensor


def scalar(modulus: float):
    """The 1D tensor eps -> modulus * eps (the rod's a or b)."""
    return lambda eps: modulus * eps


def strain(u, dim: int):
    """eps(u) = sym grad u (the derivative in 1D)."""
    if dim == 1:
        return ngs.grad(u)[0]
    return ngs.Sym(ngs.Grad(u))


def tensors(scene):
    """The scene's (A, G): viscous and elastic tensors as strain -> stress functions."""
    v = scene.values
    if scene.dim == 1:
        return scalar(v["b"]), scalar(v["a"])
    moduli = plane_stress_moduli if scene.dim == 2 else lame_moduli
    return isotropic(v["a1"], v["a2"]), isotropic(*moduli(v["E"], v["nu"]))


def energy_product(tensor, u, w, dim: int):
    """The integrand tensor(eps(u)) : eps(w) of a stiffness or viscosity form."""
    eu, ew = strain(u, dim), strain(w, dim)
    if dim == 1:
        return tensor(eu) * ew
    return ngs.InnerProduct(tensor(eu), ew)


def von_mises(sigma, dim: int):
    """|sigma|_vM: plane stress (s11^2 + s22^2 - s11 s22 + 3 s12^2)^(1/2); 3D the usual J2 form; 1D |sigma|."""
    if dim == 1:
        return ngs.IfPos(sigma, sigma, -sigma)
    if dim == 2:
        s11, s22, s12 = sigma[0, 0], sigma[1, 1], sigma[0, 1]
        return ngs.sqrt(s11 * s11 + s22 * s22 - s11 * s22 + 3 * s12 * s12)
    dev = sigma - (ngs.Trace(sigma) / 3) * ngs.Id(3)
    return ngs.sqrt(1.5 * ngs.InnerProduct(dev, dev))
