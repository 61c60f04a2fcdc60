"""The contact solvers side by side: condensed (dense contact stiffness) against coupled (whole body, S never
formed), on the same meshes, in one process, one thread each.

    python studies/contact_solver.py [--out data/contact_solver] [--big] [--slope] [--slope-cg] [--slope-auto]
        [--repeat N] [--pdas-amg] [--pardiso]

Per case and solver: dofs, contact points, steps, wall time of ``workbench.run`` (the mesh made once beforehand, so
both pay the same), the setup time, back-substitutions (``linear_solves``), active-set and conjugate gradient
iterations (Model A: Newton iterations; its back-substitutions are not counted: -1), and the largest difference between the two solvers' contact displacements (relative). Beside them the
cost of assembling and factoring K alone (NGSolve's sparse Cholesky, the yardstick of issue 22). ``--big`` adds the
hemisphere at h_contact = 0.005 (47k dofs, 5186 contact vertices), coupled only (condensed: 783 s, measured before,
``data/hertz/hertz3d_fine.csv``). Writes ``summary.csv`` and prints its table (the table of docs/schemes.md now
comes from ``--pardiso``, which runs both factors side by side). ``--slope`` (alone):
the cost of a step of the coupled solver against the dofs at three sizes of the block and of the hemisphere, the time
loop's wall time over its steps, and the least-squares slope in log-log (``slope.csv``). ``--slope-cg`` (alone): the
same for ``memory_block`` to T = 0.3 at four sizes (4k to 78k dofs), with the sparse factor (``solver = "auto"``) and
with AMG-preconditioned conjugate gradients (``solver = "cg"``), side by side (``slope_cg.csv``; about 12 minutes).
``--slope-auto`` (alone): the same four sizes with the contact solver ``auto`` takes (``slope_auto.csv``).
``--repeat N``: each size of a slope N times, the median loop kept (the loops are tenths of a second at the small
sizes: one run is noise).
``--pardiso`` (alone; with ``--big`` also the 47k hemisphere): both contact solvers on NGSolve's factor and on MKL
PARDISO's, beside the yardsticks: one factorization with each, a back-substitution with each, and PARDISO's Schur
complement on the contact points (``pardiso.csv``). ``--pdas-amg`` (alone): a route measured and not taken, the active set on the whole body with AMG-CG solves
(:func:`pdas_amg`, ``pdas_amg.csv``).
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

import workbench

CASES = [
    ("memory_slab", dict(h=0.05)),
    ("memory_slab", dict(h=0.0125)),
    ("memory_block", dict(h=0.05)),
    ("memory_hertz", dict(h_contact=0.001)),
    ("memory_hertz3d", dict()),
    ("memory_hertz3d", dict(h_contact=0.02)),
    ("memory_hertz3d", dict(h_contact=0.01)),
    ("hertz3d", dict(h_contact=0.01, k=0.1)),
    ("tp5", dict(scheme="bdf2", k=0.005)),
]
BIG = [("memory_hertz3d", dict(h_contact=0.005))]


def factor_alone(name, overrides):
    """Seconds to assemble and to factor K_A of the case's mesh (sparse Cholesky, one thread)."""
    from workbench.discrete import discretisation, solvers

    d = discretisation.build(workbench.scene(name, **overrides))
    t0 = time.perf_counter()
    d.elastic.Assemble()
    t1 = time.perf_counter()
    solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "sparsecholesky")
    return t1 - t0, time.perf_counter() - t1


def one(name, overrides, solver):
    t0 = time.perf_counter()
    ds = workbench.run(name, contact_solver=solver, progress=False, **overrides)
    wall = time.perf_counter() - t0
    row = dict(case=name, overrides=" ".join(f"{k}={v}" for k, v in overrides.items()), solver=solver,
               ndof=ds.attrs["ndof"], points=int(np.isfinite(ds.contact_pressure.isel(time=-1)).sum()),
               steps=ds.sizes["time"] - 1, wall=round(wall, 2), setup=round(float(ds.attrs["setup_time"]), 2),
               backsubs=int(ds.linear_solves.sum()) if "linear_solves" in ds else -1,
               active_set=int(ds["iterations" if "iterations" in ds else "newton_iterations"].sum()),
               cg=int(ds.linear_iterations.sum()) if "linear_iterations" in ds else 0)
    if name.startswith("memory_hertz"):
        from workbench.references import hertz

        row["pressure_l2"] = round(float(hertz.profile(ds)["l2"]), 5)
    return row, ds


SLOPE = [("memory_block", [dict(h=0.1), dict(h=0.07), dict(h=0.05)]),
         ("memory_hertz3d", [dict(h_contact=0.02), dict(h_contact=0.01), dict(h_contact=0.005)])]


