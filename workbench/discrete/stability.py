"""Step-size limit of the paper's explicit scheme: predicted before a run, kept up to date during it.

The scheme advances u' = K_A^{-1} (F - K_G u - j(u)): forward Euler on the
elastic and contact terms, so (linearised) it is stable for
k < k_crit = 2 / lambda_max(K_A^{-1} (K_G + D)), where D is the boundary spring
matrix T^T diag(w s) T of the slopes s of the contact terms at the contact
quadrature points. lambda_max comes from the discretisation's operators of the body on
its springs (:meth:`workbench.discrete.discretisation.Discretisation.springs`, :mod:`workbench.discrete.eigen`:
Lanczos with the factored K_A, or LOBPCG with an iterative solver's preconditioner),
which on several MPI processes reduce their products over the ranks.

Which slopes: :func:`critical_step` without ``springs`` takes every term at its
largest slope on the whole contact side (each term says its own:
:meth:`workbench.physics.contact.ContactTerm.max_slope`), a bound for any state.
A run takes only the springs that act (:class:`StepLimit`): the slopes of the laws
at the state, where a point whose law can switch on within the first step counts
(the state after one trial step is included), and it re-checks every step. A
spring that cannot act -- the foundation's under a body pulled away, the
compliance of a curved side off the foundation, the pull of a body pressed in --
does not shorten the step. When the acting springs grow during the run, lambda_max is
estimated again (warm started) once the total spring int s da has grown by
:data:`REESTIMATE_TOTAL` or the local stiffness max_i (K_G + D)_ii / (K_A)_ii by
:data:`REESTIMATE_LOCAL` since the last estimate: the largest mode of a thin body
on springs is global (tp5: springs on the whole bottom give k_crit = 6.97e-4 s, on
the part pressed after one step 3.3e-3 s), so both the amount and the local
stiffness count. A step above the new limit stops the run
(:class:`~workbench.errors.StepLimitExceeded`, the steps so far kept).

Examples
--------
>>> import workbench
>>> est = critical_step(workbench.scene("slab", h=0.05, c_nu=100.0, gamma_nu=20.0))
>>> 1e-4 < est.k_crit < 1e-2
True
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import StepTooLarge

__all__ = ["Estimate", "StepLimit", "critical_step", "check", "StepTooLarge"]

#: Relative growth of the total spring and of the local stiffness (module docs) above which a run estimates
#: lambda_max again: lambda_max grows at most in proportion to the springs, so the limit a run works with is within
#: about these fractions of the limit of the springs it has met.
REESTIMATE_TOTAL, REESTIMATE_LOCAL = 0.10, 0.01


@dataclass(frozen=True)
class Estimate:
    """A predicted limit. ``spring_normal`` / ``spring_tangential``: the largest spring (Pa/m) taken;
    ``acting``: (contact points with a normal spring, with a tangential one, all points), or None for the bound
    over all states."""
    k_crit: float
    lambda_max: float
    spring_normal: float
    spring_tangential: float
    acting: tuple | None = None

    def describe(self) -> str:
        springs = (f"normal {self.spring_normal:.3g}, tangential {self.spring_tangential:.3g} Pa/m")
        if self.acting is None:
            return f"boundary springs at their largest slopes everywhere: {springs}"
        n, t, total = self.acting
        return (f"springs acting in the state: normal on {n} and tangential on {t} of {total} contact points, "
                f"largest {springs}")


def critical_step(disc_or_scene, solver=None) -> Estimate:
    """Predict k_crit for the explicit scheme on a discretisation (or a scene, discretised here), with every spring
    at its largest slope on the whole contact side.

    ``solver`` (the factored K_A, e.g. the explicit scheme's) avoids refactoring.
    """
    from ..input.scenes import Scene
    from . import discretisation

    d = discretisation.build(disc_or_scene) if isinstance(disc_or_scene, Scene) else disc_or_scene
    s_nu, s_tau = d.model.contact.max_slope(d.model.beta0)
    w = d.side.weights if d.side is not None else np.zeros(0)
    lam, _ = d.springs(solver or d.viscous_solver()).largest_eigenvalue(s_nu * w, s_tau * w)
    return Estimate(2.0 / lam, lam, s_nu, s_tau)


class StepLimit:
    """The explicit scheme's limit for the springs that act, as the state evolves (module docs).

    Holds the envelope of the slopes met so far per contact quadrature point (normal, and the largest
    eigenvalue of the tangential slope), which only grows, and the estimate for it.

    Parameters
    ----------
    disc : workbench.discrete.discretisation.Discretisation
        Model A's, with its contact side.
    solver
        The factored K_A (the explicit scheme's).
    """

    def __init__(self, disc, solver):
        d = self.d = disc
        self.side, self.contact, self.solver = d.side, d.model.contact, solver
        self.world = d.world
        self.free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
        side = self.side
        # the body on its springs: assembled here, or this rank's part of a body distributed over processes
        self.operators = d.springs(solver)
        self.diag_KG, self.diag_KA = self.operators.diagonals()
        T_nu, T_tau = side.T_nu[:, self.free], [T[:, self.free] for T in side.T_tau]
        # (T^2)^T (w s) is the diagonal of T^T diag(w s) T, on the free dofs: the indicator costs one sparse product
        self.sq_nu = T_nu.multiply(T_nu).T.tocsr()
        self.sq_tau = sum((T.multiply(T).T.tocsr() for T in T_tau), sp.csr_matrix(self.sq_nu.shape))
        self.tangential = self.contact.tangential and bool(side.T_tau)
        self.normal = np.zeros(side.points)
        self.tangent = np.zeros(side.points)
        self.estimate, self.indicator, self.updates, self._vector = None, (-np.inf, -np.inf), 0, None

    def slopes(self, u_nu, u_tau, beta_q):
        """(normal, tangential) spring per point at a state: the laws' slopes, the tangential one as the largest
        eigenvalue of d p_tau / d u_tau."""
        s_nu = self.contact.normal_slope(u_nu, beta_q, self.side.gap0)
        if not self.tangential:
            return s_nu, None
        S = self.contact.tangential_slope(u_tau, beta_q)
        if S.shape[-1] == 1:
            return s_nu, S[..., 0, 0]
        a, b, c = S[..., 0, 0], 0.5 * (S[..., 0, 1] + S[..., 1, 0]), S[..., 1, 1]
        return s_nu, 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)

    def grows(self, s_nu, s_tau) -> bool:
        """Whether a state's springs exceed the envelope somewhere (the per-step test, with :meth:`slopes` about 40 us
        at 160 points; every step, since an unstable contact mode alternates from step to step and a sparser check
        can see the same phase only: measured on tp4)."""
        return self.world.any(np.any(s_nu > self.normal) or (s_tau is not None and np.any(s_tau > self.tangent)))

    def absorb(self, s_nu, s_tau) -> bool:
        """Take a state's springs into the envelope; True when lambda_max must be estimated again."""
        np.maximum(self.normal, s_nu, out=self.normal)
        if s_tau is not None:
            np.maximum(self.tangent, s_tau, out=self.tangent)
        total, local = self._indicator()
        return (total > self.indicator[0] * (1.0 + REESTIMATE_TOTAL)
                or local > self.indicator[1] * (1.0 + REESTIMATE_LOCAL))

    def _indicator(self) -> tuple:
        """(int s_nu + s_tau da, max_i (K_G + D)_ii / (K_A)_ii) of the envelope."""
        w, world = self.side.weights, self.world
        # (a shared dof's spring is summed over the ranks whose facets touch it)
        springs = self.operators.cumulated(self.sq_nu @ (w * self.normal) + self.sq_tau @ (w * self.tangent))
        ratio = (self.diag_KG + springs) / self.diag_KA
        return world.sum(w @ (self.normal + self.tangent)), world.max(np.max(ratio, initial=0.0))

    def estimate_now(self) -> Estimate:
        """lambda_max for the envelope (warm started from the last eigenvector)."""
        w = self.side.weights
        lam, self._vector = self.operators.largest_eigenvalue(w * self.normal, w * self.tangent, self._vector)
        return self._estimated(lam)

    def _estimated(self, lam: float) -> Estimate:
        self.indicator = self._indicator()
        self.updates += 1
        self.estimate = self._described(lam)
        return self.estimate

    def _described(self, lam: float) -> Estimate:
        """The estimate lambda_max = ``lam`` of the envelope, with its largest springs and where they act."""
        world = self.world
        acting = tuple(int(world.sum(n)) for n in (np.count_nonzero(self.normal), np.count_nonzero(self.tangent),
                                                   self.side.points))
        return Estimate(2.0 / lam, lam, world.max(self.normal.max(initial=0.0)),
                        world.max(self.tangent.max(initial=0.0)), acting)

    def state(self) -> dict:
        """The envelope and the last estimate, as copies (a restart goes on with them)."""
        return {"step_limit_normal": self.normal.copy(), "step_limit_tangent": self.tangent.copy(),
                "step_limit": [*self.indicator, float(self.updates), self.estimate.lambda_max]}

    def restore(self, state: dict) -> None:
        self.normal[:], self.tangent[:] = state["step_limit_normal"], state["step_limit_tangent"]
        numbers = list(state["step_limit"])
        self.indicator, self.updates = (numbers[0], numbers[1]), int(numbers[2])
        self.estimate = self._described(numbers[3])


def check(k: float, estimate: Estimate, bound: Estimate | None = None) -> None:
    """Raise :class:`StepTooLarge` with the estimate and the ways out when k > k_crit (``bound``: the limit with
    every spring acting, said too when it is lower: the run may reach it)."""
    if k > estimate.k_crit:
        also = ""
        if bound is not None and bound.k_crit < 0.99 * estimate.k_crit:
            also = (f"; with every spring acting, which later states may reach, k_crit = {bound.k_crit:.3g} s")
        raise StepTooLarge(
            f"k = {k:.3g} s exceeds the predicted stability limit of the explicit scheme, "
            f"k_crit = {estimate.k_crit:.3g} s (2 / lambda_max of K_A^-1 (K_G + springs); {estimate.describe()}"
            f"{also}). "
            f"Ways out: k <= {0.9 * estimate.k_crit:.2g}, or scheme = 'implicit' (stable), "
            "or allow_unstable = true to run anyway (recorded in the results).")
