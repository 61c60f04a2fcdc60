"""The paper's fully discrete scheme PV^hk (Chau et al. 2003, eqs. 6.9–6.12, 7.1–7.4): ``scheme = "explicit"``.

Per step n (k_n = t_n - t_{n-1}):

    (A eps(v_n), eps(w)) = (f_n, w) - (G eps(u_{n-1}), eps(w)) - j(beta_{n-1}, u_{n-1}, w)
    u_n = u_{n-1} + k_n v_n
    beta_n = clip(beta_{n-1} - k_n P_B (gamma_nu beta_{n-1} R(u_{n-1,nu})^2 - eps_a)_+, 0, 1)
    sigma_n = P_Q [A eps(v_n) + G eps(u_{n-1})]

The viscous matrix is factored once (:mod:`workbench.discrete.solvers`); the elastic term is
a matvec with the matrix assembled once; the contact terms and the bonding rate are
evaluated at the contact quadrature points with trace operators assembled once
(:mod:`workbench.discrete.boundary`): one back-substitution per step and vector work.
Contact is lagged, so the scheme is only conditionally stable: k < k_crit, which
:meth:`ExplicitEuler.preflight` predicts before the run for the springs that act at the
start (and within a trial first step), and which every step re-checks against the springs
of its state (:class:`workbench.discrete.stability.StepLimit`).
"""
from __future__ import annotations

import warnings

import numpy as np

from ..discrete import stability
from ..errors import StepLimitExceeded
from ..physics.ops import NP
from .model_a import KelvinVoigtScheme


