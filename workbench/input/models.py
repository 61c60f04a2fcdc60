"""From a scene to its model: typed physics objects, built once.

A scene is checked values (:mod:`workbench.input.scenes`); a model is what those values
mean: the body (:mod:`workbench.input.geometry`), the material tensors, the contact
terms and the bonding law (Model A), or the relaxation kernel and the compliant
layer (Model B), and the loads. Discretisation, schemes, the stability estimate
and the condensed Newton take these objects, never the scene's physics values
(the contact laws read their own values, :mod:`workbench.physics.laws`).

Both models answer one interface, :class:`Model`: each has every part, and a part a
model does not have is None (or an empty :class:`~workbench.physics.contact.Contact`),
so that the code downstream assembles and steps what is declared and never asks
which model it has.

Examples
--------
>>> import workbench
>>> m = from_scene(workbench.scene("tp5", c_tau=2.0))
>>> m.kind, m.terms, type(m.elastic).__name__, m.bonding.truncation
('A', ('compliance', 'adhesion', 'glue'), 'Isotropic', 'tension')
>>> from_scene(workbench.scene("memory_slab")).memory.kind
'prony'
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Protocol

from ..physics import kelvin_voigt
from ..physics.contact import Contact
from ..physics.laws import LAWS
from ..physics.laws.adhesion import bonding_law
from ..physics.memory import GeneralKernel, Prony
from ..physics.unilateral import Layer
from .numerics import schemes_of


@dataclass(frozen=True)
class Loads:
    """Volume force, tractions by boundary, a nodal point force, the rod's prescribed end and initial state."""

    tractions: dict = field(default_factory=dict)  # boundary name -> vector Expression
    body_force: object = None
    point_force: object = None
    point_force_at: tuple = ()
    delta: object = None  # rod: u(0, t)
    u0: object = None  # rod, Model A: the initial displacement

    def in_time(self) -> list:
        """The loads that change with t (what drives the body; error control lands on their kinks and resolves
        them: :class:`~workbench.schemes.stepping.AdaptiveSteps`)."""
        loads = [*self.tractions.values(), self.body_force, self.point_force, self.delta]
        return [e for e in loads if e is not None and e.depends_on("t")]


class Model(Protocol):
    """What every model declares (module docs).

    Attributes
    ----------
    kind : str
        Its letter as scenes and archives name it ("A", "B").
    schemes : tuple of str
        The time schemes that step it (:data:`workbench.input.numerics.SCHEMES`).
    geometry, loads
        The body and its loads.
    elastic : tensor
        The instantaneous elastic tensor (Model A: G; Model B: A).
    viscous : tensor or None
        A Kelvin-Voigt body's viscous tensor (strain rate to stress).
    contact : Contact
        The contact laws on the contact side (empty: none).
    bonding : BondingLaw or None
        The bonding field's law, with beta0 its initial value.
    memory : Prony, GeneralKernel or None
        A relaxation kernel (long memory).
    layer : Layer or None
        A unilateral constraint with a compliant layer at the contact vertices.
    terms : tuple of str
        The names of the terms it has (a run records them).
    """

    kind: ClassVar[str]
    schemes: ClassVar[tuple]

    def max_order(self, dim: int) -> int:
        """The highest element order it runs in ``dim`` dimensions."""


@dataclass(frozen=True)
class ModelA:
    """Kelvin–Voigt body with normal compliance and adhesion (Chau, Fernández, Shillor, Sofonea 2003)."""

    geometry: object
    viscous: object  # A (strain rate -> stress)
    elastic: object  # G (strain -> stress)
    contact: Contact
    bonding: object  # BondingLaw or None
    beta0: float
    loads: Loads
    memory: ClassVar = None
    layer: ClassVar = None
    kind: ClassVar[str] = "A"
    schemes: ClassVar[tuple] = schemes_of("A")

    @property
    def terms(self) -> tuple:
        return self.contact.names

    @staticmethod
    def max_order(dim: int) -> int:
        return 4

    def stress(self, u, v, eps):
        """sigma = A eps(v) + G eps(u) as a coefficient function (``eps`` maps a field to its strain)."""
        return self.viscous(eps(v)) + self.elastic(eps(u))


