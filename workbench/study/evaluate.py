"""A study's Dataset: per-case errors, measures and costs on the sweep's axes; fitted orders; Pareto front.

Dimensions are the sweep axes (``h``, ``k``, ``order``, ``scheme``, then any other
swept parameter). When a parameter is coupled to the others (``k = 0.2 h``, or
``gamma_nu`` to ``c_nu``), the axis it is a function of and the coupled parameters
become coordinates of one dimension ``level`` (:class:`Layout`). Cases that a union
of grids does not contain are NaN (``ran = 0``).

Observed orders: the least-squares slope of log(error) against log(x) along each
refinement axis with more than one value (the other refinement axes at their
finest value), or, for coupled refinement sweeps (``k = 0.2 h``), along ``h``, ``k``
(only if h is fixed) and ``h+k``, for every combination of the remaining axes
(``DataArray.polyfit``).
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from ..input.numerics import REFINEMENT
from ..output.results import attr_value
from . import times
from .cases import canonical

NORMS = ("error", "error_V", "error_Q", "error_beta", "error_beta_end")
COSTS = ("wall_time", "cpu_time", "setup_time", "memory_peak_mb", "h_max")
_UNITS = {"wall_time": "s", "cpu_time": "s", "setup_time": "s", "memory_peak_mb": "MB", "h_max": "m",
          "ndof": "1", "nsteps": "1"}
_LONG = {"error": "max over compared times of |u - u_ref|_V + |sigma - sigma_ref|_Q + |beta - beta_ref|_L2(Gamma3)",
         "error_V": "max over compared times of ||eps(u - u_ref)||_L2",
         "error_Q": "max over compared times of ||sigma - sigma_ref||_L2",
         "error_beta": "max over compared times of ||beta - beta_ref||_L2(Gamma3)",
         "error_beta_end": "max over recorded times of |beta - beta_ref| on the facet at the far end",
         "wall_time": "wall time of the time loop", "cpu_time": "CPU time of the time loop",
         "setup_time": "wall time of assembly and factorisation", "memory_peak_mb": "peak resident memory",
         "h_max": "longest cell side", "ndof": "displacement dofs", "nsteps": "time steps",
         "reference_norm_V": "max over compared times of ||eps(u_ref)||_L2",
         "reference_norm_Q": "max over compared times of ||sigma_ref||_L2",
         "reference_norm_beta": "max over compared times of ||beta_ref||_L2(Gamma3)"}

#: An error at most this share of its reference's norm is round-off, not discretisation: no order is fitted to it
#: (tp1's stress and bonding errors are 1e-16..1e-15, and gave orders of -1.2 and -0.3 along k). A solve's own
#: round-off is about the condition number times eps, 1e-12 for a stiffness of condition 1e4, and it adds up over
#: the steps: tp1's stress under backward Euler and BDF2 at k = 0.04 ... 0.005 sat at 0.98-1.16e-12 of its norm, and
#: 1e-12 let three of the four through, with orders of 0.06 and -0.04.
ROUNDOFF = 1e-11
#: The norm of the reference each error is measured against (error: the sum of the three; error_beta_end: beta's
#: largest value, 1).
_SCALES = {"error_V": ("reference_norm_V",), "error_Q": ("reference_norm_Q",),
           "error_beta": ("reference_norm_beta",),
           "error": ("reference_norm_V", "reference_norm_Q", "reference_norm_beta")}


def _error_units(dim: int) -> dict:
    """Units of the L2 norms over a body of dimension ``dim`` (its contact side has dimension dim - 1)."""
    half = {0: "", 1: "m^(1/2)", 2: "m", 3: "m^(3/2)"}.get
    units = {"error": "mixed (sum of the three norms)", "error_V": half(dim) or "1",
             "error_Q": f"Pa {half(dim)}".strip(), "error_beta": half(dim - 1) or "1", "error_beta_end": "1"}
    return units | {f"reference_norm_{n}": units[f"error_{n}"] for n in ("V", "Q", "beta")}


def at_roundoff(ds: xr.Dataset, norm: str) -> xr.DataArray:
    """Where the error ``norm`` is at round-off: finite, and at most :data:`ROUNDOFF` of its reference's norm
    (:data:`_SCALES`; False everywhere without the reference's norms, as for a study without a reference)."""
    scales = [ds[n] for n in _SCALES.get(norm, ()) if n in ds]
    if norm == "error_beta_end":
        scale = xr.ones_like(ds[norm])
    elif scales:
        scale = sum(s.fillna(0.0) for s in scales)
    else:
        return xr.zeros_like(ds[norm], dtype=bool)
    return np.isfinite(ds[norm]) & (ds[norm] <= ROUNDOFF * scale)


class Layout:
    """Dimensions and coordinates of a study Dataset, and where each case sits in it.

    With couplings, the *driver* is the first axis (in dimension order) of which every coupled parameter is a
    function (k of h for ``k = 0.2 h``, gamma_nu of c_nu, ...): it and the coupled parameters are the
    coordinates of ``level``. The levels are a refinement series (orders are fitted along them) when
    the driver or a coupled parameter is a refinement axis; otherwise ``level`` is an axis like any
    other swept parameter and orders are fitted along the refinement axes, per level.
    """

    def __init__(self, cases, axes: dict, coupled: tuple):
        self.axes, self.coupled = axes, tuple(coupled)
        names = list(axes)
        if coupled:
            self.driver = _driver(cases, axes, self.coupled)
            self.dims = ("level",) + tuple(n for n in names if n != self.driver)
            self.levels = list(axes[self.driver])
            self.level_coords = {n: [next(c[n] for c in cases if c[self.driver] == v) for v in self.levels]
                                 for n in coupled}
        else:
            self.driver = None
            self.dims = tuple(names)
        #: whether the levels refine (then they are the series orders are fitted along)
        self.refining = bool(coupled) and any(n in REFINEMENT for n in (self.driver,) + self.coupled)
        self.shape = tuple(len(self.levels) if d == "level" else len(axes[d]) for d in self.dims)

    def index(self, case) -> tuple:
        out = []
        for d in self.dims:
            if d == "level":
                out.append(self.levels.index(case[self.driver]))
            else:
                out.append(self.axes[d].index(case[d]))
        return tuple(out)

    def coords(self) -> dict:
        coords = {}
        for d in self.dims:
            if d == "level":
                coords["level"] = np.arange(len(self.levels))
                coords[self.driver] = ("level", list(self.levels))
                for n, vals in self.level_coords.items():
                    coords[n] = ("level", vals)
            else:
                coords[d] = list(self.axes[d])
        return coords


def _driver(cases, axes: dict, coupled: tuple) -> str:
    """The first axis (in dimension order) of which every coupled parameter is a function; a ParameterError if none."""
    swept = [n for n in axes if len(axes[n]) > 1]
    for name in axes:
        if all(len({c[p] for c in cases if c[name] == v}) == 1 for v in axes[name] for p in coupled):
            return name
    from ..errors import ParameterError

    raise ParameterError(f"the coupled parameter(s) {', '.join(coupled)} must each be a function of one swept axis "
                         f"({', '.join(swept) or 'none is swept'}), the same for all: a coupling of several axes at "
                         "once is not a level of the study")


def dataset(layout: Layout, rows: dict, n_probe: int, probe_coords: dict, dim: int, T=None) -> xr.Dataset:
    """The study Dataset from per-case ``rows`` (case -> dict of values) on ``layout``; ``T`` (fixed steps only): the
    run's end, which gives each k the step its grid takes (:func:`step_taken`), the one orders are fitted against."""
    dims, shape = layout.dims, layout.shape
    names = list(NORMS) + list(COSTS) + sorted({k for r in rows.values() for k in r
                                                if k not in NORMS + COSTS + ("ndof", "nsteps", "complete", "status",
                                                                             "error_probe", "transfer")})
    arrays = {n: np.full(shape, np.nan) for n in names}
    ints = {n: np.full(shape, -1, dtype=np.int64) for n in ("ndof", "nsteps")}
    complete = np.zeros(shape, dtype=np.int8)
    status = np.full(shape, "", dtype=object)
    ran = np.zeros(shape, dtype=np.int8)
    probe_err = np.full(shape + (n_probe,), np.nan)
    for case, row in rows.items():
        i = layout.index(case)
        ran[i] = 1
        for n in names:
            if n in row:
                arrays[n][i] = row[n]
        for n in ints:
            ints[n][i] = row[n]
        complete[i] = row["complete"]
        status[i] = row.get("status", "")
        if "error_probe" in row:
            probe_err[i] = row["error_probe"]
    data = {}
    for n, arr in list(arrays.items()) + list(ints.items()):
        units = _UNITS.get(n, _error_units(dim).get(n, "1"))
        data[n] = (dims, arr, {"units": units, "long_name": _LONG.get(n, n.replace("_", " "))})
    data["error_probe"] = (dims + ("probe",), probe_err,
                           {"units": "m", "long_name": "max over time of |u - u_ref| at the probe"})
    data["complete"] = (dims, complete, {"units": "1", "long_name": "1 if the case ran to T"})
    data["status"] = (dims, status.astype(str), {"long_name": "complete | incomplete (the failure) | refused | "
                                                             "'' (not part of the sweep)"})
    data["ran"] = (dims, ran, {"units": "1", "long_name": "1 if the case is part of the sweep (0: a hole of a "
                                                          "union of grids)"})
    coords = layout.coords() | {"probe": np.arange(n_probe)} | probe_coords
    ds = xr.Dataset(data, coords=coords)
    if T is not None and "k" in ds.coords:
        ds.coords["k_step"] = (ds["k"].dims, step_taken(T, ds["k"].values),
                               {"units": "s", "long_name": "the step taken: T / ceil(T / k)"})
    orders, spread = fit(ds, layout)
    ds["observed_order"] = orders
    ds["observed_order_stderr"] = spread
    ds["pareto"] = (dims, pareto_front(ds["error"].values, (ds["wall_time"] + ds["setup_time"]).values),
                    {"units": "1", "long_name": "1 if no other case is both cheaper and more accurate"})
    return _labelled(ds)


def _labelled(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with long_name and units on every coordinate that has none, as a run's archive has them."""
    for name in ds.coords:
        if not ds[name].attrs:
            ds[name].attrs.update(_coordinate_attrs(name))
    return ds


#: The study's own coordinates: (units, long_name); a swept parameter's come from the parameter table.
_COORDINATES = {"order": ("1", "element order"), "scheme": ("", "time-stepping scheme"),
                "probe": ("1", "probe number"), "norm": ("", "error norm"),
                "along": ("", "axis the order is fitted along"), "level": ("1", "refinement level (coupled axes)")}


def _coordinate_attrs(name: str) -> dict:
    from ..input.parameters import PARAMETERS

    if name in _COORDINATES:
        units, meaning = _COORDINATES[name]
    else:
        param = PARAMETERS.get(name)
        units, meaning = (param.unit or "1", param.meaning) if param is not None else ("", name)
    return {"units": units, "long_name": meaning}


def _alongs(layout: Layout) -> list:
    if layout.refining:
        return [a for a in ("h", "k", "h+k") if a == "h+k" or a == layout.driver or a in layout.coupled]
    return [a for a in REFINEMENT if a in layout.axes] + ["h+k"]


def fit(ds: xr.Dataset, layout: Layout, extrapolated: bool = False):
    """observed_order(norm, along, *other axes) and its standard error (see the module docs). ``extrapolated``: the
    errors are a :class:`~.reference.DifferenceReference`'s, whose finest case's is the order's own extrapolation,
    on the line by construction: left out of the fit (with it, three levels gave a standard error of 3e-15 from
    two differences; without, NaN, and four levels that of the three differences)."""
    alongs = _alongs(layout)
    series_dims = {"level"} if layout.refining else set(REFINEMENT) & set(layout.dims)
    rest = [d for d in layout.dims if d not in series_dims]
    coeff, err = [], []
    for norm in NORMS:
        c_row, e_row = [], []
        errors = ds[norm].where(~at_roundoff(ds, norm))  # (round-off has no order)
        for along in alongs:
            c, e = _fit_one(errors, layout, along, rest, extrapolated)
            c_row.append(c)
            e_row.append(e)
        coeff.append(xr.concat(c_row, dim="along"))
        err.append(xr.concat(e_row, dim="along"))
    coords = {"norm": list(NORMS), "along": alongs}
    o = xr.concat(coeff, dim="norm").assign_coords(coords).transpose("norm", "along", *rest)
    s = xr.concat(err, dim="norm").assign_coords(coords).transpose("norm", "along", *rest)
    o.attrs = {"units": "1", "long_name": "least-squares slope of log error"}
    s.attrs = {"units": "1", "long_name": "standard error of the slope"}
    return o, s


def _fit_one(err: xr.DataArray, layout: Layout, along: str, rest: list, extrapolated: bool = False):
    template = err.isel({d: 0 for d in err.dims if d not in rest}, drop=True) * np.nan
    if layout.refining:
        if along == "k" and len(set(layout.levels)) > 1 and "k" in layout.coupled:
            return template, template
        dim = "level"
        k = err["k_step"].values if "k_step" in err.coords else err["k"].values
        x = err["h"].values + k if along == "h+k" else (k if along == "k" else err[along].values)
        y = err
    else:
        if along not in layout.axes or len(layout.axes[along]) < 2:
            return template, template
        dim = along
        others = {d: -1 for d in REFINEMENT if d in err.dims and d != along}
        y = err.isel(others, drop=True)
        x = np.asarray(err["k_step"].values if along == "k" and "k_step" in err.coords else layout.axes[along],
                       dtype=float)
    x = np.asarray(x, dtype=float)
    if not (x > 0).all():  # (an axis with 0, e.g. rtol = 0 for fixed steps beside error-controlled ones)
        y, x = y.isel({dim: np.flatnonzero(x > 0)}), x[x > 0]
    if extrapolated and x.size > 1:  # (the finest case's error: the fitted order's extrapolation, no datum)
        kept = np.flatnonzero(x != x.min())
        y, x = y.isel({dim: kept}), x[kept]
    with np.errstate(divide="ignore", invalid="ignore"):
        logy = np.log(y.where(np.isfinite(y) & (y > 0)))
    logy = logy.drop_vars([c for c in logy.coords if dim in logy[c].dims and c != dim])
    logy = logy.assign_coords({dim: np.log(x)})
    count = np.isfinite(logy).sum(dim)
    if int(count.max()) < 2:
        return template, template
    # (full=True: xarray then ignores the rank warnings of slices with fewer than two points, masked below; with
    # full=False it resets the filter to warn once per variable, whatever the caller's: ten warnings a study)
    res = logy.polyfit(dim, 1, skipna=True, full=True)
    slope = res.polyfit_coefficients.sel(degree=1, drop=True).where(count >= 2)
    # standard error of the slope from the residuals: s^2 / sum (x - mean x)^2, s^2 = sum r^2 / (n - 2)
    valid = np.isfinite(logy)
    xs = xr.where(valid, logy[dim], np.nan)
    resid = logy - xr.polyval(logy[dim], res.polyfit_coefficients)
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = (resid ** 2).sum(dim) / (count - 2)
        sxx = ((xs - xs.mean(dim)) ** 2).sum(dim)
        stderr = np.sqrt(s2 / sxx).where(count >= 3)
    keep = lambda a: a.drop_vars([c for c in a.coords if c not in rest])  # noqa: E731
    return keep(slope), keep(stderr)


def pareto_front(err: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """1 where no other case is both at least as cheap and as accurate, and better in one."""
    flat_e, flat_c = err.ravel(), cost.ravel()
    out = np.zeros(flat_e.shape, dtype=np.int8)
    ok = np.isfinite(flat_e) & np.isfinite(flat_c)
    for i in np.nonzero(ok)[0]:
        dominated = ok & (flat_e <= flat_e[i]) & (flat_c <= flat_c[i]) & ((flat_e < flat_e[i]) | (flat_c < flat_c[i]))
        out[i] = not dominated.any()
    return out.reshape(err.shape)


def fit_order(x, y):
    """Least-squares slope of log(y) against log(x) and its standard error.

    Only the points with finite, positive x and y are used (a refused or diverged
    case is NaN); with fewer than two distinct x among them there is no slope, and
    both are NaN, without a warning. With two points the standard error is NaN.

    Examples
    --------
    >>> round(fit_order([0.1, 0.05, 0.025], [1.0, 0.5, 0.25])[0], 12)
    1.0
    >>> fit_order([0.1, 0.05], [1.0, float("nan")])
    (nan, nan)
    """
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    usable = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    lx, ly = np.log(x[usable]), np.log(y[usable])
    if np.unique(lx).size < 2:
        return np.nan, np.nan
    if len(lx) == 2:
        return float((ly[1] - ly[0]) / (lx[1] - lx[0])), np.nan
    coef, cov = np.polyfit(lx, ly, 1, cov=True)
    return float(coef[0]), float(np.sqrt(cov[0, 0]))


def study_dataset(study, runs: dict, compare, history: str) -> xr.Dataset:
    """The study's Dataset of its cases' runs (``runs``: case -> Dataset): per case its cost, status, errors against
    the reference at the comparison times ``compare`` and measures, laid out on the study's axes, with the fitted
    orders and the Pareto front (:func:`dataset`), and attributes that say how it was made (``history``: the
    call)."""
    ref = study.reference
    rows, methods, ref_measures = {}, set(), {}
    for case in study.listed:
        ds = runs[case]
        row = _costs_and_status(ds.attrs)
        if ref is not None and ds.attrs["status"] == "complete":
            own = times.compared(study, case, compare)
            err = ref.errors(case, study.scene_of(case, own), ds, runs, own, lambda c: study.scene_of(c, compare))
            methods.add(err.pop("transfer", "same mesh / exact solution"))
            row |= err
        if study.measures is not None:
            values = _measured(study.measures, ds)
            row |= values
            if ref is not None and ref.kind == "run":
                rc = ref.of(case)
                if rc not in ref_measures:
                    ref_measures[rc] = _measured(study.measures, runs[rc])
                for n, v in values.items():
                    r = ref_measures[rc][n]
                    row[f"rel_error_{n}"] = abs(v - r) / abs(r) if r != 0 else np.nan
        rows[case] = row
    # the probes from the case's scene, not its run: a refused case has no Dataset to read them from
    dim = study.scene.dim
    probes = np.asarray(study.scene_of(study.listed[0])["probes"], dtype=float).reshape(-1, dim)
    probe_coords = {f"probe_{c}": ("probe", probes[:, i], {"units": "m", "long_name": f"{c} of the probe"})
                    for i, c in enumerate("xyz"[:dim])}
    fixed = not any(study._adaptive(c) for c in study.listed)
    ds = dataset(study.layout, rows, len(probes), probe_coords, dim, T=study.scene["T"] if fixed else None)
    if ref is not None and ref.kind == "difference":
        extrapolate(ds, study.layout, ref)
    _say_roundoff(ds)
    ds["compare_time"] = ("compare", np.asarray(compare), {"units": "s", "long_name": "times at which fields are "
                                                           "compared" + (" (each case at its own grid's points "
                                                                         "nearest them)" if study.own_times else "")})
    for name in set(ds.coords) & {"h", "k"}:
        ds[name].attrs.update(units="s" if name == "k" else "m", long_name="time step" if name == "k" else "target "
                              "element size")
    swept = set(study.axes) | set(study.coupled)
    ref_case = study.ref_case
    ds.attrs = {
        "Conventions": "CF-1.10", "title": f"workbench study of scene {study.scene.name}",
        "scene": study.scene.name, "geometry": study.scene.geometry, "model": study.scene.model,
        "reference": ref.describe() if ref is not None else "none",
        "reference_case": ref_case.key if ref_case is not None else "",
        "transfer": "; ".join(sorted(methods)) or "same mesh / exact solution",
        "coupling": ("k = k_over_h * h" if study.coupled == ("k",) else ", ".join(study.coupled)) if study.coupled
        else "product of the axes" + (" (union of grids)" if not ds.ran.all() else ""),
        "axes": ",".join(study.axes),
        "parameters_json": canonical(study.scene.plain()),
        "cases_total_wall_time": float(np.nansum(ds["wall_time"]) + np.nansum(ds["setup_time"])),
        "history": history,
    } | {k: attr_value(v) for k, v in study.scene.values.items() if k not in swept}
    return ds


def _costs_and_status(a: dict) -> dict:
    """A case's row from its run's attributes ``a``: its costs, sizes and how it ended."""
    return {n: a.get(n, np.nan) for n in COSTS} | {
        "ndof": a["ndof"], "nsteps": a["nsteps"], "complete": int(a["status"] == "complete"),
        "status": a["status"] if not a.get("failure_type") or a["status"] == "refused"
        else f"{a['status']} ({a['failure_type']})"}


def _say_roundoff(ds: xr.Dataset) -> None:
    """Warn of errors at round-off (:func:`at_roundoff`): their orders are NaN, which said nothing of why."""
    counts = {n: int(at_roundoff(ds, n).sum()) for n in NORMS}
    said = [f"{n} ({c} case{'s' if c > 1 else ''})" for n, c in counts.items() if c]
    if said:
        import warnings

        warnings.warn(f"errors at round-off, at most {ROUNDOFF:g} of the reference's norm: {', '.join(said)}; no "
                      "order is fitted to them (the scheme is exact there, or the cases are too fine to tell)",
                      RuntimeWarning, stacklevel=4)


def _measured(measures, ds) -> dict:
    """``measures(ds)`` as a dict of floats, or a ParameterError saying what it returned."""
    from ..errors import ParameterError

    try:
        got = measures(ds)
    except Exception as err:  # noqa: BLE001 (the user's function: named, its own traceback kept as the cause)
        raise ParameterError(f"measures raised {type(err).__name__}: {str(err)[:200]} (the function given as measures "
                             "is called with each case's Dataset)") from err
    if not isinstance(got, dict):
        raise ParameterError(f"measures returned {type(got).__name__} {str(got)[:40]!r}: return a dict of names to "
                             "numbers")
    out = {}
    for name, value in got.items():
        try:
            out[str(name)] = float(value)
        except (TypeError, ValueError):
            raise ParameterError(f"measures returned {name} = {str(value)[:40]!r}: return a number for each name") \
                from None
    return out


def extrapolate(ds: xr.Dataset, layout: Layout, ref) -> None:
    """Turn the consecutive differences d_i of a :class:`~.reference.DifferenceReference` (in the error variables)
    into error estimates, in place, and fit the orders again: along the series (coarse to fine, x its driver's
    values) the order p is the slope of log d_i against log x_i, e_i = d_i / (1 - r_i^p) with r_i = x_{i+1} / x_i,
    and the finest case's e_n = e_{n-1} r^p. A series whose differences do not fall (p <= 0: not yet in the
    asymptotic range) gives no estimates (NaN)."""
    dim = "level" if layout.refining else ref.driver
    x = np.asarray(ds["k_step" if ref.driver == "k" and "k_step" in ds.coords else ref.driver].values, dtype=float)
    order = np.argsort(-x)  # coarse first
    none = []  # (the series of "error" that give no estimate, by their driver's differences)
    for name in list(NORMS) + ["error_probe"]:
        da = ds[name].transpose(dim, ...)
        d = np.moveaxis(da.values, 0, -1)[..., order]
        e = np.full(d.shape, np.nan)
        xs = x[order]
        for index in np.ndindex(d.shape[:-1]):
            diffs = d[index][:-1]
            ok = np.isfinite(diffs) & (diffs > 0)
            p = richardson_order(xs[:-1][ok], xs[1:][ok], diffs[ok]) if ok.sum() >= 2 else np.nan
            if not p > 0:
                if name == "error" and np.isfinite(diffs).any():
                    none.append(", ".join(f"{v:.3g}" for v in diffs))
                continue
            r = xs[1:] / xs[:-1]
            e[index][:-1] = diffs / (1.0 - r ** p)
            e[index][-1] = e[index][-2] * r[-1] ** p
        back = np.empty_like(e)
        back[..., order] = e
        ds[name].values = _restore(back, da, ds[name].dims)
    if none:  # (NaN errors and no order, which a plot showed as an empty panel without a word)
        import warnings

        finer = {ref.driver: float(x.min()) / (4 if ref.driver in ("h", "k", "h_contact") else 10)}
        warnings.warn(f"reference: the extrapolated reference gives no error estimate for {len(none)} series: the "
                      f"differences between their levels of {ref.driver} do not fall ({'; '.join(none[:3])}"
                      f"{'; ...' if len(none) > 3 else ''}; error-controlled runs of neighbouring tolerances may take "
                      f"the same steps); give a finer run as the reference, such as {finer} or 'finest'",
                      RuntimeWarning, stacklevel=4)
    orders, spread = fit(ds, layout, extrapolated=True)
    ds["observed_order"] = orders
    ds["observed_order_stderr"] = spread
    _labelled(ds)  # (the orders fitted again brought their norm and along without attributes)
    ds["pareto"] = (layout.dims, pareto_front(ds["error"].values, (ds["wall_time"] + ds["setup_time"]).values),
                    ds["pareto"].attrs)


def richardson_order(x, finer, d) -> float:
    """The order p of errors e = C x^p whose consecutive differences are ``d``: d_i = C x_i^p (1 - r_i^p), r_i =
    ``finer``_i / x_i, fitted in log by least squares over C and p (p in (0, 12]; NaN where the best p is at its
    lower end: the differences do not fall). With one ratio throughout, this is the slope of log d against log x;
    with several (0.1, 0.07, 0.05), that slope is not the order: it fitted 1.83 for backward Euler on tp1.

    >>> round(richardson_order([0.1, 0.07], [0.07, 0.05], [0.1 - 0.07, 0.07 - 0.05]), 9)  # e = x exactly
    1.0
    >>> x = np.array([0.01, 0.0075, 0.005, 0.0025])
    >>> round(richardson_order(x[:-1], x[1:], x[:-1] ** 0.93 - x[1:] ** 0.93), 6)  # the differences rise
    0.93
    """
    from scipy.optimize import minimize_scalar

    x, finer, d = (np.asarray(a, dtype=float) for a in (x, finer, d))
    lx, lr, ld = np.log(x), np.log(finer / x), np.log(d)

    def misfit(p):
        resid = ld - p * lx - np.log(-np.expm1(p * lr))
        return float(np.sum((resid - resid.mean()) ** 2))

    grid = np.geomspace(1e-3, 12.0, 400)
    i = int(np.argmin([misfit(p) for p in grid]))
    if i == 0:
        return np.nan
    best = minimize_scalar(misfit, bounds=(grid[i - 1], grid[min(i + 1, grid.size - 1)]), method="bounded",
                           options={"xatol": 1e-10})
    return float(best.x)


def step_taken(T: float, k):
    """The step of the uniform grid a run to ``T`` with steps of at most ``k`` takes: T / ceil(T / k)
    (:func:`workbench.schemes.stepping.time_grid`). k = 0.07 to T = 1 takes 15 steps of 0.0667: fitted against the
    k asked for, backward Euler's order came out 0.94 and BDF2's 1.95 at k = 0.09, 0.045, 0.0225.

    >>> step_taken(1.0, [0.1, 0.07, 0.05]).round(4).tolist()
    [0.1, 0.0667, 0.05]
    """
    k = np.asarray(k, dtype=float)
    return T / np.maximum(1.0, np.ceil(T / k - 1e-9))


def _restore(values_last, da, dims) -> np.ndarray:
    """Values with the series axis last, back in the order of ``dims`` (``da``: the array with the series first)."""
    first = np.moveaxis(values_last, -1, 0)  # (da.dims order)
    return np.transpose(first, [da.dims.index(d) for d in dims])
