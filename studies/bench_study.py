"""Cost of a 5-level coupled h = k sweep on the slab, and the Study machinery's own overhead.

Run:  python studies/bench_study.py

The sweep: tp5 (P1, explicit), h = 0.05 ... 0.003125 (ny = 2 ... 32), k = 0.2 h (below k_crit ~ 0.03), T = 1,
reference = the finest level. Measured in one process, one after another:
(a) the five runs as a plain loop of ``workbench.run`` (the floor),
(b) the same as a Study in this process (workers=0: archiving + error evaluation),
(c) the Study with 2 spawned workers (process start, pickling, archiving, evaluation).
Overhead of the machinery = (b - a) / b; the 2-worker wall time (c) is the headline figure.
"""
from __future__ import annotations

import json
import tempfile
import time

import workbench
from workbench.study import Study

LEVELS = [0.05, 0.025, 0.0125, 0.00625, 0.003125]
C = 0.2


def main():
    sc = workbench.scene("tp5")
    t0 = time.perf_counter()
    per_case = []
    for h in LEVELS:
        a = time.perf_counter()
        ds = workbench.run(sc.with_(h=h, k=C * h), progress=False)
        per_case.append(dict(h=h, k=C * h, ndof=ds.attrs["ndof"], steps=ds.attrs["nsteps"],
                             setup_s=ds.attrs["setup_time"], loop_s=ds.attrs["wall_time"],
                             total_s=time.perf_counter() - a))
    plain = time.perf_counter() - t0
    for r in per_case:
        print(f"  h={r['h']:<8g} k={r['k']:<8g} ndof={r['ndof']:6d} steps={r['steps']:5d}  setup {r['setup_s']:.2f} s"
              f"  loop {r['loop_s']:.2f} s  run() total {r['total_s']:.2f} s", flush=True)
    print(f"(a) plain loop of run(): {plain:.2f} s", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        st = Study("tp5", h=LEVELS, k_over_h=C, workers=0)
        t0 = time.perf_counter()
        st.run(tmp + "/seq", progress=False)
        seq = time.perf_counter() - t0
        print(f"(b) Study, in process: {seq:.2f} s (evaluation {st.overhead['evaluate']:.2f} s); "
              f"machinery overhead (b - a) / b = {100 * (seq - plain) / seq:.1f} %", flush=True)
        st2 = Study("tp5", h=LEVELS, k_over_h=C, workers=2)
        t0 = time.perf_counter()
        ds = st2.run(tmp + "/par", progress=False)
        par = time.perf_counter() - t0
        print(f"(c) Study, 2 workers: {par:.2f} s (running {st2.overhead['execute']:.2f} s, "
              f"evaluation {st2.overhead['evaluate']:.2f} s)", flush=True)
    rates = {n: round(float(ds.observed_order.sel(norm=n, along="h+k").squeeze()), 3)
             for n in ("error", "error_V", "error_Q", "error_beta")}
    print(f"fitted orders along h+k: {rates}")
    print(json.dumps(dict(per_case=per_case, plain_s=plain, study_seq_s=seq, study_2workers_s=par, orders=rates)))


if __name__ == "__main__":
    main()
