"""What a study compares its cases with: a finer run, an independent solution, or nothing.

Errors (docs/models.md; Corollary 6.7 of the 2003 paper), at the study's comparison times t_j:
``error = max_j (|u - u_ref|_V + |sigma - sigma_ref|_Q + |beta - beta_ref|_L2(Gamma3))``,
each part also alone (``error_V``, ``error_Q``, ``error_beta``), the probe errors
``error_probe`` (max over the common recorded times) and the bonding field at the
far end of the contact side ``error_beta_end``.

* :class:`RunReference` — a separate, finer run of the same scene (or the finest
  case of the sweep, which is then not reported as a case); fields are compared
  on the finer of the two meshes (:mod:`workbench.discrete.transfer`). Cases that differ
  in a physical parameter (``c_nu``, ``gamma_nu``, ...) each get their own
  reference run; cases that differ only in their discretisation share one.
* :class:`SolutionReference` — an exact or ODE/Volterra solution of a rod scene
  (:func:`workbench.references.rod_reference`), or any object with the same calls.
* :class:`DifferenceReference` — no run beyond the sweep: each case against the next
  finer case of its refinement series (consecutive differences d_i), the order p fitted
  to them, and the errors extrapolated (Richardson): e_i = d_i / (1 - r_i^p) with
  r_i = x_{i+1} / x_i, the finest case's e_n = e_{n-1} r^p. Comparing every case with
  the finest one instead biases the order: the finest case's own error is not small
  against theirs (``Study("tp1", k=[0.02, 0.01, 0.005, 0.0025])`` fitted 1.40 for a
  first-order scheme).
* ``None`` — no errors (a sweep of measures only).

``"auto"`` (the default) is the scene's exact or ODE reference where it has one, else the
extrapolated reference where a refinement series has three levels or more, else the finest
case (said in the Dataset's ``reference`` attribute, with a warning that its orders are
biased).

A case is never its own reference.
"""
from __future__ import annotations

import json
import warnings
from typing import Protocol, runtime_checkable

import numpy as np

from ..discrete import transfer
from ..errors import ParameterError
from ..input.numerics import DISCRETISATION
from ..output.results import far_facet
from .cases import Case


def physics_of(case: Case) -> tuple:
    """The values of a case that change the modelled problem (not its discretisation)."""
    return tuple((k, v) for k, v in case.values().items() if k not in DISCRETISATION)


class RunReference:
    """A finer run per physical setting; ``listed``: whether the reference cases are also reported as cases."""

    kind = "run"

    def __init__(self, cases, values: dict, listed: bool, describe: str):
        self.listed = listed
        self.by_physics = {}
        groups = {}
        for case in cases:
            groups.setdefault(physics_of(case), []).append(case)
        picked = {}
        for group, members in groups.items():
            chosen = _most_accurate(members, values)
            picked |= chosen
            self.by_physics[group] = Case(dict(members[0].values(), **chosen, **values))
        # (the options chosen for it, said where it is described: the dataset's attribute, the plots' titles)
        self._describe = describe + (f"; of what the cases differ in, the most accurate: "
                                     f"{json.dumps(picked, sort_keys=True, default=str)}" if picked else "")

    def cases(self) -> list:
        return list(dict.fromkeys(self.by_physics.values()))

    def of(self, case: Case) -> Case:
        return self.by_physics[physics_of(case)]

    def reported(self, case: Case) -> bool:
        return self.listed or case not in self.by_physics.values()

    def describe(self) -> str:
        return self._describe

    def errors(self, case, case_scene, ds, runs, compare, scene_of) -> dict:
        ref_case = self.of(case)
        return compare_runs(case_scene, ds, scene_of(ref_case), runs[ref_case], compare)


#: For a discretisation option the cases differ in and the reference leaves open, the reference's value: the most
#: accurate one (the trapezoid rule; the kernel itself by quadrature, not its fitted exponentials; the smallest
#: tolerance or contact mesh size; the most cells).
_MOST_ACCURATE = {"memory_rule": lambda seen: "trapezoid" if "trapezoid" in seen else seen[0],
                  "kernel_approximation": lambda seen: "quadrature" if "quadrature" in seen else seen[0],
                  "kernel_tol": min, "contact_tol": min, "h_contact": min, "nx": max, "ny": max, "nz": max}


