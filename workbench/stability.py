"""Step-size limit of the paper's explicit scheme, predicted before a run.

The scheme advances u' = K_A^{-1} (F - K_G u - j(u)): forward Euler on the
elastic and contact terms, so (linearised) it is stable for
k < k_crit = 2 / lambda_max(K_A^{-1} (K_G + D)), where D is the boundary
spring matrix at the largest slopes the contact terms can have:
c_nu m_nu r^(m_nu - 1) for the compliance (r = L when m_nu > 1), gamma_nu beta0^2
for the adhesive pull, on the normal component, and c_tau beta0 for the glue on
the tangential one. lambda_max comes from Lanczos (SciPy ``eigsh``) on the
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
from scipy.sparse.linalg import LinearOperator, eigsh

from . import discretisation, solvers
from .errors import StepTooLarge
from .physics import contact


@dataclass(frozen=True)
class Estimate:
    k_crit: float
    lambda_max: float
    spring_normal: float
    spring_tangential: float


def boundary_springs(scene) -> tuple[float, float]:
    """Largest slopes (normal, tangential) of the declared contact terms."""
    v, terms = scene.values, scene.terms
    normal = 0.0
    if "compliance" in terms:
        normal = v["c_nu"] * v["m_nu"] * (v["L"] ** (v["m_nu"] - 1.0) if v["m_nu"] != 1 else 1.0)
    if "adhesion" in terms:
        normal = max(normal, v["gamma_nu"] * v["beta0"] ** 2)
    tangential = v["c_tau"] * v["beta0"] if "glue" in terms else 0.0
    return normal, tangential


def critical_step(scene, d=None, solver=None) -> Estimate:
    """Predict k_crit for the explicit scheme on ``scene``.

    ``d`` (an existing discretisation) and ``solver`` (its factored K_A, e.g. the
    explicit scheme's) avoid rebuilding and refactoring.
    """
    d = d or discretisation.build(scene)
    s_nu, s_tau = boundary_springs(scene)
    u, w = d.fes.TnT()
    from .physics import kelvin_voigt

    _, G = kelvin_voigt.tensors(scene)
    stiff = ngs.BilinearForm(d.fes, symmetric=True)
    stiff += kelvin_voigt.energy_product(G, u, w, d.dim) * ngs.dx
    if s_nu > 0 or s_tau > 0:
        n = contact.outward_normal(d.dim)
        u_nu, u_tau = contact.normal_and_tangential(u, n, d.dim)
        w_nu, w_tau = contact.normal_and_tangential(w, n, d.dim)
        spring = s_nu * u_nu * w_nu
        if s_tau > 0:
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
    if n <= 3:
        lam = float(np.max(np.real(np.linalg.eigvals(np.linalg.solve(KA.toarray(), K.toarray())))))
    else:
        Minv = LinearOperator((n, n), matvec=apply_inverse, dtype=float)
        lam = float(eigsh(K, k=1, M=KA, Minv=Minv, which="LM", tol=1e-4, return_eigenvectors=False,
                          v0=np.ones(n))[0])
    return Estimate(2.0 / lam, lam, s_nu, s_tau)


def check(scene, k: float, estimate: Estimate) -> None:
    """Raise :class:`StepTooLarge` with the estimate and the ways out when k > k_crit."""
    if k > estimate.k_crit:
        raise StepTooLarge(
            f"k = {k:.3g} s exceeds the predicted stability limit of the explicit scheme, "
            f"k_crit = {estimate.k_crit:.3g} s (2 / lambda_max of K_A^-1 (K_G + springs); boundary springs: "
            f"normal {estimate.spring_normal:.3g}, tangential {estimate.spring_tangential:.3g} Pa/m). "
            f"Ways out: k <= {0.9 * estimate.k_crit:.2g}, or scheme = 'implicit' (stable), "
            "or allow_unstable = true to run anyway (recorded in the results).")
