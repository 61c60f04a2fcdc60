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

from ..physics.laws import LAWS
from ..values import Param, closest_name, to_plain  # noqa: F401 (the table's row type and helpers, imported from here)
from .numerics import SCHEMES


def _p(name, default, unit, meaning, kind="float", **kw) -> Param:
    return Param(name, default, unit, meaning, kind, **kw)


_POS = dict(lower=0.0, lower_open=True)
_NONNEG = dict(lower=0.0)

#: The parameters of the table, by name (the contact laws add theirs: :data:`PARAMETERS`).
_TABLE: dict[str, Param] = {p.name: p for p in [
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
       "per step)", "choice", choices=tuple(SCHEMES)),
    _p("rtol", 0.0, "1", "relative tolerance of error-controlled steps (implicit, bdf2, vi); 0: fixed steps of k",
       lower=0.0, upper=0.5),
    _p("atol", 1e-9, "m", "absolute tolerance of error-controlled steps (the displacement's)", **_POS),
    _p("k_min", 1e-9, "s", "smallest step error control may take (below: the run stops)", **_POS),
    _p("k_max", 0.0, "s", "largest step error control may take (0: T)", lower=0.0),
    _p("space_tol", 0.0, "1", "relative tolerance of the a posteriori estimate of the error in space (energy norm): "
       "the mesh is refined where the estimate is large and the run repeated until the estimate meets it, or "
       "max_dofs; 0: the mesh as given", lower=0.0, upper=0.5),
    _p("max_dofs", 200000, "1", "the most displacement dofs adaptive refinement (space_tol > 0) may reach",
       "int", lower=100),
    _p("space_adapt", "repeat", "", "how the mesh is adapted (space_tol > 0): 'repeat' = the whole run repeated on "
       "each finer mesh (one mesh for the whole history), 'during' = refined during the run where the estimate asks, "
       "the state carried onto the finer mesh (implicit, bdf2, vi), 'remesh' = as 'repeat', each mesh made anew from "
       "the body's geometry with the sizes the estimate asks for (the Hertz bodies)", "choice",
       choices=("repeat", "during", "remesh")),
    _p("space_goal", "energy", "", "what adaptive refinement (space_tol > 0) aims at: 'energy' = the error in the "
       "energy norm, 'pressure' = the contact pressure (each element's energy indicator weighted by a dual problem's: "
       "the body held where it presses, moved by the pressure's shape there); the tolerance stays the energy's",
       "choice", choices=("energy", "pressure")),
    _p("edge_tol", 0.0, "1", "how finely a mesh that follows the run (space_adapt = 'during') resolves the edge of the "
       "contact zone: at every estimate time the facets across the edge are at most edge_tol times the zone's size "
       "(its measure to the power 1/(d-1)), else the run goes back and refines a mesh graded toward the edge; "
       "0: not asked", lower=0.0, upper=0.5),
    _p("allow_unstable", False, "", "run the explicit scheme even when k exceeds its predicted stability limit",
       "flag"),
    _p("solver", "auto", "", "linear solver for the constant matrix: banded Cholesky (RCM order), MKL's pardiso "
       "(a supernodal Cholesky, where the mkl wheel is installed), NGSolve's sparsecholesky or umfpack, mixed "
       "(conjugate gradients on pardiso's factor in single precision: half its memory, 4-5 iterations a solve), or cg "
       "(AMG-preconditioned conjugate gradients, no factor); mixed and cg: the explicit scheme, and the implicit ones "
       "with the coupled contact solver; auto = banded when the bandwidth is small, else pardiso (sparsecholesky "
       "without MKL), and in 3D where a sparse factor would exceed 2 GB mixed, or cg where even the single one would "
       "(the explicit scheme, and the implicit ones unless contact_solver = condensed)",
       "choice", choices=("auto", "banded", "pardiso", "sparsecholesky", "umfpack", "mixed", "cg")),
    _p("contact_solver", "auto", "", "how an implicit step's contact problem is solved: condensed (the dense contact "
       "stiffness, made inside one factorization where MKL loads, else one solve per contact point) or coupled (on "
       "the whole body, conjugate gradients on the active contact points, one back-substitution each: for thousands "
       "of points, "
       "3D); auto = coupled from 2500 contact unknowns where the factor forms the condensed stiffness inside one "
       "factorization (MKL; Model B's 3D contact vertices sooner, from about 1000 to 2500 as K's factor grows), else "
       "when they outnumber 20 x the steps, or 5000", "choice",
       choices=("auto", "condensed", "coupled")),
    _p("contact_tol", 1e-11, "1", "Model B, the coupled contact solver: the residual at which a step's forces are "
       "taken as solved once its active set has settled, relative to the contact points' displacement scale "
       "(larger: fewer back-substitutions, and the solution further from the exact discrete one: on the Hertz "
       "hemisphere at 47k dofs 1e-9 moved u by 1.3e-8 of its largest value and the pressure by 7.1e-6 of its peak, "
       "1e-7 by 1e-6 and 4.1e-4; docs/schemes.md)", lower=1e-14, upper=1e-6),
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
    _p("prony", (), "Pa/s, 1, s", "Prony series B(t) = sum_i C(E_i, nu_i) exp(-t / tau_i): list of (E_i, nu_i, tau_i) "
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


def _law_parameters() -> dict:
    """The parameters the contact laws declare in their own files (:mod:`workbench.physics.laws`), by name."""
    out = {}
    for law in LAWS:
        for param in law.parameters:
            if param.name in _TABLE or out.get(param.name, param) != param:
                raise RuntimeError(f"contact law {law.name}: parameter {param.name} is already defined")
            out[param.name] = param
    return out


#: Names of the parameters the contact laws add (beyond the table above).
LAW_PARAMETERS = tuple(_law_parameters())
#: Every parameter any scene may use, by name: the table and the laws' own.
PARAMETERS: dict[str, Param] = _TABLE | _law_parameters()
