"""Command line: ``workbench scenes | show | run`` (and the study/reproduction commands).

Examples (shell)::

    workbench study tp1 --k 0.04 0.02 0.01 --reference ode -o out/tp1-k.nc --plot out/tp1-k.png
    workbench scenes
    workbench show tp5
    workbench run tp1 --k 0.005 -o out/tp1.nc --plot out/tp1.png
    workbench run slab --set "traction_top=(0, 2*t)" --set gamma_nu=1 -o out/slab.nc
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from .parameters import ParameterError

EXIT_BAD_INPUT, EXIT_DIVERGED = 2, 3


def _overrides(args, swept=()) -> dict:
    """Scene overrides from ``--set`` and the options ``--h --k --T --order --scheme``.

    A name given twice (two ``--set``, or ``--set k=`` beside ``--k``) is refused. In a
    study the options in ``swept`` are sweep axes, not scene values: they are left out
    here, and a ``--set`` of the same name beside them is refused too.
    """
    out = {}
    for item in args.set or []:
        if "=" not in item:
            raise ParameterError(f"--set {item!r}: write name=value, e.g. --set gamma_nu=0.5")
        name, value = item.split("=", 1)
        name = name.strip()
        if name in out:
            raise ParameterError(f"--set {name} is given twice ({out[name]!r} and {value.strip()!r}); give it once")
        out[name] = value.strip()
    for name in ("h", "k", "order", "scheme", "T"):
        value = getattr(args, name, None)
        if value is None:
            continue
        if name in out:
            raise ParameterError(f"{name} is given twice (--{name} and --set {name}=...); give it once")
        if name not in swept:
            out[name] = value
    return out


def _add_scene_args(p, run_options=True):
    p.add_argument("scene", help="built-in scene name (see 'workbench scenes') or a .toml scene file")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter (repeatable)")
    if run_options:
        p.add_argument("--h", type=float, help="element size")
        p.add_argument("--k", type=float, help="time step")
        p.add_argument("--T", type=float, help="final time")
        p.add_argument("--order", type=int, help="polynomial order of the displacement")
        p.add_argument("--scheme", help="time scheme")


def cmd_scenes(args) -> int:
    from .scenes import PRESETS

    width = max(map(len, PRESETS))
    for name, preset in PRESETS.items():
        print(f"{name:<{width}}  {preset.geometry:<5}  {preset.description}")
    return 0


def cmd_show(args) -> int:
    from .scenes import scene

    sc = scene(args.scene, **_overrides(args))
    print(f"{sc.name} ({sc.geometry}, {sc.dim}D): {sc.description}")
    print(f"terms assembled on the contact boundary: {', '.join(sc.terms) or 'none'}\n")
    rows = [(n, str(v), u, r, m) for n, v, u, r, m in sc.table()]
    w = [max(len(r[i]) for r in rows) for i in range(4)]
    print(f"{'parameter':<{w[0]}}  {'value':<{w[1]}}  {'unit':<{w[2]}}  {'allowed':<{w[3]}}  meaning")
    for r in rows:
        print(f"{r[0]:<{w[0]}}  {r[1]:<{w[1]}}  {r[2]:<{w[2]}}  {r[3]:<{w[3]}}  {r[4]}")
    return 0


def cmd_run(args) -> int:
    from . import plotting, results
    from .run import run
    from .schemes import Diverged

    overrides = _overrides(args)
    try:
        ds = run(args.scene, progress=False if args.no_progress else None, threads=args.threads, **overrides)
        code = 0
    except Diverged as err:
        print(f"error: {err}", file=sys.stderr)
        ds, code = err.dataset, EXIT_DIVERGED
    if args.output:
        results.write(ds, args.output)
        note = " (incomplete: see attrs 'failure')" if code else ""
        print(f"wrote {args.output}{note}")
    if args.plot:
        plotting.overview(ds, args.plot)
        print(f"wrote {args.plot}")
    if args.vtk:
        from . import vtk

        files = vtk.export(ds, args.vtk)
        print(f"wrote {len(files)} VTK files to {args.vtk}/ (open the .pvd in ParaView)")
    if not args.output and not args.plot:
        print(_summary(ds))
    return code


def _summary(ds) -> str:
    a = ds.attrs
    lines = [f"{a['scene']}: {a['status']}, scheme {a['scheme']}, ndof {a['ndof']}, {a['nsteps']} steps, "
             f"wall {a['wall_time']:.3g} s"]
    last = ds.isel(time=-1)
    for p in ds.probe.values:
        xyz = ", ".join(f"{float(ds[f'probe_{c}'][p]):g}" for c in ds.component.values)
        u = ", ".join(f"{float(v):.6g}" for v in last.u_probe.sel(probe=p).values)
        lines.append(f"  u({xyz}; t={float(last.time):g}) = ({u})")
    if "beta" in ds:
        lines.append(f"  beta at t={float(last.time):g}: min {float(last.beta.min()):.6g}, max {float(last.beta.max()):.6g}")
    return "\n".join(lines)


def _reference(text):
    if text in (None, "finest", "ode", "exact"):
        return text or "finest"
    out = {}
    for part in text.split(","):
        if "=" not in part:
            raise ParameterError(f"--reference {text!r}: give finest, ode, exact or e.g. h=0.003,k=0.0005")
        key, value = part.split("=", 1)
        out[key.strip()] = value.strip() if key.strip() == "scheme" else float(value)
    return out


def cmd_study(args) -> int:
    from pathlib import Path

    from . import plotting, results
    from .study import Study

    overrides = _overrides(args, swept=("h", "k", "order", "scheme"))
    st = Study(args.scene, h=args.h, k=args.k, k_over_h=args.k_over_h, order=args.order, scheme=args.scheme,
               reference=_reference(args.reference), n_compare=args.compare, workers=args.workers,
               client=args.scheduler, **overrides)
    archive = Path(args.output + ".cases") if args.output else None
    ds = st.run(archive, progress=False if args.no_progress else None)
    if args.output:
        results.write(ds, args.output)
        print(f"wrote {args.output} (cases in {archive}/)")
    for norm in ("error", "error_V", "error_Q", "error_beta", "error_beta_end"):
        rates = ds.observed_order.sel(norm=norm)
        found = {str(a): np.round(rates.sel(along=a).values.ravel(), 3).tolist() for a in rates.along.values
                 if np.isfinite(rates.sel(along=a).values).any()}
        if found:
            print(f"observed order of {norm}: {found}")
    o = st.overhead
    if o["new_cases"]:
        print(f"study: {o['execute']:.1f} s running {o['new_cases']} new case(s) (their own setup + time loops, "
              f"summed over workers: {o['cases']:.1f} s), {o['evaluate']:.1f} s comparing fields")
    if args.plot:
        plotting.convergence(ds, args.plot)
        print(f"wrote {args.plot}")
    if args.pareto:
        plotting.pareto(ds, args.pareto)
        print(f"wrote {args.pareto}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="workbench", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.set_defaults(func=cmd_scenes)
    p = sub.add_parser("show", help="list a scene's parameters with value, unit, allowed range and meaning")
    _add_scene_args(p, run_options=True)
    p.set_defaults(func=cmd_show)
    p = sub.add_parser("run", help="run a scene, write a netCDF archive and plots")
    _add_scene_args(p)
    p.add_argument("-o", "--output", help="netCDF archive to write (atomically)")
    p.add_argument("--plot", help="PNG overview plot to write")
    p.add_argument("--vtk", metavar="DIR", help="write VTK (.vtu + .pvd) files of the snapshots for ParaView")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--threads", type=int, help="NGSolve TaskManager threads for assembly (default: off)")
    p.set_defaults(func=cmd_run)
    p = sub.add_parser("study", help="refinement sweep over h, k, order, scheme: errors, observed orders, cost")
    p.add_argument("scene", help="built-in scene name or .toml file")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter (repeatable)")
    p.add_argument("--h", type=float, nargs="+", help="element sizes")
    p.add_argument("--k", type=float, nargs="+", help="time steps (all combinations with --h)")
    p.add_argument("--k-over-h", type=float, help="couple k = C h instead of --k")
    p.add_argument("--order", type=int, nargs="+", help="element orders")
    p.add_argument("--scheme", nargs="+", help="schemes (explicit, implicit)")
    p.add_argument("--reference", help="finest (default) | ode | exact | h=..,k=..[,order=..,scheme=..]")
    p.add_argument("--compare", type=int, default=10, help="number of common times at which fields are compared")
    p.add_argument("--workers", type=int, default=2, help="local worker processes (0: in this process)")
    p.add_argument("--scheduler", help="dask.distributed scheduler address (run the cases there)")
    p.add_argument("-o", "--output", help="netCDF archive of the study (cases archived in OUTPUT.cases/)")
    p.add_argument("--plot", help="PNG convergence plot")
    p.add_argument("--pareto", help="PNG error-vs-cost plot")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=cmd_study)
    return parser


def main(argv=None) -> int:
    import shlex

    from .results import invocation

    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    invocation.set(shlex.join(["workbench"] + argv))
    try:
        return args.func(args)
    except ParameterError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
