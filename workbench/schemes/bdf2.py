"""Variable-step BDF2 with implicit contact and adhesion: the second-order scheme (``scheme = "bdf2"``, Model A).

With k = t_n - t_{n-1}, k' = t_{n-1} - t_{n-2} and w = k / k', the derivative at t_n is

    u'_n ~ a0 u_n + a1 u_{n-1} + a2 u_{n-2},   a0 = (1 + 2w) / ((1 + w) k),  a1 = -(1 + w) / k,
                                               a2 = w^2 / ((1 + w) k),

exact for quadratics, so that each step solves

    (a0 K_A + K_G) u_n + j(beta_n, u_n, .) = F_n - K_A (a1 u_{n-1} + a2 u_{n-2})

(solved for the increment u_n - u_{n-1}) by the same condensed semismooth Newton as backward Euler
(:class:`~workbench.schemes.implicit_euler.ImplicitEuler`); the first step is one
backward-Euler step. sigma_n = P_Q [A eps(v_n) + G eps(u_n)] with v_n the BDF2 derivative.

The bonding field is integrated to second order as well: while debonding,
beta' = -(gamma beta r2 - eps_a) is linear in beta, and the exponential update with
r2 averaged over the step, r2 = (P_B[R_b(u_{n-1})^2] + P_B[R_b(u_n)^2]) / 2, has a local
error O(k^3) (the exponential of the trapezoid rule). The predictor evaluates the same
update with u_n extrapolated linearly from u_{n-1}, u_{n-2} (error O(k^2), so the
coupling error is O(k^3) per step); the corrector uses the solved u_n.

Where the order must drop: the laws are only Lipschitz at their kinks (u_nu = gap where
the compliance starts, u_nu = 0 and -L for the adhesive pull, |u_tau| = L for the glue,
the onset of debonding where gamma beta R^2 = eps_a, and beta reaching 0), and BDF2 is
second order only across steps where the solution is smooth: a step containing a kink
makes an O(k^2) local error there (first order in that step), so the global error stays
O(k^2) when the kinks are few and isolated and drops towards O(k) when the solution
keeps crossing them (chatter, a moving contact front resolved by few steps). The
error-controlled steps (``rtol > 0``) land on the kinks instead (:mod:`.stepping`).
"""
from __future__ import annotations

import math

from .implicit_euler import ImplicitEuler


