"""Regression archives: one run of each kind the package makes, archived, and two such sets compared.

    python studies/regression.py run DIR              # every case into DIR/<case>.nc (about 3 minutes on 2 cores)
    python studies/regression.py run DIR --only tp    # the cases whose name contains 'tp'
    python studies/regression.py compare OLD NEW      # per archive: bitwise, or the largest relative difference

A refactoring of the run core must leave every result as it was: run the cases on the code before it (into OLD)
and after it (into NEW), then compare. Every data variable and coordinate is compared, and every numerical
attribute except the costs and the provenance (wall and CPU times, history, versions); a round-off residual
(``complementarity``) only absolutely. NGSolve's sparse Cholesky factors one matrix differently from run to run
(the 3D cases: 1e-14 to 1e-12 relative between two runs of the same code), so compare a set with a second run of
the same code too, to see that floor.

The cases cover the schemes (explicit, implicit, bdf2 fixed and error-controlled, vi with each memory rule and
kernel), both models in 1D, 2D and 3D, P1 and P2, the curved (Hertz) bodies, a restart and a checkpointed run, and
one explicit case on 2 and 3 MPI processes (when mpiexec is installed).
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: name -> (scene, overrides) for workbench.run
CASES = {
    "tp1": ("tp1", {}),
    "tp2": ("tp2", {}),
    "tp3": ("tp3", {"T": 2.0}),
    "tp4": ("tp4", {"T": 0.3}),
    "tp5": ("tp5", {"T": 0.3}),
    "tp5_implicit": ("tp5", {"T": 0.3, "scheme": "implicit", "c_nu": 100.0, "gamma_nu": 20.0}),
    "tp5_bdf2": ("tp5", {"T": 0.3, "scheme": "bdf2", "c_tau": 1.0}),
    "tp2_bdf2_rtol": ("tp2", {"scheme": "bdf2", "rtol": 1e-4}),
    "tp1_implicit_rtol": ("tp1", {"scheme": "implicit", "rtol": 1e-3}),
    "slab_bdf2_rtol": ("slab", {"h": 0.05, "order": 2, "k": 0.01, "T": 0.3, "scheme": "bdf2", "rtol": 1e-3,
                                "traction_top": "(0, 5*t*ifpos(x-0.5, 1, 0))", "gamma_nu": 20.0}),
    "tp3_rod_explicit": ("tp3", {"T": 1.0, "k": 0.005}),
    "memory_rod": ("memory_rod", {}),
    "memory_rod_trapezoid_rtol": ("memory_rod", {"memory_rule": "trapezoid", "rtol": 1e-4}),
    "memory_rod_kernel": ("memory_rod", {"prony": (), "kernel": "exp(-t/0.2)", "kernel_E": 0.5, "T": 0.5}),
    "memory_rod_kernel_exp": ("memory_rod", {"prony": (), "kernel": "exp(-t/0.2)/(1+t)", "kernel_E": 0.5, "T": 0.5,
                                             "kernel_approximation": "exponentials"}),
    "memory_slab": ("memory_slab", {"h": 0.1}),
    "memory_slab_p2_trapezoid": ("memory_slab", {"h": 0.2, "order": 2, "memory_rule": "trapezoid"}),
    "memory_slab_rtol": ("memory_slab", {"h": 0.2, "rtol": 1e-3}),
    "hertz": ("hertz", {"h": 0.2, "T": 0.5}),
    "memory_hertz": ("memory_hertz", {"h": 0.2, "h_contact": 0.02}),  # (h_contact: the default before 2026-12-03)
    "memory_hertz_p2": ("memory_hertz", {"h": 0.2, "order": 2, "h_contact": 0.02}),
    "hertz3d": ("hertz3d", {"h": 0.3, "h_contact": 0.06, "T": 0.2, "k": 0.1}),
    "memory_hertz3d": ("memory_hertz3d", {"h": 0.3, "h_contact": 0.06}),
    "block": ("block", {"h": 0.1, "T": 0.005}),
    "block_cg": ("block", {"h": 0.1, "T": 0.005, "solver": "cg"}),
    "memory_block": ("memory_block", {"h": 0.2, "T": 0.5}),
    "block_bdf2": ("block", {"h": 0.2, "order": 1, "T": 0.05, "k": 0.01, "scheme": "bdf2", "c_tau": 1.0}),
}

#: Round-off residuals (their relative differences mean nothing): compared absolutely, in m.
ROUNDOFF = {"complementarity": 1e-12}
#: Attributes that are costs or provenance, not results.
SKIP_ATTRS = {"history", "wall_time", "cpu_time", "setup_time", "memory_peak_mb", "restarted_from", "title",
              "version_workbench", "version_ngsolve", "version_numpy", "version_scipy", "version_xarray",
              "version_netCDF4", "case_inputs", "case_fingerprint", "source", "state_json", "mesh"}


def _scene_names():
    import workbench.input.scenes as scenes

    return set(scenes.PRESETS)


def run_cases(out: Path, only: str | None = None) -> None:
    import workbench

    out.mkdir(parents=True, exist_ok=True)
    known = _scene_names()
    for name, (scene, overrides) in CASES.items():
        if only and only not in name:
            continue
        if scene not in known:
            print(f"{name}: scene {scene!r} not in this version, skipped")
            continue
        t0 = time.perf_counter()
        try:
            ds = workbench.run(scene, progress=False, **overrides)
        except workbench.Diverged as err:
            ds = err.dataset
        workbench.write(ds, out / f"{name}.nc")
        print(f"{name}: {ds.attrs['status']}, {ds.sizes.get('time', 0)} records, {time.perf_counter() - t0:.1f} s",
              flush=True)
    if not only or "restart" in only:
        _restarts(out)
    if not only or "mpi" in only:
        _mpi(out)


def _restarts(out: Path) -> None:
    """A run to T/2 continued to T, and a checkpointed run continued from a checkpoint."""
    import workbench

    with tempfile.TemporaryDirectory() as tmp:
        half = workbench.write(workbench.run("memory_slab", h=0.2, k=0.05, T=0.4, progress=False), f"{tmp}/h.nc")
        workbench.write(workbench.run(restart=half, T=0.8, progress=False), out / "restart_memory_slab.nc")
        half = workbench.write(workbench.run("tp5", T=0.2, scheme="bdf2", progress=False), f"{tmp}/b.nc")
        workbench.write(workbench.run(restart=half, T=0.4, progress=False), out / "restart_tp5_bdf2.nc")
        ds = workbench.run("tp4", T=0.2, checkpoint_every=7, checkpoint=f"{tmp}/c.nc", progress=False)
        workbench.write(ds, out / "checkpointed_tp4.nc")
        ds = workbench.run(restart=f"{tmp}/c.nc", T=0.2, checkpoint=f"{tmp}/c2.nc", progress=False)
        workbench.write(ds, out / "from_checkpoint_tp4.nc")
    print("restarts: done", flush=True)


def _mpi(out: Path) -> None:
    if shutil.which("mpiexec") is None:
        print("mpi: no mpiexec, skipped")
        return
    for n, args in ((2, ["block", "--h", "0.1", "--T", "0.005"]),
                    (3, ["slab", "--h", "0.05", "--order", "2", "--T", "0.01", "--set", "point_force=(0, t)"])):
        path = out / f"mpi{n}_{args[0]}.nc"
        cmd = ["mpiexec", "-n", str(n), sys.executable, "-m", "workbench.cli", "run", *args, "-o", str(path),
               "--no-progress"]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        print(f"mpi{n}_{args[0]}: exit {done.returncode} {done.stderr.strip()[-200:]}", flush=True)


def compare(old_dir: Path, new_dir: Path) -> int:
    import xarray as xr

    worst = 0.0
    for old_path in sorted(old_dir.glob("*.nc")):
        new_path = new_dir / old_path.name
        if not new_path.exists():
            print(f"{old_path.stem}: missing in {new_dir}")
            worst = np.inf
            continue
        with xr.open_dataset(old_path, decode_times=False) as a, xr.open_dataset(new_path, decode_times=False) as b:
            a, b = a.load(), b.load()
        diffs, notes = {}, []
        for name in sorted(set(a.variables) | set(b.variables)):
            if str(name).startswith("state_") and name not in ("state_u", "state_v", "state_beta"):
                continue  # (the restart state's private layout may change; u, v, beta must not)
            if name not in a.variables or name not in b.variables:
                notes.append(f"{name} only in {'old' if name in a.variables else 'new'}")
                continue
            x, y = a[name].values, b[name].values
            if x.shape != y.shape:
                notes.append(f"{name} shape {x.shape} -> {y.shape}")
                diffs[name] = np.inf
                continue
            if x.dtype.kind in "fc" or y.dtype.kind in "fc":
                x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
                same_nan = np.isnan(x) == np.isnan(y)
                if not same_nan.all():
                    diffs[name] = np.inf
                    continue
                d = np.abs(np.nan_to_num(x) - np.nan_to_num(y))
                if name in ROUNDOFF:
                    diffs[name] = 0.0 if d.max(initial=0.0) <= ROUNDOFF[name] else np.inf
                    continue
                scale = max(np.abs(np.nan_to_num(x)).max(initial=0.0), 1e-300)
                diffs[name] = float(d.max(initial=0.0) / scale)
            elif not np.array_equal(x, y):
                diffs[name] = np.inf
        for key in sorted(set(a.attrs) | set(b.attrs)):
            if key in SKIP_ATTRS or key.endswith("_units"):
                continue
            va, vb = a.attrs.get(key), b.attrs.get(key)
            if isinstance(va, (int, float, np.number)) and isinstance(vb, (int, float, np.number)):
                if va != vb:
                    rel = abs(float(va) - float(vb)) / max(abs(float(va)), 1e-300)
                    diffs[f"attr {key}"] = rel
            elif str(va) != str(vb):
                notes.append(f"attr {key}: {str(va)[:50]!r} -> {str(vb)[:50]!r}")
        largest = max(diffs.values(), default=0.0)
        worst = max(worst, largest)
        verdict = "bitwise" if largest == 0.0 else f"max relative difference {largest:.2e}"
        where = ", ".join(f"{k} {v:.1e}" for k, v in sorted(diffs.items(), key=lambda kv: -kv[1])[:4] if v > 0)
        print(f"{old_path.stem}: {verdict}" + (f" ({where})" if where else "") + ("; " + "; ".join(notes)
                                                                                   if notes else ""))
    print(f"worst: {worst:.2e}")
    return 0 if worst <= 1e-12 else 1


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("out")
    r.add_argument("--only")
    c = sub.add_parser("compare")
    c.add_argument("old")
    c.add_argument("new")
    args = p.parse_args(argv)
    if args.command == "run":
        run_cases(Path(args.out), args.only)
        return 0
    return compare(Path(args.old), Path(args.new))


if __name__ == "__main__":
    sys.exit(main())
