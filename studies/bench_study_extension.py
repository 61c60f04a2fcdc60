"""A sweep extended to a longer T: continuing the archived cases against running the sweep straight to that T.

    python studies/bench_study_extension.py [--T 1.0]

Runs the tp5 sweep h = 0.0125, implicit, k = 0.004, 0.002 (finer-run reference k = 0.001) to T, then again to 2T on the same
archive folder (the cases continue from their archived states), and straight to 2T in a fresh folder; prints the
wall times and the largest relative difference of the errors.
"""
import argparse
import tempfile
import time

import numpy as np

from workbench import Study


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--T", type=float, default=1.0)
    T = p.parse_args().T
    kw = dict(h=[0.0125], k=[0.004, 0.002], reference={"k": 0.001}, scheme="implicit", workers=2)
    folder = tempfile.mkdtemp(prefix="extension-")
    times = {}
    for label, t_end, where in (("to T", T, folder), ("extended to 2T", 2 * T, folder),
                                ("straight to 2T", 2 * T, tempfile.mkdtemp(prefix="straight-"))):
        t0 = time.perf_counter()
        st = Study("tp5", T=t_end, **kw)
        ds = st.run(where, progress=False)
        times[label] = (time.perf_counter() - t0, ds, st.overhead)
        o = st.overhead
        print(f"{label:16s} {times[label][0]:7.2f} s (running the cases {o['execute']:6.2f} s, comparing "
              f"{o['evaluate']:5.2f} s)  new cases {o['new_cases']}, extended {o['extended_cases']}")
    a, b = times["extended to 2T"][1], times["straight to 2T"][1]
    diff = max(float(np.nanmax(np.abs(a[n].values - b[n].values) / np.abs(b[n].values)))
               for n in ("error", "error_probe", "error_beta"))
    ratio = times["extended to 2T"][2]["execute"] / times["straight to 2T"][2]["execute"]
    print(f"running the cases, extension / straight: {ratio:.2f}; "
          f"largest relative difference of the errors: {diff:.2g}")


if __name__ == "__main__":
    main()
