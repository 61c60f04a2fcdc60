"""Model B's memory term over a step, as objects: M_n ~ int_0^{t_n} B(t_n - s) eps(u(s)) ds by a rule.

Two rules (``memory_rule``), each for two kinds of kernel:

* ``rectangle`` (first order): M_n = sum_{j<n} (t_{j+1} - t_j) B(t_n - t_j) eps(u_j);
* ``trapezoid`` (second order): u taken piecewise linear in time. A Prony term C exp(-t/tau)
  is then integrated exactly: with x = k/tau, the history
  H_n = e^{-x} H_{n-1} + tau ((1 - e^{-x})/x - e^{-x}) u_{n-1} + tau (1 - (1 - e^{-x})/x) u_n;
  a general kernel b(t) C by the product trapezoid rule,
  sum_j (k_j / 2) [b(t_n - t_j) u_j + b(t_n - t_{j+1}) u_{j+1}]. The part that multiplies u_n
  (:meth:`MemoryRule.implicit_weights`) joins the operator of step n.

:class:`PronyMemory` keeps one history per term (O(1) work per step: the exact recursion);
:class:`QuadratureMemory` keeps every step's u (O(n) work per step). A rule applies its
histories with one matvec per distinct stiffness (a fitted kernel's terms share one).

A new rule is a subclass with :meth:`~MemoryRule.advance`, :meth:`~MemoryRule.finish`,
:meth:`~MemoryRule.implicit_weights`, :meth:`~MemoryRule.error_terms` and its state;
:func:`rule_for` picks it from the discretisation's memory.

Examples
--------
>>> import workbench
>>> from workbench.discrete import discretisation
>>> d = discretisation.build(workbench.scene("memory_rod", h=0.25))
>>> rule = rule_for(d, trapezoid=True)
>>> type(rule).__name__, rule.order, [round(float(w), 6) for w in rule.implicit_weights(0.01)]
('PronyMemory', 2, [0.004918])
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np


class MemoryRule:
    """The memory of one discretisation (``d.memory``: (K_C, C, tau or shape) per relaxation tensor), integrated by
    the rectangle or the ``trapezoid`` rule (module docs)."""

    kind = ""

    def __init__(self, d, trapezoid: bool):
        self.d, self.trapezoid = d, trapezoid
        self.order = 2 if trapezoid else 1
        self.scales = d.memory_scale or [1.0] * len(d.memory)  # K_i = scales[i] K for terms sharing a stiffness
        groups = OrderedDict()  # terms sharing one stiffness: sum_i s_i H_i first, then one matvec
        for i, (K, _, _) in enumerate(d.memory):
            groups.setdefault(id(K), (K, []))[1].append(i)
        self.groups = list(groups.values())
        self.combined = np.zeros(d.ndof)
        self.histories = []
        self.tmp, self.work = d.u.vec.CreateVector(), d.u.vec.CreateVector()  # matvecs (allocated once)
        self._weights = [0.0] * len(d.memory)

    def implicit_weights(self, k: float) -> list:
        """Per memory term, the weight of u_n in the step's memory term (0 for the rectangle rule): the operator of
        a step of length k is K_A + sum_i w_i s_i K_i."""
        raise NotImplementedError

    def operator(self, weights):
        """K_A + sum_i w_i s_i K_i for the ``weights`` w of :meth:`implicit_weights` (K_A itself where all are 0)."""
        K_A = self.d.elastic.mat
        if not any(weights):
            return K_A
        M = K_A.CreateMatrix()
        vec = M.AsVector()
        vec.data = K_A.AsVector()
        for wi, si, (K, _, _) in zip(weights, self.scales, self.d.memory):
            vec.data += (wi * si) * K.mat.AsVector()
        return M

    def advance(self, t_prev: float, t_next: float, u_prev: np.ndarray, out: np.ndarray, weights: list) -> None:
        """out = sum_i K_Ci H~_i: the histories advanced to t_next without their u_n part (``weights``: this step's
        :meth:`implicit_weights`, kept for :meth:`finish`)."""
        raise NotImplementedError

    def finish(self, u: np.ndarray) -> None:
        """The u_n part of the trapezoid rule joins the histories once u_n is known."""
        for H, w in zip(self.histories, self._weights):
            if w:
                H += w * u

    def error_terms(self, k: float, history: list, u: np.ndarray) -> list:
        """Per memory term, the vector that its tensor's stiffness turns into the rule's error force over the last
        step (``history``: the accepted (t, u, beta), the last one u_{n-1}; see
        :meth:`workbench.schemes.memory_vi.MemoryVI.local_error`)."""
        raise NotImplementedError

    def apply(self, vectors: list, out: np.ndarray) -> None:
        """out += sum_i s_i K_i vectors[i], one matvec per distinct stiffness (a fitted kernel's 32 terms: one)."""
        for K, members in self.groups:
            if len(members) == 1 and self.scales[members[0]] == 1.0:
                self._add_matvec(K, vectors[members[0]], out)
                continue
            self.combined[:] = 0.0
            for i in members:
                self.combined += self.scales[i] * vectors[i]
            self._add_matvec(K, self.combined, out)

    def held(self) -> np.ndarray:
        """sum_i s_i K_i H_i of the histories as they stand: the rectangle rule's memory at the last accepted t_n
        (which holds no u_n part)."""
        out = np.zeros(self.d.ndof)
        self.apply(self.histories, out)
        return out

    def error_force(self, k: float, history: list, u: np.ndarray) -> np.ndarray:
        """The rule's error force over the last step (:meth:`error_terms` through the stiffnesses), 0 on the
        Dirichlet dofs."""
        force = np.zeros(self.d.ndof)
        self.apply(self.error_terms(k, history, u), force)
        force[self.d.dirichlet_dofs] = 0.0
        return force

    def _add_matvec(self, K, H, out):
        self.tmp.FV().NumPy()[:] = H
        self.work.data = K.mat * self.tmp
        out += self.work.FV().NumPy()

    def stress_parts(self) -> list:
        """The memory's part of sigma_n: (C_i, H_i) per term."""
        return [(C, H) for H, (_, C, _) in zip(self.histories, self.d.memory)]

    def state(self) -> dict:
        return {"histories": [H.copy() for H in self.histories]}

    def restore(self, extra: dict) -> None:
        self.histories = [H.copy() for H in extra["histories"]]

    def _curvature(self, k, history, u):
        """2 [u_n, u_{n-1}, u_{n-2}] divided differences: u'' of the quadratic through the last three states."""
        t1, u1 = history[-1][0], history[-1][1]
        t2, u2 = history[-2][0], history[-2][1]
        kp = t1 - t2
        return 2.0 * (u / (k * (k + kp)) - u1 / (k * kp) + u2 / (kp * (k + kp))), kp


class PronyMemory(MemoryRule):
    """B(t) = sum_i C_i exp(-t / tau_i): one history H_i per term, advanced by the exact one-step recursion."""

    kind = "prony"

    def __init__(self, d, trapezoid: bool):
        super().__init__(d, trapezoid)
        self.histories = [np.zeros(d.ndof) for _ in d.memory]

    def implicit_weights(self, k: float) -> list:
        if not self.trapezoid or k == 0.0:
            return [0.0] * len(self.d.memory)
        return self.d.model.memory.trapezoid_weights(k)

    def advance(self, t_prev, t_next, u_prev, out, weights):
        k = t_next - t_prev
        out[:] = 0.0
        self._weights = weights
        for H, (_, _, tau) in zip(self.histories, self.d.memory):
            x = k / tau
            decay = np.exp(-x)
            if self.trapezoid:  # exact for u linear on the step
                H *= decay
                H += (tau * ((-np.expm1(-x)) / x - decay)) * u_prev
            else:
                H += k * u_prev
                H *= decay
        self.apply(self.histories, out)

    def error_terms(self, k, history, u):
        """Rectangle: the exact integral of the linear interpolant minus k e^-x u_{n-1}; trapezoid: its own leading
        error -(k^3/12) ((1 - e^-x)/x) u'' (the kernel is integrated exactly, only u's curvature counts)."""
        u1 = history[-1][1]
        if self.trapezoid:
            curvature, _ = self._curvature(k, history, u)
        out = []
        for _, _, tau in self.d.memory:
            x = k / tau
            mean = -np.expm1(-x) / x
            if self.trapezoid:
                out.append((-k ** 3 / 12.0 * mean) * curvature)
            else:
                out.append((tau * (mean - np.exp(-x)) - k * np.exp(-x)) * u1 + tau * (1.0 - mean) * u)
        return out


class QuadratureMemory(MemoryRule):
    """B(t) = b(t) C: every step's u stored, the memory a weighted sum over all of them (O(n) per step)."""

    kind = "kernel"

    def __init__(self, d, trapezoid: bool):
        super().__init__(d, trapezoid)
        self.kernel = d.model.memory
        self.stored = np.empty((64, d.ndof))
        self.times = [0.0]

    def implicit_weights(self, k: float) -> list:
        if not self.trapezoid or k == 0.0:
            return [0.0] * len(self.d.memory)
        return self.kernel.trapezoid_weights(k)

    def advance(self, t_prev, t_next, u_prev, out, weights):
        out[:] = 0.0
        self._weights = weights
        K = self.d.memory[0][0]
        n = len(self.times) - 1  # u_0 ... u_{n} stored after this append
        if n >= self.stored.shape[0]:  # grow the history buffer by doubling
            grown = np.empty((2 * self.stored.shape[0], self.stored.shape[1]))
            grown[:n] = self.stored[:n]
            self.stored = grown
        self.stored[n] = u_prev
        self.times.append(t_next)
        t = np.asarray(self.times)
        w = self.kernel.weights(t, self.trapezoid)
        H = w @ self.stored[: n + 1]  # O(n) work: the whole history
        self.histories = [H]
        self._add_matvec(K, H, out)

    def error_terms(self, k, history, u):
        """Rectangle: the trapezoid rule minus the rectangle rule, (k/2) (b(0) u_n - b(k) u_{n-1}); trapezoid: its
        own leading error -(k^3/12) g'', g(s) = b(t_n - s) u(s) by divided differences."""
        u1 = history[-1][1]
        b = lambda s: float(self.kernel.shape(t=s))  # noqa: E731
        if self.trapezoid:
            kp, u2 = history[-1][0] - history[-2][0], history[-2][1]
            g = 2.0 * (b(0.0) * u / (k * (k + kp)) - b(k) * u1 / (k * kp) + b(k + kp) * u2 / (kp * (k + kp)))
            return [(-k ** 3 / 12.0) * g]
        return [0.5 * k * (b(0.0) * u - b(k) * u1)]

    def state(self) -> dict:
        # (u_0 ... u_{n-1} for the n + 1 times: the buffer's next row is not yet written, and copying it put whatever
        # memory held, NaN patterns among it, into the state and the archives)
        n = len(self.times) - 1
        return super().state() | {"times": list(self.times), "stored": self.stored[:n].copy()}

    def restore(self, extra: dict) -> None:
        super().restore(extra)
        self.times = list(extra["times"])
        n = len(self.times) - 1
        if self.stored.shape[0] <= n:
            self.stored = np.empty((max(64, 2 * n), self.stored.shape[1]))
        self.stored[:n] = np.asarray(extra["stored"])[:n]  # (archives before the fix hold one row more)


def rule_for(d, trapezoid: bool):
    """The memory rule of a discretisation's memory (None without one)."""
    if not d.memory:
        return None
    return {"prony": PronyMemory, "kernel": QuadratureMemory}[d.memory_kind](d, trapezoid)
