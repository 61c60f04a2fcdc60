"""Tangential glue p_tau = c_tau beta R*(u_tau), R*(v) = v if |v| <= L else L v / |v| (Model A, 2D and 3D).

Examples
--------
>>> import numpy as np
>>> from workbench.physics.ops import NP
>>> g = TangentialGlue(c_tau=2.0, L=0.3)
>>> g.tangential_traction(NP, np.array([[0.1], [0.6]]), np.array([1.0, 0.5])).round(6).tolist()
[[0.2], [0.3]]
"""
from __future__ import annotations

import numpy as np

from ..contact import ContactTerm


class TangentialGlue(ContactTerm):
    name, rank = "glue", 30
    tangential = uses_beta = True

    def __init__(self, c_tau: float, L: float):
        self.c_tau, self.L = float(c_tau), float(L)

    @classmethod
    def from_values(cls, v):
        if not v["adhesion"] or v.get("c_tau", 0.0) <= 0:
            return None
        return cls(v["c_tau"], v["L"])

    def tangential_traction(self, ops, u_tau, beta):
        norm = ops.sqrt(ops.norm2(u_tau) + 1e-300)
        factor = ops.ifpos(norm - self.L, self.L / norm, 1.0)
        if ops.name == "numpy":
            return (self.c_tau * beta * factor)[..., None] * u_tau
        return self.c_tau * beta * factor * u_tau

    def tangential_slope(self, ops, u_tau, beta):
        norm = np.sqrt(np.sum(u_tau * u_tau, axis=-1) + 1e-300)
        d = u_tau.shape[-1]
        eye = np.broadcast_to(np.eye(d), u_tau.shape[:-1] + (d, d))
        unit = u_tau / norm[..., None]
        beyond = (norm - self.L > 0)[..., None, None]
        slope = np.where(beyond, (self.L / norm)[..., None, None] * (eye - unit[..., :, None] * unit[..., None, :]),
                         eye)
        return (self.c_tau * beta)[..., None, None] * slope

    def kinks(self, u_nu, u_tau):
        if u_tau is None:  # (the rod has no tangential components)
            return []
        return [np.sqrt(np.sum(u_tau * u_tau, axis=-1)) - self.L]  # where the glue saturates

    def max_slope(self, beta0):
        return 0.0, self.c_tau * beta0
