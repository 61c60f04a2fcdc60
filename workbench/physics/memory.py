"""Long memory (Model B): sigma(t) = A eps(u(t)) + int_0^t B(t - s) eps(u(s)) ds.

The relaxation kernel is either a Prony series B(t) = sum_i C_i exp(-t / tau_i)
(C_i isotropic, given by (E_i, nu_i); the rod's by a modulus) or a general
b(t) C with b an expression in t. The fully discrete memory term is the left
rectangle rule on the time grid (SPEC):

    M_n = sum_{j < n} (t_{j+1} - t_j) B(t_n - t_j) eps(u_j).

For a Prony term the history H_n = sum_{j<n} (t_{j+1} - t_j) exp(-(t_n - t_j)/tau) u_j
obeys the exact one-step recursion H_n = exp(-k_n / tau) (H_{n-1} + k_n u_{n-1})
(O(1) work and memory per step); a general kernel needs the stored u_j (O(n)).
Both give the same M_n where both apply.

Examples
--------
>>> import workbench
>>> [(round(t[0].lam, 3), round(t[0].two_mu, 3), t[1]) for t in prony_tensors(workbench.scene("memory_slab"))]
[(-329.67, -769.231, 0.5)]
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Isotropic:
    """lam tr(eps) I + two_mu eps (in 1D: two_mu eps with lam = 0)."""

    lam: float
    two_mu: float

    def __call__(self, eps):
        from .kelvin_voigt import isotropic

        if not hasattr(eps, "dims") or len(eps.dims) < 2:
            return self.two_mu * eps
        return isotropic(self.lam, self.two_mu)(eps)


def tensor_of(E: float, nu: float, dim: int) -> Isotropic:
    """The isotropic tensor with Young's modulus E and Poisson's ratio nu (plane stress in 2D; 1D: E)."""
    from .kelvin_voigt import lame_moduli, plane_stress_moduli

    if dim == 1:
        return Isotropic(0.0, E)
    lam, two_mu = (plane_stress_moduli if dim == 2 else lame_moduli)(E, nu)
    return Isotropic(lam, two_mu)


def prony_tensors(scene) -> list:
    """[(C_i, tau_i)] of the scene's Prony series."""
    out = []
    for term in scene["prony"]:
        E, tau = term[0], term[-1]
        nu = term[1] if len(term) == 3 else 0.0
        out.append((tensor_of(E, nu, scene.dim), tau))
    return out


def kernel_tensor(scene):
    """(C, b) of a general kernel B(t) = b(t) C, or None when there is none."""
    v = scene.values
    if v["kernel"].is_zero() or v["kernel_E"] == 0:
        return None
    return tensor_of(v["kernel_E"], v.get("kernel_nu", 0.0), scene.dim), v["kernel"]


def quadrature_weights(times: np.ndarray, n: int, kernel) -> np.ndarray:
    """w_j = (t_{j+1} - t_j) b(t_n - t_j), j < n: the left-rectangle weights of M_n."""
    t = times[: n + 1]
    return np.diff(t) * np.asarray(kernel(t=t[n] - t[:n]), dtype=float)
