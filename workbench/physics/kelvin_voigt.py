"""Linear material tensors (strain -> stress) for both models, and the strain, energy and von Mises forms.

Model A is a Kelvin–Voigt body sigma = A eps(u') + G eps(u) (A viscous, G elastic);
Model B's instantaneous tensor A and its relaxation tensors are the same kind of
object. A tensor is one of

* :class:`Isotropic` ``lam tr(eps) I + two_mu eps`` (any dimension), built from
  (E, nu) by :func:`from_young`: plane stress (the paper's 2D tests), plane strain,
  or 3D; in plane strain (eps33 = 0) it also carries sigma33 = lam tr(eps), which
  the 2D stress components leave out but the von Mises norm needs;
* :class:`Scalar` ``modulus * eps`` (the rod);
* :class:`Voigt` any symmetric positive definite matrix in Voigt notation
  (strain (e11, e22, 2 e12) in 2D, (e11, e22, e33, 2 e23, 2 e13, 2 e12) in 3D),
  for anisotropic materials.

Examples
--------
>>> lam, two_mu = plane_stress_moduli(E=1000.0, nu=0.3)
>>> round(lam, 3), round(two_mu, 3)
(329.67, 769.231)
>>> G = from_young(1000.0, 0.3, dim=2)
>>> round(float(G.voigt()[0, 0]), 3)  # E / (1 - nu^2)
1098.901
>>> P = from_young(1000.0, 0.3, dim=2, plane="strain")
>>> stress, vm = stress_and_von_mises([(P, np.array([[1e-3, 0.0, 0.0]]))], dim=2)
>>> round(float(vm[0]), 6)  # sigma11 - sigma33 = 2 mu e11 (sigma22 = sigma33)
0.769231
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError


def plane_stress_moduli(E: float, nu: float) -> tuple[float, float]:
    """(lam, two_mu) of the plane-stress elasticity: E nu / (1 - nu^2), E / (1 + nu)."""
    return E * nu / (1.0 - nu * nu), E / (1.0 + nu)


def lame_moduli(E: float, nu: float) -> tuple[float, float]:
    """(lam, two_mu) of 3D isotropic elasticity (also plane strain): E nu / ((1 + nu)(1 - 2 nu)), E / (1 + nu)."""
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (1.0 + nu)


_VOIGT = {2: [(0, 0), (1, 1), (0, 1)], 3: [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]}
#: Tensor components in storage order (the results' stress_component): Voigt order, tensor (not engineering) shear.
COMPONENTS = {1: [(0, 0)], **_VOIGT}


@dataclass(frozen=True)
class Isotropic:
    """eps -> lam tr(eps) I + two_mu eps.

    ``plane_strain``: a 2D body with eps33 = 0, whose sigma33 = lam tr(eps) is not zero
    (:meth:`out_of_plane`); in plane stress (the default) sigma33 = 0.
    """

    lam: float
    two_mu: float
    plane_strain: bool = False

    def __call__(self, eps):
        import ngsolve as ngs  # here, not at the top: a scene is built and checked without NGSolve

        dim = eps.dims[0]
        return self.lam * ngs.Trace(eps) * ngs.Id(dim) + self.two_mu * eps

    def scaled(self, factor: float) -> "Isotropic":
        return Isotropic(factor * self.lam, factor * self.two_mu, self.plane_strain)

    def multiple_of(self, other) -> float | None:
        """f where this tensor is f times ``other`` (to 1e-12 of its moduli), else None. A Kelvin-Voigt body with
        A = tau G has K_A = tau K_G, so every implicit step operator a0 K_A + K_G is a multiple of K_G.

        >>> G = Isotropic(576.9, 769.2)
        >>> round(G.scaled(0.05).multiple_of(G), 12), Isotropic(1.0, 769.2).multiple_of(G)
        (0.05, None)
        """
        if not isinstance(other, Isotropic) or other.plane_strain != self.plane_strain or other.two_mu <= 0.0:
            return None
        f = self.two_mu / other.two_mu
        return f if abs(self.lam - f * other.lam) <= 1e-12 * max(abs(self.lam), self.two_mu) else None

    def apply(self, strain: np.ndarray) -> np.ndarray:
        """The stress of strains given as components (..., COMPONENTS order), the same layout back."""
        dim = {3: 2, 6: 3}[strain.shape[-1]]
        out = self.two_mu * strain
        out[..., :dim] += self.lam * strain[..., :dim].sum(axis=-1, keepdims=True)
        return out

    def out_of_plane(self, strain: np.ndarray) -> np.ndarray:
        """sigma33 of 2D strains (..., 3): lam tr(eps) in plane strain, 0 in plane stress."""
        return self.lam * strain[..., :2].sum(axis=-1) if self.plane_strain else np.zeros(strain.shape[:-1])

    def voigt(self, dim: int = 2) -> np.ndarray:
        """The matrix of this tensor in Voigt notation (engineering shear strains)."""
        n = len(_VOIGT[dim])
        C = np.zeros((n, n))
        C[:dim, :dim] = self.lam
        C[np.arange(dim), np.arange(dim)] += self.two_mu
        C[np.arange(dim, n), np.arange(dim, n)] = 0.5 * self.two_mu
        return C


@dataclass(frozen=True)
class Scalar:
    """eps -> modulus * eps (the rod's a, b, or a relaxation modulus)."""

    modulus: float

    def __call__(self, eps):
        return self.modulus * eps

    def scaled(self, factor: float) -> "Scalar":
        return Scalar(factor * self.modulus)

    def multiple_of(self, other) -> float | None:
        """f where this modulus is f times ``other``'s (:meth:`Isotropic.multiple_of`)."""
        return self.modulus / other.modulus if isinstance(other, Scalar) and other.modulus > 0.0 else None

    def apply(self, strain: np.ndarray) -> np.ndarray:
        return self.modulus * strain

    def out_of_plane(self, strain: np.ndarray) -> np.ndarray:
        return np.zeros(strain.shape[:-1])

    def voigt(self, dim: int = 1) -> np.ndarray:
        return np.array([[self.modulus]])


class Voigt:
    """A user-supplied linear tensor: stress_v = C strain_v in Voigt notation (see the module docs)."""

    def __init__(self, matrix, dim: int, name: str = "tensor"):
        C = np.asarray(matrix, dtype=float)
        n = len(_VOIGT.get(dim, ()))
        if dim not in _VOIGT or C.shape != (n, n):
            raise ParameterError(f"{name}: a {dim}D body needs a {n} x {n} matrix in Voigt notation, got shape "
                                 f"{C.shape}")
        if not np.all(np.isfinite(C)) or not np.allclose(C, C.T, rtol=1e-12, atol=0.0):
            raise ParameterError(f"{name}: the matrix must be finite and symmetric")
        if np.linalg.eigvalsh(C).min() <= 0:
            raise ParameterError(f"{name}: the matrix must be positive definite (a strongly monotone tensor)")
        self.C, self.dim, self.name = C, dim, name

    def __call__(self, eps):
        import ngsolve as ngs

        dim = self.dim
        strain = ngs.CF(tuple((1.0 if i == j else 2.0) * eps[i, j] for i, j in _VOIGT[dim]))
        stress = ngs.CF(tuple(self.C.ravel()), dims=self.C.shape) * strain
        comp = {pair: k for k, pair in enumerate(_VOIGT[dim])}
        return ngs.CF(tuple(stress[comp[min(i, j), max(i, j)]] for i in range(dim) for j in range(dim)),
                      dims=(dim, dim))

    def scaled(self, factor: float) -> "Voigt":
        return Voigt(factor * self.C, self.dim, self.name)

    def multiple_of(self, other) -> float | None:
        """None: a user's matrix is not taken as a multiple of another (:meth:`Isotropic.multiple_of`)."""
        return None

    def apply(self, strain: np.ndarray) -> np.ndarray:
        engineering = strain.copy()
        engineering[..., self.dim:] *= 2.0
        return engineering @ self.C.T

    def out_of_plane(self, strain: np.ndarray) -> np.ndarray:
        """0: a 2D Voigt matrix does not say sigma33 (taken as in plane stress)."""
        return np.zeros(strain.shape[:-1])

    def voigt(self, dim: int = 2) -> np.ndarray:
        return self.C.copy()


def from_young(E: float, nu: float, dim: int, plane: str = "stress"):
    """The isotropic tensor of Young's modulus E and Poisson's ratio nu: the rod's E, plane stress or strain, 3D."""
    if dim == 1:
        return Scalar(E)
    if dim == 2 and plane == "stress":
        return Isotropic(*plane_stress_moduli(E, nu))
    return Isotropic(*lame_moduli(E, nu), plane_strain=dim == 2)


def strain(u, dim: int):
    """eps(u) = sym grad u (the derivative in 1D)."""
    import ngsolve as ngs

    if dim == 1:
        return ngs.grad(u)[0]
    return ngs.Sym(ngs.Grad(u))


def energy_product(tensor, u, w, dim: int):
    """The integrand tensor(eps(u)) : eps(w) of a stiffness or viscosity form."""
    import ngsolve as ngs

    eu, ew = strain(u, dim), strain(w, dim)
    if dim == 1:
        return tensor(eu) * ew
    if isinstance(tensor, Isotropic):
        # the same form, which NGSolve assembles faster with div u and no stress tensor evaluated (the hemisphere's
        # K at 47k dofs, P1: 1.68 s against 2.06 s, medians of 3; the trace of eps in div's place: 2.08 s)
        return tensor.lam * ngs.div(u) * ngs.div(w) + tensor.two_mu * ngs.InnerProduct(eu, ew)
    return ngs.InnerProduct(tensor(eu), ew)


def stress_and_von_mises(parts, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The stress of a sum of tensors and its von Mises norm, per cell.

    Parameters
    ----------
    parts : iterable of (tensor, strain)
        Each tensor with the strains it acts on, (cell, COMPONENTS order): for a
        Kelvin–Voigt body the viscous tensor with eps(u') and the elastic one with eps(u).
    dim : int

    Returns
    -------
    stress : ndarray (cell, COMPONENTS order)
    von_mises : ndarray (cell,)
        With each part's sigma33 in 2D (non-zero in plane strain).
    """
    stress = s33 = None
    for tensor, eps in parts:
        part = tensor.apply(eps)
        stress = part if stress is None else stress + part
        if dim == 2:
            out = tensor.out_of_plane(eps)
            s33 = out if s33 is None else s33 + out
    return stress, von_mises_cells(stress, dim, s33)


def von_mises_cells(stress: np.ndarray, dim: int, s33=None) -> np.ndarray:
    """The same norm of stresses given as components (cell, COMPONENTS order), with NumPy.

    In 2D ``s33`` is sigma33 (None: 0, plane stress).
    """
    s = stress
    if dim == 1:
        return np.abs(s[:, 0])
    if dim == 2:
        s11, s22, s12 = s[:, 0], s[:, 1], s[:, 2]
        s33 = 0.0 if s33 is None else s33
        return np.sqrt(0.5 * ((s11 - s22) ** 2 + (s22 - s33) ** 2 + (s33 - s11) ** 2) + 3 * s12 * s12)
    mean = s[:, :3].sum(axis=1) / 3
    dev = s[:, :3] - mean[:, None]
    return np.sqrt(1.5 * ((dev ** 2).sum(axis=1) + 2 * (s[:, 3:] ** 2).sum(axis=1)))


def von_mises(sigma, dim: int, s33=0.0):
    """|sigma|_vM: in 2D (((s11 - s22)^2 + (s22 - s33)^2 + (s33 - s11)^2) / 2 + 3 s12^2)^(1/2), s33 = 0 in plane
    stress; 3D the usual J2 form; 1D |sigma|."""
    import ngsolve as ngs

    if dim == 1:
        return ngs.IfPos(sigma, sigma, -sigma)
    if dim == 2:
        s11, s22, s12 = sigma[0, 0], sigma[1, 1], sigma[0, 1]
        return ngs.sqrt(0.5 * ((s11 - s22) ** 2 + (s22 - s33) ** 2 + (s33 - s11) ** 2) + 3 * s12 * s12)
    dev = sigma - (ngs.Trace(sigma) / 3) * ngs.Id(3)
    return ngs.sqrt(1.5 * ngs.InnerProduct(dev, dev))
