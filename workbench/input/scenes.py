"""Scenes: one modelled situation (geometry, material, loads, contact physics) as checked data.

A scene is a geometry (``rod`` 1D, ``slab`` 2D, ``block`` 3D: :mod:`workbench.input.geometry`),
a model (A or B: :mod:`workbench.input.models`), and a dict of parameter values drawn from
:data:`~workbench.input.parameters.PARAMETERS`. Built-in scenes are the bare geometries, the
paper's test problems ``tp1`` … ``tp5`` and the Model B scenes; a TOML file can start
from any of them. Every value is checked when the scene is made, so nothing runs on
bad input.

Examples
--------
>>> s = scene("tp1", k=0.005)
>>> s["k"], s.geometry, s.terms
(0.005, 'rod', ('compliance', 'adhesion'))
>>> scene("tp1", gama_nu=1)
Traceback (most recent call last):
...
workbench.errors.ParameterError: unknown parameter 'gama_nu' for scene 'tp1'; did you mean 'gamma_nu'?
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..values import Param, closest_name, to_plain
from .geometry import GEOMETRIES
from .models import MODELS
from .numerics import (
    ADAPT,
    CONTROL,
    EXPLICIT,
    ITERATIVE_SOLVERS,
    MEMORY,
    SCHEMES,
    SPACE,
    TIME,
    VI,
    is_adaptive,
    schemes_of,
)
from .parameters import LAW_PARAMETERS, PARAMETERS

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

_CONTACT = ("contact", "adhesion", "c_nu", "m_nu", "gap", "gamma_nu", "eps_a", "L", "beta0",
            "bonding_truncation") + LAW_PARAMETERS
_TIME = ("T",) + SPACE + TIME + CONTROL + ADAPT + EXPLICIT
_TIME_B = ("T",) + SPACE + TIME + CONTROL + ADAPT + VI  # Model B's numerics (and its memory's, _MEMORY)
_OUTPUT = ("probes", "snapshots", "checkpoint_every")
_KV = ("E", "nu", "a1", "a2", "elastic_tensor", "viscous_tensor")
_UNILATERAL = ("gap", "F", "c")
_MEMORY = ("kernel", "kernel_E", "kernel_nu", "prony") + MEMORY
_LOADS = ("body_force", "point_force", "point_force_at")
_MESH = ("mesh", "boundaries", "mesh_digest")
_HERTZ = ("radius", "h_contact", "contact_zone")
_HERTZ_LOADS = ("body_force", "load")


def _geometry_parameters(kind: str) -> tuple:
    g = GEOMETRIES[kind]
    return g.extent_names + g.cell_names


def _loads(kind: str) -> tuple:
    return _LOADS + tuple(f"traction_{side}" for side in GEOMETRIES[kind].boundaries["traction"])


#: Parameters each (geometry, model) uses; a scene knows exactly these (plus preset extras).
MODEL_PARAMETERS = {
    ("rod", "A"): ("length",) + _TIME + ("a", "b") + _CONTACT + ("delta", "u0") + _OUTPUT,
    ("slab", "A"): _geometry_parameters("slab") + _TIME + ("plane",) + _KV + _CONTACT + ("c_tau",) + _loads("slab")
                   + _OUTPUT,
    ("block", "A"): _geometry_parameters("block") + _TIME + _KV + _CONTACT + ("c_tau",) + _loads("block") + _OUTPUT,
    ("rod", "B"): ("length",) + _TIME_B + ("a",) + _UNILATERAL + ("kernel", "kernel_E", "prony") + MEMORY
                  + ("delta",)
                  + _OUTPUT,
    ("slab", "B"): _geometry_parameters("slab") + _TIME_B + ("plane", "E", "nu", "elastic_tensor") + _UNILATERAL
                   + _MEMORY + _loads("slab") + _OUTPUT,
    ("block", "B"): _geometry_parameters("block") + _TIME_B + ("E", "nu", "elastic_tensor") + _UNILATERAL + _MEMORY
                    + _loads("block") + _OUTPUT,
    ("mesh2d", "A"): _MESH + _TIME + ("plane",) + _KV + _CONTACT + ("c_tau",) + _LOADS + ("traction",) + _OUTPUT,
    ("mesh3d", "A"): _MESH + _TIME + _KV + _CONTACT + ("c_tau",) + _LOADS + ("traction",) + _OUTPUT,
    ("mesh2d", "B"): _MESH + _TIME_B + ("plane", "E", "nu", "elastic_tensor") + _UNILATERAL + _MEMORY + _LOADS
                     + ("traction",) + _OUTPUT,
    ("mesh3d", "B"): _MESH + _TIME_B + ("E", "nu", "elastic_tensor") + _UNILATERAL + _MEMORY + _LOADS + ("traction",)
                     + _OUTPUT,
    ("halfdisc", "A"): _HERTZ + _TIME + ("plane",) + _KV + _CONTACT + ("c_tau",) + _HERTZ_LOADS + _OUTPUT,
    ("hemisphere", "A"): _HERTZ + _TIME + _KV + _CONTACT + ("c_tau",) + _HERTZ_LOADS + _OUTPUT,
    ("halfdisc", "B"): _HERTZ + _TIME_B + ("plane", "E", "nu", "elastic_tensor") + _UNILATERAL + _MEMORY + _HERTZ_LOADS
                       + _OUTPUT,
    ("hemisphere", "B"): _HERTZ + _TIME_B + ("E", "nu", "elastic_tensor") + _UNILATERAL + _MEMORY + _HERTZ_LOADS
                         + _OUTPUT,
}

#: The scenes whose body is a mesh file, by (dimension, model).
MESH_SCENES = {(2, "A"): "mesh2d", (3, "A"): "mesh3d", (2, "B"): "memory_mesh2d", (3, "B"): "memory_mesh3d"}

#: Parameters a model refuses with a reason (rather than as merely unknown).
_NOT_APPLICABLE = {"B": {"u0": "without viscosity the problem is quasistatic in u, so u(0) is the solution of the "
                               "inequality at t = 0 (computed), not an initial condition"},
                   "A": {"contact_tol": "it sets Model B's coupled contact solve; Model A's implicit steps solve their "
                                        "contact by Newton's method to a tolerance of their own"}}


@dataclass(frozen=True)
class Preset:
    """A built-in scene: a geometry plus overrides of the parameter defaults."""

    geometry: str
    description: str
    values: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)  # preset-only parameters: name -> Param
    derive: object = None  # callable(values) -> dict of derived values (when not set by the user)
    model: str = "A"


def _tp3_delta(v):
    return {"delta": f"{v['delta_amp']!r}*sin({v['omega']!r}*t)"}


_ROD_PAPER = dict(h=0.01, k=0.01, T=1.0, a=1.0, b=1.0, eps_a=0.0, beta0=1.0,
                  snapshots=(0.2, 0.4, 0.6, 0.8, 1.0))
_SLAB_PAPER = dict(E=1000.0, nu=0.3, a1=30.0, a2=20.0, c_nu=1.0, gamma_nu=0.3, L=0.3, eps_a=0.0,
                   beta0=1.0, c_tau=0.0, T=1.0, snapshots=(0.1, 0.4, 0.6, 0.7, 0.8, 1.0))

_MEMORY_ROD = dict(h=0.05, k=0.01, T=1.0, a=1.0, gap=0.1, F=0.05, c=1.0, scheme="vi",
                   prony=((0.5, 0.2),), delta="0.3*sin(2*pi*t) - 0.05", snapshots=(0.25, 0.5, 0.75, 1.0))
_MEMORY_2D = dict(width=2.0, height=1.0, h=0.05, k=0.02, T=1.0, E=1000.0, nu=0.3, scheme="vi",
                  gap=0.02, F=20.0, c=2000.0, prony=((-1000.0, 0.3, 0.5),),
                  traction_top="(0, -60*t*ifpos(x - 1, 1, -0.25))", snapshots=(0.25, 0.5, 0.75, 1.0))

def _kelvin_voigt_of_tau(v):
    """A = tau G: the viscosity a1 = tau lambda, a2 = 2 tau mu of E, nu (plane strain and 3D: the 3D Lame constants;
    plane stress: lambda* = 2 lambda mu / (lambda + 2 mu)); where G is given as ``elastic_tensor``, the viscous
    tensor tau G itself (a1, a2 of the default E, nu made A half of tau G's for E = 2000; an outside pass, December
    2026)."""
    E, nu, tau = v["E"], v["nu"], v["tau"]
    if v.get("elastic_tensor"):
        return {"viscous_tensor": tuple(tuple(tau * float(c) for c in row) for row in v["elastic_tensor"])}
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    if v.get("plane") == "stress":
        lam = 2 * lam * mu / (lam + 2 * mu)
    return {"a1": tau * lam, "a2": 2 * tau * mu}


_TAU = {"tau": Param("tau", 0.05, "s", "Kelvin-Voigt relaxation time: the viscous tensor is tau times the elastic one "
                     "(sets a1, a2 unless they are given, or viscous_tensor where elastic_tensor is given)",
                     lower=0.0, lower_open=True)}
_MESH_A = dict(k=0.01, T=1.0, scheme="implicit", adhesion=False, c_nu=1e4, snapshots=(0.5, 1.0))
_MESH_B = dict(k=0.25, T=1.0, scheme="vi", gap=0.0, F=0.0, c=0.0, snapshots=(0.5, 1.0))
_HERTZ_A = dict(radius=1.0, h=0.1, E=1000.0, nu=0.3, plane="strain", contact=True, adhesion=False, c_nu=1e5,
                gap=0.0, load="10*t", T=1.0, k=0.02, scheme="implicit", snapshots=(0.25, 0.5, 0.75, 1.0))
_HERTZ_B = dict(radius=1.0, h=0.1, E=1000.0, nu=0.3, plane="strain", gap=0.0, F=0.0, c=0.0, load="10*t", T=1.0,
                k=0.25, scheme="vi", snapshots=(0.25, 0.5, 0.75, 1.0))

PRESETS: dict[str, Preset] = {
    "rod": Preset("rod", "1D Kelvin-Voigt rod (0, length), end x = 0 moved by delta(t), adhesive contact at x = length",
                  dict(h=0.01, k=0.01, delta="-0.5*t")),
    "slab": Preset("slab", "2D plane-stress slab (0, width) x (0, height), clamped at x = 0, adhesive contact on y = 0",
                   dict(h=0.0125, k=0.001, traction_top="(0, t)")),
    "block": Preset("block", "3D block (0, width) x (0, depth) x (0, height), clamped at x = 0, adhesive contact on z = 0",
                    dict(h=0.05, order=2, k=0.001, traction_top="(0, 0, t)")),  # P1 locks: tip 50 % low at h = 0.05
    "tp1": Preset("rod", "Paper test problem 1: rod end held at -0.6, case (b) A + delta < -L; exact solution "
                  "(docs/models.md)", dict(_ROD_PAPER, gamma_nu=0.3, L=0.3, delta="-0.6", u0="-0.6")),
    "tp2": Preset("rod", "Paper test problem 2: rod end held at -0.1, case (a) -L <= A + delta < 0; reduced ODE reference",
                  dict(_ROD_PAPER, gamma_nu=0.1, L=1.0, delta="-0.1", u0="-0.1")),
    "tp3": Preset("rod", "Paper test problem 3: periodic end displacement delta_amp sin(omega t); debonding only in tension",
                  dict(_ROD_PAPER, T=5.0, gamma_nu=0.3, L=0.3, u0="0", c_nu=1.0, bonding_truncation="tension",
                       snapshots=(1.0, 2.0, 3.0, 4.0, 5.0)),
                  extras={"delta_amp": Param("delta_amp", 0.05, "m", "amplitude of delta(t) (not in the paper)"),
                          "omega": Param("omega", 10.0, "1/s", "angular frequency of delta(t) (OCR: sin 10t)",
                                         lower=0.0, lower_open=True)},
                  derive=_tp3_delta),
    "tp4": Preset("slab", "Paper test problem 4: slab pulled up by a point force (0, 1) at the top-right corner",
                  dict(_SLAB_PAPER, h=0.0125, k=0.01, point_force="(0, 1)", point_force_at=((1.0, 0.1),))),
    "tp5": Preset("slab", "Paper test problem 5: slab under a periodic traction on the top side (inferred from OCR)",
                  dict(_SLAB_PAPER, h=0.0125, k=0.01, traction_top="(-10*sin(50*t), -sin(50*t))",
                       bonding_truncation="tension")),
    "memory_rod": Preset("rod", "Model B: rod with long memory (Prony term), end x = 0 moved by delta(t), unilateral "
                         "contact with a compliant layer of thickness gap at x = length", _MEMORY_ROD, model="B"),
    "memory_slab": Preset("slab", "Model B: 2D body (0,2) x (0,1) with long memory, clamped at x = 0, pressed down on "
                          "its right half and lifted on its left half; layer of thickness gap on y = 0",
                          _MEMORY_2D, model="B"),
    "memory_block": Preset("block", "Model B: 3D block (0,2) x (0,0.5) x (0,1) with long memory, loaded as "
                           "memory_slab; layer of thickness gap on z = 0",
                           dict(_MEMORY_2D, depth=0.5, h=0.1, traction_top="(0, 0, -60*t*ifpos(x - 1, 1, -0.25))"),
                           model="B"),
    "mesh2d": Preset("mesh2d", "Model A: a 2D body from a mesh file (mesh, boundaries: clamped / traction / contact / "
                     "free), foundation y = 0", _MESH_A),
    "mesh3d": Preset("mesh3d", "Model A: a 3D body from a mesh file, foundation z = 0", _MESH_A),
    "memory_mesh2d": Preset("mesh2d", "Model B: a 2D body from a mesh file, unilateral contact "
                            "with a layer of thickness gap on y = 0", _MESH_B, model="B"),
    "memory_mesh3d": Preset("mesh3d", "Model B: a 3D body from a mesh file, unilateral contact on z = 0", _MESH_B,
                            model="B"),
    "hertz": Preset("halfdisc", "Hertz: 2D half-disc of radius R, plane strain, pressed on y = 0 by the total force "
                    "load (per unit thickness) on its flat top; Kelvin-Voigt with A = tau G, normal compliance c_nu "
                    "(modelled as its half x >= 0)", _HERTZ_A, extras=_TAU, derive=_kelvin_voigt_of_tau),
    "hertz3d": Preset("hemisphere", "Hertz: 3D hemisphere of radius R pressed on z = 0 by the total force load on its "
                      "flat top; Kelvin-Voigt with A = tau G, normal compliance (modelled as its quarter x, y >= 0)",
                      dict(_HERTZ_A, h=0.25), extras=_TAU, derive=_kelvin_voigt_of_tau),
    "memory_hertz": Preset("halfdisc", "Model B Hertz: the half-disc of hertz, unilateral contact with a layer of "
                           "thickness gap (gap = F = c = 0: Signorini), elastic unless a memory is given; contact "
                           "zone meshed at h_contact = 0.0025 (the pressure within 1 % of Hertz's)",
                           dict(_HERTZ_B, h_contact=0.0025), model="B"),
    "memory_hertz3d": Preset("hemisphere", "Model B Hertz: the hemisphere of hertz3d, unilateral contact (Signorini by "
                             "default)", dict(_HERTZ_B, h=0.25), model="B"),
}


@dataclass(frozen=True)
class Scene:
    """A checked scene. Read values with ``scene["name"]``; derive variants with :meth:`with_`.

    Attributes
    ----------
    name : str
        Built-in name or TOML file stem (or its ``name``).
    geometry : str
        ``rod``, ``slab`` or ``block`` (the body itself: :attr:`body`).
    values : dict
        Every parameter the scene uses, checked (expressions parsed).
    description : str
    set_by_user : frozenset
        The names given as overrides (the rest are the preset's).
    base : str
        The built-in scene this one starts from.
    model : str
        ``"A"`` or ``"B"`` (what the values mean: :meth:`model_of`).
    source : str
        The TOML file it was read from ('' for a built-in scene).
    """

    name: str
    geometry: str
    values: dict
    description: str = ""
    set_by_user: frozenset = frozenset()
    base: str = ""
    model: str = "A"
    source: str = ""

    def __getitem__(self, key):
        return self.values[key]

    @property
    def dim(self) -> int:
        return GEOMETRIES[self.geometry].dim

    @cached_property
    def body(self):
        """The geometry object (:mod:`workbench.input.geometry`) of this scene's values."""
        return GEOMETRIES[self.geometry].from_values(self.values)

    def model_of(self):
        """The physics objects of this scene (:func:`workbench.input.models.from_scene`)."""
        from .models import from_scene

        return from_scene(self)

    @property
    def terms(self) -> tuple:
        """The terms this scene declares; only these are assembled (see :mod:`workbench.input.models`)."""
        return self.model_of().terms

    def with_(self, **overrides) -> "Scene":
        """A new scene with some values changed (checked again)."""
        user = {k: self.values[k] for k in self.set_by_user}
        return make(self.name, user | overrides, base=self.base, description=self.description, source=self.source)

    def plain(self) -> dict:
        """Values as JSON-able data (expressions as text)."""
        return {k: to_plain(v) for k, v in self.values.items()}

    def table(self):
        """Rows (name, value, unit, allowed, meaning) for ``workbench show``."""
        params = _known(self.base)
        rows = []
        for n in self.values:
            allowed = params[n].range_text()
            if n == "scheme":
                allowed = " | ".join(repr(s) for s in schemes_of(self.model))
            elif n == "order":
                allowed = " | ".join(str(o) for o in range(1, MODELS[self.model].max_order(self.dim) + 1))
            rows.append((n, to_plain(self.values[n]), params[n].unit, allowed, params[n].meaning))
        return rows


def _known(base):
    preset = PRESETS[base]
    return {n: PARAMETERS[n] for n in MODEL_PARAMETERS[preset.geometry, preset.model]} | preset.extras


def names() -> list[str]:
    """Built-in scene names."""
    return list(PRESETS)


def make(name: str, overrides: dict | None = None, *, base: str | None = None, description: str = "",
         source: str = "") -> Scene:
    """Build and check a built-in scene (``base`` defaults to ``name``) with ``overrides``."""
    base = base or name
    if base not in PRESETS:
        shown = repr(base) if len(str(base)) <= 80 else repr(str(base)[:80]) + f"... ({len(str(base))} characters)"
        raise ParameterError(f"unknown scene {shown}; built-in scenes: {', '.join(PRESETS)}"
                             + closest_name(str(base)[:80], PRESETS) + " (or give a .toml file)")
    preset = PRESETS[base]
    known = _known(base)
    overrides = dict(overrides or {})
    for key in overrides:
        if key in _NOT_APPLICABLE.get(preset.model, {}):
            raise ParameterError(f"{key} does not apply to the Model {preset.model} scene {name!r}: "
                                 + _NOT_APPLICABLE[preset.model][key])
        if key not in known:
            raise ParameterError(f"unknown parameter {key!r} for scene {name!r}" + closest_name(key, known))
    raw = {n: p.default for n, p in known.items()} | preset.values | overrides
    derived, inputs = {}, []
    if preset.derive is not None:
        inputs = [n for n in known if n in preset.extras or n in ("E", "nu", "plane", "elastic_tensor")]
        checked_extras = {n: known[n].check(raw[n]) for n in inputs}
        # (a viscosity given as a1 or a2 stands: no viscous tensor is derived over it)
        given = set(overrides) | ({"viscous_tensor"} if {"a1", "a2"} & set(overrides) else set())
        derived = {k: v for k, v in preset.derive(checked_extras).items() if k not in given}
        raw |= derived
    geometry = GEOMETRIES[preset.geometry]
    if "mesh" in known:
        _mesh_values(raw, overrides, geometry.dim, name)
    values = {}
    for n in known:
        try:
            values[n] = known[n].check(raw[n], size=geometry.dim)
        except ParameterError as err:
            if n not in derived:
                raise
            given = ", ".join(f"{i} = {raw[i]}" for i in inputs if i in overrides) or "the preset's values"
            raise ParameterError(f"{given}: the derived {err}") from None  # (what the user typed, and what follows)
    body = geometry.from_values(values)
    _check_size(body, values)
    if "mesh" in known:  # a mesh body's element size is its mesh's
        if "h" in overrides and not math.isclose(float(overrides["h"]), body.h_max(), rel_tol=1e-9):
            raise ParameterError(f"h = {overrides['h']}: a mesh body's element size is its mesh's (h = "
                                 f"{body.h_max():.6g}); refine the mesh itself (in Python, give a netgen/OCC geometry "
                                 "and h: it is meshed with maxh = h)")
        values["h"] = body.h_max()
    if not values["probes"]:
        values["probes"] = body.default_probes()
    if "snapshots" not in overrides:  # preset snapshot times beyond a shortened T are dropped
        values["snapshots"] = tuple(t for t in values["snapshots"] if t <= values["T"])
    if "point_force_at" in values and not values["point_force_at"]:
        values["point_force_at"] = (body.default_probes()[-1],)
    if "scheme" not in overrides and values["scheme"] not in schemes_of(preset.model):  # (the table's default is A's)
        values["scheme"] = schemes_of(preset.model)[0]
    _check_consistency(name, body, values, preset.model)
    user = frozenset(overrides) | ({"mesh_digest"} if "mesh" in known else set())  # (a variant keeps the digest)
    return Scene(name, preset.geometry, values, description or preset.description, user, base, preset.model, source)


def _mesh_values(raw: dict, overrides: dict, dim: int, name: str) -> None:
    """The mesh file of a mesh body, checked: its absolute path and the digest of its content (``mesh_digest``; one
    given, as by a restart or an archive, must still be the file's)."""
    from . import meshes

    if not raw.get("mesh"):
        raise ParameterError("mesh: give the body's mesh file (a gmsh .msh or netgen .vol), and boundaries, the role of "
                             "each of its boundaries")
    path = meshes.check_file(raw["mesh"])
    found = meshes.digest(path)
    if raw.get("mesh_digest") and raw["mesh_digest"] != found:
        raise ParameterError(f"mesh = {str(path)!r}: the file has changed since this scene was made (mesh_digest "
                             f"{raw['mesh_digest'][:12]}... then, {found[:12]}... now)")
    raw["mesh"], raw["mesh_digest"] = str(path), found
    from .geometry import _read_mesh

    have = _read_mesh(str(path), found).dim
    if have != dim:
        other = {2: "mesh2d / memory_mesh2d", 3: "mesh3d / memory_mesh3d"}.get(have, "none")
        raise ParameterError(f"mesh = {str(path)!r} is a {have}D mesh; this scene needs a {dim}D one ({name!r}; the "
                             f"scenes for a {have}D mesh: {other}; workbench.scene(mesh=...) picks by the dimension)")


#: Above this many time steps a run is refused (a typing slip such as k = 1e-300 or T = 1e6).
MAX_STEPS = 10**7
#: Above this many mesh vertices a scene is refused before meshing (a typing slip such as h = 1e-7: the mesher alone
#: would run for hours; the largest run measured here, the P2 block at 1.19M dofs, has 50k vertices).
MAX_VERTICES = 5e6


def _check_size(body, values) -> None:
    """Refuse, before any meshing, a mesh far finer than any run here (named by the parameters that set it)."""
    n = body.estimated_vertices()
    if n > MAX_VERTICES:
        given = ", ".join(f"{name} = {values[name]:g}" for name in body.size_names
                          if isinstance(values.get(name), (int, float)) and values.get(name))
        raise ParameterError(f"{given or 'the mesh'} would give about {n:.2g} mesh vertices, more than the "
                             f"{MAX_VERTICES:.0e} this workbench runs (a slip of a digit?); use a coarser mesh")


def _check_solvers(v, scheme, model):
    """The linear and contact solvers against what the scheme can do."""
    coupled_cg = scheme.coupled and v["contact_solver"] != "condensed"  # (no per-dof solves to repeat)
    if v["solver"] in ITERATIVE_SOLVERS and not (scheme.iterative or coupled_cg):
        iterative = " | ".join(repr(n) for n, e in SCHEMES.items() if e.iterative and e.model == model)
        coupled = " or contact_solver = 'coupled'" if scheme.coupled else ""
        raise ParameterError(f"solver = {v['solver']!r} (iterative) applies to the scheme(s) {iterative or 'none'} "
                             f"and to the coupled contact solver; scheme = {v['scheme']!r} with contact_solver = "
                             f"{v['contact_solver']!r} condenses on the contact dofs, one solve per contact dof: use "
                             f"solver = 'auto' (a direct factor){coupled}"
                             + (f" or scheme = {iterative}" if iterative else ""))
    if v["contact_solver"] == "coupled" and not scheme.coupled:
        coupled = " | ".join(repr(n) for n, e in SCHEMES.items() if e.coupled)
        raise ParameterError(f"contact_solver = 'coupled' applies to the schemes that solve a contact problem each "
                             f"step ({coupled}); scheme = {v['scheme']!r} takes its contact forces from the last step: "
                             "leave contact_solver = 'auto'")
    if v["contact_solver"] == "condensed" and v.get("contact_tol", PARAMETERS["contact_tol"].default) != \
            PARAMETERS["contact_tol"].default:
        raise ParameterError(f"contact_tol = {v['contact_tol']:g} sets the coupled contact solve's residual; "
                             "contact_solver = 'condensed' solves each active set exactly (a dense factor), so it "
                             "would change nothing: leave contact_tol at its default, or give contact_solver = "
                             "'coupled' or 'auto'")


def _check_adaptive(body, v) -> None:
    """space_tol > 0: a body netgen can refine, and a run that need not be continued."""
    if body.dim < 2:
        raise ParameterError(f"space_tol = {v['space_tol']:g}: a {body.kind}'s mesh cannot be refined adaptively "
                             "(netgen refines 2D and 3D meshes); refine it by h, or leave space_tol = 0")
    if v.get("space_adapt") == "during" and v["scheme"] == "explicit":
        raise ParameterError("space_adapt = 'during' carries the state of the schemes 'implicit', 'bdf2' and 'vi' "
                             "onto a finer mesh, not the explicit scheme's (its step limit is the mesh's): give "
                             "scheme = 'implicit' or 'bdf2', or space_adapt = 'repeat'")
    if v.get("space_adapt") == "remesh" and not body.remeshable:
        raise ParameterError(f"space_adapt = 'remesh' meshes the body anew from its geometry, which a {body.kind} "
                             "does not have (the Hertz bodies halfdisc and hemisphere do): give space_adapt = 'repeat' "
                             "or 'during'")
    if v["checkpoint_every"] and v.get("space_adapt", "repeat") != "during":
        raise ParameterError(f"checkpoint_every = {v['checkpoint_every']} with space_tol = {v['space_tol']:g}: an "
                             "adapted run is repeated on each mesh and cannot be continued from a checkpoint; leave "
                             "checkpoint_every = 0, or adapt during the run (space_adapt = 'during')")


def _check_consistency(name, body, v, model="A"):
    """Checks that involve several parameters."""
    allowed = schemes_of(model)
    if v["scheme"] not in allowed:
        raise ParameterError(f"scheme = {v['scheme']!r} does not apply to a Model {model} scene; "
                             f"allowed: {' | '.join(repr(s) for s in allowed)}")
    scheme = SCHEMES[v["scheme"]]
    if "prony" in v:
        _check_memory(body, v)
    highest = MODELS[model].max_order(body.dim)
    if v["order"] > highest:
        raise ParameterError(f"order = {v['order']}: Model {model} constrains the contact nodes (K_h): order 1, or 2 on "
                             f"a 2D body (vertices and facet midpoints); allowed here: order "
                             f"{' | '.join(str(o) for o in range(1, highest + 1))}")
    _check_solvers(v, scheme, model)
    if v["k"] > v["T"]:
        raise ParameterError(f"k = {v['k']:g} is larger than T = {v['T']:g}; allowed: 0 < k <= T")
    if is_adaptive(v["rtol"]):
        if not scheme.error_control:
            controlled = ", ".join(n for n, e in SCHEMES.items() if e.error_control)
            raise ParameterError(f"rtol > 0 (error-controlled steps) applies to the schemes that estimate their error "
                                 f"({controlled}); the {v['scheme']} scheme's step is bounded by its stability limit "
                                 "k_crit")
        k_max = v["k_max"] or v["T"]
        if v["k_min"] > min(k_max, v["T"]):  # (named as itself: the message named k, the first step)
            raise ParameterError(f"k_min = {v['k_min']:g} is larger than {'T' if k_max >= v['T'] else 'k_max'} = "
                                 f"{min(k_max, v['T']):g}; allowed: 0 < k_min <= k_max <= T")
        if not v["k_min"] <= v["k"] <= k_max:
            raise ParameterError(f"k = {v['k']:g} (the first step) must lie in [k_min, k_max] = [{v['k_min']:g}, "
                                 f"{k_max:g}]")
    if v.get("space_tol", 0.0) > 0:
        _check_adaptive(body, v)
    if v.get("edge_tol", 0.0) > 0 and (v.get("space_tol", 0.0) <= 0 or v.get("space_adapt", "repeat") != "during"):
        raise ParameterError(f"edge_tol = {v['edge_tol']:g} is judged by a mesh that follows the run: give space_tol > "
                             "0 (the energy's tolerance, e.g. 0.2) and space_adapt = 'during', or leave edge_tol = 0")
    steps = v["T"] / v["k"]
    if steps > MAX_STEPS and not is_adaptive(v.get("rtol", 0.0)):  # (under error control k is the first step alone)
        raise ParameterError(f"k = {v['k']:g} and T = {v['T']:g} make {steps:.3g} time steps; at most {MAX_STEPS:.0e} "
                             "are allowed (check the values of k and T)")
    if v["h"] > body.size and "mesh" not in v:  # (a mesh body's h is its longest cell edge: a diagonal may exceed it)
        raise ParameterError(f"h = {v['h']:g} is larger than the body ({body.size:g}); "
                             f"allowed: 0 < h <= {body.size:g}")
    for key in ("probes", "point_force_at"):
        for p in v.get(key, ()):
            body.check_point(key, p)
    bad = [t for t in v["snapshots"] if t > v["T"] * (1 + 1e-12)]
    if bad:
        raise ParameterError(f"snapshots: time {bad[0]:g} is after T = {v['T']:g}; allowed: 0 <= t <= T")
    for key in ("elastic_tensor", "viscous_tensor"):
        if v.get(key):
            from ..physics.kelvin_voigt import Voigt

            Voigt(v[key], body.dim, key)  # checks shape, symmetry, definiteness
    _check_expressions(body, v)
    if body.dim == 1 and "u0" in v:
        u0_at_0, d0 = v["u0"](x=0.0), v["delta"](t=0.0)
        if not math.isclose(u0_at_0, d0, rel_tol=1e-12, abs_tol=1e-12):
            raise ParameterError(f"u0 = {v['u0']} gives u0(0) = {u0_at_0:g} but delta(0) = {d0:g}; "
                                 "the initial displacement must match the prescribed end (compatibility)")


def _check_expressions(body, v):
    """Every expression is finite on the body at a few times in [0, T] (a division by zero fails here, not later)."""
    from ..expressions import VARIABLES, Expression

    coordinates = set("xyz"[: body.dim])
    for key, expr in v.items():
        if isinstance(expr, Expression):
            # (the parameter's own variables: u0 is a field in space alone, which its parse checked)
            declared = set(PARAMETERS[key].variables) if key in PARAMETERS else set(VARIABLES)
            allowed = sorted(coordinates & declared) + (["t"] if "t" in declared else [])
            extra = sorted(expr.variables - set(allowed))
            if extra:
                raise ParameterError(f"in {key} = {_clip(expr.source)}: {extra[0]!r} is not a coordinate of a "
                                     f"{body.kind} (allowed: {', '.join(allowed)})")
    corners = np.array(np.meshgrid(*[[lo, 0.5 * (lo + hi), hi] for lo, hi in body.bbox], indexing="ij")
                       ).reshape(body.dim, -1)
    found = not_finite(v, np.linspace(0.0, v["T"], 11), corners)
    if found:
        raise ParameterError(found)


def not_finite(values: dict, times, points: np.ndarray) -> str:
    """Which expression of a scene's ``values`` is not finite at one of ``times`` at one of ``points`` (dim x n
    coordinates): a sentence naming it, or "" where each is finite there.

    >>> from workbench.expressions import parse
    >>> not_finite({"delta": parse("0.01/(t - 0.5)")}, [0.0, 0.5], np.zeros((1, 1)))
    "delta = '0.01/(t - 0.5)' is not finite at t = 0.5"
    """
    from ..expressions import Expression

    coords = dict(zip("xyz", points))
    for key, expr in values.items():
        if not isinstance(expr, Expression):
            continue
        for t in times:
            try:
                with np.errstate(all="ignore"):
                    value = np.asarray(expr(t=t, **coords), dtype=float)
            except (ZeroDivisionError, OverflowError, ValueError, FloatingPointError, TypeError):
                value = np.array([np.nan])
            if not np.all(np.isfinite(value)):
                where = f"t = {t:g}" + ("" if not expr.variables & {"x", "y", "z"} else " somewhere in the body")
                return f"{key} = {_clip(expr.source)} is not finite at {where}"
    return ""


def _clip(text: str, n: int = 60) -> str:
    return repr(text) if len(text) <= n else repr(text[:n - 3] + "...")


def _check_memory(body, v):
    rod = body.dim == 1
    for i, term in enumerate(v["prony"]):
        if len(term) != (2 if rod else 3):
            want = "(E_i, tau_i)" if rod else "(E_i, nu_i, tau_i)"
            raise ParameterError(f"prony: term {i} = {term} must be {want}")
        tau = term[-1]
        if not tau > 0:
            raise ParameterError(f"prony: term {i} has tau = {tau:g}; allowed: tau_i > 0")
        if len(term) == 3 and not -1.0 < term[1] < 0.5:
            raise ParameterError(f"prony: term {i} has nu = {term[1]:g}; allowed: -1 < nu_i < 0.5")
    if v["prony"] and not v["kernel"].is_zero():
        raise ParameterError("give the memory either as kernel (quadrature, O(n) work per step) or as prony "
                             "(exact recursion, O(1)), not both")
    if not v["kernel"].is_zero() and v["kernel_E"] == 0:
        raise ParameterError(f"kernel = {v['kernel']} has no effect with kernel_E = 0: give kernel_E, the modulus "
                             "of the kernel tensor (negative for relaxation)")


#: The largest scene file read: a scene is a few lines of TOML, but comments may be long (a 2 MB file of comments
#: parses in 0.1 s); at this size a file of junk keys still parses in about 20 s before it is refused.
MAX_SCENE_FILE = 16e6

_TOML_KEYS = {"scene", "name", "description", "parameters", "traction", "geometry", "boundaries", "model"}


def from_toml(path, overrides: dict | None = None) -> Scene:
    """Read a scene file.

    The file names a built-in ``scene`` to start from, optionally a ``name`` and
    ``description``, a ``[parameters]`` table, and a ``[traction]`` table keyed by
    boundary name (``top = "(0, -1)"`` sets ``traction_top``). Unknown keys,
    parameters or boundaries are errors, and so is a load given in both tables.
    """
    path = Path(path)
    data = _read_toml(path)
    for key in data:
        if key not in _TOML_KEYS:
            raise ParameterError(f"{path.name}: unknown top-level key {key!r}; allowed: {', '.join(sorted(_TOML_KEYS))}"
                                 + closest_name(key, _TOML_KEYS))
    if "geometry" in data:
        return _toml_mesh_scene(path, data, overrides)
    for key in ("boundaries", "model"):
        if key in data:
            raise ParameterError(f"{path.name}: {key} applies to a body from a mesh file: give geometry = \"body.msh\" "
                                 "too")
    base = data.get("scene")
    if base is None:
        raise ParameterError(f"{path.name}: give the built-in scene to start from, e.g. scene = \"slab\"")
    if not isinstance(base, str):
        raise ParameterError(f"{path.name}: scene = {base!r} must be the name of a built-in scene, e.g. scene = \"slab\"")
    if base not in PRESETS:
        raise ParameterError(f"{path.name}: unknown scene {base!r}; built-in scenes: {', '.join(PRESETS)}"
                             + closest_name(base, PRESETS))
    for key in ("parameters", "traction"):
        if key in data and not isinstance(data[key], dict):
            raise ParameterError(f"{path.name}: {key} must be a table ([{key}] with name = value lines), "
                                 f"got {data[key]!r}")
    for key in ("name", "description"):
        if key in data and not isinstance(data[key], str):
            raise ParameterError(f"{path.name}: {key} must be text, got {data[key]!r}")
    if "name" in data and not data["name"].strip():  # (it names the run's status line, archive and files)
        raise ParameterError(f"{path.name}: name = {data['name']!r}: give a name, or leave it out (the file's: "
                             f"{path.stem!r})")
    values = _toml_values(path, data, base) | dict(overrides or {})
    name = data.get("name", path.stem)
    try:
        return make(name, values, base=base, description=data.get("description", ""), source=str(path.resolve()))
    except ParameterError as err:
        raise ParameterError(f"{path.name}: {err}") from None


def _read_toml(path: Path) -> dict:
    """The table of a scene file; a file that is missing, unreadable or not TOML is a ParameterError naming it."""
    import stat

    from ..values import check_utf8_path

    check_utf8_path(path, "scene file")  # (its path is an attribute of the archive)
    label = str(path) if len(str(path)) <= 200 else str(path)[:200] + "..."
    try:
        mode = path.stat()
    except FileNotFoundError:
        raise ParameterError(f"scene file {label!r} not found") from None
    except OSError as err:  # (a name too long, a loop of links, no permission on a folder)
        raise ParameterError(f"scene file {label!r} cannot be read: {err.strerror}") from None
    if not stat.S_ISREG(mode.st_mode) and not stat.S_ISDIR(mode.st_mode):  # (a pipe would wait for ever, /dev/zero
        raise ParameterError(f"scene file {label!r} is not a regular file (a device, a pipe or a socket)")  # fill RAM)
    if stat.S_ISREG(mode.st_mode) and mode.st_size > MAX_SCENE_FILE:
        raise ParameterError(f"scene file {label!r} is {mode.st_size / 1e6:.3g} MB long; a scene file is a "
                             f"short TOML text (at most {MAX_SCENE_FILE / 1e6:g} MB)")
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ParameterError(f"scene file {label!r} not found") from None
    except IsADirectoryError:
        raise ParameterError(f"scene file {label!r} is a directory, not a TOML file") from None
    except OSError as err:
        raise ParameterError(f"scene file {label!r} cannot be read: {err.strerror}") from None
    try:
        # (utf-8-sig: a byte-order mark, as Windows editors write one, was an "invalid statement" at line 1)
        return tomllib.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise ParameterError(f"scene file {label!r} is not a text (UTF-8 TOML) file") from None
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"scene file {label!r}: {err}") from None
    except RecursionError:
        raise ParameterError(f"scene file {label!r}: its tables or lists are nested too deeply") from None


