"""Hertz's contact of a cylinder and of a sphere on a rigid flat, elastic and viscoelastic (Lee-Radok).

Frictionless contact of an elastic body of radius R with a rigid plane, pressed by a total force P
(per unit thickness for the cylinder); E* = E / (1 - nu^2) (plane strain for the cylinder):

* cylinder: a = sqrt(4 P R / (pi E*)), p(x) = (2 P / (pi a^2)) sqrt(a^2 - x^2);
* sphere: a = (3 P R / (4 E*))^(1/3), p(r) = (3 P / (2 pi a^2)) sqrt(1 - r^2 / a^2).

For a linear viscoelastic body whose contact area does not shrink (Lee and Radok), 1/E* is replaced
by the creep compliance: a(t)^2 = (4 R / pi) int_0^t J*(t - s) dP(s) for the cylinder and
a(t)^3 = (3 R / 4) int_0^t J*(t - s) dP(s) for the sphere, and the pressure is the body's relaxation
operator applied to the elastic pressure of the growing a. For a Kelvin-Voigt body whose viscous
tensor is tau times its elastic one, J*(t) = (1 - exp(-t / tau)) / E*, the operator is 1 + tau d/dt,
and with a^k the solution of tau (a^k)' + a^k = c_k P (k = 2, c_2 = 4 R / (pi E*); k = 3,
c_3 = 3 R / (4 E*)), the pressure is the elastic one plus tau a a' over the root:

* cylinder: p(x) = (E* / 2R) [sqrt(a^2 - x^2) + q / sqrt(a^2 - x^2)], q = (c_2 P - a^2) / 2;
* sphere: p(r) = (2 E* / (pi R)) [sqrt(a^2 - r^2) + q / sqrt(a^2 - r^2)], q = (c_3 P - a^3) / (3 a).

While the contact grows the edge carries an inverse square root, and the elastic part alone carries
a^k / (c_k P) of the load (0.95 for the ``hertz`` scene's tau = 0.05 under its ramp at t = 1).
:func:`kelvin_voigt` gives (a, p) for any load from rest.

These are the references of the ``hertz`` scenes (half-space theory: a << R); :func:`profile`
reads a run's contact pressure against them.

Examples
--------
>>> a, p = cylinder(P=10.0, R=1.0, E=1000.0, nu=0.3)
>>> round(a, 4), round(float(p(0.0)), 2), float(p(2 * a))
(0.1076, 59.14, 0.0)
>>> round(lee_radok(t=1.0, rate=10.0, R=1.0, E=1000.0, nu=0.3, tau=0.05, body="cylinder") / a, 4)
0.9747
"""
from __future__ import annotations

import math

import numpy as np


def reduced_modulus(E: float, nu: float) -> float:
    """E* = E / (1 - nu^2) of a body on a rigid flat."""
    return E / (1.0 - nu * nu)


def cylinder(P: float, R: float, E: float, nu: float):
    """(a, p) of a cylinder (plane strain) pressed by P per unit thickness: the half-width and p(x)."""
    Es = reduced_modulus(E, nu)
    a = math.sqrt(4.0 * P * R / (math.pi * Es))
    return a, lambda x: 2.0 * P / (math.pi * a * a) * np.sqrt(np.maximum(a * a - np.asarray(x) ** 2, 0.0))


def sphere(P: float, R: float, E: float, nu: float):
    """(a, p) of a sphere pressed by P: the contact radius and p(r)."""
    Es = reduced_modulus(E, nu)
    a = (3.0 * P * R / (4.0 * Es)) ** (1.0 / 3.0)
    return a, lambda r: 3.0 * P / (2.0 * math.pi * a * a) * np.sqrt(np.maximum(1.0 - (np.asarray(r) / a) ** 2, 0.0))


def lee_radok(t: float, rate: float, R: float, E: float, nu: float, tau: float, body: str = "cylinder") -> float:
    """a(t) under the ramp load P = rate t of a Kelvin-Voigt body with A = tau G (J* = (1 - e^(-t/tau)) / E*)."""
    creep = rate * (t - tau * (-math.expm1(-t / tau))) / reduced_modulus(E, nu)  # int_0^t J*(t - s) P'(s) ds
    if body == "cylinder":
        return math.sqrt(4.0 * R * creep / math.pi)
    return (0.75 * R * creep) ** (1.0 / 3.0)


