"""What Model A's schemes share: the bonding-resolution check, the kinks of the laws at a state, and the observer.

The stress a Kelvin-Voigt body reports is A eps(v) + G eps(u - lag k v) (the explicit scheme takes the elastic
part at u_{n-1}, the implicit ones at u_n); the contact pressure at a contact vertex is the normal force the laws
exert on it over its share of the side (:class:`KelvinVoigtObserver`).

Examples
--------
>>> import workbench
>>> from workbench.discrete import discretisation
>>> from workbench.schemes import scheme_class
>>> d = discretisation.build(workbench.scene("tp5", h=0.1))
>>> scheme = scheme_class("implicit")(d)
>>> [len(values) for values, weights in kinks(d, d.u.vec.FV().NumPy(), scheme._beta())]  # per contact point / facet
[20, 20, 20, 10, 10]
"""
from __future__ import annotations

import numpy as np

from ..discrete import solvers
from ..physics.ops import NP
from .base import Observer, Scheme, events


class KelvinVoigtScheme(Scheme):
    """Model A's shared parts of a stepper: the bonding-resolution check and its warning, the observer."""

    #: The elastic part of the reported stress is taken at u_n - lag * k v_n (explicit: u_{n-1}; implicit: u_n).
    lag = 0.0

    def __init__(self, disc):
        super().__init__(disc)
        self._resolution = None  # (k gamma L^2 beta0, the debonding time scale, the k that resolves it) if not

    def bonding_check(self, k_max: float) -> dict:
        """Record (and later warn) whether the step resolves the fastest debonding (k gamma_nu L^2 beta0 <= 0.1)."""
        law = self.d.model.bonding
        if law is None:
            return {}
        beta0 = self.d.model.beta0
        resolved = law.resolved(k_max, beta0)
        rate = law.fastest_rate(beta0)
        self._resolution = None if resolved else (k_max * rate, 1.0 / rate, law.RESOLVED / rate)  # (rate > 0 here)
        return {"bonding_resolved": int(resolved)}

    def warnings(self) -> list:
        if self._resolution is None:
            return []
        ratio, scale, k_ok = self._resolution
        return [f"k gamma_nu L^2 beta0 = {ratio:.3g}: debonding (time scale {scale:.3g} s) is faster than the step, "
                f"so the bonding field is not resolved where |u_nu| ~ L (O(1) errors in beta possible); use k <= "
                f"{k_ok:.2g} s for an accurate beta"]

    def observer(self, disc=None) -> "KelvinVoigtObserver":
        return KelvinVoigtObserver(self, disc or self.d)


def kinks(d, u: np.ndarray, beta) -> list:
    """The functions whose zeros are the kinks of the contact laws and of the bonding law at the state (u, beta), in
    groups of (values, weights) for the event detection: the laws' own kinks
    (:meth:`workbench.physics.contact.ContactTerm.kinks`) at the contact quadrature points, weighted by the
    quadrature, and the bonding law's (:meth:`workbench.physics.bonding.BondingLaw.kinks`) at the facet midpoints,
    weighted by the facet measure."""
    m = d.model
    if d.side is None:
        return []
    side = d.side
    u_tau = side.u_tau(u) if side.T_tau else None
    groups = [(values, side.weights) for values in m.contact.kinks(side.u_nu(u), u_tau, side.gap0)]
    if m.bonding is not None and beta is not None:
        rs = d.rate_side
        groups += [(values, rs.weights) for values in m.bonding.kinks(beta[rs.element], rs.u_nu(u))]
    return groups


def kink_event(d, start: dict, beta) -> tuple:
    """(theta, crossed) of the step from the state ``start`` to the current one (:meth:`ErrorControlled.event`)."""
    before = kinks(d, start["u"], start["beta"])
    after = kinks(d, d.u.vec.FV().NumPy(), beta)
    return events(before, after, d.world)


class KelvinVoigtObserver(Observer):
    """What a run records of a Kelvin-Voigt body: sigma = A eps(v) + G eps(u - lag k v), and the contact pressure at
    the contact vertices."""

    def stress_parts(self) -> list:
        m, d, s = self.d.model, self.d, self.scheme
        u, v = d.u.vec.FV().NumPy(), d.v.vec.FV().NumPy()
        return [(m.viscous, v), (m.elastic, u - s.lag * s.k_last * v if s.lag else u)]

    def node_values(self, t: float | None = None) -> dict:
        """The contact pressure at the contact vertices: the normal force the laws exert on each, int p_nu phi_i da
        (by the quadrature of the boundary functional), over its share w_i of the side (the lumped pressure, as
        Model B reports it); where a vertex is held (``pins_contact``) the whole force there, K_A v + K_G u - f
        at its normal dof, over w_i."""
        d, m = self.d, self.d.model
        if d.dim == 1 or not m.contact or d.side is None:
            return {}
        u = d.u.vec.FV().NumPy()
        side = d.side
        beta = None if d.beta is None else d.beta.vec.FV().NumPy()[d.beta_dofs]
        p = m.contact.normal(NP, side.u_nu(u), None if beta is None else beta[side.element], side.gap0)
        pressure = np.zeros(len(d.node_dofs)) if p is None else d.nodal_pressure(p)
        pinned = d.pinned_nodes
        if pinned.size and t is not None:
            pressure[pinned] = self._reaction(t, pinned)
        return {"contact_pressure": pressure, "contact_pressure_recovered": d.pressure_recovery(pressure, d.node_weights)}

    def _reaction(self, t: float, pinned: np.ndarray) -> np.ndarray:
        """The pressure at held contact vertices: the support's reaction (K_A v + K_G u - f at their normal dofs)
        over their share of the side."""
        d = self.d
        dofs = d.normal_dofs[pinned]
        force = self.gathered_record[0][dofs] if self.gathered_record is not None else self._residual_at(t, dofs)
        return -d.geometry.normal_sign * force / d.node_weights[pinned]

    _rows = None  # (the held dofs, and K_A's and K_G's rows there: _residual_at)

    def _residual_at(self, t: float, dofs: np.ndarray) -> np.ndarray:
        """:meth:`record_vectors`' K_A v + K_G u - f at ``dofs`` alone, from the matrices' rows there, cut once: the
        whole products cost 7.5 ms a record at 47k dofs (2.3 s of a 45 s error-controlled run recording every step),
        for the held apex's one value."""
        d, m = self.d, self.d.model
        if self._rows is None or not np.array_equal(self._rows[0], dofs):
            self._rows = (dofs.copy(), *(solvers.to_scipy(mat)[dofs] for mat in (d.viscous.mat, d.elastic.mat)))
        _, viscous, elastic = self._rows
        f = d.u.vec.CreateVector()
        d.load_vector(t, f)
        internal = sum((viscous if tensor is m.viscous else elastic) @ vector for tensor, vector in self.stress_parts())
        return internal - f.FV().NumPy()[dofs]

    def record_vectors(self, t: float) -> list:
        """On a body that holds contact vertices: K_A v + K_G u - f, whose value at a held vertex is the support's
        reaction."""
        d, m = self.d, self.d.model
        if not d.geometry.pins_contact or d.side is None:
            return []
        f, internal = d.u.vec.CreateVector(), d.u.vec.CreateVector()
        tmp, out = d.u.vec.CreateVector(), d.u.vec.CreateVector()
        d.load_vector(t, f)
        internal[:] = 0.0
        for tensor, vector in self.stress_parts():
            tmp.FV().NumPy()[:] = vector
            out.data = (d.viscous.mat if tensor is m.viscous else d.elastic.mat) * tmp
            internal.data += out
        return [internal.FV().NumPy() - f.FV().NumPy()]