def _most_accurate(cases, values: dict) -> dict:
    """The options that ``cases`` (of one physical setting) differ in and ``values`` does not fix, at their most
    accurate value (:data:`_MOST_ACCURATE`); one without such an order is taken from the first case, and said. The
    first case's had been taken for every one: a sweep over memory_rule compared both rules with the rectangle rule's
    run when it was listed first (the trapezoid's order 1.09, against 1.79 listed the other way)."""
    out, open_ = {}, []
    for name in sorted(DISCRETISATION - set(values)):
        seen = list(dict.fromkeys(c.get(name) for c in cases))
        if len(seen) < 2:
            continue
        if name in _MOST_ACCURATE:
            out[name] = _MOST_ACCURATE[name](seen)
        else:
            open_.append(f"{name} (the reference takes {seen[0]!r})")
    if open_:
        warnings.warn(f"reference: the cases differ in {', '.join(open_)}; give it in the reference to choose",
                      RuntimeWarning, stacklevel=6)
    return out


def compare_runs(case_scene, ds, ref_scene, R, compare) -> dict:
    """The errors of the run ``ds`` against the run ``R`` at the times ``compare``, on the finer of the two meshes."""
    fine_first = R.attrs["ndof"] >= ds.attrs["ndof"]
    coarse_sc, fine_sc = case_scene, ref_scene
    if not fine_first:
        coarse_sc, fine_sc = fine_sc, coarse_sc
    cds, fds = (ds, R) if fine_first else (R, ds)
    ci, fi = transfer.mesh_info(coarse_sc, cds), transfer.mesh_info(fine_sc, fds)
    tr = transfer.Transfer(ci, fi)
    parts, sizes = [], []
    for t in compare:
        i_c, i_f = snapshot_index(cds, t), snapshot_index(fds, t)
        betas = beta = None
        if "beta" in ds:
            beta = fds.beta.sel(time=t, method="nearest").values
            betas = (beta, cds.beta.sel(time=t, method="nearest").values)
        fields = [(d.u_dofs.values[i], d.u_nodes.values[i], d.stress.values[i]) for d, i in ((fds, i_f), (cds, i_c))]
        parts.append(tr.difference_norms(*fields, betas))
        sizes.append(transfer.norms(fi, fds.u_dofs.values[i_f], fds.stress.values[i_f], beta))
    t_rec = ds.time.values
    ref_probe = R.u_probe.sel(time=t_rec, method="nearest").values
    ref_end = far_facet(R.beta).sel(time=t_rec, method="nearest").values if "beta" in ds else None
    out = _combine(parts, ds, ref_probe, ref_end, sizes)
    out["transfer"] = tr.method
    return out


class DifferenceReference:
    """Each case against the next finer case of its refinement series, errors extrapolated (module docs).

    ``series``: the names whose values step along the series (one refinement axis, or the coupled ones of a
    study's levels), ``driver`` the one whose values order it (coarse first) and give the ratios r_i."""

    kind = "difference"

    def __init__(self, cases, series: tuple, driver: str, describe: str):
        self.series, self.driver, self._describe = tuple(series), driver, describe
        self.chains = {}
        for case in cases:
            key = tuple((k, v) for k, v in case.values().items() if k not in self.series)
            self.chains.setdefault(key, []).append(case)
        for chain in self.chains.values():
            chain.sort(key=lambda c: -float(c[driver]))

    def chain(self, case) -> list:
        return self.chains[tuple((k, v) for k, v in case.values().items() if k not in self.series)]

    def of(self, case):
        """The next finer case of ``case``'s series (None for the finest)."""
        chain = self.chain(case)
        i = chain.index(case)
        return chain[i + 1] if i + 1 < len(chain) else None

    def cases(self) -> list:
        return []

    def reported(self, case) -> bool:
        return True

    def describe(self) -> str:
        return self._describe

    def errors(self, case, case_scene, ds, runs, compare, scene_of) -> dict:
        finer = self.of(case)
        if finer is None:  # (its error is extrapolated from the series: evaluate.extrapolate)
            return {}
        if runs[finer].attrs.get("status") != "complete":
            return {}
        return compare_runs(case_scene, ds, scene_of(finer), runs[finer], compare)


class SolutionReference:
    """An independent solution object: ``solution(t, x) -> (u, beta)`` and ``solution.stress(t)`` (rod scenes)."""

    kind = "solution"

    def __init__(self, make, describe: str):
        self.make, self._describe = make, describe
        self._cache = {}

    def cases(self) -> list:
        return []

    def reported(self, case: Case) -> bool:
        return True

    def describe(self) -> str:
        return self._describe

    def solution(self, case_scene):
        key = json.dumps({k: v for k, v in case_scene.plain().items() if k not in DISCRETISATION}, sort_keys=True,
                         default=str)
        if key not in self._cache:
            self._cache[key] = self.make(case_scene)
        return self._cache[key]

    def errors(self, case, case_scene, ds, runs, compare, scene_of) -> dict:
        sol = self.solution(case_scene)
        info = transfer.mesh_info(case_scene)
        t_rec = ds.time.values
        parts, sizes = [], []
        for t in compare:
            i = snapshot_index(ds, t)
            u_ref, beta_ref = sol(np.array([t]), x=info.xyz[:, 0])
            ref_vec = np.zeros(info.fes.ndof)
            ref_vec[: len(info.xyz)] = np.ravel(u_ref)  # linear in x: vertex values are the whole field
            sig_ref = np.full_like(ds.stress.values[i], np.ravel(sol.stress(np.array([t])))[0])
            beta = np.full(info.facet_measure.shape, np.ravel(beta_ref)[0]) if "beta" in ds else None
            dbeta = ds.beta.values[np.argmin(np.abs(t_rec - t))] - beta if "beta" in ds else None
            parts.append(transfer.norms(info, ds.u_dofs.values[i] - ref_vec, ds.stress.values[i] - sig_ref, dbeta))
            sizes.append(transfer.norms(info, ref_vec, sig_ref, beta))
        xs = ds.probe_x.values
        ref_probe = np.stack([sol(t_rec, x=x)[0] for x in xs], axis=1)[..., None]
        ref_end = sol(t_rec)[1] if "beta" in ds else None
        return _combine(parts, ds, ref_probe, ref_end, sizes)


