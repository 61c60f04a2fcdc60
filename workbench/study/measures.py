"""Measures of one run for a study's ``measures=``: scalars read from a (possibly incomplete) run Dataset.

A :class:`~workbench.study.Study` calls ``measures(ds)`` on every case's Dataset
and stores each returned scalar as a data variable on the sweep's axes. The
helpers here read the quantities that the studies and tests share: the tip
displacement, the normal displacement of the contact side, the penetration
and the bonding field at the far end; :func:`summary` collects them per case.
A case that never ran (``status = "refused"``: an empty Dataset) has no
measures (``summary`` returns an empty dict, so the Study stores NaN).

Conventions: the normal displacement is u_nu = -u_y on the slab's contact side
y = 0 and u_nu = +u at the rod's end x = 1 (positive into the foundation); the
penetration is u_nu - gap; the tip is the last probe (the slab's (1, 0.1), the
rod's x = 1).

Examples
--------
>>> from workbench import Study
>>> st = Study("tp4", h=0.1, k=[0.05, 0.025], T=0.1, reference=None, measures=summary, workers=0)
>>> ds = st.run(progress=False)
>>> ds.steps_done.squeeze().values.tolist(), ds.beta_monotone.squeeze().values.tolist()
([2.0, 4.0], [1.0, 1.0])
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from ..output.results import far_facet

__all__ = ["computed", "normal_displacement", "tip", "beta_far", "penetration", "run_records", "summary"]


def computed(ds: xr.Dataset) -> xr.Dataset:
    """The records of ``ds`` that hold a computed (finite) state: the first n, n = number of finite records.

    A run stopped by :class:`workbench.Diverged` keeps only the steps before the failing one, so
    this is ``ds`` itself unless a record holds non-finite values.
    """
    n = int(np.sum(np.isfinite(ds.u_contact.isel(node=0, component=0).values)))
    return ds.isel(time=slice(0, n))


def normal_displacement(ds: xr.Dataset) -> np.ndarray:
    """u_nu(time, node) on the contact side: -u_y on the slab's y = 0, +u at the rod's end x = 1."""
    if "y" in ds.component.values:
        return -ds.u_contact.sel(component="y").values
    return ds.u_contact.sel(component="x").values


def tip(ds: xr.Dataset) -> np.ndarray:
    """The tip displacement over time: u_y at the last probe (the slab's (1, 0.1)), u at the rod's x = 1."""
    comp = "y" if "y" in ds.component.values else "x"
    return ds.u_probe.isel(probe=-1).sel(component=comp).values


def beta_far(ds: xr.Dataset) -> np.ndarray:
    """beta(t) on the contact facet farthest along x (the slab's (1, 0)): :func:`workbench.output.results.far_facet`."""
    return far_facet(ds.beta).values


def penetration(ds: xr.Dataset) -> float:
    """max over the recorded times and contact nodes of u_nu - gap (NaN records are skipped).

    Examples
    --------
    >>> from workbench.running.runner import run
    >>> ds = run("slab", h=0.1, k=0.05, T=0.1, traction_top="(0, -1)", progress=False)
    >>> penetration(ds) > 0  # pressed into the foundation
    True
    """
    return float(np.nanmax(normal_displacement(ds) - float(ds.attrs.get("gap", 0.0))))


def run_records(ds: xr.Dataset, max_records: int | None = None) -> xr.Dataset:
    """The records that a plain :func:`workbench.run` keeps, from a run recorded at every step.

    A plain run of more than ``max_records`` (default :data:`workbench.running.runner.MAX_RECORDS`) steps keeps
    t = 0, T and one step whenever T / max_records has passed since the last kept one; a study case
    records every step of its grid. Measures that are maxima over the recorded times (the penetration,
    the largest increase of beta, a first crossing time) then see the same records as a plain run of
    the same case. Runs of at most ``max_records`` steps are returned as they are.

    Raises
    ------
    ValueError
        If the run has more than ``max_records`` steps and ``ds`` does not record every one of them.

    Examples
    --------
    >>> t = np.linspace(0.0, 1.0, 5001)
    >>> ds = xr.Dataset(coords={"time": t, "step": ("time", np.arange(t.size))}, attrs={"T": 1.0, "nsteps": 5000})
    >>> kept = run_records(ds)
    >>> kept.sizes["time"], kept.step.values[:3].tolist(), int(kept.step[-1])
    (1668, [0, 3, 6], 5000)
    """
    from ..running.runner import MAX_RECORDS

    max_records = MAX_RECORDS if max_records is None else int(max_records)
    n_steps = int(ds.attrs.get("nsteps", ds.sizes.get("time", 1) - 1))
    if "time" not in ds.dims or n_steps <= max_records:
        return ds
    steps = ds.step.values
    if not np.array_equal(steps, np.arange(len(steps))):
        raise ValueError(f"run_records: the run has {n_steps} steps but not every step is recorded")
    t = ds.time.values
    T = float(ds.attrs["T"])
    spacing = T / max_records
    final = abs(t[-1] - T) <= 1e-9 * T and len(t) == n_steps + 1
    keep, last = [0], t[0]
    for i in range(1, len(t)):  # the rule of workbench.output.results.Recorder
        if (final and i == len(t) - 1) or t[i] - last >= spacing * (1 - 1e-9):
            keep.append(i)
            last = t[i]
    return ds.isel(time=keep)


def summary(ds: xr.Dataset) -> dict:
    """The per-case measures of a (possibly incomplete) run; an empty dict for a run that never started.

    Keys: ``steps_done``, ``t_end`` (last computed step and time), ``max_penetration`` (:func:`penetration`),
    ``penetration_end`` (max over the contact nodes at the last computed time), ``tip_u`` (:func:`tip` at
    the last computed time); with a bonding field ``beta_in_range`` (1 if beta is in [0, 1] everywhere),
    ``beta_min``, ``beta_monotone`` (1 if beta never increases between records at any facet),
    ``beta_max_increase``, ``beta_exact_beta0`` (1 if beta == beta0 exactly everywhere) and ``beta_end``
    (:func:`beta_far` at the last computed time); for the implicit scheme ``newton_max`` and
    ``newton_mean`` (Newton iterations per step, t = 0 excluded).

    Examples
    --------
    >>> from workbench.running.runner import run
    >>> s = summary(run("tp4", h=0.1, k=0.05, T=0.1, scheme="implicit", progress=False))
    >>> s["steps_done"], s["beta_in_range"], s["beta_monotone"], s["newton_max"] >= 1
    (2, 1, 1, True)
    >>> summary(xr.Dataset())  # a refused case
    {}
    """
    if "u_contact" not in ds:
        return {}
    ds = computed(ds)
    n = ds.sizes["time"]
    gap = float(ds.attrs.get("gap", 0.0))
    u_nu = normal_displacement(ds)
    out = dict(steps_done=int(ds.step.values[-1]) if n else 0, t_end=float(ds.time.values[-1]) if n else 0.0,
               max_penetration=float(np.nanmax(u_nu - gap)), penetration_end=float(np.max(u_nu[-1] - gap)),
               tip_u=float(tip(ds)[-1]))
    if "beta" in ds:
        b = ds.beta.values
        inc = float(np.max(np.diff(b, axis=0))) if b.shape[0] > 1 else 0.0
        beta0 = float(ds.attrs["beta0"])
        out |= dict(beta_in_range=int(np.all((b >= 0) & (b <= 1))), beta_min=float(b.min()),
                    beta_monotone=int(inc <= 0.0), beta_max_increase=inc,
                    beta_exact_beta0=int(np.all(b == beta0)), beta_end=float(beta_far(ds)[-1]))
    if "newton_iterations" in ds and n > 1:
        it = ds.newton_iterations.values[1:]
        out |= dict(newton_max=int(it.max()), newton_mean=float(it.mean()))
    return out
