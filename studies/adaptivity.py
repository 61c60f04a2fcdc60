"""Adaptive meshes against the built-in contact-zone refinement: the estimator's effectivity and what the dofs buy.

    python studies/adaptivity.py [--levels 7] [--three-d LEVELS] [--lee-radok] [--during] [--edge] [--balance] [--goal]
                                 [--out data/adaptivity]

For ``memory_hertz`` (2D Signorini Hertz) it follows the adaptive loop of ``space_tol > 0`` level by level (the same
meshes: :func:`workbench.running.adapt.refined` of each run) and reports per level the dofs, the estimate at T, the
true error at T in the energy norm against a run on the finest adapted mesh refined uniformly twice (16x the cells;
nested meshes, so the error is integrated exactly), the effectivity index (estimate / true error), the contact
pressure's L2 error against Hertz (lumped and recovered) and the cumulative cost of the loop. Beside it, the built-in
refinement (``h_contact`` = 0.01 ... 0.00125) on the same measures of the pressure. The slab of tp4 (Model A,
debonding, backward Euler; P1 and P2) gives the effectivity on structured meshes. With ``--three-d N``, ``memory_hertz3d`` for
N adaptive levels (the pressure's errors and the cost; the effectivity of the first levels against the third level
refined once). ``--lee-radok`` (alone): the viscoelastic Hertz's contact radius against Lee and Radok's, built-in
zones against space_tol (``lee_radok.csv``). ``--during`` (alone): the mesh refined during the run
(``space_adapt = "during"``) against the repeated runs on the tp4 slab, the 2D Hertz and Lee and Radok's Hertz, and the
transfer error of the carried state on the curved half-disc (``during.csv``). ``--balance`` (alone): tp4 with
error-controlled BDF2 steps and a mesh refined during the run, space_tol against rtol, the energy error at T against
a finer run in both (``balance.csv``). ``--goal`` (alone, or with ``--three-d 1`` for the hemisphere): refinement
aimed at the pressure (``space_goal = "pressure"``) against the energy's, by bisection and by remeshing
(``space_adapt = "remesh"``), the pressure's errors against the dofs (``goal.csv``, ``goal_3d.csv``). ``--edge``
(alone): Lee and Radok's radius with the mesh following the contact zone's edge during the run (``edge_tol``) against
the built-in zones, and the constants of that refinement (``edge.csv``, ``space_edge_lee_radok.png``). Writes ``adaptivity.csv``, ``adaptivity_mesh.png`` (the final 2D mesh, whole and at the contact zone)
and prints the tables of docs/adaptivity.md. One thread.
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import time
import warnings
from pathlib import Path

from threadpoolctl import threadpool_limits

import workbench
from workbench import plotting
from workbench.discrete.estimator import energy_error
from workbench.input.geometry import of_run, on_mesh
from workbench.references import hertz
from workbench.running import adapt


def run_on(sc, body, estimate=True):
    """The run of ``sc`` on ``body``'s mesh (with its estimate: max_dofs below the mesh's, no refinement) and its
    wall time."""
    model = dataclasses.replace(sc.model_of(), geometry=body)
    extra = dict(space_tol=0.5, max_dofs=100) if estimate else {}
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ds = workbench.run(sc, model=model, progress=False, **extra)
    return ds, time.perf_counter() - t0


def refined_uniformly(body, times):
    m = body.mesh()
    for _ in range(times):
        m.Refine()
    return on_mesh(body, m.ngmesh)


def pressure(ds):
    out = {}
    for name, variable in (("lumped", "contact_pressure"), ("recovered", "contact_pressure_recovered")):
        r = hertz.profile(ds, variable=variable)
        out[f"p_l2_{name}"] = r["l2"]
    return out


def effectivity(sc, runs, reference_refinements):
    """The true errors of ``runs`` [(body, ds)] at T against the last body refined uniformly, and the reference's
    dofs."""
    ref_body = refined_uniformly(runs[-1][0], reference_refinements)
    ref, _ = run_on(sc, ref_body, estimate=False)
    tensor = sc.model_of().elastic
    return [energy_error(b, ds, ref_body, ref, tensor) for b, ds in runs], ref.attrs["ndof"]


def adaptive_levels(sc, levels, case, rows, reference_refinements, effectivity_levels=None):
    body, runs, cost = sc.model_of().geometry, [], 0.0
    for level in range(levels):
        ds, wall = run_on(sc, body)
        cost += wall
        runs.append((body, ds))
        rows.append(dict(case=case, mesh="adaptive", level=level, ndof=ds.attrs["ndof"],
                         estimate=float(ds.space_error_estimate[-1]), cost=round(cost, 2), **pressure(ds)))
        print(rows[-1], flush=True)
        if level + 1 < levels:
            body = adapt.refined(body, ds)
    chosen = runs[:effectivity_levels]
    errors, ref_ndof = effectivity(sc, chosen, reference_refinements)
    for row, error in zip(rows[-levels:], errors):
        row.update(true_error=error, effectivity=row["estimate"] / error, reference_ndof=ref_ndof)
        print(case, row["ndof"], "true", round(error, 5), "effectivity", round(row["effectivity"], 3), flush=True)
    return runs[-1]


def built_in(name, sizes, rows):
    for hc in sizes:
        t0 = time.perf_counter()
        ds = workbench.run(name, h_contact=hc, progress=False)
        rows.append(dict(case=name, mesh=f"h_contact={hc}", ndof=ds.attrs["ndof"],
                         cost=round(time.perf_counter() - t0, 2), **pressure(ds)))
        print(rows[-1], flush=True)


def lee_radok(rows):
    """Model A's viscoelastic Hertz (c_nu = 1e8, A = 0.2 G, BDF2): the last vertex in contact against Lee and Radok's
    a(t), the largest error over the recorded times from t = 0.2 s and from 0.5 s, built-in zones against space_tol
    (bisection, and meshes made anew: space_adapt = "remesh")."""
    base = dict(c_nu=1e8, tau=0.2, k=0.02, scheme="bdf2", snapshots=(), progress=False)
    # (c_nu = 1e8: at 1e7 the compliance alone put the last vertex in contact 3.7 % beyond a at t = 0.24 s on any mesh)
    runs = [(f"h_contact={h}", dict(h_contact=h)) for h in (0.0025, 0.00125, 0.001, 0.000625)]
    runs += [(f"space_tol={tol}", dict(space_tol=tol)) for tol in (0.05, 0.04, 0.03)]
    runs += [(f"space_tol={tol} remesh", dict(space_tol=tol, space_adapt="remesh")) for tol in (0.05, 0.04, 0.03)]
    for label, kw in runs:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ds = workbench.run("hertz", **base, **kw)
        wall = time.perf_counter() - t0
        errors = radius_errors(ds)
        rows.append(dict(case="hertz Lee-Radok", mesh=label, ndof=ds.attrs["ndof"], cost=round(wall, 2),
                         radius_error_from_0_2=errors[0.2], radius_error_from_0_5=errors[0.5]))
        print(rows[-1], flush=True)


def edge(rows, out):
    """Lee and Radok's radius with the mesh adapted during the run toward the contact zone's edge (``edge_tol``,
    ``space_adapt = "during"``, space_tol = 0.2) against the built-in zones, every run recorded (and so estimated) from
    0.2 s, the largest error of the last vertex in contact over those records; then the constants of the edge's
    refinement (``adapt.EDGE_MARGIN``, ``adapt.EDGE_GRADING``; a huge grading refines only the elements that hold the
    edge) at edge_tol = 0.03, and the run recorded from the first step."""
    import numpy as np

    from workbench.running import adapt

    base = dict(c_nu=1e8, tau=0.2, k=0.02, scheme="bdf2", snapshots=(), progress=False)
    late = np.round(np.arange(0.2, 1.0 + 1e-9, 0.02), 10)

    def one(label, record_times=late, **kw):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ds = workbench.run("hertz", **base, **kw, record_times=record_times)
        errors = radius_errors(ds)
        rows.append(dict(case="hertz Lee-Radok", mesh=label, ndof=ds.attrs["ndof"], mean_ndof=round(float(
            ds.ndof.mean() if "ndof" in ds else ds.attrs["ndof"])), cost=round(time.perf_counter() - t0, 2), refinements=ds.attrs.get("space_refinements", 0),
            edge_resolution=ds.attrs.get("contact_edge_resolution", float("nan")),
            radius_error_from_0_2=errors[0.2], radius_error_from_0_5=errors[0.5],
            radius_error_from_first=errors[0.0]))
        print(rows[-1], flush=True)
        return ds

    for h in (0.00125, 0.001, 0.000625):
        one(f"h_contact={h}", h_contact=h)
    following = dict(space_tol=0.2, space_adapt="during")
    for tol in (0.04, 0.03, 0.02):
        ds = one(f"during edge_tol={tol}", edge_tol=tol, **following)
        if tol == 0.03:
            plotting.space(ds, out / "space_edge_lee_radok.png")
    one("during, energy only", **following)
    one("during edge_tol=0.03, recorded from the first step", record_times=None, edge_tol=0.03, **following)
    for kw in (dict(k=0.02), dict(k=0.02, edge_tol=0.01), dict(k=0.005), dict(k=0.00125), dict(k=0.02, c_nu=1e9),
               dict(k=0.02, c_nu=1e10)):  # (the first 0.2 s: the error at 0.02, 0.04 and 0.1 s)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ds = workbench.run("hertz", **{**base, **following, "edge_tol": 0.03, **kw}, T=0.1,
                               record_times=[0.02, 0.04, 0.1])
        early = {}
        for t in (0.02, 0.04, 0.1):
            a = hertz.lee_radok(t, rate=10.0, R=1.0, E=1000.0, nu=0.3, tau=0.2, body="cylinder")
            early[f"radius_error_at_{t:g}"] = hertz.profile(ds, t)["a_last"] / a - 1
        rows.append(dict(case="hertz Lee-Radok, T = 0.1", mesh=f"during {kw}", ndof=ds.attrs["ndof"], **early))
        print(rows[-1], flush=True)
    for tol in (0.2, 0.1):  # (3D: the hemisphere's ring of an edge, Signorini, four steps)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ds = workbench.run("memory_hertz3d", space_tol=0.3, edge_tol=tol, space_adapt="during", max_dofs=150000,
                               progress=False)
        prof = hertz.profile(ds)
        rows.append(dict(case="memory_hertz3d", mesh=f"during edge_tol={tol}", ndof=ds.attrs["ndof"],
                         cost=round(time.perf_counter() - t0, 2), edge_resolution=ds.attrs["contact_edge_resolution"],
                         radius_error_at_T=prof["a_last"] / prof["a"] - 1, **pressure(ds)))
        print(rows[-1], flush=True)
    kept = adapt.EDGE_MARGIN, adapt.EDGE_GRADING
    try:
        for margin, grading in ((0.5, 0.5), (0.7, 0.5), (0.85, 0.5), (1.0, 0.25), (1.0, 0.75), (1.0, 1e9)):
            adapt.EDGE_MARGIN, adapt.EDGE_GRADING = margin, grading
            one(f"during edge_tol=0.03, EDGE_MARGIN={margin}, EDGE_GRADING={grading:g}", edge_tol=0.03, **following)
    finally:
        adapt.EDGE_MARGIN, adapt.EDGE_GRADING = kept


def during(rows, out):
    """``space_adapt = "during"`` against ``"repeat"`` at the same space_tol: dofs (final, and the mean over the
    records), cost, the largest relative estimate, and the case's own measure of the error: tp4's energy error at T
    against a run on 16x the cells of the finest mesh either mode made, the Hertz pressure's L2 error, Lee and Radok's
    radius."""
    slab = dict(scheme="implicit", T=0.3, h=0.05, k=0.01)
    cases = [("tp4", slab, (0.1, 0.07, 0.05)), ("memory_hertz", dict(h_contact=0.01), (0.05, 0.035, 0.025)),
             ("hertz", dict(c_nu=1e8, tau=0.2, k=0.02, scheme="bdf2", snapshots=()), (0.05, 0.04, 0.03)),
             ("memory_hertz3d", {}, (0.15, 0.1))]
    for name, kw, tols in cases:
        runs = []
        for tol in tols:
            for mode in ("repeat", "during"):
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    ds = workbench.run(name, **kw, space_tol=tol, space_adapt=mode, progress=False)
                row = dict(case=name, mode=mode, space_tol=tol, ndof=ds.attrs["ndof"], mean_ndof=round(float(
                    ds.ndof.mean())), cost=round(time.perf_counter() - t0, 2),
                    estimate=round(float(ds.attrs["space_error_estimate"]), 4),
                    refinements=int(ds.sizes.get("refinement", ds.attrs.get("space_levels", 1) - 1)))
                if name.startswith("memory_hertz"):
                    row.update(pressure(ds))
                if name == "hertz":
                    row.update(radius_error_from_0_2=radius_errors(ds)[0.2])
                    if mode == "during" and tol == tols[0]:  # (the estimate and the dofs over the run)
                        plotting.space(ds, out / "space_during_lee_radok.png")
                rows.append(row)
                runs.append(ds)
                print(row, flush=True)
        if name == "tp4":
            sc = workbench.scene(name, **kw)
            finest = max(runs, key=lambda d: d.attrs["ndof"])
            ref_body = refined_uniformly(of_run(sc.model_of().geometry, finest), 2)
            ref, _ = run_on(sc, ref_body, estimate=False)
            for row, ds in zip(rows[-len(runs):], runs):
                row["true_error"] = energy_error(of_run(sc.model_of().geometry, ds), ds, ref_body, ref,
                                                 sc.model_of().elastic) if "adapted_mesh" in ds else float("nan")
                print(name, row["mode"], row["space_tol"], "true error at T", row["true_error"], flush=True)
    rows.extend(transfer_errors())


def balance(rows):
    """Space against time: tp4 (BDF2 with error control, the mesh refined during the run) for space_tol x rtol, the
    energy error at T against the finest of those meshes refined once, run at rtol = 1e-5."""
    base = dict(scheme="bdf2", T=0.3, h=0.05, k=0.01, space_adapt="during")
    sc = workbench.scene("tp4", **base)
    runs = []
    for tol in (0.2, 0.1):
        for rtol in (1e-2, 1e-3, 1e-4):
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                ds = workbench.run(sc, space_tol=tol, rtol=rtol, progress=False)
            runs.append(ds)
            rows.append(dict(case="tp4 bdf2", space_tol=tol, rtol=rtol, ndof=ds.attrs["ndof"], steps=ds.attrs["nsteps"],
                             cost=round(time.perf_counter() - t0, 2), estimate=ds.attrs["space_error_estimate"]))
            print(rows[-1], flush=True)
    finest = max(runs, key=lambda d: d.attrs["ndof"])
    ref_body = refined_uniformly(of_run(sc.model_of().geometry, finest), 1)
    ref, _ = run_on(workbench.scene("tp4", **{**base, "space_adapt": "repeat"}, rtol=1e-5), ref_body, estimate=False)
    for row, ds in zip(rows[-len(runs):], runs):
        row.update(true_error=energy_error(of_run(sc.model_of().geometry, ds), ds, ref_body, ref,
                                           sc.model_of().elastic), reference_ndof=ref.attrs["ndof"])
        print(row, flush=True)


def goal(rows, three_d: bool):
    """Refinement aimed at the pressure (``space_goal = "pressure"``) against the energy's and the built-in zone, by
    bisection (``space_adapt = "repeat"``) and by meshes made anew (``"remesh"``): the Hertz pressure's L2 errors
    against the dofs. One adaptive loop per max_dofs (the loop is deterministic: each ends on a mesh of the same
    sequence). 2D from h_contact = 0.01; 3D from the scene's mesh. Lee and Radok's radius along
    the same lines for the goal (the energy's rows are ``lee_radok.csv``'s)."""
    cases = [("memory_hertz", dict(h_contact=0.01), "repeat", (700, 1500, 3000, 6000, 12000, 24000)),
             ("memory_hertz", dict(h_contact=0.01), "remesh", (1000, 2000, 3000, 4000, 6000, 8000, 12000, 16000))]
    if three_d:
        cases = [("memory_hertz3d", {}, "repeat", (5000, 20000, 70000)),
                 ("memory_hertz3d", {}, "remesh", (5000, 10000, 15000, 20000, 30000, 40000))]
    for name, kw, mode, bounds in cases:
        for aim in ("energy", "pressure"):
            last = None
            for bound in bounds:
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    ds = workbench.run(name, **kw, space_tol=0.001, max_dofs=bound, space_goal=aim, space_adapt=mode,
                                       progress=False)
                if ds.attrs["ndof"] == last:  # (the next mesh would have exceeded this bound too)
                    continue
                last = ds.attrs["ndof"]
                rows.append(dict(case=name, mesh=f"space_adapt={mode} space_goal={aim}", max_dofs=bound,
                                 ndof=ds.attrs["ndof"], levels=ds.attrs["space_levels"],
                                 estimate=round(ds.attrs["space_error_estimate"], 4),
                                 cost=round(time.perf_counter() - t0, 2), **pressure(ds)))
                print(rows[-1], flush=True)
    if not three_d:  # (other starting meshes: is the remeshed sequence's accuracy its start's luck?)
        for start in (0.02, 0.005):
            last = None
            for bound in (1500, 2500, 3500, 5000, 7000):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    ds = workbench.run("memory_hertz", h_contact=start, space_tol=0.001, max_dofs=bound,
                                       space_goal="pressure", space_adapt="remesh", progress=False)
                if ds.attrs["ndof"] != last:
                    last = ds.attrs["ndof"]
                    rows.append(dict(case="memory_hertz", mesh=f"space_adapt=remesh space_goal=pressure from "
                                     f"h_contact={start}", max_dofs=bound, ndof=last, **pressure(ds)))
                    print(rows[-1], flush=True)
    if three_d:  # (the built-in zone beyond the scene's finest: does its lumped pressure reach 2.5 %?)
        built_in("memory_hertz3d", [0.01, 0.005, 0.0035], rows)
    if not three_d:  # (the built-in zone on a finer ladder: which h_contact first reaches an error)
        built_in("memory_hertz", [0.0025, 0.0015, 0.00125, 0.001, 0.0008, 0.0007, 0.000625, 0.0005], rows)
        base = dict(c_nu=1e8, tau=0.2, k=0.02, scheme="bdf2", snapshots=(), progress=False)
        for tol in (0.05, 0.04, 0.03):
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                ds = workbench.run("hertz", **base, space_tol=tol, space_goal="pressure")
            errors = radius_errors(ds)
            rows.append(dict(case="hertz Lee-Radok", mesh=f"space_tol={tol} space_goal=pressure", ndof=ds.attrs["ndof"],
                             cost=round(time.perf_counter() - t0, 2), radius_error_from_0_2=errors[0.2],
                             radius_error_from_0_5=errors[0.5]))
            print(rows[-1], flush=True)


def radius_errors(ds):
    """The largest error of the last vertex in contact against Lee and Radok's a(t) over the records from 0.2 s,
    from 0.5 s and from the first after t = 0 (key 0.0)."""
    errors = {0.0: 0.0, 0.2: 0.0, 0.5: 0.0}
    for t in ds.time.values[ds.time.values > 0]:
        a = hertz.lee_radok(t, rate=10.0, R=1.0, E=1000.0, nu=0.3, tau=0.2, body="cylinder")
        off = abs(hertz.profile(ds, t)["a_last"] / a - 1)
        for start in errors:
            if t >= start - 1e-12:
                errors[start] = max(errors[start], off)
    return errors


def transfer_errors():
    """The carried state's strain energy on the finer mesh against the coarse one's, on the curved half-disc (the new
    boundary vertices lie on the circle, off the coarse faceted side) and on a box (exact)."""
    import numpy as np

    from workbench.discrete import discretisation
    from workbench.discrete.transfer import MeshInfo
    from workbench.input import numerics as numerics_of
    from workbench.running import adapt, follow
    from workbench.schemes import scheme_class

    out = []
    for name, kw in (("hertz", dict(scheme="bdf2", k=0.1)), ("memory_hertz", dict(k=0.25)),
                     ("tp4", dict(scheme="implicit", k=0.05))):
        sc = workbench.scene(name, **kw)
        coarse = discretisation.build(sc)
        s_c = scheme_class(sc["scheme"])(coarse)
        s_c.start(0.0)
        s_c.accept(0.0)
        for n in range(2):
            s_c.step(sc["k"] * n, sc["k"] * (n + 1))
            s_c.accept(sc["k"] * (n + 1))
        body = sc.model_of().geometry
        mesh = body.mesh()
        finer = on_mesh(body, adapt.refine(mesh, np.ones(mesh.ne, dtype=bool)))
        fine = discretisation.build(dataclasses.replace(sc.model_of(), geometry=finer), sc, numerics_of.from_scene(sc))
        s_f = scheme_class(sc["scheme"])(fine)
        s_f.restore(follow.carry({"scheme": s_c.state(restart=True)}, (coarse, s_c), (fine, s_f))["scheme"])
        K_c, K_f = (MeshInfo(d.geometry, 1).strain_matrix() for d in (coarse, fine))
        u_c, u_f = s_c.state()["u"], s_f.state()["u"]
        e_c, e_f = float(np.sqrt(u_c @ K_c @ u_c)), float(np.sqrt(u_f @ K_f @ u_f))
        out.append(dict(case=name, mode="transfer", ndof=fine.ndof, transfer_energy_difference=abs(e_f / e_c - 1)))
        print(out[-1], flush=True)
    return out


def mesh_figure(ds, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x, y, cells = ds.vertex_x.values, ds.vertex_y.values, ds.cell_vertices.values
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (xlim, ylim) in zip(axes, (((0, 1), (0, 1)), ((0, 0.16), (0, 0.08)))):
        ax.triplot(x, y, cells, lw=0.3, color="k")
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        ax.set_aspect("equal")
    a = hertz.profile(ds)["a"]
    axes[1].axvline(a, color="r", lw=0.8, label=f"Hertz's a = {a:.4f}")
    axes[1].legend(loc="upper right")
    axes[0].set_title(f"memory_hertz adapted: {ds.attrs['ndof']} dofs")
    axes[1].set_title("the contact zone")
    fig.tight_layout()
    fig.savefig(path, dpi=130)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, default=7)
    parser.add_argument("--three-d", type=int, default=0)
    parser.add_argument("--lee-radok", action="store_true", help="only the growing contact zone (lee_radok.csv)")
    parser.add_argument("--edge", action="store_true", help="only Lee and Radok's radius with edge_tol (edge.csv)")
    parser.add_argument("--during", action="store_true", help="only the mesh refined during the run (during.csv)")
    parser.add_argument("--balance", action="store_true", help="only space_tol against rtol (balance.csv)")
    parser.add_argument("--goal", action="store_true", help="only space_goal = 'pressure' against the energy's "
                        "(goal.csv; with --three-d N, any N > 0: the hemisphere, goal_3d.csv)")
    parser.add_argument("--out", default="data/adaptivity")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if args.lee_radok:
        with threadpool_limits(1):
            lee_radok(rows)
        return write(rows, out / "lee_radok.csv")
    if args.edge:
        with threadpool_limits(1):
            edge(rows, out)
        return write(rows, out / "edge.csv")
    if args.during:
        with threadpool_limits(1):
            during(rows, out)
        return write(rows, out / "during.csv")
    if args.goal:
        with threadpool_limits(1):
            goal(rows, args.three_d > 0)
        return write(rows, out / ("goal_3d.csv" if args.three_d else "goal.csv"))
    if args.balance:
        with threadpool_limits(1):
            balance(rows)
        return write(rows, out / "balance.csv")
    with threadpool_limits(1):
        _, final = adaptive_levels(workbench.scene("memory_hertz", h_contact=0.01), args.levels, "memory_hertz", rows, 2)
        mesh_figure(final, out / "adaptivity_mesh.png")
        built_in("memory_hertz", [0.01, 0.005, 0.0025, 0.00125], rows)
        for order in (1, 2):
            slab = workbench.scene("tp4", h=0.05, T=0.3, k=0.01, scheme="implicit", order=order)
            body = slab.model_of().geometry
            runs = [(b, run_on(slab, b)[0]) for b in (body, refined_uniformly(body, 1))]
            errors, ref_ndof = effectivity(slab, runs, 2)
            for (b, ds), error in zip(runs, errors):
                est = float(ds.space_error_estimate[-1])
                rows.append(dict(case=f"tp4 implicit T=0.3 P{order}", mesh="uniform", ndof=ds.attrs["ndof"],
                                 estimate=est, true_error=error, effectivity=est / error, reference_ndof=ref_ndof))
                print(rows[-1], flush=True)
        if args.three_d:
            sc3 = workbench.scene("memory_hertz3d")
            adaptive_levels(sc3, args.three_d, "memory_hertz3d", rows, 1, effectivity_levels=3)
    write(rows, out / "adaptivity.csv")


def write(rows, path):
    fields = list(dict.fromkeys(k for row in rows for k in row))
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows({k: (round(v, 6) if isinstance(v, float) else v) for k, v in row.items()} for row in rows)


if __name__ == "__main__":
    main()
