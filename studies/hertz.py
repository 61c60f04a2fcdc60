"""The Hertz benchmarks: dofs, wall time and the pressure's error for three mesh levels, 2D and 3D.

    python studies/hertz.py [--out data/hertz]

Runs the elastic contact in the Signorini limit (Model B, ``memory_hertz`` / ``memory_hertz3d``) and with a stiff
normal compliance (Model A, ``hertz``, c_nu = 1e7, tau = 1e-3 s) at three contact-zone sizes h_contact, and the
viscoelastic ramp (Model A, tau = 0.2 s) against Lee and Radok. Writes ``hertz.csv`` (one row per run), the
pressure profiles (``hertz_profiles.png``) and a(t) (``lee_radok.png``), and prints the table and the observed
orders of the pressure's L2 error in h_contact; the profiles show the lumped pressure (dots) and the recovered one
(crosses, ``contact_pressure_recovered``).

    python studies/hertz.py --fine3d HC [HC ...] [--contact-zone Z] [--threads N]

runs only ``memory_hertz3d`` at those h_contact (the finer 3D levels: minutes each) with the contact zone Z R
(default 0.3; 1.25 a = 0.24 holds the contact of the default load with 64 % of the vertices) and appends the rows
to ``hertz3d_fine.csv``.
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

import workbench
from workbench.references import hertz

CASES = [
    ("memory_hertz", "2D, Model B (Signorini)", {}, [0.005, 0.0025, 0.00125]),
    ("hertz", "2D, Model A (c_nu = 1e7)", dict(c_nu=1e7, tau=1e-3, k=0.05), [0.005, 0.0025, 0.00125]),
    ("memory_hertz3d", "3D, Model B (Signorini)", {}, [0.04, 0.02, 0.01]),
]


def fine3d(levels, zone, threads, out):
    """memory_hertz3d at finer levels (rows appended to hertz3d_fine.csv)."""
    path = out / "hertz3d_fine.csv"
    for hc in levels:
        t0 = time.perf_counter()
        ds = workbench.run("memory_hertz3d", h_contact=hc, contact_zone=zone, threads=threads, progress=False)
        wall = time.perf_counter() - t0
        r = hertz.profile(ds)
        row = dict(h_contact=hc, contact_zone=zone, threads=threads or 1, ndof=ds.attrs["ndof"],
                   contact_nodes=ds.sizes["node"], wall_time=round(wall, 1),
                   setup_time=round(float(ds.attrs["setup_time"]), 1), a=r["a"], a_last=r["a_last"], l2=r["l2"],
                   force=r["force"])
        print(f"3D Signorini h_contact {hc:g} zone {zone:g}: ndof {row['ndof']}, {row['contact_nodes']} contact "
              f"vertices, {wall:.1f} s, L2 {100 * r['l2']:.2f} %, a {r['a']:.4f}, last in contact "
              f"{r['a_last']:.4f}, force/load {r['force']:.9f}", flush=True)
        new = not path.exists()
        with open(path, "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(row))
            if new:
                w.writeheader()
            w.writerow(row)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/hertz")
    p.add_argument("--fine3d", type=float, nargs="*", default=None)
    p.add_argument("--contact-zone", type=float, default=0.3)
    p.add_argument("--threads", type=int, default=None)
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.fine3d:
        return fine3d(args.fine3d, args.contact_zone, args.threads, out)
    rows, profiles = [], {}
    for scene, label, extra, levels in CASES:
        errors = []
        for hc in levels:
            t0 = time.perf_counter()
            ds = workbench.run(scene, h_contact=hc, progress=False, **extra)
            wall = time.perf_counter() - t0
            r = hertz.profile(ds)
            recovered = hertz.profile(ds, variable="contact_pressure_recovered")
            errors.append(r["l2"])
            profiles[scene, hc] = r, recovered
            rows.append(dict(scene=scene, case=label, h_contact=hc, ndof=ds.attrs["ndof"], contact_nodes=ds.sizes["node"],
                             wall_time=round(wall, 2), setup_time=round(float(ds.attrs["setup_time"]), 2),
                             a=r["a"], a_last=r["a_last"], a_next=r["a_next"], l2=r["l2"], force=r["force"],
                             l2_recovered=recovered["l2"]))
            print(f"{label:26s} h_contact {hc:<8g} ndof {rows[-1]['ndof']:6d}  {wall:6.2f} s  a {r['a']:.4f}  "
                  f"last in contact {r['a_last']:.4f}  next {r['a_next']:.4f}  L2 {100 * r['l2']:5.2f} % "
                  f"(recovered {100 * recovered['l2']:5.2f} %)  force/load {r['force']:.6f}")
        order = np.polyfit(np.log(levels), np.log(errors), 1)[0]
        print(f"{label:26s} observed order of the L2 error in h_contact: {order:.2f}")
    with open(out / "hertz.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lee = lee_radok(out)
    plot(profiles, lee, out)
    print(f"wrote {out / 'hertz.csv'}, {out / 'hertz_profiles.png'}, {out / 'lee_radok.png'}")


def lee_radok(out):
    """a(t) of the viscoelastic ramp against Lee-Radok (2D, Model A, tau = 0.2 s, BDF2)."""
    t0 = time.perf_counter()
    ds = workbench.run("hertz", h_contact=0.00125, c_nu=1e7, tau=0.2, k=0.02, scheme="bdf2", snapshots=(),
                       progress=False)
    wall = time.perf_counter() - t0
    times = ds.time.values[1:]
    a = np.array([hertz.lee_radok(t, 10.0, 1.0, 1000.0, 0.3, 0.2) for t in times])
    last = np.array([hertz.profile(ds, t)["a_last"] for t in times])
    nxt = np.array([hertz.profile(ds, t)["a_next"] for t in times])
    ok = a / 0.00125 >= 35
    print(f"Lee-Radok (ndof {ds.attrs['ndof']}, {wall:.2f} s): a_last / a - 1 within "
          f"[{(last[ok] / a[ok] - 1).min():+.4f}, {(last[ok] / a[ok] - 1).max():+.4f}] once a >= 35 h_contact "
          f"(t >= {times[ok][0]:.2f} s)")
    return times, a, last, nxt


def plot(profiles, lee, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    for ax, (scene, label, _, levels) in zip(axes, CASES):
        r0 = profiles[scene, levels[0]][0]
        x = np.linspace(0, 1.5 * r0["a"], 300)
        ref = hertz.cylinder if "3d" not in scene else hertz.sphere
        ax.plot(x, ref(10.0, 1.0, 1000.0, 0.3)[1](x), "k", lw=2, label="Hertz")
        for hc in levels:
            r, recovered = profiles[scene, hc]
            near = r["x"] < 1.5 * r["a"]
            dots = ax.plot(r["x"][near], r["p"][near], ".", ms=3,
                           label=f"h_contact = {hc:g}: lumped ({100 * r['l2']:.1f} %)")[0]
            near = recovered["x"] < 1.5 * recovered["a"]
            ax.plot(recovered["x"][near], recovered["p"][near], "+", ms=4, color=dots.get_color(), alpha=0.6,
                    label=f"recovered ({100 * recovered['l2']:.1f} %)")
        ax.set_title(label)
        ax.set_xlabel("distance from the apex [m]")
        ax.set_ylabel("pressure [Pa]")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "hertz_profiles.png", dpi=120)
    times, a, last, nxt = lee
    fig, ax = plt.subplots(figsize=(6, 3.8))
    ax.fill_between(times, last, nxt, alpha=0.3, label="computed: last vertex in contact .. next")
    ax.plot(times, a, "k", label="Lee-Radok")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("a [m]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "lee_radok.png", dpi=120)


if __name__ == "__main__":
    main()
