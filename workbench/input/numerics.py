"""How a problem is discretised and solved, apart from what is modelled: the numerical options as one object.

A scene's values hold physics and numerics side by side (one table of parameters, :mod:`workbench.input.parameters`);
this module is the one place that says which of them are numerics, and the one registry of the time schemes.
:class:`Numerics` is built beside the model from a scene (:func:`from_scene`), frozen, and is what the schemes,
the solvers, the runner, restarts and studies consult: the scheme and its step control, the element order, the
linear solver, the memory rule, whether an unstable explicit step is allowed, the threads.

Examples
--------
>>> import workbench
>>> n = from_scene(workbench.scene("tp2", scheme="bdf2", rtol=1e-4))
>>> n.scheme, n.adaptive, n.largest_step
('bdf2', True, 1.0)
>>> sorted(set(DISCRETISATION) & {"h", "k", "gamma_nu"})
['h', 'k']
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple


class Registered(NamedTuple):
    """A time scheme's entry in :data:`SCHEMES`: the model it steps, its module in :mod:`workbench.schemes` and its
    class, and what it can do (what the scene checks before any work)."""

    model: str
    module: str
    cls: str
    #: Whether it takes error-controlled steps (``rtol > 0``): it estimates its local error.
    error_control: bool = True
    #: Whether its systems may be solved iteratively (``solver = 'cg'``): one constant matrix, no condensation (the
    #: schemes with ``coupled`` may too, with their contact solved on the whole body: :func:`may_iterate`).
    iterative: bool = False
    #: Whether it runs on a body distributed over several MPI processes.
    distributed: bool = False
    #: Whether its contact problem can be solved on the whole body (``contact_solver = 'coupled'``).
    coupled: bool = False


#: The time schemes by name. Registering a scheme is one line here; the scene's choices of ``scheme``, each model's
#: schemes and the checks of what a scheme can do come from it.
SCHEMES = {
    "explicit": Registered("A", "explicit_euler", "ExplicitEuler", error_control=False, iterative=True,
                           distributed=True),
    "implicit": Registered("A", "implicit_euler", "ImplicitEuler", coupled=True, distributed=True),
    "bdf2": Registered("A", "bdf2", "BDF2", coupled=True, distributed=True),
    "vi": Registered("B", "memory_vi", "MemoryVI", coupled=True, distributed=True),
}

#: The element size and order (a geometry adds its cell counts, ``nx`` ..., and a Hertz body ``h_contact``).
SPACE = ("h", "order")
#: The time scheme, its step and the solvers of its systems (the linear one and the contact problem's).
TIME = ("k", "scheme", "solver", "contact_solver")
#: Error-controlled steps (``rtol > 0``): the tolerances and the bounds of the step.
CONTROL = ("rtol", "atol", "k_min", "k_max")
#: Adaptive refinement in space (``space_tol > 0``): the tolerance of the estimate and the bound of the mesh.
ADAPT = ("space_tol", "max_dofs", "space_adapt", "space_goal", "edge_tol")
#: The explicit scheme's stability override.
EXPLICIT = ("allow_unstable",)
#: Model B: the tolerance of the coupled contact solve.
VI = ("contact_tol",)
#: Model B: the rule of the memory integral and the approximation of a general kernel.
MEMORY = ("memory_rule", "kernel_approximation", "kernel_tol")
#: The mesh options a geometry may add to SPACE.
MESH = ("nx", "ny", "nz", "h_contact")

#: Every numerical option: two runs that differ only in these model the same problem (a study compares them with
#: one reference; any other difference is physics).
DISCRETISATION = frozenset(SPACE + TIME + CONTROL + ADAPT + EXPLICIT + VI + MEMORY + MESH)
#: The options along which a study fits an observed order (the finest value is the smallest).
REFINEMENT = ("h", "k", "rtol", "h_contact", "space_tol", "edge_tol")
#: The axes every study has (length 1 when not swept), and the command line's named options besides T.
AXES = ("h", "k", "order", "scheme")


#: ``contact_solver = 'auto'`` solves on the whole body when the contact unknowns outnumber COUPLED_PER_STEP times
#: the steps (T / k), or COUPLED_FROM (the condensed solver's dense matrices: 8 m^2 bytes each). The condensed solver
#: pays one back-substitution per unknown and operator, the coupled one about 20 per step (measured,
#: ``studies/contact_solver.py``: the block at 440 points and 52 steps, condensed 28 s, coupled 49 s; the hemisphere
#: at 1291 points and 4 steps, 18 s and 3.9 s).
COUPLED_PER_STEP, COUPLED_FROM = 20, 5000
#: Where the factor forms the condensed stiffness inside one factorization (MKL PARDISO's Schur complement), the
#: condensed solver's setup costs about one factorization, and what limits it is its dense work on the points whose
#: position is unknown, ~m^3/3 per active-set iteration: ``auto`` condenses up to COUPLED_FROM_SCHUR unknowns
#: (measured, ``studies/contact_solver.py --pardiso``: the hemisphere at 1291 points, condensed 1.7 s, coupled 2.3 s;
#: at 5186 points 39.6 s and 9.8 s; the block at 440 points and 52 steps, 5.8 s and 21.5 s). Model B's 3D contact
#: vertices, whose coupled solve the half-space preconditions, pass sooner
#: (:func:`workbench.schemes.coupled_contact.condensed_up_to`).
COUPLED_FROM_SCHUR = 2500


#: The linear solvers that iterate on each solve (conjugate gradients: AMG-preconditioned, or on a single-precision
#: factor), with no factor in double precision to form a condensed contact stiffness or repeat per-point solves with.
ITERATIVE_SOLVERS = ("cg", "mixed")


def may_iterate(scheme: str, contact_solver: str) -> bool:
    """Whether the systems of ``scheme`` may be solved without a factor (``solver = 'cg'``): the explicit scheme's,
    and the implicit ones' with their contact solved on the whole body (not ``contact_solver = 'condensed'``, whose
    dense contact stiffness takes one solve per contact point).

    >>> may_iterate("explicit", "auto"), may_iterate("bdf2", "auto"), may_iterate("bdf2", "condensed")
    (True, True, False)
    """
    entry = SCHEMES[scheme]
    return entry.iterative or (entry.coupled and contact_solver != "condensed")


def schemes_of(model: str) -> tuple:
    """The scheme names a model (``"A"`` or ``"B"``) can run."""
    return tuple(name for name, entry in SCHEMES.items() if entry.model == model)


def is_adaptive(rtol):
    """Whether steps are error-controlled at the tolerance ``rtol`` (also for an array of tolerances): rtol > 0."""
    import numpy as np

    out = np.asarray(rtol, dtype=float) > 0
    return bool(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class Numerics:
    """The numerical options of one run (module docs).

    ``k`` is the fixed step, or with error control (``rtol > 0``) the first step; ``k_max = 0`` means T.
    ``threads``: NGSolve's TaskManager threads for the setup and the time loop (None: none).
    """

    scheme: str
    k: float
    T: float
    order: int = 1
    solver: str = "auto"
    contact_solver: str = "auto"
    contact_tol: float = 1e-11
    rtol: float = 0.0
    atol: float = 1e-9
    k_min: float = 1e-9
    k_max: float = 0.0
    allow_unstable: bool = False
    memory_rule: str = "rectangle"
    space_tol: float = 0.0
    max_dofs: int = 200000
    space_adapt: str = "repeat"
    space_goal: str = "energy"
    edge_tol: float = 0.0
    threads: int | None = None

    @property
    def adaptive(self) -> bool:
        """Whether the steps are error-controlled."""
        return is_adaptive(self.rtol)

    def coupled_contact(self, unknowns: int, solver: str | None = None, schur: bool = False,
                        condensed_up_to: int = COUPLED_FROM_SCHUR) -> bool:
        """Whether a contact problem of ``unknowns`` contact unknowns is solved on the whole body (``contact_solver``;
        ``auto``: :data:`COUPLED_PER_STEP`, or from ``condensed_up_to`` (:data:`COUPLED_FROM_SCHUR`, or the scheme's
        own figure where its coupled solve is cheaper) where the factor forms the condensed stiffness inside one
        factorization, ``schur``); ``solver``: the linear solver taken, when ``auto`` resolved it.

        >>> Numerics("vi", k=0.25, T=1.0).coupled_contact(203), Numerics("vi", k=0.02, T=1.0).coupled_contact(440)
        (True, False)
        >>> Numerics("vi", k=0.25, T=1.0).coupled_contact(1291, schur=True)
        False
        """
        if self.contact_solver != "auto":
            return self.contact_solver == "coupled"
        if (solver or self.solver) in ITERATIVE_SOLVERS:
            return True  # (an iterative solver has no factor to repeat the condensed solver's per-point solves with)
        if schur:
            return unknowns > condensed_up_to
        return unknowns >= min(COUPLED_PER_STEP * max(1.0, self.T / self.k), COUPLED_FROM)

    @property
    def largest_step(self) -> float:
        """The largest step error control may take (``k_max``, or T when it is 0)."""
        return self.k_max or self.T


def from_values(values: dict, threads: int | None = None) -> Numerics:
    """The numerics of checked scene values (the options a scene does not have keep their defaults)."""
    names = {f.name for f in fields(Numerics)} - {"threads"}
    return Numerics(**{name: values[name] for name in names if name in values}, threads=threads)


def from_scene(scene, threads: int | None = None) -> Numerics:
    """The numerics of a checked scene (:class:`workbench.input.scenes.Scene`)."""
    return from_values(scene.values, threads)
