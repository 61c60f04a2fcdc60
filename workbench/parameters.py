"""Every scene parameter: its name (as in docs/conventions.md), default, unit, meaning and allowed range.

This table is the single place where a parameter is defined. Scenes pick the
names their geometry and model use; values are coerced (text from the command
line or TOML becomes numbers, flags or expressions) and checked here, before any
mesh is built, so a bad value fails with a message naming the parameter and its
allowed range.

Examples
--------
>>> PARAMETERS["nu"].check(0.3)
0.3
>>> PARAMETERS["nu"].check(0.5)
Traceback (most recent call last):
...
workbench.errors.ParameterError: nu = 0.5 is outside the allowed range -1 < nu < 0.5
"""
from __future__ import annotations

import difflib
import json
import math
from dataclasses import dataclass

from .errors import ParameterError
from .expressions import Expression, ExpressionError, parse
from .schemes import REGISTRY as SCHEME_REGISTRY


@dataclass(frozen=True)
class Param:
    """One parameter.

    ``kind`` is one of ``float``, ``int``, ``flag``, ``choice``, ``expr``
    (scalar expression), ``vector`` (vector expression, size set by the
    geometry), ``points`` (a list of coordinate tuples), ``times`` (a list of
    times) or ``matrix`` (a square matrix of numbers, empty when not given). ``lower``/``upper`` bound numbers; ``*_open`` says whether the bound
    itself is excluded.
    """

    name: str
    default: object
    unit: str
    meaning: str
    kind: str = "float"
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    upper_open: bool = False
    choices: tuple = ()
    variables: tuple = ("x", "y", "z", "t")

    def range_text(self) -> str:
        """The allowed range in words, for messages and ``workbench show``."""
        if self.kind == "choice":
            return " | ".join(repr(c) for c in self.choices)
        if self.kind == "flag":
            return "true | false"
        if self.kind in ("expr", "vector"):
            return "expression in " + ", ".join(self.variables)
        if self.kind == "text":
            return "text"
        if self.kind == "mapping":
            return "a table name = role"
        if self.lower is None and self.upper is None:
            return "any finite number" if self.kind in ("float", "int") else ""
        parts = []
        if self.lower is not None:
            parts.append(f"{_fmt(self.lower)} {'<' if self.lower_open else '<='}")
        parts.append(self.name)
        if self.upper is not None:
            parts.append(f"{'<' if self.upper_open else '<='} {_fmt(self.upper)}")
        return " ".join(parts)

    def check(self, value, size: int | None = None):
        """Coerce ``value`` to this parameter's kind and check its range."""
        name = self.name
        if self.kind in ("float", "int"):
            if isinstance(value, str):
                try:
                    value = float(value.strip())
                except ValueError:
                    raise ParameterError(f"{name} = {value!r} is not a number") from None
            if isinstance(value, bool) or not isinstance(value, (int, float)) and not hasattr(value, "__float__"):
                raise ParameterError(f"{name} = {value!r} is not a number")
            value = float(value)
            if not math.isfinite(value):
                raise ParameterError(f"{name} = {value} is not finite; allowed: {self.range_text()}")
            if self.kind == "int":
                if value != int(value):
                    raise ParameterError(f"{name} = {value} must be an integer; allowed: {self.range_text()}")
                value = int(value)
            lo, hi = self.lower, self.upper
            bad_lo = lo is not None and (value <= lo if self.lower_open else value < lo)
            bad_hi = hi is not None and (value >= hi if self.upper_open else value > hi)
            if bad_lo or bad_hi:
                raise ParameterError(f"{name} = {_fmt(value)} is outside the allowed range {self.range_text()}")
            return value
        if self.kind == "flag":
            if isinstance(value, str):
                low = value.strip().lower()
                if low in ("1", "true", "yes", "on"):
                    return True
                if low in ("0", "false", "no", "off"):
                    return False
            elif isinstance(value, (bool, int)) and value in (0, 1):
                return bool(value)
            raise ParameterError(f"{name} = {value!r} is not a flag; allowed: true | false")
        if self.kind == "choice":
            if value in self.choices:
                return value
            hint = difflib.get_close_matches(str(value), [str(c) for c in self.choices], n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise ParameterError(f"{name} = {value!r} is not allowed; choose one of {self.range_text()}{extra}")
        if self.kind in ("expr", "vector"):
            try:
                return parse(value, name=name, allowed=self.variables,
                             size=(1 if self.kind == "expr" else size))
            except ExpressionError as err:
                raise ParameterError(str(err)) from None
        if self.kind == "points":
            return _points(name, value)
        if self.kind == "times":
            return _times(name, value)
        if self.kind == "matrix":
            return _matrix(name, value)
        if self.kind == "text":
            if not isinstance(value, str):
                raise ParameterError(f"{name} = {value!r}: give text (a file path)")
            return value
        if self.kind == "mapping":
            return _mapping(name, value)
        raise AssertionError(self.kind)


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _points(name, value):
    if isinstance(value, str):
        text = value.strip()
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            # "(1, 0.1); (0.5, 0)" on the command line
            try:
                value = [[float(c) for c in p.strip().strip("()[]").split(",") if c.strip()]
                         for p in text.split(";") if p.strip()]
            except ValueError:
                raise ParameterError(f"{name} = {text!r}: give points as '(x, y); (x, y)' or a JSON list") from None
    try:
        pts = tuple(tuple(float(c) for c in (p if isinstance(p, (list, tuple)) else [p])) for p in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {value!r}: expected a list of coordinate tuples") from None
    if any(not math.isfinite(c) for p in pts for c in p):
        raise ParameterError(f"{name}: coordinates must be finite")
    return pts


def _times(name, value):
    if isinstance(value, str):  # "0.1, 0.2", or as `workbench show` prints a list: "[0.1, 0.2]"
        value = [v for v in value.strip().strip("[]()").replace(";", ",").split(",") if v.strip()]
    try:
        ts = tuple(float(v) for v in (value if hasattr(value, "__iter__") else [value]))
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {value!r}: expected a list of times") from None
    if any(not math.isfinite(t) or t < 0 for t in ts):
        raise ParameterError(f"{name}: times must be finite and >= 0")
    return ts


def _matrix(name, value):
    if isinstance(value, str):
        text = value.strip()
        if not text:
            return ()
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            raise ParameterError(f"{name} = {text!r}: give a matrix as a JSON list of rows, e.g. "
                                 "[[1100, 330, 0], [330, 1100, 0], [0, 0, 385]]") from None
    try:
        rows = tuple(tuple(float(c) for c in row) for row in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {value!r}: expected a list of rows of numbers") from None
    if rows and (any(len(r) != len(rows) for r in rows) or any(not math.isfinite(c) for r in rows for c in r)):
        raise ParameterError(f"{name}: the matrix must be square with finite entries")
    return rows


def _mapping(name, value):
    """A mapping of names to text (the roles of a mesh's boundaries), sorted by name; JSON text is read too."""
    if isinstance(value, str):
        try:
            value = json.loads(value) if value.strip() else {}
        except json.JSONDecodeError:
            raise ParameterError(f"{name} = {value!r}: give a table of name = value, e.g. "
                                 '{"bottom": "contact", "left": "clamped"}') from None
    if isinstance(value, (list, tuple)):
        try:
            value = dict(value)
        except (TypeError, ValueError):
            raise ParameterError(f"{name} = {value!r}: expected a table of name = value") from None
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in value.items()):
        raise ParameterError(f"{name} = {value!r}: expected a table of names to text, e.g. "
                             '{"bottom": "contact", "left": "clamped"}')
    return dict(sorted(value.items()))


def _p(name, default, unit, meaning, kind="float", **kw) -> Param:
    return Param(name, default, unit, meaning, kind, **kw)


_POS = dict(lower=0.0, lower_open=True)
_NONNEG = dict(lower=0.0)

#: Every parameter any scene may use, by name.
PARAMETERS: dict[str, Param] = {p.name: p for p in [
    # geometry and mesh
    _p("length", 1.0, "m", "rod length", **_POS),
    _p("width", 1.0, "m", "body extent in x", **_POS),
    _p("depth", 0.2, "m", "body extent in y (3D block)", **_POS),
    _p("height", 0.1, "m", "body extent in y (2D slab) or z (3D block)", **_POS),
    _p("h", 0.01, "m", "target element size (cells per side = round(side / h))", **_POS),
    _p("nx", 0, "1", "cells along x; 0 = from h", "int", lower=0),
    _p("ny", 0, "1", "cells along y; 0 = from h", "int", lower=0),
    _p("nz", 0, "1", "cells along z (3D); 0 = from h", "int", lower=0),
    _p("order", 1, "1", "polynomial order of the displacement elements", "int", lower=1, upper=4),
    _p("mesh", "", "", "the body's mesh file (gmsh .msh or netgen .vol; in Python also a netgen/OCC geometry or a "
       "mesh, stored as a file)", "text"),
    _p("boundaries", {}, "", "the role of every boundary of the mesh: clamped, traction, contact or free",
       "mapping"),
    _p("mesh_digest", "", "", "sha256 of the mesh file's content (set from the file: results and caches are keyed "
       "by it)", "text"),
    _p("radius", 1.0, "m", "radius of the Hertz body (half-disc or hemisphere)", **_POS),
    _p("h_contact", 0.0, "m", "element size at the Hertz body's contact point, graded to h away from it; 0 = h / 10",
       **_NONNEG),
    _p("contact_zone", 0.3, "1", "the Hertz body's contact side: the part of its curved side within contact_zone x "
       "radius of the apex, meshed with h_contact (and the body beneath it); the rest is free", lower=0.05,
       upper=0.9),
    # time
    _p("T", 1.0, "s", "final time", **_POS),
    _p("k", 0.01, "s", "time step (uniform grid; the last step is not longer than k)", **_POS),
    _p("scheme", "explicit", "", "time scheme: 'explicit' = the paper's (contact lagged, conditionally stable), "
       "'implicit' = backward Euler with implicit contact (stable), 'bdf2' = second-order BDF with implicit contact; Model B: 'vi' (one variational inequality "
       "per step)", "choice", choices=tuple(SCHEME_REGISTRY)),
    _p("rtol", 0.0, "1", "relative tolerance of error-controlled steps (implicit, bdf2, vi); 0: fixed steps of k",
       lower=0.0, upper=0.5),
    _p("atol", 1e-9, "m", "absolute tolerance of error-controlled steps (the displacement's)", **_POS),
    _p("k_min", 1e-9, "s", "smallest step error control may take (below: the run stops)", **_POS),
    _p("k_max", 0.0, "s", "largest step error control may take (0: T)", lower=0.0),
    _p("allow_unstable", False, "", "run the explicit scheme even when k exceeds its predicted stability limit",
       "flag"),
    _p("solver", "auto", "", "linear solver for the constant matrix: banded Cholesky (RCM order), NGSolve's "
       "sparsecholesky or umfpack, or cg (AMG-preconditioned conjugate gradients, explicit scheme only); auto = banded "
       "when the bandwidth is small, cg for the explicit scheme in 3D when a sparse factor would exceed 2 GB",
       "choice", choices=("auto", "banded", "sparsecholesky", "umfpack", "cg")),
    # material
    _p("E", 1000.0, "Pa", "Young's modulus (elasticity G)", **_POS),
    _p("nu", 0.3, "1", "Poisson's ratio (elasticity G)", lower=-1.0, upper=0.5, lower_open=True, upper_open=True),
    _p("a1", 30.0, "Pa s", "viscosity: coefficient of tr(eps') I", **_NONNEG),
    _p("a2", 20.0, "Pa s", "viscosity: coefficient of eps'", **_POS),
    _p("plane", "stress", "", "2D bodies: plane stress (the paper's tests) or plane strain", "choice",
       choices=("stress", "strain")),
    _p("elastic_tensor", (), "Pa", "elastic tensor (Model A: G, Model B: A) as a matrix in Voigt notation, strains "
       "(e11, e22, 2 e12) in 2D or (e11, e22, e33, 2 e23, 2 e13, 2 e12) in 3D; replaces E and nu", "matrix"),
    _p("viscous_tensor", (), "Pa s", "Model A: the viscous tensor A as a Voigt matrix (as elastic_tensor); replaces "
       "a1 and a2", "matrix"),
    _p("a", 1.0, "Pa", "rod elastic modulus (sigma = a u_x + b u_xt)", **_POS),
    _p("b", 1.0, "Pa s", "rod viscosity (sigma = a u_x + b u_xt)", **_POS),
    # contact physics on Gamma_3
    _p("contact", True, "", "normal compliance of the foundation is modelled", "flag"),
    _p("adhesion", True, "", "bonding field beta and adhesive tractions are modelled", "flag"),
    _p("c_nu", 1.0, "Pa/m^m", "normal compliance stiffness: p_nu(r) = c_nu ((r - gap)_+)^m_nu", **_NONNEG),
    _p("m_nu", 1.0, "1", "normal compliance exponent", lower=1.0, upper=10.0),
    _p("gap", 0.0, "m", "g: Model A, the initial gap to the foundation; Model B, the thickness of the compliant "
       "layer over the rigid foundation (u_nu <= g)", **_NONNEG),
    _p("gamma_nu", 0.3, "Pa/m", "adhesion coefficient", **_NONNEG),
    _p("eps_a", 0.0, "J/m^2", "limit bond energy (below it nothing debonds)", **_NONNEG),
    _p("L", 0.3, "m", "characteristic bond length (truncation R)", **_POS),
    _p("beta0", 1.0, "1", "initial bonding field", lower=0.0, upper=1.0, lower_open=True),
    _p("c_tau", 0.0, "Pa/m", "tangential glue stiffness: p_tau(beta) = c_tau beta", **_NONNEG),
    _p("bonding_truncation", "tension", "", "R in the bonding law: symmetric clip (eq. 3.7 as printed) or tension only",
       "choice", choices=("tension", "symmetric")),
    # Model B: memory and the unilateral, multivalued normal compliance
    _p("F", 0.0, "Pa", "yield limit of the foundation layer: psi(r) = F r_+ + (c/2) r_+^2", lower=0.0),
    _p("c", 0.0, "Pa/m", "hardening stiffness of the foundation layer (psi above)", lower=0.0),
    _p("kernel", "0", "1/s", "relaxation kernel shape b(t): B(t) = b(t) C(kernel_E, kernel_nu)", "expr",
       variables=("t",)),
    _p("kernel_E", 0.0, "Pa", "Young's modulus of the kernel tensor C (rod: its modulus); negative = relaxation"),
    _p("kernel_nu", 0.3, "1", "Poisson's ratio of the kernel tensor C", lower=-1.0, upper=0.5, lower_open=True,
       upper_open=True),
    _p("memory_rule", "rectangle", "", "Model B: the memory integral by the left rectangle rule (first order) or the "
       "trapezoid rule, u piecewise linear in time (second order)", "choice", choices=("rectangle", "trapezoid")),
    _p("kernel_approximation", "quadrature", "", "Model B, a general kernel: the quadrature over all stored steps "
       "(O(n) per step) or a sum of exponentials fitted within kernel_tol on [0, T] (O(terms) per step)", "choice",
       choices=("quadrature", "exponentials")),
    _p("kernel_tol", 1e-6, "1", "Model B: the error bound of the exponential-sum kernel, relative to max |b| on "
       "[0, T]", lower=1e-12, upper=0.1),
    _p("prony", (), "Pa, 1, s", "Prony series B(t) = sum_i C(E_i, nu_i) exp(-t / tau_i): list of (E_i, nu_i, tau_i) "
       "(rod: (E_i, tau_i))", "points"),
    # loads and prescribed displacements
    _p("delta", "0", "m", "prescribed rod-end displacement u(0, t)", "expr", variables=("t",)),
    _p("u0", "0", "m", "initial displacement (rod: must equal delta(0) at x = 0)", "expr", variables=("x", "y", "z")),
    _p("body_force", "0", "N/m^3", "volume force f0", "vector", variables=("x", "y", "z", "t")),
    _p("traction_top", "0", "N/m^2", "traction on the top side", "vector"),
    _p("traction", "0", "N/m^2", "traction on every boundary of a mesh body with the role traction", "vector"),
    _p("load", "10*t", "N", "Hertz bodies: the total force pressing the flat side towards the foundation "
       "(per unit thickness in 2D), spread uniformly over it", "expr", variables=("t",)),
    _p("traction_right", "0", "N/m^2", "traction on the right side (x = width)", "vector"),
    _p("traction_front", "0", "N/m^2", "traction on the front side (y = 0, 3D)", "vector"),
    _p("traction_back", "0", "N/m^2", "traction on the back side (y = depth, 3D)", "vector"),
    _p("point_force", "0", "N", "concentrated force applied as a nodal force at point_force_at", "vector",
       variables=("t",)),
    _p("point_force_at", (), "m", "where point_force acts (nearest mesh vertex); default: the top-right corner",
       "points"),
    # output
    _p("probes", (), "m", "points where u is recorded every step", "points"),
    _p("snapshots", (), "s", "times at which whole fields are stored (T is always stored)", "times"),
    _p("checkpoint_every", 0, "1", "write the archive so far with the full state every N accepted steps to the "
       "output file (-o; workbench.run: checkpoint=PATH), so that a killed run goes on with --restart; 0: only the "
       "final archive holds the state", "int", lower=0),
]}


def _add_law_parameters() -> tuple:
    """Add the parameters the contact laws declare in their own files (workbench.physics.laws); their names."""
    from .physics.laws import LAWS

    names = []
    for law in LAWS:
        for param in law.parameters:
            if param.name in PARAMETERS and PARAMETERS[param.name] != param:
                raise RuntimeError(f"contact law {law.name}: parameter {param.name} is already defined")
            PARAMETERS[param.name] = param
            names.append(param.name)
    return tuple(names)


#: Names of the parameters the contact laws add (beyond the table above).
LAW_PARAMETERS = _add_law_parameters()


def closest_name(name: str, known) -> str:
    """A 'did you mean' suffix for an unknown name, or '' (an exact match but for case comes first)."""
    known = list(known)
    same = [k for k in known if k.lower() == str(name).lower()]
    hint = same or difflib.get_close_matches(str(name), known, n=1, cutoff=0.6)
    return f"; did you mean {hint[0]!r}?" if hint else ""


def to_plain(value):
    """A JSON-able form of a checked value (expressions become their text)."""
    if isinstance(value, Expression):
        return value.source
    if isinstance(value, tuple):
        return [to_plain(v) for v in value]
    return value
