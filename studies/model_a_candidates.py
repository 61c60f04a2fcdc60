"""Model A's implicit steps on the contact candidates against the coupled solver on the whole side, on the hemisphere.

    python studies/model_a_candidates.py [--out data/hertz] [--levels 0.005 0.0035] [--scheme implicit] [--repeat 1]
        [--variants both|candidates] [--cap B]

``hertz3d`` at its defaults (Kelvin-Voigt, normal compliance, backward Euler with k = 0.02 to T = 1: 52 steps, the
load's kinks met by half steps), ``contact_solver = "auto"``, where ``auto`` takes the coupled solver (from 2500
contact unknowns: h_contact = 0.005 and finer). Each level runs twice, each in a process of its own with one thread:
as ``auto`` takes it now (``candidates``: :mod:`workbench.schemes.facet_candidates`) and with the coupled solver on
the whole side alone (``coupled alone``: ``Candidates.most`` made 0, as before the candidates). Per run: dofs,
contact dofs, candidates and whether they missed, Newton and inner iterations (the coupled solver's inner ones are
back-substitutions; the candidates' are dense products), the whole ``workbench.run``, the time loop, PARDISO's
factorizations inside it, ``per_step`` (the loop less those, over the steps), the process's peak memory, and
``du_rel``, the largest difference of u at the contact dofs from the candidates' run, over its largest value (the two
solve the same discrete problem). ``operator_dense``: the time spent inverting the candidates' condensed stiffness
into their compliance, once per step operator (a dense Cholesky factor and its inverse, the dense counterpart of the
operator's sparse factorization), and ``per_step_marginal``, the loop less both over the steps: what one more step of
a size already met costs. ``slope`` and ``slope_marginal``: per_step and per_step_marginal against the dofs in
log-log, per variant, from the medians of the ``--repeat`` runs of each level (the levels alternate, so the
machine's drift falls on all of them). ``--variants candidates`` leaves out the coupled solver alone. ``--cap B``:
at most B back-substitutions' worth of candidates instead of the package's 4 (``Candidates.backsubs``; docs/schemes.md,
"More candidates for runs of many steps", measured B = 8), written to ``model_a_candidates_capB.csv``. Writes
``model_a_candidates.csv`` (about 6 minutes at the default levels; 16 at the three levels with both variants).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHILD = """
import json, resource, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
import workbench
from workbench.discrete import discretisation, pardiso
from workbench.schemes.candidates import Candidates
hc, variant, scheme, out, cap = float(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5]
if cap != "default":  # (--cap: more or fewer candidates for runs of many steps)
    Candidates.backsubs = (Candidates.backsubs[0], float(cap))
if variant != "candidates":
    Candidates.most = classmethod(lambda cls, ndof, method, steps: 0)
from workbench.discrete import condensation, solvers
factoring, dense = [], []
init, inverse = pardiso.Factor.__init__, solvers.inverse

def timed(self, *args, **kwargs):
    t = time.perf_counter()
    init(self, *args, **kwargs)
    factoring.append(time.perf_counter() - t)

def timed_inverse(A):
    t = time.perf_counter()
    out = inverse(A)
    dense.append(time.perf_counter() - t)
    return out

condensation.inverse = solvers.inverse = timed_inverse  # (the compliance: a factor's kept() or a DenseSchur)

with threadpool_limits(1):
    discretisation.build(workbench.scene("hertz3d", h_contact=hc))  # (the mesh made and cached, modules loaded)
    pardiso.Factor.__init__ = timed
    t0 = time.perf_counter()
    ds = workbench.run("hertz3d", h_contact=hc, scheme=scheme, progress=False, threads=1)
    run = time.perf_counter() - t0
