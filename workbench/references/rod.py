"""Rod references: exact formulas and ODE/Volterra solves of the 1D problems, independent of the schemes.

* :func:`tp1_exact` — Test Problem 1 in closed form (corrected exponents: docs/choices.md).
* :func:`rod_ode` — any rod scene with u0 = delta(0) reduces to an ODE for the
  end strain A(t) and beta(t) (docs/models.md, Appendix A of the paper), integrated here
  with SciPy's Radau method to tight tolerance.
* :func:`rod_memory` — a Model B rod scene: the scalar Volterra inclusion solved by
  :mod:`workbench.references.volterra` (Prony kernels: an ODE for the memory variables; a general
  kernel: the product trapezoid rule on a fine grid, Richardson-extrapolated).
* :func:`rod_reference` — whichever of the two fits the scene's model.

Examples
--------
>>> ref = tp1_exact()
>>> round(float(ref(1.0, x=1.0)[0]), 6), round(float(ref(1.0)[1]), 6)
(-0.544863, 0.973361)
>>> round(float(ref.stress(1.0)), 6)  # sigma(1) = gamma L beta(1)^2 (the adhesive pull balances it)
0.085269
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError


class RodSolution:
    """A rod reference u(x, t) = delta(t) + A(t) x with beta(t).

    ``solution(t, x)`` returns (u, beta); ``strain(t)`` is A(t) = u_x;
    ``stress(t)`` is sigma = a A + b A'.
    """

    def __init__(self, delta, strain, strain_rate, beta, a=1.0, b=1.0, stress=None):
        self._delta, self._A, self._dA, self._beta, self.a, self.b = delta, strain, strain_rate, beta, a, b
        self._stress = stress  # given where sigma is not a A + b A' (Model B: a A + memory)

    def __call__(self, t, x=1.0):
        t = np.asarray(t, dtype=float)
        A = self._A(t)
        x = np.asarray(x, dtype=float)
        if A.ndim and x.ndim:  # (time, point)
            return self._delta(t)[:, None] + A[:, None] * x[None, :], self._beta(t)
        return self._delta(t) + A * x, self._beta(t)

    def strain(self, t):
        return self._A(np.asarray(t, dtype=float))

    def stress(self, t):
        t = np.asarray(t, dtype=float)
        if self._stress is not None:
            return self._stress(t)
        return self.a * self._A(t) + self.b * self._dA(t)


def tp1_exact():
    """u(x, t) and beta(t) of Test Problem 1: beta = exp(-0.027 t), u = 0.09513 (e^{-0.054 t} - e^{-t}) x - 0.6.

    The constants follow from the reduced ODE A' + A = gamma L beta^2,
    beta' = -gamma L^2 beta with gamma = L = 0.3 (docs/models.md): 0.027 = gamma L^2,
    0.054 = 2 gamma L^2, 0.09513 = gamma L / (1 - 2 gamma L^2).
    """
    gamma, L = 0.3, 0.3
    c = gamma * L / (1.0 - 2.0 * gamma * L * L)
    r = 2 * gamma * L * L
    return RodSolution(delta=lambda t: np.full_like(t, -0.6),
                       strain=lambda t: c * (np.exp(-r * t) - np.exp(-t)),
                       strain_rate=lambda t: c * (-r * np.exp(-r * t) + np.exp(-t)),
                       beta=lambda t: np.exp(-gamma * L * L * t))


def rod_ode(scene, rtol=1e-11, atol=1e-13, model=None):
    """Reference for a Model A rod scene: b A' + a A = -p_nu(u_end) + gamma beta^2 (-R(u_end))_+, u_end = delta + A length.

    Derivation (docs/models.md): with u0 = delta(0) constant the displacement stays
    u = delta(t) + A(t) x, so sigma = a A + b A' is constant in x and the contact
    condition at x = length gives the ODE above, together with
    beta' = -(gamma beta R_b(u_end)^2 - eps_a)_+ (R_b the scene's bonding truncation).
    The laws are written here again as scalar formulas (independent of the
    finite-element code); only their numbers come from the scene's model (or from
    ``model``, e.g. one with the adhesive pull's sign flipped).

    Returns
    -------
    RodSolution
        ``solution(t, x=length) -> (u(x, t), beta(t))`` (dense output, vectorised in t),
        with ``strain(t)`` and ``stress(t)``.
    """
    model = model or scene.model_of()
    terms = check_rod_ode(scene, model)
    delta, ell = model.loads.delta, model.geometry.extent[0]
    a, b, law = model.elastic.modulus, model.viscous.modulus, model.bonding
    rhs = _rod_rhs(delta, ell, a, b, terms, law)

    # The right-hand side is only Lipschitz (kinks at end = 0, +-L, g): limit the step so kinks are resolved;
    # Radau's error control then does the rest. How short the step must be at a kink depends on how stiff the laws
    # make the rod, rate = (a + length (c_nu + gamma_nu)) / b. Against T/20000 at rtol 1e-12, of max |y|
    # (studies/reference_steps.py, data/references/reference_steps.csv): T/200 is within 1.5e-12 on tp1, tp2 (also
    # with gamma_nu = 1.5) and 1.4e-11 on the rod under 0.3 sin(2 pi t) with c_nu = 1000 (rate * T/200 = 5), in 1/10
    # to 1/3 of the time of T/2000 (1.6-1.8 s); on tp3 both are within 3e-10. With c_nu = 1e5 and 1e7 (b = 0.01)
    # T/200 is 2.6e-10 and 7.4e-10 off where T/2000 is 6e-12 and 1e-13: so T/200 only where rate * T/200 <= 10.
    T = scene["T"]
    beta0 = model.beta0 if law is not None else 1.0
    comp, pull = terms.get("compliance"), terms.get("adhesion")
    stiffness = (a + ell * ((comp.c_nu if comp else 0.0) + (pull.gamma_nu if pull else 0.0))) / b
    max_step = T / 200 if stiffness * T / 200 <= 10.0 else T / 2000
    sol = _radau(rhs, T, [0.0, beta0], rtol, atol, max_step, stiffness)

    def strain_rate(t):
        y = sol.sol(t)
        return np.array([rhs(ti, yi)[0] for ti, yi in zip(np.atleast_1d(t), np.atleast_2d(y.T))]).reshape(np.shape(t))

    return RodSolution(delta=lambda t: np.broadcast_to(np.asarray(delta(t=t), dtype=float), np.shape(t)).copy(),
                       strain=lambda t: sol.sol(t)[0], strain_rate=strain_rate, beta=lambda t: sol.sol(t)[1],
                       a=a, b=b)


def check_rod_ode(scene, model=None) -> dict:
    """Refuse a scene :func:`rod_ode` cannot solve (ValueError; ParameterError for a contact term it does not know),
    before it or a run is made: a Kelvin-Voigt rod with u0 = delta(0). Its contact terms by their law's name.

    >>> import workbench
    >>> check_rod_ode(workbench.scene("tp2", u0="-0.1 + 0.01*x"))
    Traceback (most recent call last):
    ...
    ValueError: rod_ode needs u0 = delta(0) (constant): only then is u linear in x
    """
    model = model or scene.model_of()
    if model.geometry.dim != 1 or model.viscous is None:
        raise ValueError(f"rod_ode needs a Kelvin-Voigt (Model A) rod scene, got {scene.name!r}")
    loads = model.loads
    if not np.allclose(loads.u0(x=np.linspace(0, model.geometry.extent[0], 7)), loads.delta(t=0.0)):
        raise ValueError("rod_ode needs u0 = delta(0) (constant): only then is u linear in x")
    return _rod_terms(model)


def _radau(rhs, T, y0, rtol, atol, max_step, stiffness):
    """SciPy's Radau on [0, T] with dense output; a RuntimeError saying why where it fails."""
    from scipy.integrate import solve_ivp

    try:
        with np.errstate(over="ignore", invalid="ignore"):  # (said below, as the failure it leads to)
            sol = solve_ivp(rhs, (0.0, T), y0, method="Radau", rtol=rtol, atol=atol, dense_output=True,
                            max_step=max_step)
    except (ValueError, FloatingPointError, OverflowError) as err:
        # (c_nu = 1e15, m_nu = 3: Radau's trial states overflow the compliance, and SciPy's own ValueError, "array
        # must not contain infs or NaNs", was all a user saw; found by an outside pass)
        raise RuntimeError(f"reference ODE failed: SciPy's Radau met an overflow ({err}); the rod's laws are too "
                           f"stiff for it here (rate (a + length (c_nu + gamma_nu)) / b = {stiffness:.3g} 1/s): "
                           "compare with a finer run instead") from None
    if not sol.success:
        raise RuntimeError(f"reference ODE failed: {sol.message}")
    return sol