SLOPE_CG = [(f"memory_block, solver = {solver}", "memory_block", [dict(h=h, T=0.3, solver=solver)
                                                                   for h in (0.1, 0.07, 0.05, 0.035)])
            for solver in ("auto", "cg")]


SLOPE_AUTO = [("memory_block, contact_solver = auto", "memory_block",
               [dict(h=h, T=0.3) for h in (0.1, 0.07, 0.05, 0.035)])]


def slope(rows, cases=None, contact="coupled", sticks=False, repeat=1) -> None:
    """The time loop's cost per step (the ``contact`` solver, one thread) against the dofs, and its log-log slope (over
    all sizes, and ``slope_last`` over the last two); ``whole_per_step``: the whole run's wall time over its steps;
    with ``sticks`` the yardsticks of each size beside (:func:`yardsticks`: a factorization and a solve). Each size
    runs ``repeat`` times, the run of the median loop time kept (``repeats``: the loop times of all)."""
    for label, name, sizes in cases or [(name, name, sizes) for name, sizes in SLOPE]:
        mine = []
        for overrides in sizes:
            runs = sorted((one(name, overrides, contact) for _ in range(repeat)),
                          key=lambda run: float(run[1].attrs["wall_time"]))
            row, ds = runs[len(runs) // 2]
            row["repeats"] = " ".join(f"{float(d.attrs['wall_time']):.3f}" for _, d in runs)
            if sticks:
                row.update(yardsticks(name, {k: v for k, v in overrides.items() if k != "solver"}))
            row.update(loop=round(float(ds.attrs["wall_time"]), 3),
                       per_step=round(float(ds.attrs["wall_time"]) / row["steps"], 4),
                       backsubs_per_step=round(row["backsubs"] / row["steps"], 1),
                       whole_per_step=round(row["wall"] / row["steps"], 4))
            mine.append(row)
            print(row, flush=True)
        fit = np.polyfit(np.log([r["ndof"] for r in mine]), np.log([r["per_step"] for r in mine]), 1)[0]
        last = np.log(mine[-1]["per_step"] / mine[-2]["per_step"]) / np.log(mine[-1]["ndof"] / mine[-2]["ndof"])
        for r in mine:
            r["slope"], r["slope_last"] = round(float(fit), 3), round(float(last), 3)
        rows.extend(mine)
        print(label, "slope of the cost of a step against the dofs", round(float(fit), 3), "(last two sizes",
              round(float(last), 3), ")", flush=True)


def pdas_amg(rows, sizes=(0.01, 0.005)) -> None:
    """A route measured and not taken (``--pdas-amg``): the primal-dual active set of deal.II's step-41/42 on the
    whole body, each active set's system (the active points' normal displacement held at the gap) solved by conjugate
    gradients preconditioned by the smoothed-aggregation AMG of the unconstrained K (pyamg, as ``solver = "cg"``),
    projected onto the free unknowns. One load step of the hemisphere, Signorini, from rest to the full load; each
    system solved loosely (10^-2) while the states change, then to 10^-10. Against the sparse Cholesky factor of K
    in the same process, one thread."""
    import pyamg
    from scipy.sparse.linalg import LinearOperator, cg

    from workbench.discrete import discretisation
    from workbench.discrete.solvers import rigid_body_modes, to_scipy

    for hc in sizes:
        sc = workbench.scene("memory_hertz3d", h_contact=hc)
        d = discretisation.build(sc)
        discretisation.assemble(d)
        t0 = time.perf_counter()
        d.elastic.mat.Inverse(d.fes.FreeDofs(), inverse="sparsecholesky")
        factor = time.perf_counter() - t0
        K = to_scipy(d.elastic.mat).tocsr()
        f = d.u.vec.CreateVector()
        d.load_vector(sc["T"], f)
        f = f.FV().NumPy().copy()
        free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
        t0 = time.perf_counter()
        Kf = K[free][:, free].tocsr()
        amg = pyamg.smoothed_aggregation_solver(Kf, B=np.ascontiguousarray(rigid_body_modes(d.fes)[free]),
                                                symmetry="hermitian", strength=("symmetric", {"theta": 0.0}),
                                                max_coarse=2000, coarse_solver="splu").aspreconditioner(cycle="V")
        setup = time.perf_counter() - t0
        g, nd = d.geometry, d.normal_dofs
        gap = d.node_xyz[:, g.normal_axis]
        where = -np.ones(K.shape[0], dtype=np.int64)
        where[free] = np.arange(len(free))
        point = where[nd]  # (-1: the held apex)
        u, active = np.zeros(K.shape[0]), point < 0
        tol, iterations, cg_iterations, solving = 1e-2, 0, 0, 0.0
        while iterations < 40:
            iterations += 1
            held = active & (point >= 0)
            keep = np.ones(len(free), dtype=bool)
            keep[point[held]] = False
            lift = np.zeros(len(free))
            lift[point[held]] = g.normal_sign * gap[held]
            b = np.where(keep, f[free] - Kf @ lift, 0.0)
            op = LinearOperator(Kf.shape, matvec=lambda x: np.where(keep, Kf @ np.where(keep, x, 0.0), 0.0))
            pre = LinearOperator(Kf.shape, matvec=lambda x: np.where(keep, amg @ np.where(keep, x, 0.0), 0.0))
            count = [0]
            t0 = time.perf_counter()
            z, _ = cg(op, b, x0=np.where(keep, u[free], 0.0), rtol=tol, atol=0.0, maxiter=1000, M=pre,
                      callback=lambda _: count.__setitem__(0, count[0] + 1))
            solving += time.perf_counter() - t0
            cg_iterations += count[0]
            u[:] = 0.0
            u[free] = np.where(keep, z, 0.0) + lift
            force = -g.normal_sign * (K @ u - f)[nd]
            new = (force + 1e3 * (g.normal_sign * u[nd] - gap) > 0) | (point < 0)
            if np.array_equal(new, active):
                if tol <= 1e-10:
                    break
                tol = 1e-10
            active = new
        rows.append(dict(case=f"memory_hertz3d h_contact={hc}", ndof=d.ndof, contact_points=len(nd),
                         factor_K=round(factor, 3), amg_setup=round(setup, 3), active_set_iterations=iterations,
                         cg_iterations=cg_iterations, solves=round(solving, 3),
                         setup_and_solves_over_factor=round((setup + solving) / factor, 2)))
        print(rows[-1], flush=True)


def yardsticks(name, overrides):
    """Seconds to factor K (the step's matrix without memory) once with NGSolve's sparse Cholesky and with MKL PARDISO
    (analysis and factorization), a back-substitution with each, PARDISO's Schur complement on the contact points
    (the condensed stiffness the condensed solver needs) made from a factored K, and (P1) the one factorization that
    keeps the contact dofs last and gives both, one thread, the mesh of the case."""
    from workbench.discrete import discretisation, pardiso, solvers
    from workbench.schemes.contact_nodes import ContactNodes

    d = discretisation.build(workbench.scene(name, **overrides))
    discretisation.assemble(d)
    out, rhs = {}, np.random.default_rng(0).standard_normal(d.ndof)
    for method in ("sparsecholesky", "pardiso"):
        t0 = time.perf_counter()
        s = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, method)
        if method == "pardiso":
            s.factor  # noqa: B018 (PARDISO factors at the first use: now)
        out[f"factor_{method}"] = round(time.perf_counter() - t0, 3)
        x, times = np.zeros(d.ndof), []
        for _ in range(5):
            t0 = time.perf_counter()
            s.solve(rhs, x)
            times.append(time.perf_counter() - t0)
        out[f"backsub_{method}"] = round(float(np.median(times)), 5)
    if d.scene["scheme"] == "vi":  # (Model B: its contact points)
        nodes = ContactNodes(d)
        t0 = time.perf_counter()
        s.condensed_stiffness(nodes.C, nodes.B)  # (s is factored: a Schur complement of its own)
        out["schur"] = round(time.perf_counter() - t0, 3)
        if nodes.B is None:  # one factorization that keeps the contact dofs last (what a condensed run makes)
            t0 = time.perf_counter()
            solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, "pardiso").condensed_stiffness(nodes.C)
            out["factor_keeping_contact"] = round(time.perf_counter() - t0, 3)
        out["schur_by_solves_estimate"] = round(nodes.size * out["backsub_sparsecholesky"], 2)
    out["mkl"] = pardiso.available()
    return out