@dataclass(frozen=True)
class ModelB:
    """Long-memory viscoelastic body with a unilateral, multivalued normal compliance (2013)."""

    geometry: object
    elastic: object  # A (instantaneous tensor)
    memory: object  # Prony, GeneralKernel or None
    layer: Layer
    loads: Loads
    viscous: ClassVar = None
    contact: ClassVar[Contact] = Contact(())
    bonding: ClassVar = None
    beta0: ClassVar[float] = 1.0
    kind: ClassVar[str] = "B"
    schemes: ClassVar[tuple] = schemes_of("B")

    @property
    def terms(self) -> tuple:
        return ("unilateral",) + (("memory",) if self.memory is not None else ())

    @staticmethod
    def max_order(dim: int) -> int:
        """The constraint and the layer's law act at the contact nodes: P1, or P2 in 2D (vertices and facet
        midpoints)."""
        return 2 if dim == 2 else 1


#: The models by their letter.
MODELS = {"A": ModelA, "B": ModelB}


def _tensor(v, dim, E="E", nu="nu", voigt="elastic_tensor"):
    if v.get(voigt):
        return kelvin_voigt.Voigt(v[voigt], dim, voigt)
    return kelvin_voigt.from_young(v[E], v[nu], dim, v.get("plane", "stress"))


def _viscous(v, dim):
    if dim == 1:
        return kelvin_voigt.Scalar(v["b"])
    if v.get("viscous_tensor"):
        return kelvin_voigt.Voigt(v["viscous_tensor"], dim, "viscous_tensor")
    return kelvin_voigt.Isotropic(v["a1"], v["a2"], plane_strain=dim == 2 and v.get("plane", "stress") == "strain")


def _loads(values, geometry) -> Loads:
    return Loads(tractions=geometry.tractions(values),
                 body_force=values.get("body_force"), point_force=values.get("point_force"),
                 point_force_at=tuple(values.get("point_force_at", ())), delta=values.get("delta"),
                 u0=values.get("u0"))


def _memory(values, dim, T):
    prony = values["prony"]
    if prony:
        terms = []
        for term in prony:
            E, tau = term[0], term[-1]
            nu = term[1] if len(term) == 3 else 0.0
            terms.append((kelvin_voigt.from_young(E, nu, dim, values.get("plane", "stress")), tau))
        return Prony(terms)
    if not values["kernel"].is_zero() and values["kernel_E"] != 0:
        tensor = kelvin_voigt.from_young(values["kernel_E"], values.get("kernel_nu", 0.0), dim,
                                         values.get("plane", "stress"))
        kernel = GeneralKernel(values["kernel"], tensor)
        if values.get("kernel_approximation") == "exponentials":
            return kernel.exponential_sum(T, values["kernel_tol"])
        return kernel
    return None


def from_scene(scene):
    """The model of a checked scene (Model A or B, as its preset declares)."""
    from .geometry import GEOMETRIES

    v = scene.values
    geometry = GEOMETRIES[scene.geometry].from_values(v)
    return _BUILDERS[scene.model](v, geometry)


def _model_a(v, geometry) -> ModelA:
    dim = geometry.dim
    elastic = kelvin_voigt.Scalar(v["a"]) if dim == 1 else _tensor(v, dim)
    terms = [t for law in LAWS if (t := law.from_values(v)) is not None]
    return ModelA(geometry, _viscous(v, dim), elastic, Contact(terms), bonding_law(v), v["beta0"],
                  _loads(v, geometry))


def _model_b(v, geometry) -> ModelB:
    dim = geometry.dim
    elastic = kelvin_voigt.Scalar(v["a"]) if dim == 1 else _tensor(v, dim)
    return ModelB(geometry, elastic, _memory(v, dim, v["T"]), Layer(v["F"], v["c"], v["gap"]), _loads(v, geometry))


_BUILDERS = {"A": _model_a, "B": _model_b}