def _rod_terms(model):
    """The model's contact terms keyed by the law :func:`rod_ode` writes for them ("compliance", "adhesion"); any
    other term is refused, by its name."""
    known = {"compliance": "compliance", "adhesion": "adhesion", "adhesion_flipped": "adhesion"}
    unknown = [t for t in model.contact.terms if t.name not in known]
    if unknown:
        # name the term and the parameters that declare it, so the user knows what to switch off
        what = "; ".join(f"{t.name!r}" + (f" (its parameters {', '.join(p.name for p in t.parameters)})"
                                           if t.parameters else "") for t in unknown)
        raise ParameterError(f"the rod reference 'ode' (rod_ode) solves the rod with the normal compliance (c_nu, "
                             f"m_nu, gap) and the adhesive pull (gamma_nu, L) only; it cannot handle the contact term "
                             f"{what}: switch it off, or compare with a finer run (reference = 'finest' or "
                             "{'k': ...})")
    return {known[t.name]: t for t in model.contact.terms}


def _rod_rhs(delta, ell, a, b, terms, law):
    """The right-hand side of the reduced ODE for y = (A, beta), the laws written as scalar formulas."""
    comp, pull = terms.get("compliance"), terms.get("adhesion")
    c_nu, m_nu, g = (comp.c_nu, comp.m_nu, comp.gap) if comp else (0.0, 1.0, 0.0)
    gamma, L, sign = (pull.gamma_nu, pull.L, pull.sign) if pull else (0.0, 1.0, 1.0)

    def clip(s, length):
        return min(max(s, -length), length)

    def rhs(t, y):
        A, beta = y
        end = delta(t=t) + A * ell
        push = c_nu * max(end - g, 0.0) ** m_nu
        adhesive = sign * gamma * beta * beta * max(-clip(end, L), 0.0)
        rate = 0.0
        if law is not None:
            r = clip(end, law.L) if law.truncation == "symmetric" else max(-clip(end, law.L), 0.0)
            rate = max(law.gamma_nu * beta * r ** 2 - law.eps_a, 0.0)
        return [(-push + adhesive - a * A) / b, -rate]

    return rhs


