"""The scheme protocol: what every time scheme provides, and the parts they share.

A scheme advances one :class:`~workbench.discretisation.Discretisation` (which holds
the state u, v and, for Model A, beta) from one time to the next. The time loop
(:func:`workbench.schemes.stepping.march`) calls, in this order:

``__init__(disc)``
    Factor and prepare what is constant (per step size where it depends on k).
``preflight(k_max) -> dict``
    Checks before any step, with the largest step of the run: may raise
    :class:`~workbench.errors.ParameterError` (e.g. the explicit scheme's
    :class:`~workbench.errors.StepTooLarge`). Returns attributes to record
    (``k_crit``, ``bonding_resolved``, ...). Warnings it has to give come after all
    its checks, so a refused run prints only its error.
``start(t0)``
    The state at t0: Model A's u0 is given (nothing to do); Model B's quasistatic
    u(0) is the solution of the inequality at t0.
``step(t_prev, t_next)``
    Advance the state; any step size (the loop asks a step controller). Raises
    :class:`~workbench.errors.Diverged` / :class:`~workbench.errors.NewtonFailed`
    when it cannot.
``diagnostics() -> dict``
    Scalars of the last step (or of ``start``), recorded by name (units in
    :data:`workbench.results.VARIABLES`).
``node_values() -> dict``
    Arrays per contact node (Model B: pressure and state); empty by default.
``stress_parts() -> [(tensor, dof vector), ...]``
    sigma at the current state as a sum of linear tensors applied to the strains of
    dof vectors (Model A: A eps(v) + G eps(u); Model B: A eps(u) + the memory). The
    recorder takes their P0 projection through the discretisation's strain operator;
    :meth:`Scheme.stress` gives the same sum as a coefficient function.
``chatter_watch``
    Whether the loop watches the contact nodes for chatter (the explicit scheme's
    unstable contact mode can bounce rather than alternate).

Registration is one line in :data:`workbench.schemes.REGISTRY` (name -> module, class,
model); the scene's allowed values of ``scheme`` and each model's schemes come from it.
"""
from __future__ import annotations

from ..physics import kelvin_voigt


class Scheme:
    """Base class with the protocol's defaults (see the module docs)."""

    name = ""
    chatter_watch = False

    def __init__(self, disc):
        self.d = disc
        self.k_last = 0.0

    def preflight(self, k_max: float) -> dict:
        return {}

    def start(self, t0: float) -> None:
        return None

    def step(self, t_prev: float, t_next: float) -> None:
        raise NotImplementedError

    def diagnostics(self) -> dict:
        return {}

    def node_values(self) -> dict:
        return {}

    def stress_parts(self) -> list:
        raise NotImplementedError

    def stress(self):
        """sigma as an NGSolve coefficient function (the sum of :meth:`stress_parts`)."""
        import ngsolve as ngs

        sigma = None
        for tensor, vector in self.stress_parts():
            g = ngs.GridFunction(self.d.fes)
            g.vec.FV().NumPy()[:] = vector
            part = tensor(self.eps(g))
            sigma = part if sigma is None else sigma + part
        return sigma

    def warnings(self) -> list:
        """Messages (text) the run should warn about, issued by the loop after every preflight check passed."""
        return []

    def eps(self, field):
        return kelvin_voigt.strain(field, self.d.dim)


class KelvinVoigtScheme(Scheme):
    """Model A's shared parts: the stress A eps(v) + G eps(u - lag v), the bonding-resolution check."""

    #: The elastic part of the reported stress is taken at u_n - lag * k v_n (explicit: u_{n-1}; implicit: u_n).
    lag = 0.0

    def stress_parts(self) -> list:
        m, d = self.d.model, self.d
        u, v = d.u.vec.FV().NumPy(), d.v.vec.FV().NumPy()
        return [(m.viscous, v), (m.elastic, u - self.lag * self.k_last * v if self.lag else u)]

    def bonding_check(self, k_max: float) -> dict:
        """Record (and later warn) whether the step resolves the fastest debonding (k gamma_nu L^2 beta0 <= 0.1)."""
        law = self.d.model.bonding
        if law is None:
            return {}
        beta0 = self.d.model.beta0
        self._resolved = law.resolved(k_max, beta0)
        rate = law.fastest_rate(beta0)
        if not self._resolved:  # (rate > 0 here)
            self._resolution = (k_max * rate, 1.0 / rate, law.RESOLVED / rate)
        return {"bonding_resolved": int(self._resolved)}

    def warnings(self) -> list:
        if getattr(self, "_resolved", True):
            return []
        ratio, scale, k_ok = self._resolution
        return [f"k gamma_nu L^2 beta0 = {ratio:.3g}: debonding (time scale {scale:.3g} s) is faster than the step, "
                f"so the bonding field is not resolved where |u_nu| ~ L (O(1) errors in beta possible); use k <= "
                f"{k_ok:.2g} s for an accurate beta"]
