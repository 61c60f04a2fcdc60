"""Long memory (Model B): sigma(t) = A eps(u(t)) + int_0^t B(t - s) eps(u(s)) ds, with the relaxation kernel B.

A kernel is a :class:`Prony` series B(t) = sum_i C_i exp(-t / tau_i) (C_i linear
tensors; the moduli may be negative, i.e. relaxation) or a :class:`GeneralKernel`
B(t) = b(t) C with b an expression in t. The fully discrete memory term is the left
rectangle rule on the time grid (docs/schemes.md):

    M_n = sum_{j < n} (t_{j+1} - t_j) B(t_n - t_j) eps(u_j).

For a Prony term the history H_n = sum_{j<n} (t_{j+1} - t_j) exp(-(t_n - t_j)/tau) u_j
obeys the exact one-step recursion H_n = exp(-k_n / tau) (H_{n-1} + k_n u_{n-1})
(O(1) work and memory per step); a general kernel needs the stored u_j (O(n)).
Both give the same M_n where both apply.

Examples
--------
>>> from workbench.physics.kelvin_voigt import Scalar
>>> k = Prony([(Scalar(0.5), 0.2)])
>>> k.kind, k.decays(0.1)
('prony', [0.6065306597126334])
"""
from __future__ import annotations

import numpy as np


class Prony:
    """B(t) = sum_i C_i exp(-t / tau_i), given as [(C_i, tau_i)]; ``fit`` says how it approximates a general
    kernel when it does (terms, error bound); ``base = (C, [c_i])`` says that C_i = c_i C (a fitted kernel), so
    that one stiffness matrix serves every term."""

    kind = "prony"

    def __init__(self, terms, fit=None, base=None):
        self.terms = list(terms)
        self.fit = fit
        self.base = base

    def decays(self, k: float) -> list:
        """exp(-k / tau_i): the one-step factors of the histories."""
        return [float(np.exp(-k / tau)) for _, tau in self.terms]

    @property
    def tensors(self) -> list:
        return [C for C, _ in self.terms]

    def trapezoid_weights(self, k: float) -> list:
        """Per term, the weight of u_n in the memory of a step of length k with u linear over the step:
        tau_i (1 - (1 - e^(-x)) / x), x = k / tau_i (k / 2 for k << tau_i, tau_i for k >> tau_i)."""
        return [tau * (1.0 - (-np.expm1(-k / tau)) / (k / tau)) if k > 0.0 else 0.0 for _, tau in self.terms]


class GeneralKernel:
    """B(t) = b(t) C with b an expression in t (O(n) quadrature per step)."""

    kind = "kernel"
    fit = None  # (it is the kernel itself, not a fit of one)

    def __init__(self, shape, tensor):
        self.shape, self.tensor = shape, tensor

    @property
    def tensors(self) -> list:
        return [self.tensor]

    def trapezoid_weights(self, k: float) -> list:
        """The weight of u_n in the product trapezoid rule's memory of a step of length k: k/2 b(0)."""
        return [0.5 * k * float(self.shape(t=0.0))]

    def weights(self, times: np.ndarray, trapezoid: bool = False) -> np.ndarray:
        """The weights w_j (j < n) of M_n = sum_j w_j u_j on the grid t_0 .. t_n.

        Left rectangle: w_j = (t_{j+1} - t_j) b(t_n - t_j). Product trapezoid rule:
        w_j = (k_{j-1} + k_j)/2 b(t_n - t_j) (w_0 = k_0/2 b(t_n)); its last weight, k_{n-1}/2 b(0),
        multiplies u_n and is not returned (it joins the step's operator).
        """
        t = np.asarray(times, dtype=float)
        b = np.asarray(self.shape(t=t[-1] - t[:-1]), dtype=float)
        k = np.diff(t)
        if not trapezoid:
            return k * b
        half = 0.5 * k
        w = half.copy()
        w[1:] += half[:-1]
        return w * b

    def exponential_sum(self, T: float, tol: float, max_terms: int = 40) -> Prony:
        """A Prony series within ``tol`` (relative to max |b|) of B on [0, T], so that memory costs O(terms).

        Relaxation times tau_i are spread geometrically over [T / 10^5, 10 T] (m of them, m
        doubling from 4 until the fit holds); the amplitudes c_i come from linear least
        squares on 4000 points (half uniform in [0, T], half geometric towards 0, where a
        fast decay lives). The error stated (``fit["error"]``) is max |b - sum c_i e^{-t/tau_i}|
        over a denser set of 40000 points in [0, T], relative to max |b| there.
        """
        fit_t = np.unique(np.concatenate([np.linspace(0.0, T, 2000), T * np.geomspace(1e-7, 1.0, 2000)]))
        check_t = np.unique(np.concatenate([np.linspace(0.0, T, 20000), T * np.geomspace(1e-8, 1.0, 20000)]))
        b_fit = np.asarray(self.shape(t=fit_t), dtype=float) * np.ones_like(fit_t)
        b_check = np.asarray(self.shape(t=check_t), dtype=float) * np.ones_like(check_t)
        scale = float(np.max(np.abs(b_check))) or 1.0
        m, best = 4, None
        while m <= max_terms:
            taus = T * np.geomspace(1e-5, 10.0, m)
            basis = np.exp(-fit_t[:, None] / taus[None, :])
            c, *_ = np.linalg.lstsq(basis, b_fit, rcond=1e-13)
            err = float(np.max(np.abs(np.exp(-check_t[:, None] / taus[None, :]) @ c - b_check))) / scale
            best = (taus, c, err)
            if err <= tol:
                break
            m *= 2
        taus, c, err = best
        terms = [(self.tensor.scaled(float(ci)), float(ti)) for ci, ti in zip(c, taus)]
        return Prony(terms, fit={"terms": len(terms), "error": err, "tol": tol, "T": float(T)},
                     base=(self.tensor, [float(ci) for ci in c]))
