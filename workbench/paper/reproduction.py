"""Reproduce the paper's Test Problems 1–5 (Chau–Fernández–Shillor–Sofonea 2003, Section 7, Figs. 2–19).

Run (from the repository root)::

    workbench reproduce all --out out/reproduction         # tp1 ... tp5 at the paper's resolution
    python studies/reproduce.py all                       # the same, into data/reproduction
    workbench reproduce tp5 --h 0.05 --k 0.01 --out /tmp/repro   # reduced size
    workbench reproduce tp3 --vtk --out out/tp3           # also ParaView files in OUT/vtk/
    workbench reproduce tp3 --set delta_amp=0.08          # any scene parameter

Resolution: the rod problems use the paper's h = k = 0.01. The paper does not state the
mesh of the slab problems; the presets use h = 0.0125 (80 x 8 squares, 1280 triangles) and
k = 0.01, inside the explicit scheme's stability limit (k_crit ~ 0.03).

For each problem it writes ``OUT/<tp>.nc`` (the run, :func:`workbench.write`),
``OUT/<tp>_<kind>.png`` (the paper's figures, :mod:`workbench.paper.figures`) and
``OUT/<tp>_numbers.json``, and prints the key numbers next to what the paper reports.

Parts (for ``workbench reproduce``, ``studies/reproduce.py`` and the tests):

* :func:`problem_scene`, :func:`reference`, :func:`run_problem` — scene, independent reference, run;
* :func:`key_numbers` — the numbers of one run (errors, beta at the end, tip displacement, von Mises);
* :func:`side_studies` — the documented deviations measured (bonding-law convention,
  Problem 2 with the adhesive sign flipped, Problem 4's exponential prediction);
* :func:`make_figures` — the PNGs; :func:`reproduce` — all of it for one problem;
* :func:`report` — the printed comparison.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

import workbench
from workbench.errors import NotWritten, ParameterError
from workbench.output.results import far_facet
from workbench.references import rod_ode, tp1_exact

from . import figures as paper_figures

PROBLEMS = ("tp1", "tp2", "tp3", "tp4", "tp5")
ROD, SLAB = ("tp1", "tp2", "tp3"), ("tp4", "tp5")
DEFAULT_OUT = Path("out") / "reproduction"

#: What the paper reports or plots, as text (figure values read from the OCR'd axes; the curves
#: themselves are not in the text). Keys are those of :func:`key_numbers` / :func:`side_studies`.
PAPER = {
    "tp1": {
        "u_err_fields": "< 1.8e-4 (Fig. 2, text)",
        "u_err_probes": "< 1e-3 (Fig. 3, text; axis to 9e-4)",
        "beta_err": "< 4e-6 (Fig. 4, text)",
        "u_end_T": "exact -0.544863 (eq. 7.11, corrected exponent)",
        "beta_end_T": "exact 0.973361 (Fig. 4 axis 0.97-1.005)",
    },
    "tp2": {
        "u_err_fields": "~0.014 (Fig. 5 error axis top)",
        "u_err_probes": "~0.014 (Fig. 6 error axis top)",
        "beta_err": "~1.5e-4 (Fig. 7 error axis top)",
        "u_end_T": "curves ~ -0.107 (Figs. 5-6 axes -0.107..-0.099); correct ODE -0.0939",
        "beta_end_T": "~0.9988 (Fig. 7 axis 0.9988-1); correct ODE 0.99907",
        "flipped_u_end_T": "~ -0.107 (the paper's curves)",
        "flipped_beta_end_T": "~0.9988 (Fig. 7 axis bottom)",
        "flipped_u_err_vs_ode": "~0.013-0.014 (the paper's reported error)",
        "flipped_beta_err_vs_ode": "~1.5e-4 (the paper's reported error)",
    },
    "tp3": {
        "beta_min": "~0.998 (Fig. 10, axis 0.9975-1)",
        "u_end_min": "axis bottom -0.1 (Fig. 9)",
        "u_end_max": "axis top 0.06 (Fig. 9)",
        "beta_rise_max": "0 (no rebonding)",
        "beta_change_in_compression": "0 ('horizontal segments', Fig. 10)",
        "symmetric_beta_min": "- (paper uses tension-only behaviour)",
    },
    "tp4": {
        "beta_end_T": "Fig. 15 axis 0.965-1.005 (the model statement expected ~0.986, docs/choices.md)",
        "exp_prediction": "- (inferred data: e^{-gamma L^2 t})",
        "uy_tip_T": "-",
        "uy_end_T": "Fig. 14 axes 0..1.6",
        "vm_max_T": "colour map only (Fig. 13)",
        "symmetric_beta_end_T": "-",
    },
    "tp5": {
        "beta_end_T": "Fig. 19 axis 0.986-1",
        "uy_tip_T": "-",
        "uy_end_min": "Fig. 18 axes -0.6..0.8",
        "uy_end_max": "Fig. 18 axes -0.6..0.8",
        "vm_max_T": "colour map only (Fig. 17)",
        "symmetric_beta_end_T": "- (paper: 'debonding stops in compression')",
    },
}

#: Human-readable names of the numbers.
LABELS = {
    "u_err_fields": "max |u_h - u| over x at the snapshot times",
    "u_err_probes": "max |u_h - u| at x = 0.25, 0.5, 1 over all t",
    "beta_err": "max |beta_h - beta| at x = 1 over all t",
    "u_end_T": "u_h(1, T)",
    "beta_end_T": "beta_h at the end facet, t = T",
    "beta_min": "min over t of beta_h(1, t)",
    "u_end_min": "min over t of u_h(1, t)",
    "u_end_max": "max over t of u_h(1, t)",
    "beta_rise_max": "max increase of beta_h between records",
    "beta_change_in_compression": "max |change of beta_h| while u_h(1) > 0",
    "compression_fraction": "fraction of records in compression",
    "u_err_vs_ode": "max |u_h - u_ODE| at the probes (not in the paper)",
    "flipped_u_end_T": "adhesive sign flipped: u_h(1, T)",
    "flipped_beta_end_T": "adhesive sign flipped: beta_h(1, T)",
    "flipped_ode_u_end_T": "adhesive sign flipped, ODE: u(1, T)",
    "flipped_u_err_vs_ode": "flipped run vs correct ODE: max |u| difference at probes",
    "flipped_beta_err_vs_ode": "flipped run vs correct ODE: max |beta| difference",
    "symmetric_beta_min": "symmetric truncation: min beta_h(1, t)",
    "symmetric_beta_end_T": "symmetric truncation: beta_h(1, 0, T)",
    "exp_prediction": "e^{-gamma L^2 T} (end in tension beyond L)",
    "facet_x": "x of the end facet (midpoint)",
    "uy_tip_T": "u_y(W, H, T) (loaded corner)",
    "uy_end_T": "u_y(W, 0, T)",
    "uy_end_min": "min over t of u_y(W, 0, t)",
    "uy_end_max": "max over t of u_y(W, 0, t)",
    "vm_max_T": "max von Mises at T [Pa]",
    "vm_max_x": "  at cell centroid x",
    "vm_max_y": "  at cell centroid y",
    "wall_time": "wall time of the run [s]",
}


# ---------------------------------------------------------------------------------------- runs

def problem_scene(problem, h=None, k=None, **overrides):
    """The scene of a paper problem (the preset) with optional ``h``, ``k`` and other overrides.

    >>> problem_scene("tp4", h=0.05)["h"]
    0.05
    """
    if problem not in PROBLEMS:
        raise ValueError(f"unknown problem {problem!r}; choose from {', '.join(PROBLEMS)} or 'all'")
    sizes = {key: val for key, val in (("h", h), ("k", k)) if val is not None}
    return workbench.scene(problem, **sizes, **overrides)


def check(problem, h=None, k=None, **overrides) -> None:
    """Refuse what :func:`reproduce` would refuse, before any run: the scene's values and those that need the
    body's matrices (the explicit scheme's stability limit, :func:`workbench.running.runner.checks`), with no step.

    >>> check("tp4", k=0.1)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    workbench.errors.StepTooLarge: k = 0.1 s exceeds the predicted stability limit of the explicit scheme, ...
    """
    from workbench.references.rod import check_rod_ode
    from workbench.running.runner import checks

    sc = problem_scene(problem, h, k, **overrides)
    if not sc["adhesion"]:  # (found after the run, as an AttributeError, by an outside pass; so was the next)
        raise ParameterError("adhesion = false: the paper's problems are compared by their bonding field beta, which "
                             "then is not modelled; run the scene with `workbench run` instead")
    if sc.dim == 2 and not {(sc["width"], sc["height"]), (sc["width"], 0.0)} <= {tuple(p) for p in sc["probes"]}:
        raise ParameterError(f"probes = {[list(p) for p in sc['probes']]}: the paper's numbers are read at the slab's "
                             f"right end, ({sc['width']:g}, {sc['height']:g}) and ({sc['width']:g}, 0): keep them "
                             "among the probes")
    if sc.dim == 1 and reference_kind(sc) == "ode":
        try:
            check_rod_ode(sc)
        except ValueError as err:
            raise ParameterError(f"the rod's reference (its reduced ODE) cannot be made: {err}") from None
    checks(sc)


def changed_from_paper(scene) -> dict:
    """The values of ``scene`` that make it another problem than the paper's, ``{name: (paper's, this run's)}``:
    what the user set, other than the discretisation (:data:`workbench.input.numerics.DISCRETISATION`) and the
    checkpoints. Where any is set, the paper's numbers (:data:`PAPER`) are not this run's to compare with.

    >>> changed_from_paper(problem_scene("tp1", h=0.05, T=0.5, scheme="bdf2"))
    {'T': (1.0, 0.5)}
    """
    from workbench.input.numerics import DISCRETISATION

    paper, mine = workbench.scene(scene.base).plain(), scene.plain()
    return {name: (paper.get(name), mine[name]) for name in scene.set_by_user
            if name not in DISCRETISATION and name != "checkpoint_every" and mine[name] != paper.get(name)}


def reference(scene):
    """The independent reference of a rod scene, or None for slabs.

    tp1: the closed form (:func:`workbench.references.tp1_exact`, valid only for the
    preset's data); any other rod scene with u0 = delta(0): the reduced ODE solved by
    Radau (:func:`workbench.references.rod_ode`).
    """
    kind = reference_kind(scene)
    return None if kind is None else tp1_exact() if kind == "exact" else rod_ode(scene)


def reference_kind(scene):
    """Which reference :func:`reference` makes: "exact" (tp1 as the paper has it), "ode", or None (slabs)."""
    if scene.dim != 1:
        return None
    return "exact" if scene.base == "tp1" and not (set(scene.set_by_user) - {"h", "k", "snapshots"}) else "ode"


def run_problem(problem, h=None, k=None, **overrides):
    """Run a paper problem (see :func:`problem_scene`) and return its Dataset.

    >>> ds = run_problem("tp1", h=0.1, k=0.1)
    >>> ds.attrs["scene"], ds.sizes["snapshot"]
    ('tp1', 5)
    """
    return workbench.run(problem_scene(problem, h, k, **overrides), progress=False)


def flipped_model(scene):
    """The scene's model with the adhesive pull's sign flipped (a diagnostic: Problem 2's curves in the paper
    look like this sign error, docs/choices.md). The law itself offers the flip (``AdhesivePull(sign=-1)``)."""
    from workbench.physics.contact import Contact
    from workbench.physics.laws import AdhesivePull

    model = scene.model_of()
    terms = [AdhesivePull(t.gamma_nu, t.L, sign=-1.0) if isinstance(t, AdhesivePull) else t for t in model.contact.terms]
    return dataclasses.replace(model, contact=Contact(terms))


# ---------------------------------------------------------------------------------------- numbers

def _rod_errors(ds, ref):
    t = ds.time.values
    x = ds.vertex_x.values
    fields = max(float(np.abs(ds.u_nodes.isel(snapshot=i, component=0).values - ref(float(ts), x=x)[0]).max())
                 for i, ts in enumerate(ds.snapshot_time.values))
    u_ref, b_ref = ref(t, x=ds.probe_x.values)
    probes = float(np.abs(ds.u_probe.isel(component=0).values - np.asarray(u_ref).reshape(len(t), -1)).max())
    beta = float(np.abs(ds.beta.isel(facet=-1).values - np.asarray(b_ref)).max())
    return fields, probes, beta


def _von_mises_max(ds):
    vm = ds.von_mises.isel(snapshot=-1).values
    cells = ds.cell_vertices.values[:, :3]
    i = int(np.argmax(vm))
    return float(vm[i]), float(ds.vertex_x.values[cells[i]].mean()), float(ds.vertex_y.values[cells[i]].mean())


def key_numbers(problem, ds, ref=None):
    """The key numbers of one run of ``problem`` (a dict of floats; see :data:`LABELS`).

    Parameters
    ----------
    problem : str
        ``tp1`` ... ``tp5``.
    ds : xarray.Dataset
        Its run (any resolution).
    ref : callable, optional
        The rod reference (:func:`reference`); tp1/tp2 errors need it, tp3 uses it for
        an extra error check.
    """
    out = {"wall_time": float(ds.attrs.get("wall_time", float("nan")))}
    if problem in ROD:
        t = ds.time.values
        beta = ds.beta.isel(facet=-1).values
        u_end = ds.u_contact.isel(node=-1, component=0).values
        out["u_end_T"] = float(u_end[-1])
        out["beta_end_T"] = float(beta[-1])
        if problem in ("tp1", "tp2") and ref is not None:
            out["u_err_fields"], out["u_err_probes"], out["beta_err"] = _rod_errors(ds, ref)
        if problem == "tp3":
            out["beta_min"] = float(beta.min())
            out["u_end_min"], out["u_end_max"] = float(u_end.min()), float(u_end.max())
            d_beta = np.diff(beta)
            out["beta_rise_max"] = float(d_beta.max()) if len(d_beta) else 0.0
            # A record interval is "in compression" when the end is compressed at both ends of it,
            # whichever of the two states the (lagged) bonding update used.
            comp = (u_end[1:] > 0) & (u_end[:-1] > 0)
            out["beta_change_in_compression"] = float(np.abs(d_beta[comp]).max()) if comp.any() else float("nan")
            out["compression_fraction"] = float(np.mean(u_end > 0))
            if ref is not None:
                u_ref = np.asarray(ref(t, x=ds.probe_x.values)[0]).reshape(len(t), -1)
                out["u_err_vs_ode"] = float(np.abs(ds.u_probe.isel(component=0).values - u_ref).max())
    else:
        far = far_facet(ds.beta)
        b_end = far.values
        out["facet_x"] = float(far.facet_x)
        out["beta_end_T"] = float(b_end[-1])
        if problem == "tp4":  # the end separates beyond L at once: beta' = -gamma L^2 beta
            v = ds.attrs
            out["exp_prediction"] = math.exp(-v["gamma_nu"] * v["L"] ** 2 * float(ds.time[-1]))
        W, H = float(ds.attrs["width"]), float(ds.attrs["height"])  # (the slab's right end, as long as it is)
        tip = _probe(ds, W, H)
        end = _probe(ds, W, 0.0)
        uy_end = ds.u_probe.isel(probe=end).sel(component="y").values
        out["uy_tip_T"] = float(ds.u_probe.isel(probe=tip, time=-1).sel(component="y"))
        out["uy_end_T"] = float(uy_end[-1])
        out["uy_end_min"], out["uy_end_max"] = float(uy_end.min()), float(uy_end.max())
        out["vm_max_T"], out["vm_max_x"], out["vm_max_y"] = _von_mises_max(ds)
    return out


def _probe(ds, x, y):
    d = (ds.probe_x.values - x) ** 2 + (ds.probe_y.values - y) ** 2
    p = int(np.argmin(d))
    if d[p] > 1e-12:
        raise ValueError(f"no probe at ({x}, {y}) in this result")
    return p


def side_studies(problem, h=None, k=None, **overrides):
    """The measured deviations of a problem: extra runs that the paper comparison needs.

    * tp2: the run with the adhesive sign flipped (:func:`flipped_model`), compared with
      the correct ODE (reproduces the paper's error magnitudes) and with the reduced ODE
      of the flipped model (:func:`workbench.references.rod_ode`, independent of the schemes);
    * tp3, tp4, tp5: the run with ``bonding_truncation = "symmetric"`` (eq. 3.7 as printed).

    Returns
    -------
    dict of float
    """
    out = {}
    if problem == "tp2":
        sc = problem_scene(problem, h, k, **overrides)
        flipped = flipped_model(sc)
        ds = workbench.run(sc, model=flipped, progress=False)
        t = ds.time.values
        out["flipped_u_end_T"] = float(ds.u_contact.isel(node=-1, component=0, time=-1))
        out["flipped_beta_end_T"] = float(ds.beta.isel(facet=-1, time=-1))
        out["flipped_ode_u_end_T"] = float(rod_ode(sc, model=flipped)(np.array([t[-1]]))[0][0])
        ref = rod_ode(sc)
        u_ref, b_ref = ref(t, x=ds.probe_x.values)
        out["flipped_u_err_vs_ode"] = float(np.abs(ds.u_probe.isel(component=0).values
                                                   - np.asarray(u_ref).reshape(len(t), -1)).max())
        out["flipped_beta_err_vs_ode"] = float(np.abs(ds.beta.isel(facet=-1).values - b_ref).max())
    elif problem in ("tp3", "tp4", "tp5"):
        ds = run_problem(problem, h, k, **(overrides | {"bonding_truncation": "symmetric"}))
        if problem == "tp3":
            out["symmetric_beta_min"] = float(ds.beta.isel(facet=-1).min())
        else:
            out["symmetric_beta_end_T"] = float(far_facet(ds.beta).isel(time=-1))
    return out


# ---------------------------------------------------------------------------------------- files

def make_figures(problem, ds, out, ref=None):
    """Write the paper's figures of ``problem`` to ``out/<problem>_<kind>.png``; return the paths.

    Rod problems 1 and 2 get the error panels against ``ref``; Problem 3 is drawn like the
    paper (no error panels) with the compression intervals shaded.
    """
    label = {"tp1": "exact (7.11)", "tp2": "ODE (7.12), Radau"}.get(problem, "reference")
    use_ref = ref if problem in ("tp1", "tp2") else None
    return paper_figures.paper_figures(ds, out, ref=use_ref, prefix=problem, ref_label=label)


def reproduce(problem, out=DEFAULT_OUT, h=None, k=None, side=True, vtk=False, **overrides):
    """Run one problem, write ``<problem>.nc``, its figures and ``<problem>_numbers.json`` to ``out``.

    Parameters
    ----------
    problem : str
        ``tp1`` ... ``tp5``.
    out : str or Path
        Output folder (created).
    h, k : float, optional
        Element size and time step (default: the preset, i.e. the paper's resolution).
    side : bool
        Also run :func:`side_studies` (cheap: one extra run).
    vtk : bool
        Also write ParaView files to ``out/vtk`` (:func:`workbench.output.vtk.export`).
    **overrides
        Other scene parameters.

    Returns
    -------
    dict
        ``numbers`` (key numbers and side studies), ``paper`` (:data:`PAPER` entry),
        ``files`` (paths written), ``ds`` (the Dataset), ``scene`` (its parameters).
    """
    out = Path(out)
    sc = problem_scene(problem, h, k, **overrides)
    ds = workbench.run(sc, progress=False)
    ref = reference(sc)
    numbers = key_numbers(problem, ds, ref)
    if side:
        numbers |= side_studies(problem, h, k, **overrides)
    changed = changed_from_paper(sc)
    paper = {} if changed else PAPER[problem]  # (the paper's numbers are its scene's, not another's)
    summary = {"problem": problem, "h": ds.attrs["h_max"], "k": ds.attrs["k_actual"],
               "numbers": numbers, "paper": paper, "changed_from_paper": changed}
    try:
        files = [workbench.write(ds, out / f"{problem}.nc")]
        files += make_figures(problem, ds, out, ref)
        if vtk:
            from workbench.output import vtk as vtk_export

            files += vtk_export.export(ds, out / "vtk", stem=problem)
        files.append(_write_json(out / f"{problem}_numbers.json", summary))
    except OSError as err:  # (the run is not lost: the caller keeps it elsewhere)
        raise NotWritten(err, ds) from None
    return {"numbers": numbers, "paper": paper, "changed_from_paper": changed, "files": files, "ds": ds,
            "scene": sc.plain()}


def _write_json(path, data):
    from workbench.output.files import atomic_write

    return atomic_write(path, lambda tmp: tmp.write_text(json.dumps(data, indent=1, sort_keys=True)))


def report(problem, result) -> str:
    """The printed comparison: our number next to the paper's, one line each."""
    ds = result["ds"]
    lines = [f"{problem}: {ds.attrs['description']}",
             f"  h = {ds.attrs['h_max']:g}, k = {ds.attrs['k_actual']:.3g}, scheme {ds.attrs['scheme']}, "
             f"ndof {ds.attrs['ndof']}, status {ds.attrs['status']}"]
    paper = result["paper"]
    changed = result.get("changed_from_paper") or {}
    if changed:
        lines.append("  not compared with the paper's numbers, as this run changes " + ", ".join(
            f"{name} = {mine} (the paper's {theirs})" for name, (theirs, mine) in changed.items()))
    for key, val in result["numbers"].items():
        label = LABELS.get(key, key)
        if "width" in ds.attrs:  # (the slab's end where it is: a slab of another width or height, an outside pass)
            label = label.replace("(W,", f"({ds.attrs['width']:g},").replace(", H,", f", {ds.attrs['height']:g},")
        ref = paper.get(key, "")
        lines.append(f"  {label:<58} {val:>12.6g}   {('paper: ' + ref) if ref else ''}".rstrip())
    return "\n".join(lines)
