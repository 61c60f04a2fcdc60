"""Contact tractions on Gamma_3 (Model A): the term protocol and their sum.

Sign convention: u_nu = u . nu with nu the body's outward normal towards the
foundation, positive = penetration; u_tau is the rest of u (the components along
the foundation plane; :mod:`workbench.input.geometry` says which). The boundary
functional of the weak form is

    j(beta, u, w) = int_Gamma3 p_nu(u_nu, beta) w_nu + p_tau(u_tau, beta) . w_tau  da,

the sum over the scene's contact terms; a positive p_nu pushes the body out of
the foundation. Each term is a :class:`ContactTerm` (the laws are in
:mod:`workbench.physics.laws`, one file each) and carries everything about
itself: its tractions (written once, evaluated as NGSolve coefficient functions
or as NumPy arrays, :mod:`.ops`), their slopes (the linearisation the implicit
schemes use, checked against finite differences in the tests), its largest
slope (the explicit scheme's stability limit), whether it acts on the
tangential components, whether it needs the bonding field, and how it is built
from a scene's values.

Examples
--------
>>> import numpy as np
>>> from workbench.physics.laws import NormalCompliance
>>> c = Contact([NormalCompliance(c_nu=2.0, m_nu=1.0, gap=0.0)])
>>> c.normal(NP, np.array([-0.1, 0.2]), None).tolist()
[0.0, 0.4]
"""
from __future__ import annotations

import numpy as np

from .ops import NGS, NP


class ContactTerm:
    """One contact law. Subclasses implement the parts they need (defaults: no traction).

    Class attributes: ``name`` (as listed in a run's ``terms``), ``rank`` (order of
    summation), ``side`` (where its normal slope can be non-zero: ``"compression"``,
    u_nu > 0, or ``"tension"``, u_nu < 0), ``tangential`` (acts on u_tau), ``uses_beta``
    (needs the bonding field), ``parameters`` (the :class:`workbench.values.Param`
    rows it adds to the table).
    """

    name = ""
    rank = 100
    side = "compression"
    tangential = False
    uses_beta = False
    #: Whether the law acts on the distance to the foundation, u_nu - g0(x) (the foundation's push), rather than on
    #: the displacement from the reference state (the glue, stress-free there); the same on a flat contact side.
    gapped = False
    parameters: tuple = ()

    @classmethod
    def from_values(cls, values: dict):
        """This term as the scene's values declare it, or None when the scene does not model it."""
        raise NotImplementedError

    def normal(self, ops, u_nu, beta):
        """p_nu, the coefficient of w_nu (None: no normal traction)."""
        return None

    def normal_slope(self, ops, u_nu, beta):
        """d p_nu / d u_nu (NumPy)."""
        return 0.0

    def tangential_traction(self, ops, u_tau, beta):
        """p_tau, the vector multiplying w_tau (None: no tangential traction)."""
        return None

    def tangential_slope(self, ops, u_tau, beta):
        """d p_tau / d u_tau, shape (..., d-1, d-1) (NumPy)."""
        return 0.0

    def max_slope(self, beta0: float) -> tuple[float, float]:
        """The largest (normal, tangential) slopes over all states with beta <= beta0."""
        return 0.0, 0.0

    def kinks(self, u_nu, u_tau) -> list:
        """Functions of the state whose zeros are where this law switches branch (NumPy arrays over the contact
        points; ``u_tau`` is None on the rod): an error-controlled run lands on them instead of stepping over a kink.
        A smooth law has none (the default)."""
        return []


class Contact:
    """The sum of a scene's contact terms (in ``rank`` order)."""

    def __init__(self, terms):
        self.terms = tuple(sorted(terms, key=lambda t: t.rank))

    @property
    def names(self) -> tuple:
        return tuple(t.name for t in self.terms)

    @property
    def tangential(self) -> bool:
        """Whether any term acts on the tangential components (then the implicit Jacobian needs them all)."""
        return any(t.tangential for t in self.terms)

    @property
    def uses_beta(self) -> bool:
        return any(t.uses_beta for t in self.terms)

    def __bool__(self):
        return bool(self.terms)

    def normal(self, ops, u_nu, beta, gap0=None):
        """p_nu, the sum of the terms; ``gap0`` (the initial gap at the points of a curved contact side, None on a
        flat one) is taken off u_nu for the terms that act on the distance to the foundation."""
        total = None
        shifted = u_nu - gap0 if gap0 is not None else u_nu
        for t in self.terms:
            p = t.normal(ops, shifted if t.gapped else u_nu, beta)
            if p is not None:
                total = p if total is None else total + p
        return total

    def normal_slope(self, u_nu, beta, gap0=None):
        shifted = u_nu - gap0 if gap0 is not None else u_nu
        return sum((t.normal_slope(NP, shifted if t.gapped else u_nu, beta) for t in self.terms), np.zeros_like(u_nu))

    def tangential_traction(self, ops, u_tau, beta):
        total = None
        for t in self.terms:
            p = t.tangential_traction(ops, u_tau, beta)
            if p is not None:
                total = p if total is None else total + p
        return total

    def tangential_slope(self, u_tau, beta):
        eye = np.zeros(u_tau.shape + (u_tau.shape[-1],))
        return sum((t.tangential_slope(NP, u_tau, beta) for t in self.terms), eye)

    def max_slope(self, beta0: float) -> tuple[float, float]:
        """Largest (normal, tangential) spring of the sum of the terms, for states with beta <= beta0.

        Terms on the same side of u_nu = 0 can be steep at the same state (the linear
        and the power-law pull both at u_nu = -L), so their slopes add; the two sides
        never overlap (gap >= 0), so the normal spring is the larger side's sum. Every
        tangential term acts everywhere: their slopes add.
        """
        normal = {}
        tangential = 0.0
        for t in self.terms:
            s_nu, s_tau = t.max_slope(beta0)
            normal[t.side] = normal.get(t.side, 0.0) + s_nu
            tangential += s_tau
        return max(normal.values(), default=0.0), tangential

    def kinks(self, u_nu, u_tau, gap0=None) -> list:
        """The kinks of every term (:meth:`ContactTerm.kinks`), with u_nu less the initial gap for the terms that act
        on the distance to the foundation."""
        shifted = u_nu - gap0 if gap0 is not None else u_nu
        return [k for t in self.terms for k in t.kinks(shifted if t.gapped else u_nu, u_tau)]

    def integrand(self, u_nu, u_tau, beta, w_nu, w_tau, gap0=None):
        """The NGSolve integrand of j(beta, u, w) (None when no term gives a traction; ``gap0`` a coefficient
        function on a curved contact side)."""
        import ngsolve as ngs

        out = None
        p = self.normal(NGS, u_nu, beta, gap0)
        if p is not None:
            out = p * w_nu
        if u_tau is not None:
            q = self.tangential_traction(NGS, u_tau, beta)
            if q is not None:
                part = ngs.InnerProduct(q, w_tau)
                out = part if out is None else out + part
        return out
