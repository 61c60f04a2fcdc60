"""Contact tractions on Gamma_3: normal compliance, adhesive pull, tangential glue (Model A).

Sign convention (SPEC): u_nu = u . nu with nu the outward normal, positive =
penetration into the foundation. The boundary functional of the weak form is

    j(beta, u, w) = int_Gamma3  p_nu(u_nu) w_nu - gamma_nu beta^2 (-R(u_nu))_+ w_nu
                                + p_tau(beta) R*(u_tau) . w_tau  da

so a positive integrand coefficient of w_nu pushes the body out of the foundation.
Every function returns an NGSolve coefficient expression; ``IfPos`` makes the
truncations exact and their linearisation semismooth.

Examples
--------
>>> import ngsolve as ngs
>>> mesh = ngs.Mesh(ngs.unit_square.GenerateMesh(maxh=1))
>>> float(truncate(ngs.CF(-0.5), 0.3)(mesh(0.1, 0.1)))
-0.3
"""
from __future__ import annotations

import ngsolve as ngs


def positive_part(s):
    """(s)_+ = max(s, 0)."""
    return ngs.IfPos(s, s, 0)


def truncate(s, L: float):
    """R(s) = clip(s, -L, L)."""
    return ngs.IfPos(s - L, L, ngs.IfPos(-L - s, -L, s))


def truncate_vector(v, L: float):
    """R*(v) = v if |v| <= L else L v / |v|."""
    norm = ngs.sqrt(ngs.InnerProduct(v, v) + 1e-300)
    return ngs.IfPos(norm - L, L / norm, 1.0) * v


def normal_compliance(u_nu, c_nu: float, m_nu: float = 1.0, gap: float = 0.0):
    """p_nu(u_nu - g) = c_nu ((u_nu - g)_+)^m_nu: the foundation's push against penetration."""
    s = u_nu - gap
    # the power sits inside the branch: d/ds (s_+)**m linearises to NaN wherever s <= 0
    return c_nu * (positive_part(s) if m_nu == 1 else ngs.IfPos(s, s**m_nu, 0))


def adhesive_pull(u_nu, beta, gamma_nu: float, L: float):
    """gamma_nu beta^2 (-R(u_nu))_+: the glue's pull back towards the foundation under tension."""
    return gamma_nu * beta * beta * positive_part(-truncate(u_nu, L))


def glue_traction(u_tau, beta, c_tau: float, L: float):
    """p_tau(beta) R*(u_tau) with p_tau(beta) = c_tau beta: tangential glue stiffness."""
    return c_tau * beta * truncate_vector(u_tau, L)


def normal_and_tangential(u, normal, dim: int):
    """(u_nu, u_tau); in 1D the rod end has u_nu = u and no tangential part."""
    if dim == 1:
        return u * normal, None
    u_nu = ngs.InnerProduct(u, normal)
    return u_nu, u - u_nu * normal


def outward_normal(dim: int):
    """The outward unit normal on the contact boundary (1D: +1 at the rod end x = length).

    NGSolve's ``specialcf.normal(1)`` is +1 at both ends of an interval, so the
    1D normal is fixed here for the right end, the only 1D contact side.
    """
    return 1.0 if dim == 1 else ngs.specialcf.normal(dim)


def boundary_integrand(terms, scene, u, beta, w):
    """The integrand of j(beta, u, w) with only the declared ``terms``; None if there are none.

    ``u`` and ``beta`` are coefficient functions (the lagged state in the
    explicit scheme, trial functions in the implicit one); ``w`` is the test function.
    """
    v, dim = scene.values, scene.dim
    n = outward_normal(dim)
    u_nu, u_tau = normal_and_tangential(u, n, dim)
    w_nu, w_tau = normal_and_tangential(w, n, dim)
    normal_push = 0
    if "compliance" in terms:
        normal_push = normal_compliance(u_nu, v["c_nu"], v["m_nu"], v["gap"])
    if "adhesion" in terms:
        normal_push = normal_push - adhesive_pull(u_nu, beta, v["gamma_nu"], v["L"])
    integrand = None if isinstance(normal_push, int) else normal_push * w_nu
    if "glue" in terms:
        glue = ngs.InnerProduct(glue_traction(u_tau, beta, v["c_tau"], v["L"]), w_tau)
        integrand = glue if integrand is None else integrand + glue
    return integrand
