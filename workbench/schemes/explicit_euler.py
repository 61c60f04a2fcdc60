"""The paper's fully discrete scheme PV^hk (eqs. 6.9–6.12, 7.1–7.4).

Per step n (k_n = t_n - t_{n-1}):

    (A eps(v_n), eps(w)) = (f_n, w) - (G eps(u_{n-1}), eps(w)) - j(beta_{n-1}, u_{n-1}, w)
    u_n = u_{n-1} + k_n v_n
    beta_n = clip(beta_{n-1} - k_n P_B (gamma_nu beta_{n-1} R(u_{n-1,nu})^2 - eps_a)_+, 0, 1)
    sigma_n = P_Q [A eps(v_n) + G eps(u_{n-1})]

The viscous matrix is factored once (:mod:`workbench.solvers`); the elastic term is a
matvec with the matrix assembled once; only the contact-boundary forms are
assembled per step. Contact is lagged, so the scheme is only conditionally
stable (k small against the viscous stiffness of the contact springs).
"""
from __future__ import annotations

import numpy as np

from .. import solvers
from ..physics import kelvin_voigt


class ExplicitEuler:
    name = "explicit"
    watch_chatter = True  # its unstable contact mode can bounce instead of alternating

    def __init__(self, disc):
        self.d = d = disc
        self.solver = solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, d.scene["solver"])
        self.rhs = d.u.vec.CreateVector()
        self.rhs_np, self.v_np = self.rhs.FV().NumPy(), d.v.vec.FV().NumPy()
        self.moves_clamp = d.dim == 1 and d.scene["delta"].depends_on("t")
        if self.moves_clamp:
            self.v_clamp = d.u.vec.CreateVector()
            self.v_clamp[:] = 0.0
        self.k_last = 0.0

    def step(self, t_prev: float, t_next: float) -> None:
        d, rhs = self.d, self.rhs
        k = t_next - t_prev
        d.load_vector(t_next, rhs)
        rhs.data -= d.elastic.mat * d.u.vec
        if d.contact_form is not None:
            d.contact_form.Assemble()  # j(beta_{n-1}, u_{n-1}, .)
            rhs.data -= d.contact_form.vec
        if d.rate_form is not None:
            d.rate_form.Assemble()  # P_B of the rate at (beta_{n-1}, u_{n-1}), before u moves
            rate = d.rate_form.vec.FV().NumPy()[d.beta_dofs] / d.facet_measure
        if self.moves_clamp:
            vc = self.v_clamp.FV().NumPy()
            vc[d.dirichlet_dofs] = (d.dirichlet_value(t_next) - d.dirichlet_value(t_prev)) / k
            rhs.data -= d.viscous.mat * self.v_clamp
            self.solver.solve(self.rhs_np, self.v_np)
            d.v.vec.data += self.v_clamp
        else:
            self.solver.solve(self.rhs_np, self.v_np)
        d.u.vec.data += k * d.v.vec
        if d.rate_form is not None:
            b = d.beta.vec.FV().NumPy()
            b[d.beta_dofs] = np.clip(b[d.beta_dofs] - k * rate, 0.0, 1.0)
        self.k_last = k

    def diagnostics(self, initial=False) -> dict:
        return {}

    def stress(self):
        """sigma_n = A eps(v_n) + G eps(u_{n-1}), with u_{n-1} = u_n - k_n v_n."""
        d = self.d
        A, G = kelvin_voigt.tensors(d.scene)
        eps = lambda f: kelvin_voigt.strain(f, d.dim)  # noqa: E731
        return A(eps(d.v)) + G(eps(d.u) - self.k_last * eps(d.v))
