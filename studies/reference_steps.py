"""The step limits of the rod references: their time and their agreement with a smaller limit.

    python studies/reference_steps.py [--out data/references]

The references are ODEs whose right-hand sides have kinks (the contact laws' and the bonding law's); a step limit
keeps the error control from stepping over a kink. This study integrates each reference with its limit and with
tighter ones, on scenes with and without stiff contact, and reports the time of each and the largest difference of
the solution from the tightest, over the solution's largest value:

* Model A's rod (:func:`workbench.references.rod.rod_ode`, Radau at rtol 1e-11): max_step T/2000 (the limit before),
  T/200 (the limit where the rod is not stiff), and T/20000 at rtol 1e-12 (the tightest);
* Model B's Prony rod (:func:`workbench.references.volterra.solve_prony`, DOP853 at rtol 1e-10): T/5000 (the
  tightest, the default before), T/1000 (the default), T/500.

Writes ``reference_steps.csv``; about 2 minutes.
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import workbench
from workbench.references import rod as rod_refs
from workbench.references import volterra

RODS = [("tp1", {}), ("tp2", {}), ("tp3", {}), ("tp2", dict(gamma_nu=1.5, L=0.2)),
        ("rod", dict(T=1.0, h=0.1, delta="0.3*sin(2*pi*t)", c_nu=1000.0)),
        ("rod", dict(T=1.0, h=0.1, delta="0.3*sin(2*pi*t)", c_nu=1e5)),
        ("rod", dict(T=1.0, h=0.1, delta="0.3*sin(2*pi*t)", c_nu=1e7, b=0.01))]
MEMORY = [{}, dict(T=2.0), dict(delta="0.15*sin(6*pi*t)")]


def _timed(solve):
    start = time.perf_counter()
    out = solve()
    return out, time.perf_counter() - start


def model_a(name, values):
    """Rows for one Model A rod: each limit's time and difference from the tightest."""
    sc = workbench.scene(name, **values)
    model = sc.model_of()
    terms = rod_refs._rod_terms(model)
    a, b, ell = model.elastic.modulus, model.viscous.modulus, model.geometry.extent[0]
    rhs = rod_refs._rod_rhs(model.loads.delta, ell, a, b, terms, model.bonding)
    T, beta0 = sc["T"], (model.beta0 if model.bonding is not None else 1.0)
    t = np.linspace(0.0, T, 4001)
    runs = {}
    for label, div, rtol, atol in (("T/20000, rtol 1e-12", 20000, 1e-12, 1e-14), ("T/2000", 2000, 1e-11, 1e-13),
                                   ("T/200", 200, 1e-11, 1e-13)):
        sol, seconds = _timed(lambda: solve_ivp(rhs, (0.0, T), [0.0, beta0], method="Radau", rtol=rtol, atol=atol,
                                                dense_output=True, max_step=T / div))
        runs[label] = (sol.sol(t), seconds, sol.t.size)
    _, used = _timed(lambda: rod_refs.rod_ode(sc))
    tightest = runs["T/20000, rtol 1e-12"][0]
    scale = np.abs(tightest).max(axis=1)
    rows = [dict(reference="rod_ode", scene=name, values=values, limit=label, seconds=round(seconds, 3), steps=steps,
                 difference=float((np.abs(y - tightest).max(axis=1) / scale).max()))
            for label, (y, seconds, steps) in runs.items()]
    return rows + [dict(reference="rod_ode", scene=name, values=values, limit="rod_ode as it chooses",
                        seconds=round(used, 3), steps="", difference="")]


def model_b(values):
    """Rows for one Model B Prony rod: each limit's time and difference from T/5000."""
    sc = workbench.scene("memory_rod", **values)
    model = sc.model_of()
    layer, delta = model.layer, model.loads.delta
    common = dict(a=model.elastic.modulus, ell=model.geometry.extent[0], F=layer.F, c=layer.c, g=layer.g, T=sc["T"],
                  delta=lambda t: np.broadcast_to(np.asarray(delta(t=t), dtype=float), np.shape(t)))
    terms = model.memory.terms
    t = np.linspace(0.0, sc["T"], 20001)
    runs = {}
    for div in (5000, 1000, 500):
        sol, seconds = _timed(lambda: volterra.solve_prony(moduli=[C.modulus for C, _ in terms],
                                                           taus=[tau for _, tau in terms], max_step=sc["T"] / div,
                                                           **common))
        runs[f"T/{div}"] = (sol.A(t), seconds)
    tightest = runs["T/5000"][0]
    return [dict(reference="solve_prony", scene="memory_rod", values=values, limit=label, seconds=round(seconds, 3),
                 steps="", difference=float(np.abs(A - tightest).max() / np.abs(tightest).max()))
            for label, (A, seconds) in runs.items()]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="data/references")
    args = parser.parse_args()
    rows = [row for name, values in RODS for row in model_a(name, values)]
    rows += [row for values in MEMORY for row in model_b(values)]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "reference_steps.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    for row in rows:
        print(f"{row['reference']:12s} {row['scene']:10s} {str(row['values']):60.60s} {row['limit']:22s} "
              f"{row['seconds']:>7} s  {row['difference']}")


if __name__ == "__main__":
    main()
