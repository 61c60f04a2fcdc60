"""Refinement studies (workbench.study): orders through Study, resumable sweeps, dask, exact transfer.

References: tp1's closed form / the reduced rod ODE (SPEC) for the rod k-sweeps; for 2D/3D the finest
case of the sweep, compared on its mesh after exact prolongation (nested meshes).
"""
import os
import signal
import subprocess
import sys
import time

import ngsolve as ngs
import numpy as np
import pytest
import xarray as xr

import workbench
from workbench import transfer
from workbench.study import Study, fit_order


@pytest.mark.parametrize("name", ["tp1", "tp2"])
def test_rod_k_sweep_order(name):
    """tp1/tp2 k-sweeps: order in [0.9, 1.1] in the paper's norm against the ODE reference."""
    st = Study(name, k=[0.02, 0.01, 0.005, 0.0025], reference="ode", workers=0)
    ds = st.run(progress=False)
    st.assert_order(1.0, tol=0.1, along="k", max_error=5e-4 if name == "tp1" else 5e-5)
    st.assert_order(1.0, tol=0.1, norm="error_beta", along="k")
    assert ds.attrs["reference"] == "ode" and np.all(ds.complete.values == 1)
    with pytest.raises(AssertionError):
        st.assert_order(2.0, tol=0.1, along="k")  # the check can fail


def test_transfer_is_exact_on_nested_meshes():
    """A coarse P1 field prolongated to the nested fine mesh is the same function (energy and values)."""
    coarse, fine = (transfer.mesh_info(workbench.scene("slab", nx=n, ny=n // 10)) for n in (20, 40))
    g = ngs.GridFunction(coarse.fes)
    g.Set(ngs.CF((ngs.sin(3 * ngs.x) * ngs.y, ngs.x * ngs.x)))
    u = g.vec.FV().NumPy().copy()
    nodes = np.stack([u[: len(coarse.xyz)], u[coarse.fes.ndof // 2: coarse.fes.ndof // 2 + len(coarse.xyz)]], axis=1)
    tr = transfer.Transfer(coarse, fine)
    uf = tr.displacement(u, nodes)
    assert tr.exact
    e_c = np.sqrt(u @ (coarse.strain_matrix() @ u))
    e_f = np.sqrt(uf @ (fine.strain_matrix() @ uf))
    assert e_f == pytest.approx(e_c, rel=1e-12)
    gf = ngs.GridFunction(fine.fes)
    gf.vec.FV().NumPy()[:] = uf
    pts = fine.mesh(np.array([0.123, 0.77]), np.array([0.031, 0.089]))
    assert np.allclose(gf(pts), g(coarse.mesh(np.array([0.123, 0.77]), np.array([0.031, 0.089]))), atol=1e-13)


def test_slab_coupled_sweep():
    """2D slab (tp5 load), coupled k = 0.2 h (explicit, k < k_crit), against the finest case.

    The reference is the finest P2 case. P2: the paper's norm falls at order >= 0.9 (measured 1.05).
    P1 on this thin slab locks in bending and the clamped corners are singular, so its order is
    pre-asymptotic here (measured: paper norm 0.90, displacement part 0.86): asserted >= 0.8.
    """
    st = Study("tp5", h=[0.05, 0.025, 0.0125, 0.00625], k_over_h=0.2, order=[1, 2], T=0.3, n_compare=5, workers=2)
    ds = st.run(progress=False)
    rates = ds.observed_order.sel(along="h+k").squeeze("scheme")
    assert float(rates.sel(norm="error", order=2)) >= 0.9
    assert float(rates.sel(norm="error", order=1)) >= 0.8 and float(rates.sel(norm="error_V", order=1)) >= 0.8
    err = ds.error.squeeze("scheme")
    assert float(err.sel(order=2).isel(level=2)) < 0.2 * float(err.sel(order=1).isel(level=0))
    assert ds.attrs["transfer"] == "nested prolongation (exact)"


def test_block_sweep():
    """3D block (P2), h-sweep at fixed k against the finest case: paper-norm order >= 0.8 (measured 1.13)."""
    st = Study("block", h=[0.1, 0.05, 0.025], k=[0.005], order=[2], T=0.05, n_compare=3, workers=2,
               traction_top="(0, 0, 2*t)")
    ds = st.run(progress=False)
    st.assert_order(1.0, tol=0.2, along="h", at_least=True)
    assert ds.attrs["transfer"].startswith("nested")


def test_fit_order_stderr():
    rate, err = fit_order([0.1, 0.05, 0.025], [1.0, 0.5, 0.25])
    assert rate == pytest.approx(1.0) and err == pytest.approx(0.0, abs=1e-12)


def test_pareto_and_cheapest():
    st = Study("tp2", k=[0.02, 0.01, 0.005], scheme=["explicit", "implicit"], reference="ode", workers=0)
    ds = st.run(progress=False)
    assert ds.pareto.sum() >= 1
    best = st.cheapest(float(ds.error.max()) * 1.01)
    assert best is not None and best["error"] <= float(ds.error.max()) * 1.01
    assert st.cheapest(1e-30) is None


def _study_cmd(out):
    return [sys.executable, "-m", "workbench.cli", "study", "tp2", "--k", "0.02", "0.01", "0.005", "0.0025",
            "--reference", "ode", "--workers", "1", "--no-progress", "-o", str(out)]


def test_kill_and_resume(tmp_path):
    """A sweep killed after its first case resumes without recomputing it; the result equals an uninterrupted run."""
    out = tmp_path / "resumed.nc"
    proc = subprocess.Popen(_study_cmd(out), start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    cases = tmp_path / "resumed.nc.cases"
    deadline = time.time() + 120
    while time.time() < deadline and not (cases.exists() and list(cases.glob("*.nc"))):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = sorted(cases.glob("*.nc"))
    assert 1 <= len(done) < 4 and not out.exists()
    stamps = {p.name: p.stat().st_mtime_ns for p in done}
    assert subprocess.run(_study_cmd(out), capture_output=True).returncode == 0
    assert all((cases / name).stat().st_mtime_ns == ns for name, ns in stamps.items())  # not recomputed
    whole = tmp_path / "whole.nc"
    assert subprocess.run(_study_cmd(whole), capture_output=True).returncode == 0
    costs = ["wall_time", "cpu_time", "setup_time", "memory_peak_mb", "pareto"]
    a, b = workbench.load(out), workbench.load(whole)
    a.attrs.pop("cases_total_wall_time"), b.attrs.pop("cases_total_wall_time")
    xr.testing.assert_identical(a.drop_vars(costs), b.drop_vars(costs))


def test_dask_local_cluster():
    """Cases run on a dask.distributed LocalCluster with 2 workers give the same errors as local processes."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        ds = Study("tp2", k=[0.02, 0.01], reference="ode", client=client).run(progress=False)
    local = Study("tp2", k=[0.02, 0.01], reference="ode", workers=0).run(progress=False)
    np.testing.assert_allclose(ds.error.values, local.error.values, rtol=1e-12)