class BDF2(ImplicitEuler):
    """Variable-step BDF2, contact and adhesion implicit, beta to second order (module docs)."""

    name = "bdf2"
    order = 2

    def _steps(self, k):
        """(k', w) of the step about to be taken, or None for the first (backward-Euler) step."""
        if len(self.history) < 2 or self.first_order:
            return None
        k_prev = self.history[-1][0] - self.history[-2][0]
        return k_prev, k / k_prev

    #: a0 is snapped up to 2^(j / A0_LEVELS) s^-1 in error-controlled runs (a step at most 19 % shorter: a0 falls at
    #: least 0.83 times as fast as k grows, the least at k / k' = 0.71): a0 K_A + K_G depends on k and on the step
    #: ratio, so without the grid nearly every step met a new matrix (measured on the slab of issue 11, rtol 1e-3: 304
    #: factorisations in 364 solves, 80 % of the run). A run whose step grows over many octaves factors about once per
    #: level it passes, so the grid's spacing trades factorisations against steps. Measured at rtol 1e-3
    #: (``studies/bdf2_a0_grid.py``, one run each, 8 / 4 / 2 levels an octave): hertz3d at 47k dofs 113 / 67 / 57
    #: factorisations for 381 / 389 / 404 solves, 290 / 223 / 207 s (268 / 217 / 209 s in runs of their own); at 12k 86
    #: / 59 / 46 for 453 / 449 / 471, 54.5 / 44.3 / 42.3 s; the slab (410 dofs) 112 / 60 / 44 for 529 / 532 / 577, 1.9 /
    #: 1.9 / 2.1 s. u at T moved by 2e-5 of its largest value or less. Four: most of the 3D gain, for at most 2 % more
    #: solves, where two take up to 9 % more.
    A0_LEVELS = 4

    def admissible_step(self, k: float) -> float:
        """The largest step <= k whose a0 = (k' + 2k) / ((k' + k) k) lies on the grid 2^(j/4): the root of
        A k^2 + (A k' - 2) k - k' = 0 for the grid value A >= a0(k) (a0 falls with k)."""
        steps = self._steps(k)
        if steps is None:
            return k
        kp, _ = steps
        a0 = (kp + 2 * k) / ((kp + k) * k)
        A = 2.0 ** (math.ceil(self.A0_LEVELS * math.log2(a0) - 1e-9) / self.A0_LEVELS)
        b = A * kp - 2.0
        return (-b + math.sqrt(b * b + 4.0 * A * kp)) / (2.0 * A)

    def _constant_a0(self, k: float) -> float:
        """a0 of a step of size k after one of the same size (w = 1): 3 / (2k)."""
        return 1.5 / k

    def coefficients(self, k: float):
        steps = self._steps(k)
        if steps is None:
            return 1.0 / k, None
        _, w = steps
        a0 = (1 + 2 * w) / ((1 + w) * k)
        a1 = -(1 + w) / k
        a2 = w * w / ((1 + w) * k)
        return a0, (a1, a2)

    def _rate_offset(self, history):
        """w_n = a0 u_{n-1} + a1 u_{n-1} + a2 u_{n-2} = -a2 (u_{n-1} - u_{n-2}) (the coefficients sum to 0)."""
        if history is None:
            return None
        _, a2 = history
        return -a2 * (self.history[-1][1] - self.history[-2][1])

    # -- the bonding field to second order ------------------------------------------------------------------------
    def _predict_beta(self, k: float, beta_old) -> None:
        steps = self._steps(k)
        if steps is None:
            return super()._predict_beta(k, beta_old)
        _, w = steps
        u1, u2 = self.history[-1][1], self.history[-2][1]
        guess = u1 + w * (u1 - u2)
        self._set_beta(k, beta_old, 0.5 * (self._r2(u1) + self._r2(guess)))

    def _update_beta(self, k: float, beta_old) -> None:
        if self._steps(k) is None:
            return super()._update_beta(k, beta_old)
        u = self.d.u.vec.FV().NumPy()
        self._set_beta(k, beta_old, 0.5 * (self._r2(self.history[-1][1]) + self._r2(u)))

    def _set_beta(self, k, beta_old, r2):
        d = self.d
        d.beta.vec.FV().NumPy()[d.beta_dofs] = self.bonding.exponential_step(beta_old, r2, k)

    def error_constant(self, t: float, order: int = 2) -> float:
        """BDF2's local error (a1 k^3 + a2 K^3) u^(3) / (6 a0) (K = t - t_{n-2}; from a0 (u_n - u(t_n)) = the
        formula's truncation error) over the quadratic predictor's (t - t_{n-1})(t - t_{n-2})(t - t_{n-3}) u^(3) / 6:
        2/9 for constant steps."""
        if order == 1:
            return super().error_constant(t, 1)
        t1, t2, t3 = (s[0] for s in self.history[-1:-4:-1])
        k, K = t - t1, t - t2
        w = k / (t1 - t2)
        a0 = (1 + 2 * w) / ((1 + w) * k)
        a1 = -(1 + w) / k
        a2 = w * w / ((1 + w) * k)
        return (a1 * k ** 3 + a2 * K ** 3) / a0 / ((t - t1) * (t - t2) * (t - t3))

    def local_error(self, rtol, atol, order=None):
        if order is None and len(self.history) < 3:  # no quadratic predictor yet: backward Euler's estimate
            order = 1
        return super().local_error(rtol, atol, order)