def _combine(parts, ds, ref_probe, ref_end, sizes) -> dict:
    """The errors from the norms of the differences ``parts`` at the compared times, and the reference's own norms
    there (``sizes``, their largest: ``reference_norm_*``, the scale an error is at round-off against)."""
    parts, sizes = np.array(parts), np.array(sizes)
    out = {}
    out["error_V"], out["error_Q"] = np.max(parts[:, :2], axis=0)
    out["error_beta"] = float(np.max(parts[:, 2])) if np.isfinite(parts[:, 2]).all() else np.nan
    out["error"] = float(np.max(np.nansum(parts, axis=1)))
    out["reference_norm_V"], out["reference_norm_Q"] = np.max(sizes[:, :2], axis=0)
    if np.isfinite(sizes[:, 2]).all():
        out["reference_norm_beta"] = float(np.max(sizes[:, 2]))
    out["error_probe"] = np.max(np.linalg.norm(ds.u_probe.values - ref_probe, axis=-1), axis=0)
    if ref_end is not None:
        out["error_beta_end"] = float(np.max(np.abs(far_facet(ds.beta).values - ref_end)))
    return out


def snapshot_index(ds, t) -> int:
    """Index of the field snapshot at time t (it must exist)."""
    i = int(np.argmin(np.abs(ds.snapshot_time.values - t)))
    if abs(ds.snapshot_time.values[i] - t) > 1e-9 * max(1.0, abs(t)):
        raise ValueError(f"no field snapshot at t = {t}")
    return i


def _warn_if_coarser(spec: dict, values: dict, cases) -> None:
    """A reference run given an h or k coarser than a case it is compared with measures its own error (a rod's
    order came out -0.41): said, naming the value and the cases' finest."""
    coarser = [f"{name} = {values[name]:g} (the cases' finest: {min(getattr(c, name) for c in cases):g})"
               for name in ("h", "k") if name in spec and values[name] > min(getattr(c, name) for c in cases)]
    if coarser and not values.get("rtol", 0.0):
        warnings.warn(f"reference: {', '.join(coarser)} is coarser than cases it is compared with: their errors are "
                      "then the reference's; give a finer run", RuntimeWarning, stacklevel=5)


