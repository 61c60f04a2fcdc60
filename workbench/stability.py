"""Step-size limit of the paper's explicit scheme, predicted before a run.

The scheme advances u' = K_A^{-1} (F - K_G u - j(u)): forward Euler on the
elastic and contact terms, so (linearised) it is stable for
k < k_crit = 2 / lambda_max(K_A^{-1} (K_G + D)), where D is the boundary spring
matrix at the largest slopes the contact terms can have (each term says its own:
:meth:`workbench.physics.contact.ContactTerm.max_slope`) on the normal and the
tangential components. lambda_max comes from Lanczos (SciPy ``eigsh``) on the
generalised problem with the factored K_A.

Examples
--------
>>> import workbench
>>> est = critical_step(workbench.scene("slab", h=0.05, c_nu=100.0, gamma_nu=20.0))
>>> 1e-4 < est.k_crit < 1e-2
True
"""
from __future__ import annotations

from dataclasses import dataclass

import ngsolve as ngs
import numpy as np
from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, LinearOperator, eigsh

from . import solvers
from .errors import ParameterError, StepTooLarge
from .physics import kelvin_voigt

__all__ = ["Estimate", "critical_step", "check", "StepTooLarge"]


@dataclass(frozen=True)
class Estimate:
    k_crit: float
    lambda_max: float
    spring_normal: float
    spring_tangential: float


def critical_step(disc_or_scene, solver=None) -> Estimate:
    """Predict k_crit for the explicit scheme on a discretisation (or a scene, discretised here).

    ``solver`` (the factored K_A, e.g. the explicit scheme's) avoids refactoring.
    """
    from . import discretisation
    from .scenes import Scene

    d = discretisation.build(disc_or_scene) if isinstance(disc_or_scene, Scene) else disc_or_scene
    model = d.model
    s_nu, s_tau = model.contact.max_slope(model.beta0)
    u, w = d.fes.TnT()
    stiff = ngs.BilinearForm(d.fes, symmetric=True)
    stiff += kelvin_voigt.energy_product(model.elastic, u, w, d.dim) * ngs.dx
    if s_nu > 0 or s_tau > 0:
        u_nu, u_tau = d._normal_and_tangential(u)
        w_nu, w_tau = d._normal_and_tangential(w)
        spring = s_nu * u_nu * w_nu
        if s_tau > 0 and u_tau is not None:
            spring = spring + s_tau * ngs.InnerProduct(u_tau, w_tau)
        stiff += spring * ngs.ds(d.contact_name)
    stiff.Assemble()
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    K = solvers.to_scipy(stiff.mat)[free][:, free]
    KA = solvers.to_scipy(d.viscous.mat)[free][:, free]
    inv = solver or solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, d.scene["solver"])
    full_in, full_out = np.zeros(d.ndof), np.zeros(d.ndof)

    def apply_inverse(x):
        full_in[free] = np.ravel(x)
        inv.solve(full_in, full_out)
        return full_out[free].copy()

    n = free.size
    try:
        if n <= 3:
            lam = float(np.max(np.real(np.linalg.eigvals(np.linalg.solve(KA.toarray(), K.toarray())))))
        else:
            Minv = LinearOperator((n, n), matvec=apply_inverse, dtype=float)
            lam = float(eigsh(K, k=1, M=KA, Minv=Minv, which="LM", tol=1e-4, return_eigenvectors=False,
                              v0=np.ones(n))[0])
    except (ArpackError, ArpackNoConvergence, np.linalg.LinAlgError) as err:
        raise ParameterError(f"the explicit scheme's step limit k_crit cannot be estimated for these values (the "
                             f"eigenvalue iteration failed: {str(err).splitlines()[0][:80]}); check the moduli "
                             "(E, a1, a2, c_nu, gamma_nu) or use scheme = 'implicit'") from None
    if not np.isfinite(lam) or lam <= 0:
        raise ParameterError(f"the explicit scheme's step limit k_crit is not finite for these values (lambda_max = "
                             f"{lam:.3g}); check the moduli (E, a1, a2, c_nu, gamma_nu) or use scheme = 'implicit'")
    return Estimate(2.0 / lam, lam, s_nu, s_tau)


def check(k: float, estimate: Estimate) -> None:
    """Raise :class:`StepTooLarge` with the estimate and the ways out when k > k_crit."""
    if k > estimate.k_crit:
        raise StepTooLarge(
            f"k = {k:.3g} s exceeds the predicted stability limit of the explicit scheme, "
            f"k_crit = {estimate.k_crit:.3g} s (2 / lambda_max of K_A^-1 (K_G + springs); boundary springs: "
            f"normal {estimate.spring_normal:.3g}, tangential {estimate.spring_tangential:.3g} Pa/m). "
            f"Ways out: k <= {0.9 * estimate.k_crit:.2g}, or scheme = 'implicit' (stable), "
            "or allow_unstable = true to run anyway (recorded in the results).")
