"""Scenes: one modelled situation (geometry, material, loads, contact physics) as checked data.

A scene is a geometry (``rod`` 1D, ``slab`` 2D plane stress, ``block`` 3D), a
model, and a dict of parameter values drawn from :data:`~workbench.parameters.PARAMETERS`.
Built-in scenes are the bare geometries and the paper's test problems
``tp1`` … ``tp5``; a TOML file can start from any of them. Every value is
checked when the scene is made, so nothing runs on bad input.

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
from dataclasses import dataclass, field
from pathlib import Path

from .parameters import PARAMETERS, ParameterError, closest_name, to_plain

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

_CONTACT = ("contact", "adhesion", "c_nu", "m_nu", "gap", "gamma_nu", "eps_a", "L", "beta0",
            "bonding_truncation")
_TIME = ("T", "k", "scheme", "order", "h", "solver", "allow_unstable")
_OUTPUT = ("probes", "snapshots")
_KV2D = ("E", "nu", "a1", "a2")

_LOADS2D = ("body_force", "traction_top", "traction_right", "point_force", "point_force_at")
_LOADS3D = ("body_force", "traction_top", "traction_right", "traction_front", "traction_back",
            "point_force", "point_force_at")
_TIME_B = ("T", "k", "scheme", "order", "h", "solver")
_UNILATERAL = ("gap", "F", "c")
_MEMORY = ("kernel", "kernel_E", "kernel_nu", "prony")

#: Parameters each (geometry, model) uses; a scene knows exactly these (plus preset extras).
MODEL_PARAMETERS = {
    ("rod", "A"): ("length",) + _TIME + ("a", "b") + _CONTACT + ("delta", "u0") + _OUTPUT,
    ("slab", "A"): ("width", "height", "nx", "ny") + _TIME + _KV2D + _CONTACT + ("c_tau",) + _LOADS2D + _OUTPUT,
    ("block", "A"): ("width", "depth", "height", "nx", "ny", "nz") + _TIME + _KV2D + _CONTACT + ("c_tau",)
                    + _LOADS3D + _OUTPUT,
    ("rod", "B"): ("length",) + _TIME_B + ("a",) + _UNILATERAL + ("kernel", "kernel_E", "prony", "delta")
                  + _OUTPUT,
    ("slab", "B"): ("width", "height", "nx", "ny") + _TIME_B + ("E", "nu") + _UNILATERAL + _MEMORY + _LOADS2D
                   + _OUTPUT,
    ("block", "B"): ("width", "depth", "height", "nx", "ny", "nz") + _TIME_B + ("E", "nu") + _UNILATERAL + _MEMORY
                    + _LOADS3D + _OUTPUT,
}
#: The schemes each model can run.
MODEL_SCHEMES = {"A": ("explicit", "implicit"), "B": ("vi",)}
DIMENSION = {"rod": 1, "slab": 2, "block": 3}
#: Boundary names per geometry: the clamp (Gamma_1), the contact side (Gamma_3), the loadable rest.
BOUNDARIES = {
    "rod": {"clamp": "left", "contact": "right", "traction": ()},
    "slab": {"clamp": "left", "contact": "bottom", "traction": ("top", "right")},
    "block": {"clamp": "left", "contact": "bottom", "traction": ("top", "right", "front", "back")},
}
DEFAULT_PROBES = {
    "rod": ((0.25,), (0.5,), (1.0,)),
    "slab": ((0.25, 0.0), (0.5, 0.0), (0.75, 0.0), (1.0, 0.0), (1.0, 0.1)),
    "block": ((0.25, 0.1, 0.0), (0.5, 0.1, 0.0), (0.75, 0.1, 0.0), (1.0, 0.1, 0.0), (1.0, 0.1, 0.1)),
}


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


def _extra(name, default, unit, meaning, **kw):
    from .parameters import Param
    return Param(name, default, unit, meaning, "float", **kw)


_ROD_PAPER = dict(h=0.01, k=0.01, T=1.0, a=1.0, b=1.0, eps_a=0.0, beta0=1.0,
                  snapshots=(0.2, 0.4, 0.6, 0.8, 1.0))
_SLAB_PAPER = dict(E=1000.0, nu=0.3, a1=30.0, a2=20.0, c_nu=1.0, gamma_nu=0.3, L=0.3, eps_a=0.0,
                   beta0=1.0, c_tau=0.0, T=1.0, snapshots=(0.1, 0.4, 0.6, 0.7, 0.8, 1.0))

_MEMORY_ROD = dict(h=0.05, k=0.01, T=1.0, a=1.0, gap=0.1, F=0.05, c=1.0, scheme="vi",
                   prony=((0.5, 0.2),), delta="0.3*sin(2*pi*t) - 0.05",
                   snapshots=(0.25, 0.5, 0.75, 1.0))
_MEMORY_2D = dict(width=2.0, height=1.0, h=0.05, k=0.02, T=1.0, E=1000.0, nu=0.3, scheme="vi",
                  gap=0.02, F=20.0, c=2000.0, prony=((-1000.0, 0.3, 0.5),),
                  traction_top="(0, -60*t*ifpos(x - 1, 1, -0.25))", snapshots=(0.25, 0.5, 0.75, 1.0))

PRESETS: dict[str, Preset] = {
    "rod": Preset("rod", "1D Kelvin-Voigt rod (0, length), end x = 0 moved by delta(t), adhesive contact at x = length",
                  dict(h=0.01, k=0.01, delta="-0.5*t")),
    "slab": Preset("slab", "2D plane-stress slab (0, width) x (0, height), clamped at x = 0, adhesive contact on y = 0",
                   dict(h=0.0125, k=0.001, traction_top="(0, t)")),
    "block": Preset("block", "3D block (0, width) x (0, depth) x (0, height), clamped at x = 0, adhesive contact on z = 0",
                    dict(h=0.05, order=2, k=0.001, traction_top="(0, 0, t)")),  # P1 locks: tip 50 % low at h = 0.05
    "tp1": Preset("rod", "Paper test problem 1: rod end held at -0.6, case (b) A + delta < -L; exact solution (SPEC)",
                  dict(_ROD_PAPER, gamma_nu=0.3, L=0.3, delta="-0.6", u0="-0.6")),
    "tp2": Preset("rod", "Paper test problem 2: rod end held at -0.1, case (a) -L <= A + delta < 0; reduced ODE reference",
                  dict(_ROD_PAPER, gamma_nu=0.1, L=1.0, delta="-0.1", u0="-0.1")),
    "tp3": Preset("rod", "Paper test problem 3: periodic end displacement delta_amp sin(omega t); debonding only in tension",
                  dict(_ROD_PAPER, T=5.0, gamma_nu=0.3, L=0.3, u0="0", c_nu=1.0, bonding_truncation="tension",
                       snapshots=(1.0, 2.0, 3.0, 4.0, 5.0)),
                  extras={"delta_amp": _extra("delta_amp", 0.05, "m", "amplitude of delta(t) (not in the paper)"),
                          "omega": _extra("omega", 10.0, "1/s", "angular frequency of delta(t) (OCR: sin 10t)",
                                          lower=0.0, lower_open=True)},
                  derive=_tp3_delta),
    "tp4": Preset("slab", "Paper test problem 4: slab pulled up by a point force (0, 1) at the top-right corner",
                  dict(_SLAB_PAPER, h=0.0125, k=0.01, point_force="(0, 1)", point_force_at=((1.0, 0.1),))),
    "tp5": Preset("slab", "Paper test problem 5: slab under a periodic traction on the top side (inferred from OCR)",
                  dict(_SLAB_PAPER, h=0.0125, k=0.01, traction_top="(-10*sin(50*t), -sin(50*t))",
                       bonding_truncation="tension")),
    "memory_rod": Preset("rod", "Model B: rod with long memory (Prony term), end x = 0 moved by delta(t), unilateral "
                         "contact with a compliant layer of thickness gap at x = length", _MEMORY_ROD, model="B"),
    "memory_slab": Preset("slab", "Model B: block (0,2) x (0,1) with long memory, clamped at x = 0, pressed down on "
                          "its right half and lifted on its left half; layer of thickness gap on y = 0",
                          _MEMORY_2D, model="B"),
    "memory_block": Preset("block", "Model B: 3D block (0,2) x (0,0.5) x (0,1) with long memory, loaded as "
                           "memory_slab; layer of thickness gap on z = 0",
                           dict(_MEMORY_2D, depth=0.5, h=0.1, traction_top="(0, 0, -60*t*ifpos(x - 1, 1, -0.25))"),
                           model="B"),
}


@dataclass(frozen=True)
class Scene:
    """A checked scene. Read values with ``scene["name"]``; derive variants with :meth:`with_`.

    Attributes
    ----------
    name : str
        Built-in name or TOML file stem.
    geometry : str
        ``rod``, ``slab`` or ``block``.
    values : dict
        Every parameter the scene uses, checked (expressions parsed).
    description : str
    """

    name: str
    geometry: str
    values: dict
    description: str = ""
    set_by_user: frozenset = frozenset()
    base: str = ""
    model: str = "A"

    def __getitem__(self, key):
        return self.values[key]

    @property
    def dim(self) -> int:
        return DIMENSION[self.geometry]

    @property
    def terms(self) -> tuple:
        """The terms this scene declares; only these are assembled.

        Model A: ``compliance`` (normal compliance p_nu), ``adhesion`` (bonding
        field beta, adhesive pull and the bonding ODE), ``glue`` (tangential glue
        c_tau beta R*(u_tau)). Model B: ``unilateral`` (the constraint u_nu <= gap
        with the layer psi) and ``memory`` (a nonzero relaxation kernel).
        """
        v = self.values
        if self.model == "B":
            memory = bool(v["prony"]) or not v["kernel"].is_zero() and v["kernel_E"] != 0
            return ("unilateral",) + (("memory",) if memory else ())
        out = []
        if v["contact"] and v["c_nu"] > 0:
            out.append("compliance")
        if v["adhesion"]:
            out.append("adhesion")
            if self.dim > 1 and v.get("c_tau", 0.0) > 0:
                out.append("glue")
        return tuple(out)

    def with_(self, **overrides) -> "Scene":
        """A new scene with some values changed (checked again)."""
        user = {k: self.values[k] for k in self.set_by_user}
        return make(self.name, user | overrides, base=self.base, description=self.description)

    def plain(self) -> dict:
        """Values as JSON-able data (expressions as text)."""
        return {k: to_plain(v) for k, v in self.values.items()}

    def table(self):
        """Rows (name, value, unit, allowed, meaning) for ``workbench show``."""
        params = _known(self.base)
        return [(n, to_plain(self.values[n]), params[n].unit, params[n].range_text(), params[n].meaning)
                for n in self.values]


#: Parameters a model refuses with a reason (rather than as merely unknown).
_NOT_APPLICABLE = {"B": {"u0": "without viscosity the problem is quasistatic in u, so u(0) is the solution of the "
                               "inequality at t = 0 (computed), not an initial condition"}}


def _known(base):
    preset = PRESETS[base]
    return {n: PARAMETERS[n] for n in MODEL_PARAMETERS[preset.geometry, preset.model]} | preset.extras


def names() -> list[str]:
    """Built-in scene names."""
    return list(PRESETS)


def make(name: str, overrides: dict | None = None, *, base: str | None = None, description: str = "") -> Scene:
    """Build and check a built-in scene (``base`` defaults to ``name``) with ``overrides``."""
    base = base or name
    if base not in PRESETS:
        raise ParameterError(f"unknown scene {base!r}; built-in scenes: {', '.join(PRESETS)}"
                             + closest_name(base, PRESETS) + " (or give a .toml file)")
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
    if preset.derive is not None:
        checked_extras = {n: known[n].check(raw[n]) for n in preset.extras}
        derived = preset.derive(checked_extras)
        raw |= {k: v for k, v in derived.items() if k not in overrides}
    dim = DIMENSION[preset.geometry]
    values = {n: known[n].check(raw[n], size=dim) for n in known}
    if not values["probes"]:
        values["probes"] = _default_probes(preset.geometry, values)
    if "snapshots" not in overrides:  # preset snapshot times beyond a shortened T are dropped
        values["snapshots"] = tuple(t for t in values["snapshots"] if t <= values["T"])
    if "point_force_at" in values and not values["point_force_at"]:
        values["point_force_at"] = (_default_probes(preset.geometry, values)[-1],)
    if "scheme" not in overrides and preset.model == "B":
        values["scheme"] = "vi"
    _check_consistency(name, preset.geometry, values, preset.model)
    return Scene(name, preset.geometry, values, description or preset.description, frozenset(overrides), base,
                 preset.model)


def _default_probes(geometry, v):
    if geometry == "rod":
        return tuple((f * v["length"],) for f in (0.25, 0.5, 1.0))
    if geometry == "slab":
        W, H = v["width"], v["height"]
        return ((0.25 * W, 0.0), (0.5 * W, 0.0), (0.75 * W, 0.0), (W, 0.0), (W, H))
    W, D, H = v["width"], v["depth"], v["height"]
    return ((0.25 * W, D / 2, 0.0), (0.5 * W, D / 2, 0.0), (0.75 * W, D / 2, 0.0), (W, D / 2, 0.0), (W, D / 2, H))


def _extent(geometry, v):
    if geometry == "rod":
        return (v["length"],)
    if geometry == "slab":
        return (v["width"], v["height"])
    return (v["width"], v["depth"], v["height"])


def _check_consistency(name, geometry, v, model="A"):
    """Checks that involve several parameters."""
    if v["scheme"] not in MODEL_SCHEMES[model]:
        raise ParameterError(f"scheme = {v['scheme']!r} does not apply to a Model {model} scene; "
                             f"allowed: {' | '.join(repr(s) for s in MODEL_SCHEMES[model])}")
    if model == "B":
        _check_memory(geometry, v)
        if v["order"] != 1:
            raise ParameterError(f"order = {v['order']}: Model B constrains the contact vertices (K_h), so order must "
                                 "be 1")
    if v["k"] > v["T"]:
        raise ParameterError(f"k = {v['k']:g} is larger than T = {v['T']:g}; allowed: 0 < k <= T")
    ext = _extent(geometry, v)
    if v["h"] > max(ext):
        raise ParameterError(f"h = {v['h']:g} is larger than the body ({max(ext):g}); allowed: 0 < h <= {max(ext):g}")
    tol = 1e-12 * max(ext)
    for key in ("probes", "point_force_at"):
        for p in v.get(key, ()):
            if len(p) != len(ext) or any(c < -tol or c > e + tol for c, e in zip(p, ext)):
                box = " x ".join(f"[0, {e:g}]" for e in ext)
                raise ParameterError(f"{key}: point {p} is not inside the body {box}")
    bad = [t for t in v["snapshots"] if t > v["T"] * (1 + 1e-12)]
    if bad:
        raise ParameterError(f"snapshots: time {bad[0]:g} is after T = {v['T']:g}; allowed: 0 <= t <= T")
    if geometry == "rod" and "u0" in v:
        u0_at_0, d0 = v["u0"](x=0.0), v["delta"](t=0.0)
        if not math.isclose(u0_at_0, d0, rel_tol=1e-12, abs_tol=1e-12):
            raise ParameterError(f"u0 = {v['u0']} gives u0(0) = {u0_at_0:g} but delta(0) = {d0:g}; "
                                 "the initial displacement must match the prescribed end (compatibility)")


def _check_memory(geometry, v):
    width = 2 if geometry == "rod" else 3
    for i, term in enumerate(v["prony"]):
        if len(term) not in (width, 3) or (geometry != "rod" and len(term) != 3):
            want = "(E_i, tau_i)" if geometry == "rod" else "(E_i, nu_i, tau_i)"
            raise ParameterError(f"prony: term {i} = {term} must be {want}")
        tau = term[-1]
        if not tau > 0:
            raise ParameterError(f"prony: term {i} has tau = {tau:g}; allowed: tau_i > 0")
        if len(term) == 3 and not -1.0 < term[1] < 0.5:
            raise ParameterError(f"prony: term {i} has nu = {term[1]:g}; allowed: -1 < nu_i < 0.5")
    if v["prony"] and not v["kernel"].is_zero():
        raise ParameterError("give the memory either as kernel (quadrature, O(n) work per step) or as prony "
                             "(exact recursion, O(1)), not both")


def from_toml(path, overrides: dict | None = None) -> Scene:
    """Read a scene file.

    The file names a built-in ``scene`` to start from, optionally a ``name`` and
    ``description``, a ``[parameters]`` table, and a ``[traction]`` table keyed by
    boundary name (``top = "(0, -1)"`` sets ``traction_top``). Unknown keys,
    parameters or boundaries are errors.
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ParameterError(f"scene file {str(path)!r} not found") from None
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"scene file {str(path)!r}: {err}") from None
    allowed = {"scene", "name", "description", "parameters", "traction"}
    for key in data:
        if key not in allowed:
            raise ParameterError(f"{path.name}: unknown top-level key {key!r}; allowed: {', '.join(sorted(allowed))}"
                                 + closest_name(key, allowed))
    base = data.get("scene")
    if base is None:
        raise ParameterError(f"{path.name}: give the built-in scene to start from, e.g. scene = \"slab\"")
    if base not in PRESETS:
        raise ParameterError(f"{path.name}: unknown scene {base!r}; built-in scenes: {', '.join(PRESETS)}"
                             + closest_name(str(base), PRESETS))
    values = dict(data.get("parameters", {}))
    sides = BOUNDARIES[PRESETS[base].geometry]["traction"]
    for side, load in data.get("traction", {}).items():
        if side not in sides:
            raise ParameterError(f"{path.name}: unknown boundary {side!r} in [traction] for a {PRESETS[base].geometry}; "
                                 f"loadable boundaries: {', '.join(sides) or 'none'}" + closest_name(side, sides))
        values[f"traction_{side}"] = load
    values |= dict(overrides or {})
    name = data.get("name", path.stem)
    try:
        return make(name, values, base=base, description=data.get("description", ""))
    except ParameterError as err:
        raise ParameterError(f"{path.name}: {err}") from None


def scene(name_or_path, **overrides) -> Scene:
    """A scene from a built-in name, a TOML path or an existing :class:`Scene`, with overrides."""
    if isinstance(name_or_path, Scene):
        return name_or_path.with_(**overrides) if overrides else name_or_path
    text = str(name_or_path)
    if text.endswith(".toml") or Path(text).is_file():
        return from_toml(text, overrides)
    return make(text, overrides)


__all__ = ["Scene", "scene", "names", "make", "from_toml", "PRESETS", "BOUNDARIES", "ParameterError"]
