"""Refinement studies: sweeps over h, k, element order and scheme, errors, observed orders, cost.

A :class:`Study` runs one scene on many discretisations (each case in its own
process, or on a dask.distributed cluster), archives every finished case at
once, compares each case with a reference on the finer mesh, fits observed
orders and measures the speed/accuracy trade.

Errors (SPEC, Corollary 6.7), at common comparison times t_j:
``error = max_j (|u - u_ref|_V + |sigma - sigma_ref|_Q + |beta - beta_ref|_L2(Gamma3))``,
each part also alone (``error_V``, ``error_Q``, ``error_beta``), plus probe
errors ``error_probe`` (max over the common recorded times) and the bonding
field at the far end of the contact side ``error_beta_end``.

References: ``"finest"`` (the finest case of the sweep, then not reported as a
case), ``"ode"``/``"exact"`` (rod scenes: the reduced ODE, :mod:`workbench.references`),
a dict of discretisation values for a separate finer run, or an object like
the ones :func:`workbench.references.rod_ode` returns. A case is never its own reference.

Examples
--------
>>> st = Study("tp1", k=[0.04, 0.02, 0.01], reference="ode", workers=0)
>>> ds = st.run(progress=False)
>>> round(float(ds.observed_order.sel(norm="error", along="k").squeeze()), 1)
1.0
"""
from __future__ import annotations

import json
import multiprocessing
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from . import meshes, results, scenes, transfer
from .results import attr_value


@dataclass(frozen=True)
class Case:
    """One discretisation of the study's scene."""

    h: float
    k: float
    order: int
    scheme: str

    @property
    def key(self) -> str:
        return f"h{self.h:.6g}_k{self.k:.6g}_p{self.order}_{self.scheme}"

    def values(self) -> dict:
        return {"h": self.h, "k": self.k, "order": self.order, "scheme": self.scheme}