def make(spec, scene, cases, axes, layout=None):
    """The reference object for a Study's ``reference`` argument (see the module docs)."""
    if spec is None:
        return None
    if spec == "auto":
        return _auto(scene, cases, axes, layout)
    if spec == "extrapolated":
        series = _series(cases, axes, layout)
        if series is None:
            raise ParameterError("reference = 'extrapolated' needs one refinement series of three levels or more (one "
                                 "of h, k, rtol, h_contact, space_tol, edge_tol swept, or coupled levels such as k = 0.2 h)")
        return DifferenceReference(cases, *series, describe=_EXTRAPOLATED)
    if isinstance(spec, str):
        if spec == "finest":
            # (error-controlled cases: the smallest tolerance; their k is only the first step)
            # (adapted meshes: the smallest space_tol, then edge_tol; 0 is the mesh as given / the edge not asked)
            best = min(cases, key=lambda c: (c.h, c.get("h_contact", 0.0), c.get("space_tol", 0.0) or np.inf,
                                             c.get("edge_tol", 0.0) or np.inf, c.get("rtol", 0.0), c.k, -c.order,
                                             c.scheme != "implicit", c.get("memory_rule") != "trapezoid"))
            values = {k: v for k, v in best.values().items() if k in DISCRETISATION}
            return RunReference(cases, values, listed=False, describe="finest")
        if spec in ("ode", "exact"):
            if scene.dim != 1:
                raise ParameterError(f"reference = {spec!r} needs a rod scene (an ODE/Volterra reference exists only "
                                     "there); use 'finest' or a finer run such as {'h': 0.005, 'k': 0.0005}")
            from ..references import rod_reference

            return SolutionReference(rod_reference, describe=spec)
        raise ParameterError(f"reference = {spec!r}; allowed: 'auto', 'extrapolated', 'finest', 'ode', 'exact', a dict "
                             "of discretisation values such as {'h': 0.005, 'k': 0.0005}, or a solution object")
    if isinstance(spec, dict):
        unknown = set(spec) - DISCRETISATION
        if unknown:
            raise ParameterError(f"reference: unknown key(s) {sorted(unknown)}; allowed: "
                                 f"{', '.join(sorted(DISCRETISATION))}")
        # from the cases, not the axes: a coupled h, k, order or scheme is not an axis
        values = {"h": min(c.h for c in cases), "k": min(c.k for c in cases), "order": max(c.order for c in cases),
                  "scheme": cases[0].scheme}
        if any("rtol" in c.values() for c in cases):  # a tolerance sweep: the finer run takes fixed steps of its k
            values["rtol"] = 0.0
        values |= spec
        for name in ("h", "k"):
            if name in spec:
                try:
                    values[name] = float(spec[name])
                except (TypeError, ValueError):
                    raise ParameterError(f"reference: {name} = {spec[name]!r} is not a number") from None
        _warn_if_coarser(spec, values, cases)
        ref = RunReference(cases, values, listed=True, describe=json.dumps(values, sort_keys=True, default=str))
        for c in ref.cases():
            scene.with_(**c.values())  # checked before any work
        return ref
    if not isinstance(spec, Solution):
        raise ParameterError(f"reference = {spec!r} ({type(spec).__name__}); allowed: 'finest', 'ode', 'exact', a dict "
                             "of discretisation values such as {'h': 0.005, 'k': 0.0005}, or a solution object "
                             "(solution(t, x) -> (u, beta) with a method stress(t))")
    return SolutionReference(lambda _scene: spec, describe=type(spec).__name__)


@runtime_checkable
class Solution(Protocol):
    """What a Study accepts as an independent reference solution (e.g. :func:`workbench.references.rod_ode`'s)."""

    def __call__(self, t, x=None):
        """(u, beta) at the times ``t`` and the points ``x``."""

    def stress(self, t):
        """The stress at the times ``t``."""


_EXTRAPOLATED = ("extrapolated (Richardson: each case against the next finer case of its series, the order fitted to "
                 "those differences, the errors extrapolated; the finest case's from the series)")


def _series(cases, axes, layout):
    """(the names that step along the study's refinement series, the one that orders it) or None: coupled levels that
    refine, or the one refinement axis swept; three levels or more."""
    from ..input.numerics import REFINEMENT

    if layout is not None and layout.refining:
        if len(layout.levels) < 3:
            return None
        return (layout.driver,) + tuple(layout.coupled), layout.driver
    swept = [a for a in REFINEMENT if a in axes and len(axes[a]) > 1]
    if len(swept) != 1 or len(axes[swept[0]]) < 3:
        return None
    return (swept[0],), swept[0]


def _auto(scene, cases, axes, layout):
    """The default reference: the scene's exact or ODE reference where it has one, else the extrapolated one, else the
    finest case (biased: said, and warned)."""
    import warnings

    if scene.dim == 1:
        from ..references import rod_reference

        try:
            rod_reference(scene)  # (a rod whose reduced ODE or Volterra equation applies)
        except (ValueError, ParameterError):
            pass
        except RuntimeError as err:  # (it applies, but its solver fails: said, and the next reference taken)
            warnings.warn(f"reference: the scene's own reference cannot be computed ({err}); the study takes the "
                          "next one", RuntimeWarning, stacklevel=4)
        else:
            return SolutionReference(rod_reference, describe="auto: the scene's own reference (exact, ODE or Volterra: "
                                                             "workbench.references.rod_reference)")
    series = _series(cases, axes, layout)
    if series is not None:
        return DifferenceReference(cases, *series, describe=f"auto: {_EXTRAPOLATED}")
    if len(cases) < 2:  # (refused here, before the warning about a biased finest reference that would follow)
        raise ParameterError("a study of a single case has nothing to compare it with (this scene has no exact "
                             "reference): sweep at least two values (e.g. k=[0.02, 0.01]) or give a reference run "
                             "or solution")
    warnings.warn("the study compares its cases with the finest one (no exact reference, and no refinement series of "
                  "three levels to extrapolate from): its orders are biased (the finest case's own error is not "
                  "small against the others'); sweep three levels, or name a finer run as the reference",
                  RuntimeWarning, stacklevel=4)
    ref = make("finest", scene, cases, axes)
    ref._describe = "auto: finest (biased: fewer than three levels and no exact reference)"
    return ref
