"""The explicit scheme's true step limit: predicted for the springs that act, against the observed onset.

Run:  python studies/step_limit.py [--out data/step_limit] [--quick]

Scenes (each with the stability map's criterion of ``studies/extremes.py``):

* ``pressed slab``: the map's slab (h = 0.05, E 1000, nu 0.3, a1 30, a2 20, c_nu 100, gamma_nu 20, L 0.3)
  under f_top = (0, -(1 + 0.5 sin(2 pi t / T))), the foundation spring acting on the whole bottom;
* ``held-out slab``: the slab of the time-stepping study (P2, h = 0.05, c_tau 10, eps_a 1e-3, the
  symmetric law) pulled up on its right half by (0, 5 t): the foundation spring cannot act;
* ``rocker``: the curved sole of ``docs/examples/rocker.toml`` (c_nu = 1e3, T = 0.2): the spring acts
  only where the sole touches.

For each: the bound with every spring acting (``stability.critical_step``), the prediction a run makes
(``k_crit_min`` of the run at the smallest k of the grid: the limit of the springs its state reached),
and runs of the explicit scheme with ``allow_unstable`` at k = f x prediction for f in FACTORS. A run is
``stable`` when it completes and its contact displacement u_nu stays within 25 % of max|u_nu| of the
reference (the implicit scheme at k = min(k/2, 1e-3) ... recorded at the explicit run's times) over the
second half of the run; ``off`` when it completes beyond that; ``diverged`` when workbench stops it. The
observed onset lies between the last stable factor and the first unstable one; the goal is an onset
within [0.8, 1.25] x the prediction.

Writes ``step_limit.json`` (the table printed) and ``step_limit.png``.
"""
from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np

import workbench
from workbench.discrete import stability
from workbench.study.measures import normal_displacement as u_nu

ROOT = Path(__file__).resolve().parents[1]
FACTORS = (0.5, 0.8, 0.9, 1.0, 1.1, 1.25, 1.5, 2.0)
OFF = 0.25
SLAB = dict(h=0.05, E=1000, nu=0.3, a1=30, a2=20, c_nu=100, gamma_nu=20, L=0.3)
SCENES = {
    "pressed slab": ("slab", dict(SLAB, traction_top="(0, -(1 + 0.5*sin(2*pi*t/0.2)))", T=0.2)),
    "held-out slab": ("slab", dict(SLAB, c_tau=10, eps_a=1e-3, bonding_truncation="symmetric", order=2,
                                   traction_top="(0, 5*t*ifpos(x - 0.5, 1, 0))", T=1.0)),
    "rocker": (str(ROOT / "docs" / "examples" / "rocker.toml"), dict(c_nu=1e3, T=0.2, snapshots=())),
}


def classify(run, ref):
    a, b = u_nu(run), u_nu(ref)[: u_nu(run).shape[0]]
    late = slice(a.shape[0] // 2, None)
    err = float(np.max(np.abs(a[late] - b[late])) / np.abs(b).max())
    return err, ("stable" if err <= OFF else "off")


def one(label, quick):
    scene, values = SCENES[label]
    sc = workbench.scene(scene, **values)
    bound = stability.critical_step(sc).k_crit
    first = workbench.run(sc, scheme="explicit", k=0.5 * bound, progress=False)
    predicted = first.attrs["k_crit_min"]
    rows = []
    for f in (FACTORS[1::2] if quick else FACTORS):
        k = f * predicted
        times = np.round(np.arange(0.0, sc["T"] + 0.5 * k, k), 12)
        times = times[times <= sc["T"] + 1e-12]
        ref = workbench.run(sc, scheme="implicit", k=min(k / 2, 1e-3), record_times=times, progress=False)
        a = time.perf_counter()
        try:
            ds = workbench.run(sc, scheme="explicit", k=k, allow_unstable=True, progress=False)
            err, cls = classify(ds, ref)
        except workbench.Diverged:
            err, cls = math.nan, "diverged"
        rows.append(dict(factor=f, k=k, cls=cls, error=err, wall=time.perf_counter() - a))
        print(f"  {label:14s} k = {f:4.2f} x {predicted:.3g}: {cls:8s} error {err:.3g}", flush=True)
    stable = [r["factor"] for r in rows if r["cls"] == "stable"]
    bad = [r["factor"] for r in rows if r["cls"] != "stable"]
    first_bad = min(bad) if bad else math.inf
    last_good = max((f for f in stable if f < first_bad), default=math.nan)
    return dict(scene=label, bound=bound, predicted=predicted, start=first.attrs["k_crit"],
                updates=first.attrs["k_crit_updates"], last_stable=last_good, first_unstable=first_bad,
                within=bool(last_good >= 0.8 and first_bad <= 1.25), rows=rows)


def plot(results, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.5))
    colour = {"stable": "tab:green", "off": "tab:orange", "diverged": "tab:red"}
    for i, r in enumerate(results):
        for row in r["rows"]:
            ax.scatter(row["factor"], i, color=colour[row["cls"]], s=60)
        ax.scatter(r["bound"] / r["predicted"], i, marker="|", color="k", s=300)
    ax.axvline(1.0, color="k", lw=1)
    ax.axvspan(0.8, 1.25, color="0.9", zorder=0)
    ax.set_yticks(range(len(results)), [r["scene"] for r in results])
    ax.set_xscale("log")
    ax.set_xlabel("k / k_crit predicted for the acting springs (|: the bound with every spring)")
    ax.set_title("explicit scheme: green stable, orange off, red stopped as diverged")
    fig.tight_layout()
    fig.savefig(out / "step_limit.png", dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "data" / "step_limit"))
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore", RuntimeWarning)  # (P1 locking, allow_unstable, debonding-resolution notes)
    results = [one(label, args.quick) for label in SCENES]
    print("\nscene           bound      predicted  start      onset in (last stable, first unstable) x predicted")
    for r in results:
        print(f"{r['scene']:15s} {r['bound']:.3g}  {r['predicted']:.3g}  {r['start']:.3g}  "
              f"({r['last_stable']:.2f}, {r['first_unstable']:.2f})  within [0.8, 1.25]: {r['within']}")
    (out / "step_limit.json").write_text(json.dumps(results, indent=1, default=float))
    plot(results, out)
    print(f"wrote {out / 'step_limit.json'}, {out / 'step_limit.png'}")


if __name__ == "__main__":
    main()