class ExplicitEuler(KelvinVoigtScheme):
    """The paper's scheme: viscous term implicit, elastic and contact terms lagged (module docs)."""

    name = "explicit"
    chatter_watch = True  # its unstable contact mode can bounce instead of alternating
    lag = 1.0  # sigma_n uses u_{n-1} = u_n - k v_n
    keep = 0  # no error control, one step: no history of accepted states (a copy of u a step saved)
    distributed_layout = {"cg_v_old": "dof", "step_limit_normal": "point", "step_limit_tangent": "point"}
    state_variables = {
        "cg_v_old": ("m/s", "restart state: the velocity of the step before (solver = 'cg': the first guess)"),
        "step_limit_normal": ("Pa/m", "restart state: the largest normal spring met at each contact point"),
        "step_limit_tangent": ("Pa/m", "restart state: the largest tangential spring met at each contact point"),
        # (numbers of several units in one variable: said by name, as the study's error is; they had none)
        "step_limit": ("mixed (the estimate's indicator, its update count, lambda_max in 1/s)",
                       "restart state: the stability estimate's own numbers"),
        "step_checks": ("mixed (k_crit_min in s, its update count, the override flag)",
                        "restart state: the step checks so far"),
    }

    def __init__(self, disc):
        super().__init__(disc)
        d = self.d
        self.solver = d.viscous_solver(iterative=True)
        self.rhs = d.u.vec.CreateVector()
        self.rhs_np, self.v_np, self.u_np = self.rhs.FV().NumPy(), d.v.vec.FV().NumPy(), d.u.vec.FV().NumPy()
        self.work = d.u.vec.CreateVector()
        self.work_np = self.work.FV().NumPy()
        self.contact = d.model.contact
        self.bonding = d.model.bonding
        self.beta_np = d.beta.vec.FV().NumPy() if d.beta is not None else None
        self.tangential = self.contact.tangential and d.side is not None and bool(d.side.T_tau)
        delta = d.model.loads.delta  # the rod's end moves in time: the velocity is lifted on the clamp
        self.v_clamp, self.limit = None, None
        self._v_old = None  # (solver = 'cg': the velocity of the step before, for the first guess)
        self._override = None  # the warning of a run above its predicted k_crit (allow_unstable)
        if delta is not None and delta.depends_on("t"):
            self.v_clamp = d.u.vec.CreateVector()
            self.v_clamp.FV().NumPy()[:] = 0.0  # CreateVector does not initialise

    def preflight(self, k_max: float) -> dict:
        """Refuse k above the predicted stability limit of the springs that act at the start (unless
        allow_unstable, recorded). The returned attributes ``k_crit_min`` and ``k_crit_updates`` follow the run's
        re-checks (:meth:`_recheck`)."""
        d = self.d
        self.limit = None
        if d.side is None:
            est = stability.critical_step(d, self.solver)
        else:  # the springs of u0 and of the state one trial step reaches (a body at a kink: which side it goes)
            limit = stability.StepLimit(d, self.solver)
            start = self.state()
            limit.absorb(*self._springs(limit))
            self.step(0.0, k_max)  # (self.limit is None: no re-check in it)
            limit.absorb(*self._springs(limit))
            self.restore(start)
            self.limit = limit
            est = limit.estimate_now()
        self.checks = {"k_crit": est.k_crit, "k_crit_min": est.k_crit, "k_crit_updates": 0,
                       "stability_override": 0, "linear_solver": self.solver.name} | self.bonding_check(k_max)
        self._override = None
        if k_max > est.k_crit:
            if not d.numerics.allow_unstable:
                stability.check(k_max, est, stability.critical_step(d, self.solver) if self.limit else None)
            self.checks["stability_override"] = 1
            self._override = (f"k = {k_max:.3g} s > predicted k_crit = {est.k_crit:.3g} s: running the explicit "
                              "scheme anyway (allow_unstable)")
        return self.checks

    def _springs(self, limit, u_nu=None, beta_q=None):
        """The acting springs at the current state (:meth:`workbench.discrete.stability.StepLimit.slopes`)."""
        d, side = self.d, self.d.side
        u = self.u_np
        if beta_q is None and self.beta_np is not None:
            beta_q = self.beta_np[d.beta_dofs][side.element]
        u_nu = side.u_nu(u) if u_nu is None else u_nu
        return limit.slopes(u_nu, side.u_tau(u) if limit.tangential else None, beta_q)

    def _recheck(self, k, t, u_nu, beta_q):
        """Stop (or, with allow_unstable, warn once) when the state's springs have grown so that k exceeds the
        limit they set; the steps before are kept (:class:`~workbench.errors.StepLimitExceeded`)."""
        lim = self.limit
        springs = self._springs(lim, u_nu, beta_q)
        if not lim.grows(*springs) or not lim.absorb(*springs):
            return
        first = lim.estimate.k_crit
        est = lim.estimate_now()
        self.checks["k_crit_min"] = min(self.checks["k_crit_min"], est.k_crit)
        self.checks["k_crit_updates"] = lim.updates - 1
        if k <= est.k_crit or self.checks["stability_override"] == 2:
            return
        message = (f"{self.d.scene.name}: the contact state changed at t = {t:.6g} s: the explicit scheme's stability "
                   f"limit is now k_crit = {est.k_crit:.3g} s (it was {first:.3g} s), below k = {k:.3g} s "
                   f"({est.describe()}). Ways out: k <= {0.9 * est.k_crit:.2g} s, or scheme = 'implicit' "
                   "(stable), or allow_unstable = true to run on (recorded)")
        if not self.d.numerics.allow_unstable:
            raise StepLimitExceeded(message + "; the steps computed so far are kept", time=t)
        self.checks["stability_override"] = 2
        warnings.warn(message + ": running on (allow_unstable)", RuntimeWarning, stacklevel=2)

    def _first_guess(self, k: float) -> None:
        """CG's warm start: v extrapolated linearly in time from the last two steps (the solve then starts from an
        O(k^2) residual instead of O(k))."""
        v = self.v_np
        old, k_old = self._v_old, self.k_last
        if old is None:
            self._v_old = v.copy()
            return
        guess = v + (k / k_old) * (v - old) if k_old > 0 else v
        old[:] = v
        v[:] = guess

    def diagnostics(self) -> dict:
        """With solver = 'cg': the iterations of the last step's solve."""
        if not self.solver.iterative:
            return {}
        return {"cg_iterations": self.solver.last_iterations if self.k_last else 0}  # (0 at the start)

    def _extra_state(self) -> dict:
        out = {"cg_v_old": self._v_old.copy()} if self._v_old is not None else {}
        if self.limit is None:
            return out
        c = self.checks
        return out | self.limit.state() | {"step_checks": [c["k_crit_min"], float(c["k_crit_updates"]),
                                                           float(c["stability_override"])]}

    def _restore_extra(self, extra: dict) -> None:
        self._v_old = extra["cg_v_old"].copy() if "cg_v_old" in extra else None
        if "step_checks" in extra and self.limit is not None:
            self.limit.restore(extra)
            k_min, updates, override = extra["step_checks"]
            self.checks.update(k_crit_min=float(k_min), k_crit_updates=int(updates),
                               stability_override=max(self.checks["stability_override"], int(override)))

    def warnings(self) -> list:
        return ([self._override] if self._override else []) + super().warnings()

    def step(self, t_prev: float, t_next: float) -> None:
        d, rhs = self.d, self.rhs
        k = t_next - t_prev
        d.load_vector(t_next, rhs)
        self.work.data = d.elastic.mat * d.u.vec
        self.rhs_np -= self.work_np
        u = self.u_np
        if d.side is not None:  # j(beta_{n-1}, u_{n-1}, .)
            side = d.side
            beta_f = self.beta_np[d.beta_dofs] if self.beta_np is not None else None
            beta_q = beta_f[side.element] if beta_f is not None else None
            u_nu = side.u_nu(u)
            if self.limit is not None:
                self._recheck(k, t_prev, u_nu, beta_q)
            p = self.contact.normal(NP, u_nu, beta_q, side.gap0)
            q = self.contact.tangential_traction(NP, side.u_tau(u), beta_q) if self.tangential else None
            if p is not None or q is not None:
                self.rhs_np -= side.integrate(p, q)
        if self.bonding is not None:  # P_B of the rate at (beta_{n-1}, u_{n-1}), before u moves
            rs = d.rate_side
            rate = np.empty(len(beta_f))
            rate[rs.element] = self.bonding.rate(NP, beta_f[rs.element], rs.u_nu(u))
        if self.v_clamp is not None:
            vc = self.v_clamp.FV().NumPy()
            vc[d.dirichlet_dofs] = (d.dirichlet_value(t_next) - d.dirichlet_value(t_prev)) / k
            self.work.data = d.viscous.mat * self.v_clamp
            self.rhs_np -= self.work_np
            self.solver.solve(self.rhs_np, self.v_np)
            self.v_np += vc
        else:
            if self.solver.warm_start:
                self._first_guess(k)
            self.solver.solve(self.rhs_np, self.v_np)
        u += k * self.v_np
        if self.bonding is not None:
            self.beta_np[d.beta_dofs] = self.bonding.forward_step(beta_f, rate, k)
        self.k_last = k