def with_pardiso(rows, cases) -> None:
    """Each case with both contact solvers on NGSolve's sparse Cholesky and on PARDISO (``solver = "pardiso"``), and
    the yardsticks (:func:`yardsticks`); the condensed solver on NGSolve's factor is left out at 47k dofs (783 s)."""
    for name, overrides in cases:
        workbench.scene(name, **overrides)
        sticks = yardsticks(name, overrides)
        print(name, overrides, sticks, flush=True)
        for contact in ("condensed", "coupled"):
            for factor in ("sparsecholesky", "pardiso"):
                if (name, overrides) in BIG and (contact, factor) == ("condensed", "sparsecholesky"):
                    continue
                row, ds = one(name, dict(overrides, solver=factor), contact)
                row.update(sticks, factor=factor,
                           over_ngsolve_factor=round(row["wall"] / sticks["factor_sparsecholesky"], 1),
                           over_pardiso_factor=round(row["wall"] / sticks["factor_pardiso"], 1))
                rows.append(row)
                print(row, flush=True)


def table(rows) -> str:
    """The markdown table of docs/schemes.md from the rows of one run."""
    by = {}
    for r in rows:
        by.setdefault((r["case"], r["overrides"]), {})[r["solver"]] = r
    lines = ["| case | dofs | contact points | steps | condensed [s] | coupled [s] | coupled: back-substitutions (CG) "
             "| difference | factor of K alone [s] |", "|---|---|---|---|---|---|---|---|---|"]
    for (case, overrides), d in by.items():
        c, k = d.get("condensed"), d["coupled"]
        backsubs = k["backsubs"] if int(k["backsubs"]) >= 0 else "—"
        difference = f"{float(k['difference']):.1e}" if k.get("difference") not in (None, "") else "—"
        lines.append(f"| `{case}` {overrides} | {k['ndof']} | {k['points']} | {k['steps']} | "
                     f"{c['wall'] if c else 'not run'} | {k['wall']} | {backsubs} ({k['cg']}) | {difference} | "
                     f"{k['factor_K']} |")
    return "\n".join(lines)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/contact_solver")
    p.add_argument("--big", action="store_true")
    p.add_argument("--slope", action="store_true", help="only the cost of a step against the dofs (slope.csv)")
    p.add_argument("--slope-cg", action="store_true", help="the same, factor against CG (slope_cg.csv)")
    p.add_argument("--slope-auto", action="store_true", help="the same, the contact solver auto takes (slope_auto.csv)")
    p.add_argument("--repeat", type=int, default=1, help="with --slope*: runs of each size, the median kept")
    p.add_argument("--pdas-amg", action="store_true", help="only the active set on the whole body with AMG-CG, one "
                   "load step of the hemisphere (pdas_amg.csv)")
    p.add_argument("--pardiso", action="store_true", help="only both contact solvers on NGSolve's factor and on "
                   "MKL PARDISO, with --big the hemisphere at 47k dofs too (pardiso.csv)")
    args = p.parse_args()
    if args.repeat < 1:
        p.error(f"--repeat: at least 1 run of each size, got {args.repeat}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if args.pardiso:
        with threadpool_limits(1):
            workbench.run("memory_slab", h=0.5, k=0.5, progress=False)  # (warm-up)
            with_pardiso(rows, CASES + (BIG if args.big else []))
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with open(out / "pardiso.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)
        return
    if args.pdas_amg:
        with threadpool_limits(1):
            pdas_amg(rows)
        with open(out / "pdas_amg.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[-1]))
            w.writeheader()
            w.writerows(rows)
        return
    if args.slope or args.slope_cg or args.slope_auto:
        with threadpool_limits(1):
            workbench.run("memory_slab", h=0.5, k=0.5, progress=False)  # (warm-up)
            if args.slope_auto:
                slope(rows, SLOPE_AUTO, "auto", sticks=True, repeat=args.repeat)
            else:
                slope(rows, SLOPE_CG if args.slope_cg else None, repeat=args.repeat)
        name = "slope_auto.csv" if args.slope_auto else "slope_cg.csv" if args.slope_cg else "slope.csv"
        with open(out / name, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[-1]))
            w.writeheader()
            w.writerows(rows)
        return
    with threadpool_limits(1):
        workbench.run("memory_slab", h=0.5, k=0.5, progress=False)  # warm-up: imports and first calls out of the timings
        for name, overrides in CASES + (BIG if args.big else []):
            workbench.scene(name, **overrides)  # (checked; the mesh is made by the first run and cached)
            assemble, factor = factor_alone(name, overrides)
            solvers = ["coupled"] if (name, overrides) in BIG else ["condensed", "coupled"]
            done = {}
            for solver in solvers:
                row, ds = one(name, overrides, solver)
                row.update(assemble_K=round(assemble, 3), factor_K=round(factor, 3),
                           wall_over_factor=round(row["wall"] / factor, 1))
                done[solver] = ds
                rows.append(row)
            if len(done) == 2:
                a, b = done["condensed"].u_contact, done["coupled"].u_contact
                rows[-1]["difference"] = float(np.abs(a - b).max() / np.abs(a).max())
            for row in rows[-len(solvers):]:
                print(" | ".join(f"{k} {v}" for k, v in row.items()), flush=True)
    keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[-1]).index(k) if k in rows[-1] else 99)
    with open(out / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    print(table(rows))
    print(f"wrote {out / 'summary.csv'}")


if __name__ == "__main__":
    main()