def kelvin_voigt(load, t: float, R: float, E: float, nu: float, tau: float, body: str = "cylinder"):
    """(a, p) of Lee and Radok at time ``t`` for a Kelvin-Voigt body with A = ``tau`` G pressed from rest by
    ``load(t)`` (module docs; tau = 0: Hertz's). A ParameterError where the contact shrank before t (Lee and Radok's
    solution holds while it grows).

    >>> a, p = kelvin_voigt(lambda t: 10.0 * t, 1.0, 1.0, 1000.0, 0.3, 0.05)  # (the hertz scene at t = 1)
    >>> a_elastic, p_elastic = cylinder(10.0, 1.0, 1000.0, 0.3)
    >>> round(a / lee_radok(1.0, 10.0, 1.0, 1000.0, 0.3, 0.05), 12), round(a / a_elastic, 4)
    (1.0, 0.9747)
    >>> round(float(p(0.0) / p_elastic(0.0)), 4), float(p(a)), bool(p(0.9999 * a) > p_elastic(0.0))
    (1.0003, 0.0, True)
    """
    from ..errors import ParameterError

    k, c = (2, 4.0 * R / (math.pi * reduced_modulus(E, nu))) if body == "cylinder" else \
        (3, 0.75 * R / reduced_modulus(E, nu))
    times = np.linspace(0.0, t, 201)[1:]
    grown = np.array([_relaxed(load, s, tau) for s in times]) * c  # a^k at those times
    if np.any(np.diff(grown) < -1e-9 * np.abs(grown).max()) or grown[-1] <= 0:
        raise ParameterError(f"hertz: the contact shrinks before t = {t:g} s under this load: Lee and Radok's pressure "
                             "holds while it grows")
    size = float(grown[-1])
    a = size ** (1.0 / k)
    q = (c * load(t) - size) / 2.0 if k == 2 else (c * load(t) - size) / (3.0 * a)  # (tau a a')
    scale = reduced_modulus(E, nu) / (2.0 * R) if k == 2 else 2.0 * reduced_modulus(E, nu) / (math.pi * R)

    def p(r):
        root = np.sqrt(np.maximum(a * a - np.asarray(r, dtype=float) ** 2, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(root > 0, scale * (root + q / root), 0.0)

    return a, p


def _relaxed(load, t: float, tau: float) -> float:
    """(1 / tau) int_0^t e^(-(t - s) / tau) load(s) ds: the solution from 0 of tau y' + y = load (load(t) at
    tau = 0)."""
    if tau <= 0.0:
        return float(load(t))
    from scipy.integrate import quad

    return quad(lambda s: math.exp(-(t - s) / tau) * float(load(s)), max(0.0, t - 60.0 * tau), t, limit=200,
                epsabs=0.0, epsrel=1e-12)[0] / tau


def profile(ds, time=None, variable: str = "contact_pressure"):
    """The contact pressure of a ``hertz`` run at ``time`` (default: its last) against Hertz's for the load then
    (``variable``: the lumped nodal pressure, or ``contact_pressure_recovered``, its patch average). A Kelvin-Voigt
    body (A = tau G) is compared with Lee and Radok's solution (:func:`kelvin_voigt`; module docs).

    Returns a dict: ``a`` (Hertz's, or Lee and Radok's), ``a_last`` / ``a_next`` (the farthest contact point with a
    positive pressure, the nearest without; the points are the vertices, and on P2 Model B's facet midpoints too),
    ``a_fit`` (the half-width of the Hertz profile fitted to the pressure: p^2 linear in r^2; NaN for a viscous
    body), ``l2`` (the relative L2 error of the pressure over the contact side within ``l2_within`` a, 2, or 0.9 for
    a viscous body, by the nodal weights), ``tau``, ``force`` (the contact force over the load's share that the
    modelled part carries), ``x``, ``p``, ``p_hertz`` (by distance from the apex).
    """
    i = -1 if time is None else int(np.argmin(np.abs(ds.time.values - time)))
    t = float(ds.time.values[i])
    three = "node_z" in ds.coords
    P, tau, (a, p_of) = _reference(ds.attrs, t, three)
    if three:
        r = np.hypot(ds.node_x.values, ds.node_y.values)
        share = P / 4.0  # the quarter x, y >= 0
    else:
        r = np.abs(ds.node_x.values)
        share = P / 2.0  # the half x >= 0
    p = ds[variable].values[i]
    w = ds.node_weight.values
    if "contact_pressure_midpoint" in ds and variable == "contact_pressure":  # Model B on P2: the facet midpoints are contact points too
        rm = np.abs(ds.midpoint_x.values) if not three else np.hypot(ds.midpoint_x.values, ds.midpoint_y.values)
        r = np.concatenate([r, rm])
        p = np.concatenate([p, ds.contact_pressure_midpoint.values[i]])
        w = np.concatenate([w, ds.midpoint_weight.values])
    order = np.argsort(r)
    r, p, w = r[order], p[order], w[order]
    ph = p_of(r)
    # (a viscous body's pressure has an inverse square root at the growing edge, whose square is not integrable)
    within = 0.9 if tau > 0 else 2.0
    near = r <= within * a
    touching = p > 0
    # Hertz's p^2 is linear in r^2, vanishing at a: fitted on the vertices in contact (the outermost one, whose
    # lumped pressure averages over the edge, left out), a = sqrt(-intercept / slope)
    # (the apex left out too: it is held, and its pressure is a reaction)
    fit = touching & (r > 0) & (r < r[touching].max()) if touching.sum() > 4 else touching & (r > 0)
    a_fit = float("nan")
    if fit.sum() >= 2 and tau == 0:
        slope, intercept = np.polyfit(r[fit] ** 2, p[fit] ** 2, 1)
        a_fit = float(np.sqrt(-intercept / slope)) if slope < 0 < intercept else float("nan")
    return {"t": t, "load": P, "a": a, "a_fit": a_fit, "a_last": float(r[touching].max()) if touching.any() else 0.0,
            "a_next": float(r[~touching & (r > 0)].min()) if (~touching).any() else float("nan"),
            "l2": float(np.sqrt(np.sum(w[near] * (p - ph)[near] ** 2) / np.sum(w[near] * ph[near] ** 2))),
            "l2_within": within, "tau": tau,
            "force": float(np.sum(w * p) / share), "x": r, "p": p, "p_hertz": ph}


def _reference(attrs, t: float, three: bool):
    """(P, tau, (a, p)) of a run's Hertz problem at ``t`` (:func:`profile`): the load then, the body's viscous time,
    Hertz's or Lee and Radok's solution; a ParameterError naming why a run is none."""
    from ..errors import ParameterError
    from ..expressions import parse

    refused = _not_hertz(attrs)
    load = parse(attrs["load"], name="load", allowed=("t",)) if not refused else None
    P = float(load(t=t)) if not refused else 0.0
    if refused or not P > 0:
        raise ParameterError(f"hertz.profile: {refused or f'the load at t = {t:g} s is {P:g}: nothing presses'}")
    R, E, nu = float(attrs["radius"]), float(attrs["E"]), float(attrs["nu"])
    tau = _viscous_time(attrs, three)
    if attrs.get("plane") == "stress" and not three:
        nu = 0.0  # (plane stress: the half-plane's modulus is E itself, E* = E / (1 - nu^2) is plane strain's)
    if tau > 0:
        return P, tau, kelvin_voigt(lambda s: float(load(t=s)), t, R, E, nu, tau, "sphere" if three else "cylinder")
    return P, tau, (sphere if three else cylinder)(P, R, E, nu)


def _viscous_time(attrs, three: bool) -> float:
    """tau of a run's Kelvin-Voigt body with A = tau G (Model A's Hertz scenes derive a1, a2 from their tau), 0 for
    an elastic one (Model B without memory); a ParameterError where the viscous tensor is no multiple of G (Lee and
    Radok's solution here is for A = tau G)."""
    from ..errors import ParameterError
    from ..physics.kelvin_voigt import lame_moduli, plane_stress_moduli

    a1, a2 = float(attrs.get("a1") or 0.0), float(attrs.get("a2") or 0.0)
    if a1 == 0.0 and a2 == 0.0:
        return 0.0
    stress = attrs.get("plane") == "stress" and not three
    lam, two_mu = (plane_stress_moduli if stress else lame_moduli)(float(attrs["E"]), float(attrs["nu"]))
    tau = a2 / two_mu
    if attrs.get("viscous_tensor", "[]") not in ("[]", "", "()") or abs(a1 - tau * lam) > 1e-9 * max(a1, a2):
        raise ParameterError(f"hertz.profile: the run's viscous tensor (a1 = {a1:g}, a2 = {a2:g}) is no multiple of "
                             "its elastic one: Lee and Radok's pressure here is that of A = tau G (give tau)")
    return tau


def _not_hertz(attrs) -> str:
    """Why a run's archive is no Hertz problem that :func:`profile` can compare ("" where it is one): the body (a
    half-disc or a hemisphere), the material (E and nu, not a matrix), a rigid foundation (Model B's layer of
    thickness gap with F and c), and no memory (Lee-Radok's ``lee_radok`` for a Kelvin-Voigt body)."""
    if attrs.get("geometry") not in ("halfdisc", "hemisphere") or "load" not in attrs:
        return (f"the run is of scene {attrs.get('scene', '?')!r} ({attrs.get('geometry', '?')}): it compares a run "
                "of hertz, hertz3d, memory_hertz or memory_hertz3d")
    if attrs.get("elastic_tensor", "[]") not in ("[]", "", "()"):
        return "the run's elastic tensor is a matrix (elastic_tensor): Hertz's pressure is that of E and nu"
    layer = {k: float(attrs.get(k, 0.0)) for k in ("gap", "F", "c")}
    if any(layer.values()):
        return (f"the run's foundation is a compliant layer ({', '.join(f'{k} = {v:g}' for k, v in layer.items())}): "
                "Hertz's pressure is that of a rigid one (gap = F = c = 0)")
    if attrs.get("prony", "[]") not in ("[]", "", "()") or attrs.get("kernel", "0") not in ("0", ""):
        return "the run's body has a relaxation memory (prony, kernel): Hertz's pressure is an elastic body's"
    return ""

