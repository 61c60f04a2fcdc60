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
    """B(t) = sum_i C_i exp(-t / tau_i), given as [(C_i, tau_i)]."""

    kind = "prony"

    def __init__(self, terms):
        self.terms = list(terms)

    def decays(self, k: float) -> list:
        """exp(-k / tau_i): the one-step factors of the histories."""
        return [float(np.exp(-k / tau)) for _, tau in self.terms]


class GeneralKernel:
    """B(t) = b(t) C with b an expression in t (O(n) quadrature per step)."""

    kind = "kernel"

    def __init__(self, shape, tensor):
        self.shape, self.tensor = shape, tensor

    def weights(self, times: np.ndarray) -> np.ndarray:
        """w_j = (t_{j+1} - t_j) b(t_n - t_j), j < n, for the grid t_0 .. t_n: the left-rectangle weights of M_n."""
        t = np.asarray(times, dtype=float)
        return np.diff(t) * np.asarray(self.shape(t=t[-1] - t[:-1]), dtype=float)