def rod_memory(scene, n=4000):
    """Reference for a Model B rod scene (memory, unilateral layer), as a :class:`RodSolution` without beta.

    With a Prony kernel the memory variables obey an ODE, integrated by
    :func:`workbench.references.volterra.solve_prony` (DOP853, rtol 1e-10); a general
    kernel b(t) kernel_E is integrated by :func:`~workbench.references.volterra.solve_quadrature`
    with ``n`` and ``2 n`` steps and Richardson-extrapolated, then interpolated linearly in t
    (error O((T/n)^2)).

    Examples
    --------
    >>> import workbench
    >>> ref = rod_memory(workbench.scene("memory_rod"))
    >>> u, beta = ref(np.array([0.25]), x=1.0)
    >>> bool(u[0] <= 0.1 + 1e-12), bool(np.isnan(beta[0]))  # the end never passes the layer (gap = 0.1)
    (True, True)
    """
    from . import volterra

    model = scene.model_of()
    if model.geometry.dim != 1 or model.layer is None:
        raise ValueError(f"rod_memory needs a rod scene with a compliant layer (Model B), got {scene.name!r}")
    delta = model.loads.delta
    layer = model.layer
    common = dict(a=model.elastic.modulus, ell=model.geometry.extent[0], F=layer.F, c=layer.c, g=layer.g, T=scene["T"],
                  delta=lambda t: np.broadcast_to(np.asarray(delta(t=t), dtype=float), np.shape(t)))
    nan = lambda t: np.full(np.shape(t), np.nan)  # noqa: E731
    lift = lambda t: common["delta"](np.asarray(t, float)).copy()  # noqa: E731
    memory = model.memory
    if memory is not None and memory.fit is not None:  # an exponential sum stands for a general kernel: the kernel
        memory = scene.with_(kernel_approximation="quadrature").model_of().memory
    if memory is None or memory.kind == "prony":
        terms = memory.terms if memory is not None else []
        sol = volterra.solve_prony(moduli=[C.modulus for C, _ in terms], taus=[tau for _, tau in terms], **common)
        return RodSolution(delta=lift, strain=sol.A, strain_rate=None, beta=nan, a=common["a"], b=0.0,
                           stress=sol.sigma)
    shape, modulus = memory.shape, memory.tensor.modulus
    b = lambda t: modulus * np.broadcast_to(np.asarray(shape(t=t), dtype=float), np.shape(t))  # noqa: E731
    ext = volterra.richardson(volterra.solve_quadrature(kernel=b, n=n, **common),
                              volterra.solve_quadrature(kernel=b, n=2 * n, **common))
    return RodSolution(delta=lift, strain=lambda t: np.interp(t, ext.t, ext.A), strain_rate=None, beta=nan,
                       a=common["a"], b=0.0, stress=lambda t: np.interp(t, ext.t, ext.sigma))


def rod_reference(scene):
    """The independent reference of a rod scene: :func:`rod_ode` (Model A) or :func:`rod_memory` (Model B)."""
    return _ROD_REFERENCES[scene.model](scene)


#: The rod reference of each model, by its letter.
_ROD_REFERENCES = {"A": rod_ode, "B": rod_memory}