def _toml_values(path: Path, data: dict, base: str) -> dict:
    """The parameter values of a scene file: its [parameters], with each [traction] entry as ``traction_{side}``
    (a side the base scene cannot load, or a load given in both tables, is an error)."""
    values = dict(data.get("parameters", {}))
    sides = GEOMETRIES[PRESETS[base].geometry].boundaries["traction"]
    for side, load in data.get("traction", {}).items():
        if side not in sides:
            raise ParameterError(f"{path.name}: unknown boundary {side!r} in [traction] for a {PRESETS[base].geometry}; "
                                 f"loadable boundaries: {', '.join(sides) or 'none'}" + closest_name(side, sides))
        if f"traction_{side}" in values:
            raise ParameterError(f"{path.name}: traction_{side} is given twice ([parameters] traction_{side} and "
                                 f"[traction] {side}); give it once")
        values[f"traction_{side}"] = load
    return values


def _toml_mesh_scene(path: Path, data: dict, overrides) -> Scene:
    """A scene file with ``geometry = "body.msh"`` (relative to the file), ``[boundaries]`` and ``model``."""
    from . import meshes

    geometry, roles = data["geometry"], data.get("boundaries", {})
    if not isinstance(geometry, str):
        raise ParameterError(f"{path.name}: geometry = {geometry!r} must be the path of a mesh file")
    if not isinstance(roles, dict):
        raise ParameterError(f"{path.name}: boundaries must be a table ([boundaries] with name = \"role\" lines)")
    if "traction" in data:
        raise ParameterError(f"{path.name}: a body from a mesh takes its load as traction = \"(...)\" in [parameters] "
                             "(on every boundary with the role traction), not a [traction] table")
    params = data.get("parameters", {})
    if not isinstance(params, dict):
        raise ParameterError(f"{path.name}: parameters must be a table ([parameters] with name = value lines)")
    mesh = Path(geometry).expanduser()
    mesh = mesh if mesh.is_absolute() else path.resolve().parent / mesh
    try:
        dim = meshes.read(mesh).dim
        model = data.get("model", "A")
        if model not in ("A", "B"):
            raise ParameterError(f"model = {model!r}; allowed: 'A' | 'B'")
        base = data.get("scene") or MESH_SCENES.get((dim, model))
        if base not in MESH_SCENES.values():
            raise ParameterError(f"scene = {base!r}: a body from a mesh file starts from one of "
                                 f"{', '.join(MESH_SCENES.values())}")
        if "model" in data and PRESETS[base].model != model:  # (the scene's model was taken, without a word)
            raise ParameterError(_model_contradicts(base, model, dim))
        values = dict(params) | {"mesh": str(mesh), "boundaries": roles} | dict(overrides or {})
        return make(data.get("name", path.stem), values, base=base, description=data.get("description", ""),
                    source=str(path.resolve()))
    except ParameterError as err:
        raise ParameterError(f"{path.name}: {err}") from None