np.save(out, ds.u_contact.values)
steps, loop = int(ds.attrs["nsteps"]), float(ds.attrs["wall_time"])
print(json.dumps(dict(h_contact=hc, variant=variant, scheme=scheme, ndof=int(ds.attrs["ndof"]),
                      contact_vertices=int(ds.sizes["node"]),
                      in_contact=int((ds.contact_pressure.values[-1] > 0).sum()),
                      contact_solver=ds.attrs["contact_solver_used"], linear_solver=ds.attrs["linear_solver"],
                      candidates=int(ds.attrs["contact_candidates"]),
                      missed=int(ds.attrs["contact_candidates_missed"]), steps=steps,
                      newton=int(ds.newton_iterations.sum()), inner=int(ds.linear_iterations.sum()),
                      run=round(run, 2), loop=round(loop, 2), factorizations=len(factoring),
                      factor_time=round(sum(factoring), 2), per_step=round((loop - sum(factoring)) / steps, 4),
                      operator_dense=round(sum(dense), 2), cap=Candidates.backsubs[1],
                      per_step_marginal=round((loop - sum(factoring) - sum(dense)) / steps, 4),
                      peak_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0))))
"""


def one(hc: float, variant: str, scheme: str, out: str, cap=None) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    args = [sys.executable, "-c", CHILD, str(hc), variant, scheme, out, "default" if cap is None else str(cap)]
    done = subprocess.run(args, capture_output=True, text=True, env=env, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/hertz")
    p.add_argument("--levels", type=float, nargs="+", default=[0.005, 0.0035])
    p.add_argument("--scheme", default="implicit", choices=["implicit", "bdf2"])
    p.add_argument("--repeat", type=int, default=1, help="runs of each level and variant (the medians are fitted)")
    p.add_argument("--variants", default="both", choices=["both", "candidates"])
    p.add_argument("--cap", type=float, default=None, help="the most back-substitutions' worth of candidates "
                   "(Candidates.backsubs' upper bound; default the package's)")
    args = p.parse_args()
    variants = ("candidates", "coupled alone") if args.variants == "both" else ("candidates",)
    rows, first = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeat):
            for hc in args.levels:
                for variant in variants:
                    row = one(hc, variant, args.scheme, f"{tmp}/u.npy", args.cap)
                    u = np.load(f"{tmp}/u.npy")
                    first.setdefault(hc, u)
                    row["repeat"] = repeat
                    row["du_rel"] = float(np.abs(u - first[hc]).max() / np.abs(first[hc]).max())
                    rows.append(row)
                    print(row, flush=True)
    for variant in variants:
        same = [r for r in rows if r["variant"] == variant]
        dofs = sorted({r["ndof"] for r in same})
        if len(dofs) > 1:
            for key, slope in (("per_step", "slope"), ("per_step_marginal", "slope_marginal")):
                medians = [np.median([r[key] for r in same if r["ndof"] == n]) for n in dofs]
                fit = np.polyfit(np.log(dofs), np.log(medians), 1)[0]
                print(f"{variant}: {key} medians {medians}, slope {fit:.3f}")
                for r in same:
                    r[slope] = round(float(fit), 3)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "model_a_candidates.csv" if args.scheme == "implicit" else f"model_a_candidates_{args.scheme}.csv"
    name = name if args.cap is None else name.replace(".csv", f"_cap{args.cap:g}.csv")
    with open(out / name, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(dict.fromkeys(k for r in rows for k in r)))
        writer.writeheader()
        writer.writerows(rows)
    print("| h_contact | dofs | contact vertices (in contact) | variant | candidates (missed) | Newton (inner) | run "
          "| loop | factorizations | a step | peak | du |\n|" + "---|" * 12)
    for r in rows:
        print(f"| {r['h_contact']} | {r['ndof']} | {r['contact_vertices']} ({r['in_contact']}) | {r['variant']} | "
              f"{r['candidates']} ({r['missed']}) | {r['newton']} ({r['inner']}) | {r['run']} s | {r['loop']} s | "
              f"{r['factorizations']}: {r['factor_time']} s | {r['per_step']} s | {r['peak_mb']} MB | "
              f"{r['du_rel']:.1e} |")
    print(f"wrote {out / name}")


if __name__ == "__main__":
    main()