def _peak_memory_reset() -> bool:
    """Reset the process's peak resident memory (Linux: write 5 to /proc/self/clear_refs)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _peak_memory_mb() -> float:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _run_case(scene, case_values, record_times, snapshots):
    """Worker: run one case; its Dataset gets the peak resident memory of the run."""
    from .run import run
    from .schemes import Diverged

    _peak_memory_reset()  # workers are reused: the peak must be this case's
    sc = scene.with_(snapshots=tuple(snapshots), **case_values)
    try:
        ds = run(sc, progress=False, record_times=record_times)
    except Diverged as err:
        ds = err.dataset
    ds.attrs["memory_peak_mb"] = _peak_memory_mb()
    return ds


class Study:
    """A sweep over discretisations of one scene.

    Parameters
    ----------
    scene : str, path or Scene
    h, k : sequence of float, optional
        Element sizes and time steps (default: the scene's). All combinations
        are run, unless ``k_over_h`` couples them (k_i = k_over_h * h_i).
    order, scheme : sequence, optional
        Element orders and schemes to sweep (default: the scene's).
    reference : str, dict or object
        See the module docs. Default ``"finest"``.
    n_compare : int
        Number of common times at which whole fields are compared (default 10, T included).
    workers : int
        Local processes (spawned, reused across cases) running cases in
        parallel (default 2); 0 runs the cases in this process, one after another.
    client : dask.distributed.Client or str, optional
        Run the cases on this cluster (or scheduler address) instead.
    **overrides
        Scene parameters for every case.
    """

    def __init__(self, scene, *, h=None, k=None, k_over_h=None, order=None, scheme=None, reference="finest",
                 n_compare=10, workers=2, client=None, **overrides):
        self.scene = scenes.scene(scene, **overrides)
        hs = [float(x) for x in (h if h is not None else [self.scene["h"]])]
        orders = [int(p) for p in (order if order is not None else [self.scene["order"]])]
        schemes_ = list(scheme if scheme is not None else [self.scene["scheme"]])
        self.coupled = k_over_h is not None
        if self.coupled:
            if k is not None:
                raise scenes.ParameterError("give either k or k_over_h, not both")
            if not k_over_h > 0:
                raise scenes.ParameterError(f"k_over_h = {k_over_h} must be > 0")
            levels = [(x, float(k_over_h) * x) for x in hs]
        else:
            ks = [float(x) for x in (k if k is not None else [self.scene["k"]])]
            levels = [(x, y) for x in hs for y in ks]
        for x, y in levels:  # check every case's values before any work
            for p in orders:
                for s in schemes_:
                    self.scene.with_(h=x, k=y, order=p, scheme=s)
        self.hs, self.orders, self.schemes = sorted(set(hs), reverse=True), orders, schemes_
        self.ks = sorted(set(y for _, y in levels), reverse=True)
        self.levels = levels
        self.cases = [Case(x, y, p, s) for (x, y) in levels for p in orders for s in schemes_]
        self.reference_spec = reference
        self.ref_case = self._reference_case(reference)
        self.n_compare = int(n_compare)
        self.workers, self.client = int(workers), client
        self.dataset = None

    # -- setup -------------------------------------------------------------------------------
    def _reference_case(self, reference):
        if isinstance(reference, str):
            if reference == "finest":
                best = min(self.cases, key=lambda c: (c.h, c.k, -c.order, c.scheme != "implicit"))
                return best
            if reference in ("ode", "exact"):
                if self.scene.geometry != "rod":
                    raise scenes.ParameterError(f"reference = {reference!r} needs a rod scene; use 'finest' or a finer run")
                return None
            raise scenes.ParameterError(f"reference = {reference!r}; allowed: 'finest', 'ode', 'exact', "
                                        "a dict such as {'h': 0.005, 'k': 0.0005}, or a solution object")
        if isinstance(reference, dict):
            unknown = set(reference) - {"h", "k", "order", "scheme"}
            if unknown:
                raise scenes.ParameterError(f"reference: unknown key(s) {sorted(unknown)}; allowed: h, k, order, scheme")
            vals = {"h": min(self.hs), "k": min(self.ks), "order": max(self.orders), "scheme": self.schemes[0]}
            vals |= reference
            ref = Case(float(vals["h"]), float(vals["k"]), int(vals["order"]), str(vals["scheme"]))
            self.scene.with_(**ref.values())
            return ref
        return None  # a solution object (rod)

    def _times(self):
        """Common record times (the coarsest grid, if on every grid) and the field comparison times."""
        from .schemes import time_grid

        T = self.scene["T"]
        grids = [time_grid(T, k) for k in self.ks + ([self.ref_case.k] if self.ref_case else [])]
        coarse = grids[int(np.argmin([len(g) for g in grids]))]
        common = [t for t in coarse if all(np.min(np.abs(g - t)) <= 1e-9 * max(T, 1.0) for g in grids)]
        common = np.array(common)
        idx = np.unique(np.round(np.linspace(0, len(common) - 1, self.n_compare + 1)).astype(int))[1:]
        return common, common[idx]

    # -- running -------------------------------------------------------------------------------
    def run(self, archive=None, *, progress=None) -> xr.Dataset:
        """Run the missing cases (each archived on completion in ``archive``), then evaluate the sweep.

        With ``archive`` (a folder), a sweep that was interrupted and is run again
        recomputes only the cases whose archive is missing; the result is identical.
        """
        from tqdm.auto import tqdm

        record, compare = self._times()
        archive = Path(archive) if archive is not None else Path(tempfile.mkdtemp(prefix="workbench-study-"))
        archive.mkdir(parents=True, exist_ok=True)
        todo = list(self.cases)
        if self.ref_case is not None and self.ref_case not in todo:
            todo.append(self.ref_case)
        paths = {c: archive / f"{c.key}.nc" for c in todo}
        missing = [c for c in todo if not paths[c].exists()]
        # biggest first, so the pool ends evenly
        missing.sort(key=lambda c: -(np.prod(meshes.cells(self.scene.with_(h=c.h))) * c.order ** 2 / c.k))
        t0 = time.perf_counter()
        bar = tqdm(total=len(todo), initial=len(todo) - len(missing), unit="case", desc=f"study {self.scene.name}",
                   disable=None if progress is None else not progress)
        try:
            for case, ds in self._execute(missing, record, compare):
                results.write(ds, paths[case])
                bar.update()
        finally:
            bar.close()
        executed = time.perf_counter() - t0
        runs = {c: results.load(paths[c]) for c in todo}
        self.dataset = self._evaluate(runs, compare, executed, len(missing))
        self.overhead["evaluate"] = time.perf_counter() - t0 - executed
        return self.dataset

    def _execute(self, cases, record, compare):
        if not cases:
            return
        args = [(self.scene, c.values(), list(record), list(compare)) for c in cases]
        if self.client is not None:
            client = self.client
            if isinstance(client, str):
                from distributed import Client

                client = Client(client)
            from distributed import as_completed as dask_completed

            futures = {client.submit(_run_case, *a, pure=False): c for a, c in zip(args, cases)}
            for fut in dask_completed(futures):
                yield futures[fut], fut.result()
            return
        if self.workers == 0:  # in this process, one after another (no isolation; memory peak is cumulative)
            for a, c in zip(args, cases):
                yield c, _run_case(*a)
            return
        # spawn, not fork: forking after NGSolve's TaskManager hangs; workers are reused across cases
        kwargs = {"max_workers": max(1, min(self.workers, len(cases))), "mp_context": multiprocessing.get_context("spawn")}
        with ProcessPoolExecutor(**kwargs) as pool:
            futures = {pool.submit(_run_case, *a): c for a, c in zip(args, cases)}
            for fut in as_completed(futures):
                yield futures[fut], fut.result()

    # -- evaluation ---------------------------------------------------------------------------
    def _reference(self, runs):
        spec = self.reference_spec
        if self.ref_case is not None:
            return ("run", runs[self.ref_case])
        if isinstance(spec, str):
            from .references import rod_reference

            return ("solution", rod_reference(self.scene))
        return ("solution", spec)

    def _errors(self, case, ds, ref, compare):
        """Error measures of one case against the reference."""
        kind, R = ref
        out = {}
        if ds.attrs["status"] != "complete":
            return out
        sc = self.scene.with_(**case.values())
        t_rec = ds.time.values
        if kind == "run":
            fine_first = R.attrs["ndof"] >= ds.attrs["ndof"]
            coarse_sc, fine_sc = (sc, self.scene.with_(**self.ref_case.values()))
            if not fine_first:
                coarse_sc, fine_sc = fine_sc, coarse_sc
            ci, fi = transfer.mesh_info(coarse_sc), transfer.mesh_info(fine_sc)
            tr = transfer.Transfer(ci, fi)
            out["transfer"] = tr.method
            cds, fds = (ds, R) if fine_first else (R, ds)
            parts = []
            for t in compare:
                i_c, i_f = _snap(cds, t), _snap(fds, t)
                du = fds.u_dofs.values[i_f] - tr.displacement(cds.u_dofs.values[i_c], cds.u_nodes.values[i_c])
                dsig = fds.stress.values[i_f] - tr.cells(cds.stress.values[i_c])
                dbeta = None
                if "beta" in ds:
                    dbeta = fds.beta.sel(time=t, method="nearest").values - tr.facets(
                        cds.beta.sel(time=t, method="nearest").values)
                parts.append(transfer.norms(fi, du, dsig, dbeta))
            ref_probe = R.u_probe.sel(time=t_rec, method="nearest").values
            if "beta" in ds:
                ref_end = _far_beta(R).sel(time=t_rec, method="nearest").values
        else:  # rod: exact / ODE solution
            sol = R
            info = transfer.mesh_info(sc)
            parts = []
            for t in compare:
                i = _snap(ds, t)
                u_ref, beta_ref = sol(np.array([t]), x=info.xyz[:, 0])
                ref_vec = np.zeros(info.fes.ndof)
                ref_vec[: len(info.xyz)] = np.ravel(u_ref)  # linear in x: vertex values are the whole field
                du = ds.u_dofs.values[i] - ref_vec
                dsig = ds.stress.values[i] - np.ravel(sol.stress(np.array([t])))[0]
                dbeta = ds.beta.values[np.argmin(np.abs(t_rec - t))] - np.ravel(beta_ref)[0] if "beta" in ds else None
                parts.append(transfer.norms(info, du, dsig, dbeta))
            xs = ds.probe_x.values
            ref_probe = np.stack([sol(t_rec, x=x)[0] for x in xs], axis=1)[..., None]
            if "beta" in ds:
                ref_end = sol(t_rec)[1]
        parts = np.array(parts)
        out["error_V"], out["error_Q"] = np.max(parts[:, :2], axis=0)
        out["error_beta"] = float(np.max(parts[:, 2])) if np.isfinite(parts[:, 2]).all() else np.nan
        out["error"] = float(np.max(np.nansum(parts, axis=1)))
        out["error_probe"] = np.max(np.linalg.norm(ds.u_probe.values - ref_probe, axis=-1), axis=0)
        if "beta" in ds:
            out["error_beta_end"] = float(np.max(np.abs(_far_beta(ds).values - ref_end)))
        return out

    def _evaluate(self, runs, compare, elapsed, n_new):
        ref = self._reference(runs)
        listed = [c for c in self.cases if c != self.ref_case or not isinstance(self.reference_spec, str)
                  or self.reference_spec != "finest"]
        first = runs[self.cases[0]]
        n_probe = first.sizes["probe"]
        if self.coupled:
            dims = ("level", "order", "scheme")
            shape = (len(self.levels), len(self.orders), len(self.schemes))

            def index(c):
                return (self.levels.index((c.h, c.k)), self.orders.index(c.order), self.schemes.index(c.scheme))
        else:
            dims = ("h", "k", "order", "scheme")
            shape = (len(self.hs), len(self.ks), len(self.orders), len(self.schemes))

            def index(c):
                return (self.hs.index(c.h), self.ks.index(c.k), self.orders.index(c.order), self.schemes.index(c.scheme))
        names = ["error", "error_V", "error_Q", "error_beta", "error_beta_end", "wall_time", "cpu_time", "setup_time",
                 "memory_peak_mb", "h_max"]
        arrays = {n: np.full(shape, np.nan) for n in names}
        for n in ("ndof", "nsteps"):
            arrays[n] = np.full(shape, -1, dtype=np.int64)
        complete = np.zeros(shape, dtype=np.int8)
        probe_err = np.full(shape + (n_probe,), np.nan)
        methods = set()
        for c in self.cases:
            ds = runs[c]
            i = index(c)
            a = ds.attrs
            for n in ("wall_time", "cpu_time", "setup_time", "memory_peak_mb", "h_max"):
                arrays[n][i] = a.get(n, np.nan)
            arrays["ndof"][i], arrays["nsteps"][i] = a["ndof"], a["nsteps"]
            complete[i] = a["status"] == "complete"
            if c not in listed:
                continue
            err = self._errors(c, ds, ref, compare)
            for n in ("error", "error_V", "error_Q", "error_beta", "error_beta_end"):
                if n in err:
                    arrays[n][i] = err[n]
            if "error_probe" in err:
                probe_err[i] = err["error_probe"]
            if "transfer" in err:
                methods.add(err["transfer"])
        units = {"wall_time": "s", "cpu_time": "s", "setup_time": "s", "memory_peak_mb": "MB", "h_max": "m",
                 "ndof": "1", "nsteps": "1"}
        long = {"error": "max over compared times of |u - u_ref|_V + |sigma - sigma_ref|_Q + |beta - beta_ref|_L2(Gamma3)",
                "error_V": "max over compared times of ||eps(u - u_ref)||_L2",
                "error_Q": "max over compared times of ||sigma - sigma_ref||_L2",
                "error_beta": "max over compared times of ||beta - beta_ref||_L2(Gamma3)",
                "error_beta_end": "max over recorded times of |beta - beta_ref| on the facet at the far end",
                "wall_time": "wall time of the time loop", "cpu_time": "CPU time of the time loop",
                "setup_time": "wall time of assembly and factorisation", "memory_peak_mb": "peak resident memory",
                "h_max": "longest cell side", "ndof": "displacement dofs", "nsteps": "time steps"}
        data = {n: (dims, arr, {"units": units.get(n, "mixed"), "long_name": long[n]}) for n, arr in arrays.items()}
        data["error_probe"] = (dims + ("probe",), probe_err, {"units": "m", "long_name": "max over time of |u - u_ref| at the probe"})
        data["complete"] = (dims, complete, {"units": "1", "long_name": "1 if the case ran to T"})
        coords = {"order": list(self.orders), "scheme": list(self.schemes), "probe": np.arange(n_probe)}
        for c in ("x", "y", "z")[: self.scene.dim]:
            coords[f"probe_{c}"] = ("probe", first[f"probe_{c}"].values)
        if self.coupled:
            coords["level"] = np.arange(len(self.levels))
            coords["h"] = ("level", [x for x, _ in self.levels])
            coords["k"] = ("level", [y for _, y in self.levels])
        else:
            coords["h"], coords["k"] = list(self.hs), list(self.ks)
        ds = xr.Dataset(data, coords=coords)
        ds["compare_time"] = ("compare", np.asarray(compare), {"units": "s", "long_name": "times at which fields are compared"})
        orders, spread = self._fit(ds)
        ds["observed_order"] = orders
        ds["observed_order_stderr"] = spread
        ds["pareto"] = (dims, self._pareto(ds), {"units": "1", "long_name": "1 if no other case is both cheaper and more accurate"})
        case_cost = float(np.nansum(arrays["wall_time"]) + np.nansum(arrays["setup_time"]))
        ref_desc = self.reference_spec if isinstance(self.reference_spec, str) else \
            (json.dumps(self.ref_case.values()) if self.ref_case else type(self.reference_spec).__name__)
        ds.attrs = {
            "scene": self.scene.name, "geometry": self.scene.geometry, "model": self.scene.model,
            "reference": ref_desc,
            "reference_case": self.ref_case.key if self.ref_case else "",
            "transfer": "; ".join(sorted(methods)) or "same mesh / exact solution",
            "coupling": "k = k_over_h * h" if self.coupled else "product of h and k",
            "parameters_json": json.dumps(self.scene.plain(), sort_keys=True),
            "cases_total_wall_time": case_cost,
            "history": f"workbench study {self.scene.name}",
        } | {k: attr_value(v) for k, v in self.scene.values.items() if k not in ("h", "k", "order", "scheme")}
        # machinery overhead is only meaningful for a run that computed everything now
        self.overhead = dict(execute=elapsed, cases=case_cost, new_cases=n_new)
        return ds

    def _fit(self, ds):
        norms = ["error", "error_V", "error_Q", "error_beta", "error_beta_end"]
        alongs = ["h", "k", "h+k"]
        o = np.full((len(norms), len(alongs), len(self.orders), len(self.schemes)), np.nan)
        s = np.full_like(o, np.nan)
        for a, norm in enumerate(norms):
            for b, along in enumerate(alongs):
                for p in range(len(self.orders)):
                    for q in range(len(self.schemes)):
                        x, y = self._series(ds, norm, along, p, q)
                        if len(x) >= 2:
                            o[a, b, p, q], s[a, b, p, q] = fit_order(x, y)
        dims = ("norm", "along", "order", "scheme")
        coords = {"norm": norms, "along": alongs}
        return (xr.DataArray(o, dims=dims, coords=coords, attrs={"units": "1", "long_name": "least-squares slope of log error"}),
                xr.DataArray(s, dims=dims, coords=coords, attrs={"units": "1", "long_name": "standard error of the slope"}))

    def _series(self, ds, norm, along, p, q):
        err = ds[norm].isel(order=p, scheme=q)
        if self.coupled:
            if along == "k" and len(set(self.hs)) > 1:
                return [], []
            x = ds.h.values + ds.k.values if along == "h+k" else (ds.h.values if along == "h" else ds.k.values)
            y = err.values
        else:
            if along == "h" and len(self.hs) > 1:
                y = err.isel(k=-1).values
                x = ds.h.values
            elif along == "k" and len(self.ks) > 1:
                y = err.isel(h=-1).values
                x = ds.k.values
            else:
                return [], []
        good = np.isfinite(y) & (y > 0)
        return np.asarray(x)[good], np.asarray(y)[good]

    def _pareto(self, ds):
        err = ds["error"].values
        cost = ds["wall_time"].values + ds["setup_time"].values
        flat_e, flat_c = err.ravel(), cost.ravel()
        out = np.zeros(flat_e.shape, dtype=np.int8)
        ok = np.isfinite(flat_e) & np.isfinite(flat_c)
        for i in np.nonzero(ok)[0]:
            dominated = ok & (flat_e <= flat_e[i]) & (flat_c <= flat_c[i]) & ((flat_e < flat_e[i]) | (flat_c < flat_c[i]))
            out[i] = not dominated.any()
        return out.reshape(err.shape)

    # -- questions -------------------------------------------------------------------------------
    def assert_order(self, expected: float, tol: float = 0.1, *, norm: str = "error", along: str | None = None,
                     at_least: bool = False, max_error: float | None = None) -> None:
        """Check the fitted order(s): |order - expected| <= tol (or order >= expected - tol with ``at_least``).

        ``along`` defaults to "h+k" for coupled sweeps, else the swept parameter.
        ``max_error`` caps the smallest error, so a wrong constant cannot hide behind a good slope.
        """
        ds = self.dataset
        if ds is None:
            raise RuntimeError("run the study first")
        along = along or ("h+k" if self.coupled else ("h" if len(self.hs) > 1 else "k"))
        rates = ds.observed_order.sel(norm=norm, along=along).values.ravel()
        if not np.all(np.isfinite(rates)):
            raise AssertionError(f"no fitted order for {norm} along {along}: {rates}")
        bad = rates < expected - tol if at_least else np.abs(rates - expected) > tol
        if np.any(bad):
            raise AssertionError(f"observed order of {norm} along {along}: {np.round(rates, 3).tolist()}, "
                                 f"expected {'>= ' if at_least else ''}{expected} within {tol}")
        if max_error is not None:
            smallest = float(np.nanmin(ds[norm].values))
            if smallest > max_error:
                raise AssertionError(f"smallest {norm} = {smallest:.3g} exceeds the cap {max_error:.3g}")

    def cheapest(self, tolerance: float, *, error: str = "error", cost: str = "wall_time"):
        """The cheapest case whose ``error`` is <= ``tolerance`` (None if none reaches it)."""
        return cheapest(self.dataset, tolerance, error=error, cost=cost)


def cheapest(ds: xr.Dataset, tolerance: float, *, error: str = "error", cost: str = "wall_time"):
    """The cheapest case of a study Dataset with ``ds[error] <= tolerance``, as a dict."""
    err = ds[error]
    c = ds[cost] + (ds["setup_time"] if cost == "wall_time" else 0)
    ok = (err <= tolerance) & np.isfinite(c)
    if not bool(ok.any()):
        return None
    masked = c.where(ok)
    flat = int(np.nanargmin(masked.values))
    idx = np.unravel_index(flat, masked.shape)
    point = {d: masked[d].values[i] for d, i in zip(masked.dims, idx)}
    sel = ds.isel(dict(zip(masked.dims, idx)))
    return {**{d: (v.item() if hasattr(v, "item") else v) for d, v in point.items()},
            "h": float(sel.h), "k": float(sel.k), error: float(sel[error]), cost: float(masked.values[idx])}


def fit_order(x, y):
    """Least-squares slope of log(y) against log(x) and its standard error."""
    lx, ly = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    if len(lx) == 2:
        return float((ly[1] - ly[0]) / (lx[1] - lx[0])), np.nan
    coef, cov = np.polyfit(lx, ly, 1, cov=True)
    return float(coef[0]), float(np.sqrt(cov[0, 0]))


def _snap(ds, t):
    i = int(np.argmin(np.abs(ds.snapshot_time.values - t)))
    if abs(ds.snapshot_time.values[i] - t) > 1e-9 * max(1.0, abs(t)):
        raise ValueError(f"no field snapshot at t = {t}")
    return i


def _far_beta(ds):
    return ds.beta.isel(facet=int(np.argmax(ds.facet_x.values)))

