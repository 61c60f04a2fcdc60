"""The contact pressure against Hertz's: the lumped nodal pressure and its patch recovery, 2D and 3D, three meshes.

    python studies/pressure_recovery.py [--out data/hertz]

Runs ``memory_hertz`` (2D, Signorini) and ``memory_hertz3d`` (the hemisphere) at three contact-zone sizes and
reports, for ``contact_pressure`` (F_i / w_i) and ``contact_pressure_recovered`` (the patch average,
:class:`workbench.discrete.pressure.Recovery`): the relative L2 error within 2 a (by
the vertices' weights), the peak's error against p0 (the apex left out: its value is the support's reaction), the
spread of p / p_Hertz inside 0.8 a (the scatter of an unstructured surface mesh) and the resultant over the load's
share. Writes ``pressure_recovery.csv`` and prints the table of docs/models.md.
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

import workbench
from workbench.references import hertz

CASES = [("memory_hertz", [0.01, 0.005, 0.0025]), ("memory_hertz3d", [0.02, 0.01, 0.005])]


def measures(ds, variable):
    r = hertz.profile(ds, variable=variable)
    three = "node_z" in ds.coords
    p0 = (hertz.sphere if three else hertz.cylinder)(r["load"], float(ds.attrs["radius"]), float(ds.attrs["E"]),
                                                      float(ds.attrs["nu"]))[1](0.0)
    x, p, ph = r["x"], r["p"], r["p_hertz"]
    inner = (x > 0) & (x < 0.8 * r["a"])
    return dict(l2=r["l2"], peak=float(np.max(p[x > 0]) / p0 - 1), spread=float(np.std(p[inner] / ph[inner])),
                force=r["force"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="data/hertz")
    out = Path(parser.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with threadpool_limits(1):
        for name, levels in CASES:
            for hc in levels:
                t0 = time.perf_counter()
                ds = workbench.run(name, h_contact=hc, progress=False)
                wall = time.perf_counter() - t0
                for variable in ("contact_pressure", "contact_pressure_recovered"):
                    row = dict(case=name, h_contact=hc, ndof=ds.attrs["ndof"], wall=round(wall, 1),
                               pressure="lumped" if variable == "contact_pressure" else "recovered")
                    row.update({k: round(v, 5) for k, v in measures(ds, variable).items()})
                    rows.append(row)
                    print(row, flush=True)
    with open(out / "pressure_recovery.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print("| body | h_contact | dofs | pressure | L2 error | peak | spread inside 0.8 a | resultant / load |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| `{r['case']}` | {r['h_contact']} | {r['ndof']} | {r['pressure']} | {100 * r['l2']:.2f} % | "
              f"{100 * r['peak']:+.2f} % | {100 * r['spread']:.2f} % | {r['force']:.6f} |")


if __name__ == "__main__":
    main()
