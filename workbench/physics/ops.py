"""Two ways to evaluate one formula: as NGSolve coefficient functions or as NumPy arrays.

A physics term writes its law once, in terms of these few operations; given
:data:`NGS` it yields the integrand of an NGSolve form (what defines the model and
what NGSolve linearises), given :data:`NP` it yields values at the contact
quadrature points (what the time loop evaluates, without assembly). The tests
check that both agree.

Examples
--------
>>> import numpy as np
>>> NP.pos(np.array([-1.0, 2.0])).tolist(), NP.clip(np.array([-1.0, 0.1]), 0.3).tolist()
([0.0, 2.0], [-0.3, 0.1])
"""
from __future__ import annotations

import numpy as np


class _NGSolve:
    """Operations on NGSolve coefficient functions (IfPos: exact, semismooth when linearised)."""

    name = "ngsolve"

    @staticmethod
    def ifpos(s, a, b):
        import ngsolve as ngs

        return ngs.IfPos(s, a, b)

    def pos(self, s):
        return self.ifpos(s, s, 0)

    def clip(self, s, L):
        return self.ifpos(s - L, L, self.ifpos(-L - s, -L, s))

    def pow_pos(self, s, m):
        """(s_+)^m, the power inside the branch: pow linearises to NaN at a base <= 0."""
        return self.ifpos(s, s ** m, 0)

    @staticmethod
    def sqrt(s):
        import ngsolve as ngs

        return ngs.sqrt(s)

    @staticmethod
    def norm2(v):
        import ngsolve as ngs

        return ngs.InnerProduct(v, v)


class _NumPy:
    """The same operations on arrays (a vector quantity has its components on the last axis)."""

    name = "numpy"

    @staticmethod
    def ifpos(s, a, b):
        # (a and b are evaluated by the caller; a comparison with NaN warns of nothing: no errstate, 1.5 us a call)
        return np.where(s > 0, a, b)

    def pos(self, s):
        return np.where(s > 0, s, 0.0)

    def clip(self, s, L):
        return np.where(s - L > 0, L, np.where(-L - s > 0, -L, s))

    @staticmethod
    def pow_pos(s, m):
        return np.where(s > 0, np.maximum(s, 0.0) ** m, 0.0)

    @staticmethod
    def sqrt(s):
        return np.sqrt(s)

    @staticmethod
    def norm2(v):
        return np.sum(v * v, axis=-1)


NGS = _NGSolve()
NP = _NumPy()
