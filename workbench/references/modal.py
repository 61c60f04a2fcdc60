"""The exact-in-time solution of a semi-discrete linear Kelvin–Voigt system (isolates a scheme's time error).

Examples
--------
>>> import numpy as np
>>> sol = modal_linear(np.eye(2), np.diag([1.0, 2.0]), np.array([1.0, 0.0]), np.arange(2))
>>> round(float(sol(1.0)[0]), 6)  # q' + q = t, q(0) = 0: q(1) = exp(-1)
0.367879
"""
from __future__ import annotations

import numpy as np


def modal_linear(K_A: np.ndarray, K_G: np.ndarray, F1: np.ndarray, free: np.ndarray):
    """Exact solution of K_A u' + K_G u = t F1, u(0) = 0, on the free dofs (dense, small systems).

    With K_G phi_i = lambda_i K_A phi_i (phi_i K_A-orthonormal), u = sum q_i phi_i
    and q_i' + lambda_i q_i = t c_i, c_i = phi_i . F1, so
    q_i(t) = c_i / lambda_i (t - (1 - exp(-lambda_i t)) / lambda_i).
    """
    from scipy.linalg import eigh

    A = K_A[np.ix_(free, free)]
    G = K_G[np.ix_(free, free)]
    lam, phi = eigh(G, A)
    c = phi.T @ F1[free]

    def solution(t):
        q = c / lam * (t - (-np.expm1(-lam * t)) / lam)
        u = np.zeros(len(F1))
        u[free] = phi @ q
        return u

    return solution
