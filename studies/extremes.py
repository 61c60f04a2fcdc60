"""Numerical stability at the extremes: both time schemes pushed to the ends of every parameter range.

Run:  python studies/extremes.py [--quick] [--out data/extremes]

Writes ``<out>/extremes.nc`` (one xarray Dataset, see :func:`to_dataset`),
``<out>/extremes.png`` (one panel per extreme) and ``<out>/stability_map.png``.
Full run: a few minutes on 2 cores; ``--quick``: about one minute (fewer values,
no k = 1e-5 runs).

Every sweep is a :class:`workbench.Study` (``reference=None``; the map's with a
reference run) on the slab (h = 0.05: 20 x 2 cells) or the rod (h = 0.1), with
one time grid per Study: a Study records only the times common to all its
cases, so cases that differ in k or T are separate Studies. Measures and errors
are taken on the records that a plain :func:`workbench.run` keeps (every step,
thinned to about 2000 records for longer runs:
``workbench.study.measures.run_records``), as in earlier archives. Every case
records: scheme, the parameter value, whether the run stayed bounded
(``status`` complete / diverged / newton_failed / refused by the k_crit check;
the Study's own text in ``study_status``), beta within [0, 1] and
non-increasing in time at every facet, the max penetration max_t,nodes (u_nu -
gap), Newton iterations (max, mean; implicit only), cost (wall time of setup +
time loop), the tip displacement (slab: u_y at (1, 0.1); rod: u at x = 1) and
beta at (1, 0) at the last computed time, the predicted k_crit of the explicit
scheme for that scene, and -- where the extreme has one -- an error against a
reference and a verdict ``ok`` against the expectation written in ``check``.

Extremes: c_nu 1 ... 1e8 (downward load; slope of log max penetration vs log
c_nu fitted over c_nu >= 1e4); k 1e-5 ... 0.5; L down to 1e-6; gamma_nu up to
1e6 in three settings -- (a) slab in tension (the glue is stiff, gamma_nu beta^2,
so it holds), (b) slab pressed into a soft foundation with the symmetric law
(u_nu > L: rate gamma_nu L^2 beta, near-instant debonding), (c) the rod of test
problem 1 (end held beyond L) against the reduced ODE; eps_a large (beta0 = 0.7
kept exactly); beta0 down to 1e-6 (against adhesion = False); nu up to 0.4999;
viscosity down to a2 = 1e-6 E (k_crit collapse, implicit k-convergence); T = 20
(complete debonding at (1, 0)); and two steady-state runs that the blow-up
detector stops (``false_alarm``).

Settings (SLAB = h 0.05, E 1000, nu 0.3, a1 30, a2 20; STIFF = c_nu 100,
gamma_nu 20, L 0.3, the slab of the stability issue, predicted k_crit 1.38e-3,
so the explicit scheme runs at k = 1e-3 where it is allowed). Loads that keep
changing are used on purpose (ramps, sines): at a steady state the
blow-up detector of :mod:`workbench.schemes.stepping` can stop a converged run
(see the ``false_alarm`` cases and the dataset attribute ``failures``).

Stability map criterion (explicit scheme, allow_unstable = True): on a grid of
(k, c_nu), each run takes N = 200 steps (T = 200 k) under the downward load
f_top(t) = (0, -(1 + 0.5 sin(2 pi t / T))), which engages the foundation spring
at once and never reaches a steady state. Reference: the implicit scheme with
k / 2 over the same T. A cell is

* ``stable``   -- the run completes and the contact displacement u_nu differs
  from the reference by at most 25 % of max|u_nu ref| over the second half of
  the run (max over time and contact nodes);
* ``off``      -- the run completes but is wildly off (> 25 %): a bounded but
  non-decaying oscillation or a wrong state;
* ``diverged`` -- the run is stopped by ``workbench.Diverged`` (non-finite,
  displacement > 10 x body, or a non-decaying sign-alternating oscillation).

The predicted boundary ``workbench.discrete.stability.critical_step(scene).k_crit`` is
drawn over the map for each c_nu.
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import os
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

import workbench
from workbench import references
from workbench.discrete import stability
from workbench.study import Study
from workbench.study.measures import beta_far, normal_displacement, run_records, summary, tip

SLAB = dict(h=0.05)
ROD = dict(h=0.1)
STIFF = dict(c_nu=100.0, gamma_nu=20.0, L=0.3)
K_EXPLICIT = 1e-3  # below STIFF's predicted k_crit = 1.38e-3 on the 20 x 2 mesh
K_IMPLICIT = 0.01
SCHEMES = (("implicit", K_IMPLICIT), ("explicit", K_EXPLICIT))
UP_RAMP = "(0, 2*t)"  # tension, keeps growing (no steady state)
SINE = "(0, -sin(3*pi*t))"  # compression until t = 1/3, then tension
MAP_STEPS = 200
MAP_OFF = 0.25
#: The Study's status text -> the suite's
STATUS = {"incomplete (Diverged)": "diverged", "incomplete (NewtonFailed)": "newton_failed"}


@functools.lru_cache(maxsize=None)
def _k_crit(scene_name, values):
    return stability.critical_step(workbench.scene(scene_name, **dict(values))).k_crit


def k_crit_of(scene_name, values):
    """Predicted k_crit of the explicit scheme for this scene (cached on every value but k, T, the scheme and
    allow_unstable, which do not enter)."""
    return _k_crit(scene_name, tuple(sorted((n, v) for n, v in values.items()
                                            if n not in ("k", "T", "scheme", "allow_unstable"))))


class Row:
    """One case of the suite: its extreme, scheme, swept value, label and parameter values, its ``record``
    (the Study's status and costs, the measures of :func:`workbench.study.measures.summary`, the extreme's
    errors and verdict) and its run ``ds`` (read from the Study's case archive when first used)."""

    def __init__(self, extreme, scene, scheme, parameter, value, label, values, record, path, ref_path=None):
        self.extreme, self.scene, self.scheme, self.parameter = extreme, scene, scheme, parameter
        self.value, self.label, self.values, self.record = value, label, values, record
        self.path, self.ref_path = path, ref_path

    @functools.cached_property
    def ds(self):
        """The run as a plain run records it (:func:`run_records`); None if it was refused."""
        return None if self.record["status"] == "refused" else run_records(workbench.load(self.path))


class Suite:
    """Runs the suite's Studies, each into its own folder of case archives under ``folder``."""

    def __init__(self, folder, workers=2):
        self.folder, self.workers, self.count = Path(folder), workers, 0

    def study(self, extreme, scene, parameter, *, k, scheme=None, sweep=None, grids=None, value=None,
              label=lambda case: "", measures=summary, reference=None, parallel=False, **overrides):
        """The cases of one ``Study(scene with k and overrides, scheme=scheme, sweep=sweep, grids=grids,
        reference=reference, measures=...)`` as rows: one time step k (and T) per Study; measures taken on the
        records a plain run keeps (:func:`run_records`); in this process unless ``parallel`` (worker start-up
        costs more than most of these cases). ``value(case)`` and ``label(case)`` name each case in the suite
        (default: its value of ``parameter``, no label)."""
        self.count += 1
        where = self.folder / f"{self.count:02d}-{extreme.replace('/', '-')}"
        swept = set(sweep or {}) | {n for g in grids or [] for n in g}
        overrides = {n: v for n, v in overrides.items() if n not in swept}
        names = set()

        def measure(ds):
            out = measures(run_records(ds))
            names.update(out)
            return out

        st = Study(workbench.scene(scene, **overrides, k=k), scheme=scheme, sweep=sweep, grids=grids,  # k with T
                   reference=reference, measures=measure if measures else None, workers=self.workers * parallel)
        with warnings.catch_warnings():  # the allow_unstable warning and an unresolved bonding layer are expected
            warnings.filterwarnings("ignore", category=RuntimeWarning, module=r"workbench\.")
            ds = st.run(where, progress=False)
        rows = []
        for case in st.listed:
            at = ds.sel({d: case[d] for d in ds.status.dims})
            status = str(at.status.values)
            with xr.open_dataset(where / f"{case.key}.nc") as f:
                message = f.attrs.get("failure", "")
                own = f.attrs.get("k_crit", math.nan)
            values = overrides | case.values()
            rec = dict(status=STATUS.get(status, status), study_status=status, message=message, k=float(case.k),
                       T=float(st.scene["T"]), k_crit=k_crit_of(scene, values), study=where.name, case_key=case.key,
                       k_crit_run=_own_limit(own, message),
                       wall_time=float(at.wall_time + at.setup_time))
            rec["bounded"] = {"complete": 1, "refused": -1}.get(rec["status"], 0)
            rec |= {n: int(at[n]) if n in _INT_FIELDS else float(at[n]) for n in sorted(names) if np.isfinite(at[n])}
            ref = where / f"{st.reference.of(case).key}.nc" if reference is not None else None
            rows.append(Row(extreme, scene, case.scheme, parameter, case[parameter] if value is None else value(case),
                            label(case), values, rec, where / f"{case.key}.nc", ref))
        return rows


def _own_limit(attr, message) -> float:
    """The explicit scheme's own predicted limit for the springs that act in a run: its ``k_crit`` attribute, or for a
    refused run the k_crit its refusal names (the bound with every spring, :func:`k_crit_of`, is lower)."""
    import re

    found = re.search(r"k_crit = ([0-9.eE+-]+) s", message or "")
    return float(found.group(1)) if found else float(attr)


def refused_as_predicted(c) -> bool:
    """The explicit scheme runs exactly when k is within its own prediction for the springs that act (a run above
    the bound with every spring acting is not refused where those springs do not act)."""
    r = c.record
    if c.scheme != "explicit":
        return r["status"] != "refused"
    return (r["status"] == "refused") == (r["k"] > r["k_crit_run"] * (1 + 1e-12))


def verdict(case, ok, check):
    case.record["ok"] = int(bool(ok))
    case.record["check"] = check


# ---------------------------------------------------------------------------------------------- extremes


def extreme_c_nu(suite, quick):
    """c_nu from 1 to 1e8 under a downward load: penetration -> 0 like 1/c_nu (Signorini limit)."""
    exps = range(0, 9, 2) if quick else range(0, 9)
    base = dict(SLAB, traction_top="(0, -1)", T=0.2)
    max_steps = 1500 if quick else 6000
    c_values = [10.0 ** e for e in exps]
    cases = suite.study("c_nu", "slab", "c_nu", sweep={"c_nu": c_values}, scheme=["implicit", "explicit"],
                        k=K_IMPLICIT, label=lambda c: "k = 0.01" if c.scheme == "explicit" else "", **base)
    for c in c_values:
        kc = k_crit_of("slab", dict(base, c_nu=c))
        if kc < K_IMPLICIT and base["T"] / (0.5 * kc) <= max_steps:
            cases += suite.study("c_nu", "slab", "c_nu", sweep={"c_nu": [c]}, scheme=["explicit"], k=0.5 * kc,
                                 label=lambda _: "k = k_crit/2", **base)
    imp = [c for c in cases if c.scheme == "implicit"]
    cs = np.array([c.value for c in imp])
    pen = np.array([c.record.get("max_penetration", np.nan) for c in imp])
    big = (cs >= 1e4) & (pen > 0)
    slope = float(np.polyfit(np.log(cs[big]), np.log(pen[big]), 1)[0]) if big.sum() >= 2 else math.nan
    for c in cases:
        r = c.record
        if c.scheme == "implicit":
            verdict(c, r["status"] == "complete" and r["beta_in_range"] and r["beta_monotone"],
                    "bounded, beta in [0, 1], non-increasing; fitted slope of log pen vs log c_nu (c_nu >= 1e4) "
                    f"= {slope:.4f}, expected in [-1.1, -0.9]")
        elif c.label == "k = 0.01":
            should_refuse = K_IMPLICIT > r["k_crit"]
            verdict(c, (r["status"] == "refused") == should_refuse,
                    "refused iff k = 0.01 > predicted k_crit")
        else:
            ref = next(i for i in imp if i.value == c.value).record["penetration_end"]
            r["error"] = abs(r["penetration_end"] - ref) / abs(ref)
            verdict(c, r["status"] == "complete" and r["error"] < 0.05,
                    "explicit at k_crit/2 bounded and its penetration at T within 5 % of the implicit one (the max "
                    "over time differs: forward Euler overshoots in the first steps)")
    return cases, dict(c_nu_slope=slope)


def extreme_k(suite, quick):
    """k from 1e-5 to 0.5: implicit bounded and converging; explicit refused above k_crit."""
    ks = [1e-4, 1e-3, 1e-2, 0.05, 0.1, 0.25, 0.5] if quick else [1e-5, 1e-4, 1e-3, 1e-2, 0.05, 0.1, 0.25, 0.5]
    base = dict(SLAB, **STIFF, traction_top=SINE, T=0.5)
    cases = []
    for k in ks:
        grids = [{"scheme": ["implicit", "explicit"]}]
        if k == 1e-2:  # above k_crit with allow_unstable: must be stopped, not return garbage
            grids.append({"scheme": ["explicit"], "allow_unstable": [True]})
        cases += suite.study("k", "slab", "k", grids=grids, k=k, parallel=k <= 1e-4,
                             label=lambda c: "allow_unstable" if c.get("allow_unstable") else "", **base)
    ref = next(c for c in cases if c.scheme == "implicit" and c.value == min(ks)).ds
    t_ref, tip_ref = ref.time.values, tip(ref)
    scale = np.abs(tip_ref).max()
    for c in cases:
        r = c.record
        if c.ds is not None and r["status"] == "complete" and (c.value > min(ks) or c.scheme == "explicit"):
            r["error"] = float(np.max(np.abs(tip(c.ds) - np.interp(c.ds.time.values, t_ref, tip_ref))) / scale)
        if c.label == "allow_unstable":
            verdict(c, r["status"] == "diverged", "explicit at k = 0.01 (> k_crit) with allow_unstable is stopped "
                    "as diverged")
        elif c.scheme == "implicit":
            verdict(c, r["status"] == "complete" and np.abs(r["tip_u"]) < 1.0 and r["beta_in_range"]
                    and r["beta_monotone"], "implicit bounded at every k, beta in [0, 1] and non-increasing "
                    f"(error: max_t |tip - tip_ref| / max|tip_ref|, ref = implicit k = {min(ks):g})")
        else:
            should_refuse = c.value > r["k_crit"]
            verdict(c, (r["status"] == "refused") if should_refuse else (r["status"] == "complete"),
                    "explicit refused iff k > predicted k_crit, bounded otherwise")
    return cases, {}


def extreme_L(suite, quick):
    """Bond length L down to 1e-6: adhesion nearly switched off, beta must stay in [0, 1]."""
    Ls = [0.3, 1e-3, 1e-6] if quick else [0.3, 1e-2, 1e-4, 1e-6]
    cases = []
    for scheme, k in SCHEMES:
        cases += suite.study("L", "slab", "L", sweep={"L": Ls}, scheme=[scheme], k=k,
                             **dict(SLAB, **STIFF, traction_top=UP_RAMP, T=0.5))
    for c in cases:
        r = c.record
        verdict(c, r["status"] == "complete" and r["beta_in_range"] and r["beta_monotone"],
                "bounded, beta in [0, 1] and non-increasing")
    return cases, {}


def extreme_gamma(suite, quick):
    """gamma_nu up to 1e6 in three settings (see the module docstring of the findings)."""
    gs = [0.3, 1e2, 1e4, 1e6] if quick else [0.3, 20.0, 1e2, 1e4, 1e6]
    cases = []
    # (a) slab in tension, load ramp: a stiff glue (stiffness gamma beta^2) holds, u_nu ~ f / gamma
    # (b) slab pressed into a soft foundation with the symmetric law (eq. 3.7 as printed): u_nu > L, so the
    #     debonding rate is gamma L^2 beta -> near-instant debonding, nothing holds it back in compression
    for extreme, ov in (("gamma_nu/slab-tension", dict(SLAB, **STIFF, traction_top=UP_RAMP, T=0.5)),
                        ("gamma_nu/slab-compression-symmetric",
                         dict(SLAB, c_nu=1.0, L=0.3, bonding_truncation="symmetric", traction_top="(0, -1)", T=0.1))):
        for scheme, k in SCHEMES:
            cases += suite.study(extreme, "slab", "gamma_nu", sweep={"gamma_nu": gs}, scheme=[scheme], k=k, **ov)
    # (c) rod of test problem 1 (end held 0.6 away, beyond L): reference = the reduced ODE (references.rod_ode);
    #     explicit (and implicit) also at k = min(0.01, k_crit/2) over T = min(1, 1000 k)
    rod = dict(ROD, T=1.0)
    k_res = {g: min(K_IMPLICIT, 0.5 * k_crit_of("tp1", dict(rod, gamma_nu=g))) for g in gs}
    same = [g for g in gs if k_res[g] == K_IMPLICIT]  # explicit at k = 0.01 too: with the implicit runs
    grids = [{"scheme": ["implicit"], "gamma_nu": gs}] + ([{"scheme": ["explicit"], "gamma_nu": same}] if same else [])

    def label(c):
        return "k = 0.01" if c.scheme == "implicit" and c.k == K_IMPLICIT else "k = min(0.01, k_crit/2)"

    cases += suite.study("gamma_nu/rod-tp1", "tp1", "gamma_nu", grids=grids, k=K_IMPLICIT, label=label, **rod)
    for g in gs:
        if k_res[g] < K_IMPLICIT:
            cases += suite.study("gamma_nu/rod-tp1", "tp1", "gamma_nu", sweep={"gamma_nu": [g]},
                                 scheme=["explicit", "implicit"], k=k_res[g], label=label,
                                 **dict(rod, T=min(1.0, 1000 * k_res[g])))
    for c in cases:
        r = c.record
        base_ok = r["status"] in ("complete", "refused") and (r["status"] == "refused" or
                                                              (r["beta_in_range"] and r["beta_monotone"]))
        if c.extreme.endswith("slab-tension"):
            verdict(c, base_ok and refused_as_predicted(c),
                    "bounded (explicit: refused iff k > its predicted k_crit), beta in [0, 1], non-increasing")
        elif c.extreme.endswith("symmetric"):
            ok = base_ok and refused_as_predicted(c)
            if r["status"] == "complete":
                b = beta_far(c.ds)
                hit = np.nonzero(b < 1e-3)[0]
                r["t_debond"] = float(c.ds.time.values[hit[0]]) if hit.size else math.nan
                if c.value >= 1e4:
                    ok = ok and hit.size and r["t_debond"] <= 0.02
            verdict(c, ok, "beta in [0, 1], non-increasing; gamma_nu >= 1e4: beta(1, 0) < 1e-3 within 0.02 s")
        else:
            physics = {n: v for n, v in c.values.items() if n != "scheme"}
            _, b_ode = references.rod_ode(workbench.scene("tp1", **dict(physics, k=r["T"] / 10)))(np.array([r["T"]]))
            r["beta_ode"] = float(b_ode[0])
            resolved = c.ds is None or c.ds.attrs.get("bonding_resolved", 1) == 1
            if r["status"] == "complete":
                r["error"] = abs(r["beta_end"] - r["beta_ode"])
            if resolved:
                verdict(c, base_ok and r.get("error", 0.0) <= 0.05,
                        "beta(1, T) within 0.05 of the reduced-ODE reference (rod_ode), in [0, 1], non-increasing")
            else:
                # k gamma_nu L^2 > 0.1: the initial debonding layer (~1/(gamma_nu L^2) s) is shorter than a
                # step; no first-order step resolves it. Expected: bounded, the end held near the foundation
                # (as by the ODE), beta admissible, and the run says so (bonding_resolved = 0, a warning).
                attached = abs(float(c.ds.u_contact.isel(time=-1).squeeze())) < 1e-3
                verdict(c, base_ok and attached,
                        "layer not resolved (k gamma_nu L^2 > 0.1, flagged): bounded, end held near the foundation, "
                        "beta in [0, 1], non-increasing")
    return cases, {}


def extreme_eps_a(suite, quick):
    """Large limit bond energy eps_a: no debonding at all, beta stays exactly beta0 = 0.7."""
    vals = [0.0, 1.0, 1e3] if quick else [0.0, 0.1, 1.0, 1e3]
    cases = []
    for scheme, k in SCHEMES:
        cases += suite.study("eps_a", "slab", "eps_a", sweep={"eps_a": vals}, scheme=[scheme], k=k,
                             **dict(SLAB, **STIFF, beta0=0.7, traction_top=UP_RAMP, T=0.5))
    # gamma_nu beta0 L^2 = 1.26 bounds the debonding rate: above it nothing can debond
    for c in cases:
        r = c.record
        ok = r["status"] == "complete" and r["beta_in_range"] and r["beta_monotone"]
        if c.value >= 20.0 * 0.7 * 0.3 ** 2:
            ok = ok and r["beta_exact_beta0"]
        verdict(c, ok, "bounded, beta in [0, 1], non-increasing; eps_a >= gamma beta0 L^2 = 1.26: beta == beta0 "
                "exactly at every facet and time")
    return cases, {}


def extreme_beta0(suite, quick):
    """beta0 -> 1e-6: the no-adhesion limit (compared with adhesion = False)."""
    vals = [1.0, 1e-3, 1e-6] if quick else [1.0, 1e-2, 1e-4, 1e-6]
    cases = []
    for scheme, k in SCHEMES:
        mine = suite.study("beta0", "slab", "beta0", grids=[{"adhesion": [False]}, {"beta0": vals}], scheme=[scheme],
                           k=k, value=lambda c: c.beta0 if c.adhesion else 0.0,
                           label=lambda c: "" if c.adhesion else "adhesion = False",
                           **dict(SLAB, **STIFF, traction_top=UP_RAMP, T=0.5))
        free = next(c for c in mine if not c.values["adhesion"])
        for c in mine:
            if c is free:
                continue
            r, b0 = c.record, c.value
            r["error"] = abs(r["tip_u"] - free.record["tip_u"]) / abs(free.record["tip_u"])
            ok = r["status"] == "complete" and r["beta_in_range"] and r["beta_monotone"] and r["beta_min"] <= b0
            if b0 <= 1e-6:
                ok = ok and r["error"] < 1e-6
            verdict(c, ok, "bounded, 0 <= beta <= beta0, non-increasing; beta0 = 1e-6: tip within 1e-6 (relative) "
                    "of the no-adhesion run (error = relative tip difference)")
        verdict(free, free.record["status"] == "complete", "bounded")
        cases += mine
    return cases, {}


def extreme_nu(suite, quick):
    """nu -> 0.4999 (plane stress: lambda* = E nu / (1 - nu^2) stays bounded, no locking expected)."""
    vals = [0.3, 0.49, 0.4995, 0.4999] if quick else [0.3, 0.45, 0.49, 0.499, 0.4995, 0.4999]
    cases = []
    for scheme, k in SCHEMES:
        cases += suite.study("nu", "slab", "nu", sweep={"nu": vals}, scheme=[scheme], k=k,
                             **dict(SLAB, **STIFF, traction_top=SINE, T=0.5))
    for c in cases:
        r = c.record
        ref = next(i for i in cases if i.scheme == c.scheme and i.value == 0.4995).record
        r["error"] = abs(r["tip_u"] - ref["tip_u"]) / abs(ref["tip_u"])
        ok = r["status"] == "complete" and r["beta_in_range"] and r["beta_monotone"]
        if c.value == 0.4999:
            ok = ok and r["error"] < 1e-3
        verdict(c, ok, "bounded; nu = 0.4999 within 0.1 % of nu = 0.4995 (error = relative tip difference)")
    return cases, {}


def extreme_viscosity(suite, quick):
    """a1, a2 scaled down to a2 = 1e-6 E: nearly elastic; explicit k_crit collapses, implicit converges."""
    scales = [1.0, 1e-2, 5e-5] if quick else [1.0, 1e-2, 1e-4, 5e-5]  # a2 = 20 s: a2 / E = 0.02 s ... 1e-6
    ks = [0.05, 0.02, 0.01, 0.005] if quick else [0.05, 0.025, 0.0125, 0.00625, 0.003125]
    k_ref = 0.001
    ov = dict(SLAB, **STIFF, traction_top="(0, sin(pi*t))", T=0.5)
    visc = [{"a1": [30.0 * s], "a2": [20.0 * s]} for s in scales]
    smallest = visc[-1]
    ratio = lambda c: c.a2 / 1000.0  # noqa: E731  (a2 / E)
    cases = suite.study("viscosity", "slab", "a2/E", grids=visc, scheme=["implicit"], k=K_IMPLICIT, value=ratio, **ov)
    # explicit at k = 1e-3 (also with allow_unstable at the smallest viscosity) and the implicit reference k = 1e-3
    cases += suite.study("viscosity", "slab", "a2/E", scheme=["explicit"], k=k_ref, value=ratio,
                         grids=visc + [dict(smallest, allow_unstable=[True]), dict(smallest, scheme=["implicit"])],
                         label=lambda c: "allow_unstable" if c.get("allow_unstable") else
                         "reference" if c.scheme == "implicit" else "", **ov)
    sweep = []
    for k in ks:
        sweep += suite.study("viscosity", "slab", "a2/E", grids=[smallest], scheme=["implicit"], k=k, value=ratio,
                             label=lambda _: "k sweep", **ov)
    cases += sweep
    ref = next(c for c in cases if c.label == "reference")
    t_ref, tip_ref = ref.ds.time.values, tip(ref.ds)
    for c in sweep:
        c.record["error"] = float(np.max(np.abs(tip(c.ds) - np.interp(c.ds.time.values, t_ref, tip_ref)))
                                  / np.abs(tip_ref).max())
    errs = [c.record["error"] for c in sweep]
    order = float(np.polyfit(np.log(ks), np.log(errs), 1)[0])
    for c in sweep:
        verdict(c, c.record["status"] == "complete" and all(a > b for a, b in zip(errs, errs[1:]))
                and order >= 0.8, f"implicit converges as k decreases: errors decrease, observed order "
                f"{order:.2f} >= 0.8 (ref = implicit k = {k_ref:g})")
    verdict(ref, ref.record["status"] == "complete", "bounded")
    kc1 = next(c for c in cases if c.value == 0.02).record["k_crit"]
    for c in cases:
        r = c.record
        if "ok" in r:
            continue
        if c.label == "allow_unstable":
            verdict(c, r["status"] == "diverged", "explicit at k = 1e-3 >> k_crit with allow_unstable is stopped")
        elif c.scheme == "implicit":
            verdict(c, r["status"] == "complete" and r["beta_in_range"] and r["beta_monotone"], "bounded")
        else:
            scale = c.value / 0.02
            verdict(c, abs(r["k_crit"] / (kc1 * scale) - 1) < 0.05 and (r["status"] == "refused") == (r["k"] > r["k_crit"]),
                    "predicted k_crit proportional to the viscosity (within 5 %); refused iff k > k_crit")
    order = next((c.record["check"] for c in cases if c.label == "k sweep"), "")
    return cases, dict(viscosity_order=order)


def extreme_long_T(suite, quick):
    """T long enough for complete debonding at (1, 0): beta -> 0, stays there, never negative."""
    ov = dict(SLAB, **STIFF, traction_top="(0, 0.5 + 0.05*t)", T=20.0)
    cases = []
    for scheme, k in (("implicit", 0.02),) + ((("explicit", K_EXPLICIT),) if not quick else ()):
        cases += suite.study("long_T", "slab", "T", scheme=[scheme], k=k, value=lambda _: 20.0, **ov)
    for c in cases:
        r = c.record
        ok = r["status"] == "complete" and r["beta_in_range"] and r["beta_monotone"]
        if ok:
            b = beta_far(c.ds)
            hit = np.nonzero(b < 1e-6)[0]
            r["t_debond"] = float(c.ds.time.values[hit[0]]) if hit.size else math.nan
            r["debonded_fraction"] = float((c.ds.beta.isel(time=-1) < 1e-6).mean())
            r["beta_exact_zero"] = int(np.any(b == 0.0))
            ok = hit.size > 0 and np.all(b[hit[0]:] < 1e-6)
        verdict(c, ok, "beta(1, 0) < 1e-6 before T and stays below, beta >= 0 and non-increasing everywhere")
    return cases, {}


def false_alarm(suite):
    """Converged runs at a steady state stopped by the oscillation watch (a package failure, see ``failures``).

    Constant load (0, -1), c_nu = 1 (predicted k_crit = 0.0455): the explicit scheme at k = 0.04 < k_crit and the
    implicit scheme at one k that showed it (round-off decides, so neighbouring k may pass).
    """
    base = dict(SLAB, c_nu=1.0, traction_top="(0, -1)")
    cases = []
    for scheme, k, T in (("explicit", 0.04, 8.0), ("implicit", 0.009280408877267919, 9.280408877267919)):
        cases += suite.study("false_alarm", "slab", "k", scheme=[scheme], k=k, value=lambda c: c.k, **base, T=T)
    for c in cases:
        r = c.record
        if c.ds is not None:
            u_nu = normal_displacement(c.ds)
            v = np.diff(u_nu, axis=0) / r["k"]
            r["velocity_at_stop"] = float(np.abs(v[-12:]).max())
            r["velocity_peak"] = float(np.abs(v).max())
        verdict(c, r["status"] == "complete", "a run at a steady state under a constant load completes (the "
                "velocity is round-off, ~1e-11 m/s, not an instability)")
    return cases, {}


# ---------------------------------------------------------------------------------------------- stability map


def stability_map(suite, quick):
    """Explicit scheme on a (k, c_nu) grid, run with allow_unstable = True and classified (module docstring).

    One Study per k (its T = MAP_STEPS k), over the c_nu that have that k, with the implicit run at k / 2 as its
    reference run (recorded at the explicit run's times).
    """
    c_values = [1.0, 1e2, 1e4] if quick else [1.0, 10.0, 1e2, 1e3, 1e4]
    grid = 10.0 ** np.arange(-6, -0.4, 1.0 if quick else 0.5)
    k_crit, ks = {}, {}
    for c in c_values:
        kc = k_crit[c] = k_crit_of("slab", dict(SLAB, c_nu=c))
        near = [0.8 * kc, 1.25 * kc] if quick else [0.7 * kc, 0.9 * kc, 1.1 * kc, 1.4 * kc]
        ks[c] = sorted(set(grid.tolist()) | set(near))
    runs = {}
    for k in sorted({k for c in c_values for k in ks[c]}):
        T = MAP_STEPS * k
        for row in suite.study("map", "slab", "k", sweep={"c_nu": [c for c in c_values if k in ks[c]]},
                               scheme=["explicit"], k=k, measures=None, allow_unstable=True,
                               reference={"scheme": "implicit", "k": k / 2, "allow_unstable": False},
                               traction_top=f"(0, -(1 + 0.5*sin(2*pi*t/{T!r})))", T=T, **SLAB):
            runs[row.values["c_nu"], k] = row
    cells = []
    for c in c_values:
        for k in ks[c]:
            exp = runs[c, k]
            ref = workbench.load(exp.ref_path)
            rec = dict(c_nu=c, k=k, k_crit=k_crit[c], status=exp.record["status"], message=exp.record["message"],
                       wall_time=exp.record["wall_time"] + ref.attrs["wall_time"] + ref.attrs["setup_time"],
                       error=math.nan, ref_status=STATUS.get(ref.attrs["status"], ref.attrs["status"]))
            if exp.ds is not None:
                a = normal_displacement(exp.ds)
                b = normal_displacement(ref)[: a.shape[0]]  # recorded at the explicit run's times t = 0, k, 2k, ...
                n = int(np.sum(np.isfinite(a[:, 0])))
                late = slice(MAP_STEPS // 2, n) if n > MAP_STEPS // 2 else slice(0, n)
                with np.errstate(invalid="ignore"):
                    rec["error"] = float(np.max(np.abs(a[late] - b[late])) / np.abs(b).max())
            if rec["status"] == "complete":
                rec["cls"] = "stable" if rec["error"] <= MAP_OFF else "off"
            else:
                rec["cls"] = "diverged" if rec["status"] == "diverged" else rec["status"]
            cells.append(rec)
    curve_c = np.logspace(0, 4, 17)
    curve_k = np.array([k_crit_of("slab", dict(SLAB, c_nu=float(c))) for c in curve_c])
    bounds = {}
    for c in c_values:
        mine = sorted((r for r in cells if r["c_nu"] == c), key=lambda r: r["k"])
        unstable = [r["k"] for r in mine if r["cls"] != "stable"]
        first_bad = min(unstable) if unstable else math.inf
        last_good = max((r["k"] for r in mine if r["cls"] == "stable" and r["k"] < first_bad), default=math.nan)
        bounds[c] = (last_good, first_bad, mine[0]["k_crit"])
    return cells, (curve_c, curve_k), bounds


# ---------------------------------------------------------------------------------------------- output

_FLOAT_FIELDS = ("value", "k", "T", "k_crit", "max_penetration", "penetration_end", "tip_u", "beta_end", "beta_min", "beta_max_increase",
                 "newton_mean", "wall_time", "t_end", "error", "beta_ode", "t_debond", "debonded_fraction",
                 "velocity_at_stop", "velocity_peak")
_INT_FIELDS = ("bounded", "beta_in_range", "beta_monotone", "beta_exact_beta0", "newton_max", "steps_done", "ok",
               "beta_exact_zero")
_STR_FIELDS = ("status", "message", "check", "study_status", "study", "case_key")
_META = {
    "extreme": ("", "which extreme the case belongs to"),
    "scene": ("", "scene name"), "scheme": ("", "time scheme"), "parameter": ("", "the swept parameter"),
    "label": ("", "variant within the extreme"), "value": ("", "value of the swept parameter"),
    "k": ("s", "time step"), "T": ("s", "final time asked"), "k_crit": ("s", "predicted k_crit of the explicit scheme"),
    "max_penetration": ("m", "max over time and contact nodes of u_nu - gap"),
    "penetration_end": ("m", "max over contact nodes of u_nu - gap at the last computed time"),
    "tip_u": ("m", "tip displacement at the last computed time: u_y(1, 0.1) slab, u(1) rod"),
    "beta_end": ("1", "beta at (1, 0) at the last computed time"), "beta_min": ("1", "min of beta over time and facets"),
    "beta_max_increase": ("1", "largest increase of beta between recorded steps (<= 0: non-increasing)"),
    "newton_max": ("1", "max Newton iterations per step (implicit; -1 otherwise)"),
    "newton_mean": ("1", "mean Newton iterations per step (implicit)"),
    "wall_time": ("s", "wall time of setup + time loop"), "t_end": ("s", "last computed time"),
    "error": ("1", "error against the extreme's reference (see check)"),
    "beta_ode": ("1", "beta(1, T) of the reduced rod ODE"), "t_debond": ("s", "first time beta(1, 0) < threshold"),
    "debonded_fraction": ("1", "fraction of contact facets with beta < 1e-6 at T"),
    "velocity_at_stop": ("m/s", "max |u_nu'| over the last 12 steps"),
    "velocity_peak": ("m/s", "max |u_nu'| over the run"),
    "bounded": ("1", "1 complete, 0 stopped (diverged/error), -1 not run (refused)"),
    "beta_in_range": ("1", "beta in [0, 1] everywhere (-1: no beta)"),
    "beta_monotone": ("1", "beta non-increasing in time at every facet (-1: no beta)"),
    "beta_exact_beta0": ("1", "beta == beta0 exactly everywhere (-1: no beta)"),
    "steps_done": ("1", "time steps computed"), "ok": ("1", "the expectation in check holds"),
    "beta_exact_zero": ("1", "beta(1, 0) reached exactly 0"),
    "status": ("", "complete | diverged | newton_failed | refused"), "message": ("", "failure message"),
    "check": ("", "the expectation this case is judged by"),
    "study_status": ("", "the Study's status: complete | incomplete (the failure) | refused"),
    "study": ("", "the Study (folder of case archives) the case belongs to"),
    "case_key": ("", "the case's key (file stem) in its Study"),
}


def to_dataset(cases, cells, curve, bounds, summary, quick):
    """One Dataset: per-case table (dim ``case``), map cells (dim ``cell``) and the predicted curve."""
    n = len(cases)
    data = {}
    for name in ("extreme", "scene", "scheme", "parameter", "label"):
        data[name] = ("case", np.array([getattr(c, name) for c in cases], dtype=object))
    data["value"] = ("case", np.array([c.value for c in cases], dtype=float))
    for name in _FLOAT_FIELDS[1:]:
        data[name] = ("case", np.array([c.record.get(name, np.nan) for c in cases], dtype=float))
    for name in _INT_FIELDS:
        data[name] = ("case", np.array([c.record.get(name, -1) for c in cases], dtype=np.int64))
    for name in _STR_FIELDS:
        data[name] = ("case", np.array([c.record.get(name, "") for c in cases], dtype=object))
    ds = xr.Dataset(data, coords={"case": np.arange(n)})
    for name, (units, long_name) in _META.items():
        ds[name].attrs.update(units=units, long_name=long_name)
    m = {
        "map_c_nu": ("cell", [r["c_nu"] for r in cells], "Pa/m", "c_nu of the map cell"),
        "map_k": ("cell", [r["k"] for r in cells], "s", "time step of the map cell"),
        "map_k_crit": ("cell", [r["k_crit"] for r in cells], "s", "predicted k_crit"),
        "map_error": ("cell", [r["error"] for r in cells], "1", "max |u_nu - u_nu ref| / max|u_nu ref|, 2nd half"),
        "map_class": ("cell", np.array([r["cls"] for r in cells], dtype=object), "", "stable | off | diverged"),
        "map_message": ("cell", np.array([r["message"] for r in cells], dtype=object), "", "Diverged message"),
        "map_wall_time": ("cell", [r["wall_time"] for r in cells], "s", "wall time (explicit + reference)"),
        "curve_c_nu": ("curve", curve[0], "Pa/m", "c_nu of the predicted curve"),
        "curve_k_crit": ("curve", curve[1], "s", "predicted k_crit (workbench.discrete.stability.critical_step)"),
    }
    for name, (dim, vals, units, long_name) in m.items():
        ds[name] = xr.Variable(dim, np.asarray(vals), attrs={"units": units, "long_name": long_name})
    ds.attrs.update({
        "title": "workbench extremes suite: stability at the ends of the parameter ranges",
        "mode": "quick" if quick else "full",
        "map_criterion": (f"explicit, allow_unstable, N = {MAP_STEPS} steps, T = N k, load (0, -(1 + 0.5 sin(2 pi t/T))); "
                          f"stable: complete and max over the 2nd half of |u_nu - u_nu_ref| <= {MAP_OFF} max|u_nu_ref| "
                          "(ref: implicit, k/2); off: complete but beyond; diverged: workbench.Diverged"),
        "map_boundary": json.dumps({f"{c:g}": {"last_stable_k": b[0], "first_unstable_k": b[1], "k_crit": b[2]}
                                    for c, b in bounds.items()}),
        "summary": json.dumps(summary, default=float),
        "failures": json.dumps([dict(case=i, extreme=c.extreme, scheme=c.scheme, value=c.value, label=c.label,
                                     status=c.record["status"], message=c.record["message"], check=c.record["check"])
                                for i, c in enumerate(cases) if not c.record.get("ok", 1)]),
        "workbench_version": workbench.__version__,
        "cases": "every case is a case of a workbench.Study with one time grid (k, T); measures "
                 "(workbench.study.measures.summary) and errors on the records a plain workbench.run keeps "
                 "(workbench.study.measures.run_records)",
    })
    return ds


def plot(cases, cells, curve, summary, out):
    """extremes.png (one panel per extreme) and stability_map.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    def sel(extreme, scheme=None, label=None):
        return [c for c in cases if c.extreme == extreme and (scheme is None or c.scheme == scheme)
                and (label is None or c.label == label)]

    fig, ax = plt.subplots(3, 3, figsize=(15, 12))
    ax = ax.ravel()
    # c_nu
    a = ax[0]
    for scheme, label, mk in (("implicit", "", "o-"), ("explicit", "k = k_crit/2", "s")):
        cs = sel("c_nu", scheme, label)
        a.loglog([c.value for c in cs], [c.record["max_penetration"] for c in cs], mk,
                 label=f"{scheme} {label or 'k = 0.01'}", mfc="none" if scheme == "explicit" else None)
    cs = np.logspace(0, 8, 9)
    a.loglog(cs[4:], 1.04e-4 * (cs[4:] / 1e4) ** -1.0, "k:", label="slope -1")
    a.set(xlabel="c_nu [Pa/m]", ylabel="max penetration [m]",
          title=f"c_nu: fitted slope {summary.get('c_nu_slope', math.nan):.3f} (c_nu >= 1e4)")
    a.legend(fontsize=8)
    # k
    a = ax[1]
    imp = [c for c in sel("k", "implicit") if "error" in c.record]
    a.loglog([c.value for c in imp], [c.record["error"] for c in imp], "o-", label="implicit")
    exp = [c for c in sel("k", "explicit", "") if "error" in c.record]
    a.loglog([c.value for c in exp], [c.record["error"] for c in exp], "s", mfc="none", label="explicit (k <= k_crit)")
    ref_fused = [c.value for c in sel("k", "explicit", "") if c.record["status"] == "refused"]
    for k in ref_fused:
        a.axvline(k, color="r", alpha=0.3)
    a.axvline(sel("k", "explicit")[0].record["k_crit"], color="k", ls="--", label="predicted k_crit")
    a.set(xlabel="k [s]", ylabel="max_t |tip - ref| / max|ref|", title="k: implicit bounded; red = explicit refused")
    a.legend(fontsize=8)
    # L
    a = ax[2]
    for c in sel("L", "implicit"):
        a.plot(c.ds.time, beta_far(c.ds), label=f"L = {c.value:g}")
    a.set(xlabel="t [s]", ylabel="beta(1, 0)", title="L: beta stays in [0, 1]")
    a.legend(fontsize=8)
    # gamma
    a = ax[3]
    for c in sel("gamma_nu/slab-compression-symmetric", "implicit"):
        a.semilogy(c.ds.time, np.maximum(beta_far(c.ds), 1e-300), "o-", ms=3, label=f"compression sym., gamma {c.value:g}")
    for c in sel("gamma_nu/slab-tension", "implicit"):
        a.semilogy(c.ds.time, beta_far(c.ds), "--", label=f"tension, gamma {c.value:g}")
    a.set(xlabel="t [s]", ylabel="beta(1, 0)", title="gamma_nu (slab, implicit)", ylim=(1e-20, 2))
    a.legend(fontsize=6)
    a = ax[4]
    rod = sel("gamma_nu/rod-tp1")
    for scheme, label, mk in (("implicit", "k = 0.01", "o-"), ("implicit", "k = min(0.01, k_crit/2)", "^"),
                              ("explicit", "k = min(0.01, k_crit/2)", "s")):
        cs = [c for c in rod if c.scheme == scheme and c.label == label and c.record["status"] == "complete"]
        a.semilogx([c.value for c in cs], [c.record["beta_end"] for c in cs], mk, mfc="none", label=f"{scheme} {label}")
    cs = [c for c in rod if c.label == "k = 0.01"]
    a.semilogx([c.value for c in cs], [c.record["beta_ode"] for c in cs], "k:", label="reduced ODE")
    a.set(xlabel="gamma_nu [Pa/m]", ylabel="beta(1, T)", title="gamma_nu: rod tp1 (end held beyond L)")
    a.legend(fontsize=8)
    # eps_a / beta0
    a = ax[5]
    for c in sel("eps_a", "implicit"):
        a.plot(c.ds.time, beta_far(c.ds), label=f"eps_a = {c.value:g}")
    a.set(xlabel="t [s]", ylabel="beta(1, 0)", title="eps_a (beta0 = 0.7): large eps_a keeps beta0")
    a.legend(fontsize=8)
    # nu
    a = ax[6]
    for scheme, mk in (("implicit", "o-"), ("explicit", "s--")):
        cs = sel("nu", scheme)
        a.plot([c.value for c in cs], [c.record["tip_u"] for c in cs], mk, mfc="none", label=scheme)
    a.set(xlabel="nu", ylabel="tip u_y(1, 0.1) at T [m]", title="nu -> 0.4999 (plane stress)")
    a.legend(fontsize=8)
    # viscosity
    a = ax[7]
    sw = sel("viscosity", "implicit", "k sweep")
    if sw:
        a.loglog([c.record["k"] for c in sw], [c.record["error"] for c in sw], "o-",
                 label=f"implicit, a2/E = {sw[0].value:g}")
        ks = np.array([c.record["k"] for c in sw])
        a.loglog(ks, sw[-1].record["error"] * ks / ks[-1], "k:", label="order 1")
    vis = sel("viscosity", "explicit", "")
    text = "\n".join(f"a2/E = {c.value:g}: k_crit = {c.record['k_crit']:.2g} s" for c in vis)
    a.text(0.03, 0.97, "predicted explicit k_crit:\n" + text, transform=a.transAxes, va="top", fontsize=7)
    a.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    a.set(xlabel="k [s]", ylabel="max_t |tip - ref| / max|ref| (ref: k = 0.001)", title="tiny viscosity (implicit)")
    a.legend(fontsize=8, loc="lower right")
    # long T
    a = ax[8]
    for c in sel("long_T"):
        a.semilogy(c.ds.time, np.maximum(beta_far(c.ds), 1e-300), label=c.scheme)
    a.axhline(1e-6, color="k", ls=":")
    a.set(xlabel="t [s]", ylabel="beta(1, 0)", title="long T: complete debonding at (1, 0)")
    a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "extremes.png", dpi=110)
    plt.close(fig)

    fig, a = plt.subplots(figsize=(7.5, 5.5))
    style = {"stable": ("o", "tab:green"), "off": ("D", "tab:orange"), "diverged": ("x", "tab:red")}
    for cls, (mk, col) in style.items():
        pts = [r for r in cells if r["cls"] == cls]
        a.scatter([r["c_nu"] for r in pts], [r["k"] for r in pts], marker=mk, color=col, label=cls, s=40)
    other = [r for r in cells if r["cls"] not in style]
    if other:
        a.scatter([r["c_nu"] for r in other], [r["k"] for r in other], marker="*", color="k", label="other failure")
    a.loglog(curve[0], curve[1], "k-", label="predicted k_crit")
    a.set(xscale="log", yscale="log", xlabel="c_nu [Pa/m]", ylabel="k [s]",
          title=f"Explicit scheme, slab 20x2, {MAP_STEPS} steps, allow_unstable\n"
                f"stable: bounded and within {int(100 * MAP_OFF)} % of implicit (k/2) over the 2nd half")
    a.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(out / "stability_map.png", dpi=110)
    plt.close(fig)


def table(cases):
    """A compact text table of the cases."""
    rows = [f"{'extreme':36s} {'scheme':8s} {'value':>9s} {'k':>9s} {'status':9s} {'pen':>9s} {'tip':>10s} "
            f"{'beta(1,0)':>9s} {'Nmax':>4s} {'Nmean':>5s} {'wall':>6s} {'error':>8s} ok"]
    for c in cases:
        r = c.record
        rows.append(f"{(c.extreme + ' ' + c.label)[:36]:36s} {c.scheme:8s} {c.value:9.5g} {r['k']:9.3g} "
                    f"{r['status'][:9]:9s} {r.get('max_penetration', np.nan):9.2e} {r.get('tip_u', np.nan):10.3e} "
                    f"{r.get('beta_end', np.nan):9.3g} {r.get('newton_max', -1):4d} {r.get('newton_mean', np.nan):5.2f} "
                    f"{r['wall_time']:6.2f} {r.get('error', np.nan):8.2e} {r.get('ok', -1)}")
    return "\n".join(rows)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer values, about one minute")
    p.add_argument("--out", default="data/extremes", help="output folder (default data/extremes)")
    p.add_argument("--cases", help="folder for the Studies' case archives, kept (default: a temporary folder); a "
                                   "rerun with the same folder recomputes only the missing cases")
    p.add_argument("--workers", type=int, default=2, help="worker subprocesses per Study (default 2; 0: in process)")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # the workers' runs warn of what is expected here (allow_unstable, unresolved bonding layers, P1 on the slab)
    os.environ["PYTHONWARNINGS"] = ",".join(filter(None, [os.environ.get("PYTHONWARNINGS"), "ignore::RuntimeWarning"]))
    t0 = time.perf_counter()
    with contextlib.nullcontext(args.cases) if args.cases else tempfile.TemporaryDirectory() as folder:
        suite = Suite(folder, args.workers)
        cases, summary = [], {}
        for fn in (extreme_c_nu, extreme_k, extreme_L, extreme_gamma, extreme_eps_a, extreme_beta0, extreme_nu,
                   extreme_viscosity, extreme_long_T):
            t1 = time.perf_counter()
            c, s = fn(suite, args.quick)
            cases += c
            summary |= s
            print(f"{fn.__name__:20s} {len(c):3d} cases  {time.perf_counter() - t1:6.1f} s", flush=True)
        c, _ = false_alarm(suite)
        cases += c
        t1 = time.perf_counter()
        cells, curve, bounds = stability_map(suite, args.quick)
        print(f"{'stability_map':20s} {len(cells):3d} cells  {time.perf_counter() - t1:6.1f} s", flush=True)
        implicit = [c.record["newton_max"] for c in cases if "newton_max" in c.record]
        summary |= dict(newton_max_overall=max(implicit), runtime=time.perf_counter() - t0)
        ds = to_dataset(cases, cells, curve, bounds, summary, args.quick)
        workbench.write(ds, out / "extremes.nc")
        plot(cases, cells, curve, summary, out)
    print(table(cases))
    print("\nstability map (explicit): c_nu, last stable k, first unstable k, predicted k_crit, observed/predicted")
    for c, (good, bad, kc) in bounds.items():
        print(f"  {c:8.3g}  {good:10.3g}  {bad:10.3g}  {kc:10.3g}  [{good / kc:.2f}, {bad / kc:.2f}]")
    fails = json.loads(ds.attrs["failures"])
    print(f"\n{len(fails)} case(s) failing their check:")
    for f in fails:
        why = f["message"][:160] or f"expected: {f['check']}"
        print(f"  case {f['case']}: {f['extreme']} {f['label']} {f['scheme']} value={f['value']:g}: {f['status']}; {why}")
    print(f"\nsummary: {json.dumps(summary, default=float)}")
    print(f"wrote {out / 'extremes.nc'}, {out / 'extremes.png'}, {out / 'stability_map.png'} "
          f"in {time.perf_counter() - t0:.0f} s")
    return 1 if fails else 0  # (a case failing its check fails the script: it exited 0 with two failing)


if __name__ == "__main__":
    import sys

    sys.exit(main())