def _model_contradicts(base: str, model: str, dim: int) -> str:
    """The refusal of a mesh scene named together with the other model."""
    return (f"model = {model!r} contradicts scene = {base!r} (Model {PRESETS[base].model}'s mesh scene): give one of "
            f"them, or scene = {MESH_SCENES[(dim, model)]!r} for Model {model}")


def _looks_like_path(text: str) -> bool:
    return text.endswith(".toml") or "/" in text or "\\" in text


def _is_file(text: str) -> bool:
    """Whether ``text`` names an existing file (False for a name the file system cannot hold, e.g. 300 bytes long)."""
    try:
        return Path(text).is_file()
    except OSError:
        return False


def scene(name_or_path=None, *, model=None, **overrides) -> Scene:
    """A scene from a built-in name, a TOML path or an existing :class:`Scene`, with overrides.

    A built-in name always means the built-in scene; a file of that name in the working
    directory is read only when given as a path (``./tp1``), and a warning says so.

    Without a name, ``mesh=`` (a mesh file, a netgen/OCC geometry meshed with ``maxh = h``, or
    an NGSolve/netgen mesh) and ``boundaries={name: role}`` make a body from a mesh: the scene
    ``mesh2d``/``mesh3d`` (``model="A"``, the default) or ``memory_mesh2d``/``memory_mesh3d``
    (``model="B"``), by the mesh's dimension.

    >>> from netgen.occ import OCCGeometry, Rectangle, X, Y
    >>> face = Rectangle(1.0, 0.2).Face()
    >>> face.edges.Min(Y).name, face.edges.Min(X).name, face.edges.Max(Y).name = "bottom", "left", "top"
    >>> s = scene(mesh=OCCGeometry(face, dim=2), h=0.1, boundaries={"bottom": "contact", "left": "clamped",
    ...           "top": "traction", "default": "free"}, traction="(0, -t)")
    >>> s.name, s.body.boundaries["contact"], s.body.boundaries["traction"], s.body.curved
    ('mesh2d', 'bottom', ('top',), False)
    """
    if name_or_path is None or "mesh" in overrides and not isinstance(overrides["mesh"], (str, Path)):
        if "mesh" not in overrides:
            raise ParameterError("workbench.scene: give a scene (a built-in name or a .toml file), or mesh=... and "
                                 "boundaries=... for a body from a mesh")
        return _mesh_scene(name_or_path, model, overrides)
    if model is not None:
        text = str(name_or_path)
        if not isinstance(name_or_path, Scene) and text not in PRESETS and (_looks_like_path(text) or _is_file(text)):
            raise ParameterError(f"model = {model!r}: a scene file names its model in the file (model = \"A\" or "
                                 "\"B\" at its top); model= applies to a body given as mesh=...")
        if text in MESH_SCENES.values() and "mesh" in overrides and PRESETS[text].model != model:
            dim = next(d for (d, _), name in MESH_SCENES.items() if name == text)
            raise ParameterError(_model_contradicts(text, model, dim))
        raise ParameterError(f"model = {model!r} applies to a body from a mesh (mesh=...); a built-in scene has its own "
                             "model")
    if isinstance(name_or_path, Scene):
        return name_or_path.with_(**overrides) if overrides else name_or_path
    text = str(name_or_path)
    if text in PRESETS:
        if _is_file(text):
            warnings.warn(f"scene {text!r}: using the built-in scene; the file ./{text} in this folder is not read "
                          f"(give it as ./{text} to use the file)", RuntimeWarning, stacklevel=2)
        return make(text, overrides)
    if _looks_like_path(text) or _is_file(text):
        return from_toml(text, overrides)
    return make(text, overrides)


def _mesh_scene(name, model, overrides) -> Scene:
    """The mesh scene of ``overrides["mesh"]`` (a file or a Python mesh/geometry object, stored as a file)."""
    from . import meshes

    overrides = dict(overrides)
    mesh = overrides["mesh"]
    if not isinstance(mesh, (str, Path)):
        overrides["mesh"] = str(meshes.store(mesh, overrides.pop("h", None)))
    if name is None:
        if model not in (None, "A", "B"):
            raise ParameterError(f"model = {model!r}; allowed: 'A' (Kelvin-Voigt, compliance, adhesion) | 'B' (memory, "
                                 "unilateral contact)")
        dim = meshes.read(overrides["mesh"]).dim
        if dim not in (2, 3):
            raise ParameterError(f"mesh = {overrides['mesh']!r} is a {dim}D mesh; give a 2D or a 3D one")
        name = MESH_SCENES[dim, model or "A"]
    return scene(name, **overrides)


__all__ = ["Scene", "scene", "names", "make", "from_toml", "PRESETS", "MODEL_PARAMETERS", "ParameterError"]
