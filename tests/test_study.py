"""Refinement studies (workbench.study): orders through Study, resumable sweeps, dask, exact transfer.

References: tp1's closed form / the reduced rod ODE (docs/models.md) for the rod k-sweeps; for 2D/3D the finest
case of the sweep, compared on its mesh after exact prolongation (nested meshes).
"""
import os
import re
import signal
import subprocess
import sys
import time
import warnings

import ngsolve as ngs
import numpy as np
import pytest
import xarray as xr

import workbench
from workbench.discrete import transfer
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


def _p1_nodes(info, cf):
    """The P1 interpolant of the vector field ``cf`` on ``info``'s mesh: (dofs, vertex values)."""
    g = ngs.GridFunction(info.fes)
    g.Set(cf)
    u = g.vec.FV().NumPy().copy()
    n, half = len(info.xyz), info.fes.ndof // 2
    return u, np.stack([u[:n], u[half: half + n]], axis=1)


def test_errors_on_meshes_that_are_not_nested_are_those_of_the_fields():
    """Found by an outside pass: on meshes that are not nested (the Hertz bodies' sweeps of h_contact) the error was
    taken of the coarse field interpolated at the fine vertices, whose strain differs from the coarse field's wherever
    a fine cell straddles coarse ones: the 2D Hertz sweep's error_V came out 25-59 % low, its order 0.70 against 0.27.
    The norm is now a sum over the cells' overlaps. Checked on two slabs whose meshes do not nest (12 x 3 and 20 x 5
    cells), each with the P1 interpolant of one smooth field, against the tester's way: the strains of both evaluated
    at 400,000 random points of the slab (Monte Carlo: 0.1000 +- 0.0001, the overlaps 0.0999); the old way gave 0.041."""
    coarse, fine = (transfer.mesh_info(workbench.scene("slab", nx=nx, ny=ny)) for nx, ny in ((12, 3), (20, 5)))
    cf = ngs.CF((ngs.sin(3 * ngs.x) * ngs.y + ngs.x * ngs.x, ngs.cos(2 * ngs.x) * ngs.y * 5))
    (uc, nc), (uf, nf) = _p1_nodes(coarse, cf), _p1_nodes(fine, cf)
    tr = transfer.Transfer(coarse, fine)
    assert not tr.exact and tr.method.startswith("cell overlaps")
    zero = np.zeros((len(fine.cells), 3)), np.zeros((len(coarse.cells), 3))
    got = tr.difference_norms((uf, nf, zero[0]), (uc, nc, zero[1]))
    rng = np.random.default_rng(1)
    pts = rng.random((400_000, 2)) * [1.0, 0.1]  # (the slab: 1 x 0.1)
    diff = transfer.p1_cell_strains(fine, nf)[fine.locate(pts)] - transfer.p1_cell_strains(coarse, nc)[coarse.locate(pts)]
    samples = (diff ** 2 * transfer.STRESS_WEIGHTS[2]).sum(axis=1) * 0.1
    monte_carlo, spread = np.sqrt(samples.mean()), samples.std() / np.sqrt(len(pts)) / (2 * np.sqrt(samples.mean()))
    assert abs(got[0] - monte_carlo) <= 4 * spread + 1e-3 * monte_carlo, (got[0], monte_carlo, spread)
    assert got[1] == 0.0
    interpolated = transfer.norms(fine, uf - tr.displacement(uc, nc), None, None)[0]
    assert abs(interpolated - monte_carlo) > 0.1 * monte_carlo  # (the old way's error, which the test can see)


def _beta_error(tr, beta_fine, beta_coarse):
    """|beta_fine - beta_coarse|_L2(Gamma3) as a Study takes it (the other fields zero)."""
    def zero(info):
        components = 3 * info.dim - 3
        return np.zeros(info.fes.ndof), np.zeros((len(info.xyz), info.dim)), np.zeros((len(info.cells), components))

    return tr.difference_norms(zero(tr.fine), zero(tr.coarse), (beta_fine, beta_coarse))[2]


def _facet_front(info, front):
    """beta = 1 on the contact facets whose midpoint lies within ``front`` of the axis, 0 beyond (a debonding front)."""
    return (np.linalg.norm(info.facet_xyz[:, :-1], axis=1) < front).astype(float)


def test_beta_on_meshes_that_are_not_nested_is_differenced_over_the_facets_overlaps():
    """Found on reading the cells' fix: on meshes that are not nested the bonding field was compared at the fine
    facets' midpoints, each fine facet taking one coarse facet's beta, so a coarse jump of beta moved by up to a fine
    facet. With a debonding front in each field (beta = 1 within 0.0737 of the axis on the 2D Hertz body at
    h_contact = 0.02 and 0.014) that gave 0 for a difference of 0.064. The norm is now a sum over the facets'
    overlaps. In 2D the contact side is a graph over x, so the tester's way is exact: both meshes' facets cut at every
    vertex's x, each piece weighed by its share of its fine facet's length; in 3D (the hemisphere at h_contact = 0.04
    and 0.03), a Monte Carlo integral over the fine facets, each point given the coarse facet below it."""
    def info(scene, h_contact):
        return transfer.MeshInfo(workbench.scene(scene, h_contact=h_contact).model_of().geometry, 1)

    coarse, fine = info("hertz", 0.02), info("hertz", 0.014)
    tr = transfer.Transfer(coarse, fine)
    xf, xc = (np.sort(i.facet_vertices()[..., 0], axis=1) for i in (fine, coarse))
    cuts = np.unique(np.concatenate([xf.ravel(), xc.ravel()]))
    middle = 0.5 * (cuts[1:] + cuts[:-1])
    jf, jc = (np.searchsorted(x[:, 0], middle, side="right") - 1 for x in (xf, xc))  # (the facets are intervals)
    assert np.all(middle <= xf[jf, 1]) and np.all(middle <= xc[jc, 1])
    length = np.linalg.norm(np.diff(fine.facet_vertices(), axis=1)[:, 0], axis=1)
    weight = length[jf] * np.diff(cuts) / (xf[jf, 1] - xf[jf, 0])
    for front in (0.031, 0.05, 0.0737, 0.1):
        bf, bc = _facet_front(fine, front), _facet_front(coarse, front)
        exact = np.sqrt(np.sum(weight * (bf[jf] - bc[jc]) ** 2))
        assert _beta_error(tr, bf, bc) == pytest.approx(exact, rel=0.015), front
    midpoints = np.sqrt(np.sum(fine.facet_measure * (bf - tr.facets(bc)) ** 2))
    assert abs(midpoints - exact) > 0.1 * exact  # (the old way, at the last front)

    coarse, fine = info("hertz3d", 0.04), info("hertz3d", 0.03)
    tr = transfer.Transfer(coarse, fine)
    bf, bc = _facet_front(fine, 0.06), _facet_front(coarse, 0.06)
    rng = np.random.default_rng(1)
    V, C = fine.facet_vertices(), coarse.facet_vertices()
    r = rng.random((len(V), 400, 2))
    r[r.sum(axis=2) > 1] = 1.0 - r[r.sum(axis=2) > 1]  # (uniform on each triangle)
    edges = V[:, None, 1:] - V[:, None, :1]  # (facet, 1, edge, coordinate)
    points = (V[:, None, 0] + r[..., :1] * edges[:, :, 0] + r[..., 1:] * edges[:, :, 1]).reshape(-1, 3)[:, :2]
    below = np.full(len(points), -1)
    for j, tri in enumerate(C[:, :, :2]):  # (the coarse facet below each point: barycentric in the plane z = 0)
        lam = np.linalg.solve(np.stack([tri[1] - tri[0], tri[2] - tri[0]], axis=1), (points - tri[0]).T).T
        below[(below < 0) & (lam >= 0).all(axis=1) & (lam.sum(axis=1) <= 1)] = j
    found = below >= 0
    assert found.mean() > 0.99
    d2 = (np.repeat(bf, 400) - bc[below]) ** 2 * np.repeat(fine.facet_measure / 400, 400)
    monte_carlo = np.sqrt(d2[found].sum() / found.mean())
    assert _beta_error(tr, bf, bc) == pytest.approx(monte_carlo, rel=0.03)
    assert np.sqrt(np.sum(fine.facet_measure * (bf - tr.facets(bc)) ** 2)) < 0.92 * monte_carlo  # (the old way)


@pytest.mark.slow
def test_slab_coupled_sweep():
    """2D slab (tp5 load), coupled k = 0.2 h (explicit, k < k_crit), against the finest case.

    The reference is the finest P2 case. P2: the paper's norm falls at order >= 0.9 (measured 1.05).
    P1 on this thin slab locks in bending and the clamped corners are singular, so its order is
    pre-asymptotic here (measured: paper norm 0.90, displacement part 0.86): asserted >= 0.8.
    """
    st = Study("tp5", h=[0.05, 0.025, 0.0125, 0.00625], k_over_h=0.2, order=[1, 2], T=0.3, n_compare=5, workers=2,
               reference="finest")
    ds = st.run(progress=False)
    rates = ds.observed_order.sel(along="h+k").squeeze("scheme")
    assert float(rates.sel(norm="error", order=2)) >= 0.9
    assert float(rates.sel(norm="error", order=1)) >= 0.8 and float(rates.sel(norm="error_V", order=1)) >= 0.8
    err = ds.error.squeeze("scheme")
    assert float(err.sel(order=2).isel(level=2)) < 0.2 * float(err.sel(order=1).isel(level=0))
    assert ds.attrs["transfer"] == "nested prolongation (exact)"


@pytest.mark.slow
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


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("x, y", [([0.1], [1.0]), ([0.1, 0.05, 0.025], [1.0, np.nan, np.nan]), ([0.1, 0.05], [1.0, 0.0]),
                                  ([0.1, 0.1, 0.1], [1.0, 2.0, 3.0]), ([], [])])
def test_fit_order_without_two_usable_points_is_nan_and_quiet(x, y):
    """Fewer than two finite, positive points (refused or diverged cases are NaN), or one x only: no slope, NaN
    without a RankWarning, a log warning or a LinAlgError."""
    assert np.isnan(fit_order(x, y)).all()


def test_fit_order_skips_unusable_points():
    """A NaN among four points leaves three on the line y = x: slope 1 (it was NaN)."""
    assert fit_order([0.1, 0.05, 0.025, 0.01], [0.1, np.nan, 0.025, 0.01])[0] == pytest.approx(1.0)


@pytest.mark.slow
def test_pareto_and_cheapest():
    st = Study("tp2", k=[0.02, 0.01, 0.005], scheme=["explicit", "implicit"], reference="ode", workers=0)
    ds = st.run(progress=False)
    assert ds.pareto.sum() >= 1
    best = st.cheapest(float(ds.error.max()) * 1.01)
    assert best is not None and best["error"] <= float(ds.error.max()) * 1.01
    assert st.cheapest(1e-30) is None
    # a tolerance below 0 (or NaN) gave None as if no case met it; error_probe took a case for one probe's error
    for tolerance in (-1.0, float("nan")):
        with pytest.raises(workbench.ParameterError, match=r"tolerance = .*: give a number >= 0"):
            st.cheapest(tolerance)
    with pytest.raises(workbench.ParameterError, match=r"'error_probe' has the dimension\(s\) \['probe'\]"):
        st.cheapest(1.0, error="error_probe")


def _study_cmd(out):
    # one long case (k = 2e-4: 5000 steps, run first, on one worker) beside three short ones (on the other): when the
    # first short case is archived the long one is still running, whatever the machine's speed
    return [sys.executable, "-m", "workbench.cli", "study", "tp2", "--k", "0.02", "0.01", "0.005", "0.0002",
            "--reference", "ode", "--workers", "2", "--no-progress", "-o", str(out)]


@pytest.mark.slow
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
    for key in ("cases_total_wall_time", "history"):  # cost and time stamp of the making
        a.attrs.pop(key), b.attrs.pop(key)
    xr.testing.assert_identical(a.drop_vars(costs), b.drop_vars(costs))


@pytest.mark.slow
def test_dask_local_cluster():
    """Cases run on a dask.distributed LocalCluster with 2 workers give the same errors as local processes."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        ds = Study("tp2", k=[0.02, 0.01], reference="ode", client=client).run(progress=False)
    local = Study("tp2", k=[0.02, 0.01], reference="ode", workers=0).run(progress=False)
    np.testing.assert_allclose(ds.error.values, local.error.values, rtol=1e-12)


def _cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, **kw)


@pytest.mark.slow
def test_case_files_are_keyed_by_every_input(tmp_path):
    """The same sweep with other scene values recomputes its cases and says why (the stale cases gave order 0 and
    an error of 0.133 while the archive claimed gamma_nu = 1.5); the same inputs again reuse them."""
    out = str(tmp_path / "s.nc")
    base = ["study", "tp2", "--k", "0.02", "0.01", "--reference", "ode", "--workers", "0", "--no-progress", "-o", out]
    assert _cli(*base).returncode == 0
    changed = base + ["--set", "gamma_nu=1.5", "--set", "L=0.2"]
    p = _cli(*changed)
    assert p.returncode == 0 and "recomputing" in p.stderr and "gamma_nu 0.1 -> 1.5" in p.stderr
    ds = workbench.load(out)
    fresh = Study("tp2", k=[0.02, 0.01], reference="ode", workers=0, gamma_nu=1.5, L=0.2).run(progress=False)
    np.testing.assert_allclose(ds.error.values, fresh.error.values, rtol=1e-12)
    assert float(ds.observed_order.sel(norm="error", along="k").squeeze()) > 0.9 and ds.attrs["gamma_nu"] == 1.5
    stamps = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "s.nc.cases").glob("*.nc")}
    p = _cli(*changed)
    assert p.returncode == 0 and "recomputing" not in p.stderr
    assert stamps == {p.name: p.stat().st_mtime_ns for p in (tmp_path / "s.nc.cases").glob("*.nc")}


@pytest.mark.slow
def test_damaged_case_files_are_recomputed(tmp_path):
    """An empty and a truncated case file (a kill, a full disk) are recomputed with a warning, not a traceback."""
    cases = tmp_path / "cases"
    st = Study("tp2", k=[0.02, 0.01], reference="ode", workers=0)
    first = st.run(cases, progress=False)
    files = sorted(cases.glob("*.nc"))
    files[0].write_bytes(b"")
    data = files[1].read_bytes()
    files[1].write_bytes(data[: len(data) // 2])
    with pytest.warns(RuntimeWarning, match="unreadable.*recomputing") as record:
        again = Study("tp2", k=[0.02, 0.01], reference="ode", workers=0).run(cases, progress=False)
    assert len([w for w in record if "recomputing" in str(w.message)]) == 2
    np.testing.assert_allclose(again.error.values, first.error.values, rtol=1e-12)


def test_stale_temporary_files_are_removed(tmp_path):
    """A kill during a write leaves .NAME.PID.RANDOM.tmp; the next write of that target removes those of dead
    processes (and leaves a live process's own)."""
    ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = tmp_path / f".a.nc.{int(dead.stdout)}.0badc0de.tmp"
    stale.write_bytes(b"x" * 100)
    live = tmp_path / f".a.nc.{os.getpid() if False else os.getppid()}.0badc0de.tmp"
    live.write_bytes(b"y")
    workbench.write(ds, tmp_path / "a.nc")
    assert not stale.exists() and live.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["a.nc", live.name])


def test_an_archive_name_of_up_to_255_bytes_is_written(tmp_path):
    """An -o of 236-255 bytes passed the check before the run, then failed at its end: the temporary beside it took
    its name and 20 bytes more (found by an outside pass). Such a name's temporary takes a digest of it; a stale
    one is still removed. An -o that is a symbolic link was replaced by a file; it is written through now."""
    ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    from workbench.output import files

    for n in (235, 250):
        target = tmp_path / ("b" * (n - 3) + ".nc")
        dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
        stale = tmp_path / f".{files._stem(target)}.{int(dead.stdout)}.0badc0de.tmp"
        stale.write_bytes(b"x")
        workbench.write(ds, target)
        assert workbench.load(target).attrs["status"] == "complete" and not stale.exists()
    with pytest.raises(workbench.ParameterError, match="256 bytes long"):
        files.check_output(tmp_path / ("b" * 253 + ".nc"), "-o")
    (tmp_path / "runs").mkdir()
    (tmp_path / "latest.nc").symlink_to(tmp_path / "runs" / "r5.nc")  # (written through, as the shell's > does)
    workbench.write(ds, tmp_path / "latest.nc")
    assert (tmp_path / "latest.nc").is_symlink() and workbench.load(tmp_path / "runs" / "r5.nc").sizes == ds.sizes


SNIPPET = """
from workbench import Study
st = Study("tp2", k=[0.02, 0.01, 0.005], reference="ode")
ds = st.run(progress=False)
print("order", float(ds.observed_order.sel(norm="error", along="k").squeeze()))
"""


@pytest.mark.slow
@pytest.mark.parametrize("how", ["script", "stdin"])
def test_study_with_workers_in_a_plain_script(tmp_path, how):
    """Default worker processes, no main guard: as a plain script and fed on standard input (the spawned pool of
    the old code re-imported __main__ and died with BrokenProcessPool)."""
    script = tmp_path / "plain.py"
    script.write_text(SNIPPET)
    if how == "script":
        p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    else:
        p = subprocess.run([sys.executable], input=SNIPPET, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr
    assert 0.9 < float(p.stdout.split("order")[1]) < 1.1


def _children(pid):
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = open(f"/proc/{pid}/stat").read().split()[2] if os.path.exists(f"/proc/{pid}/stat") else "X"
    return stat != "Z"


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_workers_exit_when_the_study_is_killed(tmp_path, sig):
    """Killing the `workbench study` process (plain kill or kill -9) leaves no worker running: the workers exit with it
    (the kernel's parent-death signal, set before their imports), waited for with a hang guard only (a loaded
    machine gave a 10 s margin too little)."""
    cmd = [sys.executable, "-m", "workbench.cli", "study", "tp2", "--k", "0.0001", "0.00005", "--reference", "ode",
           "--workers", "2", "--no-progress", "-o", str(tmp_path / "k.nc")]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    workers = []
    while time.time() < deadline and len(workers) < 2:
        time.sleep(0.1)
        workers = _children(proc.pid)
    assert len(workers) == 2
    os.kill(proc.pid, sig)
    proc.wait()
    deadline = time.time() + 300
    while time.time() < deadline and any(_alive(w) for w in workers):
        time.sleep(0.1)
    assert not any(_alive(w) for w in workers)


@pytest.mark.slow
def test_single_case_study_is_refused():
    """reference = 'finest' with one case: nothing to compare; refused before any work (it exited 0 with NaN). With
    the default reference a single rod case is compared with the rod's own (exact) reference."""
    with pytest.raises(workbench.ParameterError, match="single case"):
        Study("tp1", k=[0.01], reference="finest")
    p = _cli("study", "tp1", "--k", "0.01", "--reference", "finest")
    assert p.returncode == 2 and p.stderr.startswith("error:")
    assert Study("tp1", k=[0.01]).reference.kind == "solution"


def test_study_axis_values_are_checked():
    """k='0.1' (text) was read character by character; a study option out of range fails before any work."""
    with pytest.raises(workbench.ParameterError, match="k = '0.1'"):
        Study("tp1", k="0.1")
    with pytest.raises(workbench.ParameterError, match="n_compare"):
        Study("tp1", k=[0.02, 0.01], reference="ode", n_compare=0)
    with pytest.raises(workbench.ParameterError, match="workers"):
        Study("tp1", k=[0.02, 0.01], reference="ode", workers=-1)
    # a value twice (k = [0.1, 0.1]) made a second case of NaN errors and a k index that selects two
    with pytest.raises(workbench.ParameterError, match=r"^k: 0.1 is given twice; give each value once"):
        Study("tp1", h=0.1, k=[0.1, 0.1])
    with pytest.raises(workbench.ParameterError, match=r"^c_nu: 1.0 is given twice"):
        Study("tp1", k=[0.1, 0.05], sweep={"c_nu": [1, 1.0]})


@pytest.mark.parametrize("reference, ks", [("exact", [0.1, 0.05]), ("extrapolated", [0.1, 0.05, 0.025])])
def test_every_coordinate_of_a_study_has_units_and_a_long_name(tmp_path, reference, ks):
    """As a run's archive has them (CF): order, scheme, probe, probe_x, norm, along and a swept parameter's axis had
    none; a swept parameter's come from the parameter table. Kept through the archive. (The extrapolated reference
    fits the orders again, and its norm and along had lost theirs.)"""
    ds = Study("tp1", k=ks, sweep={"gamma_nu": [0.1, 0.2]}, reference=reference, workers=0).run(progress=False)
    back = workbench.load(workbench.write(ds, tmp_path / "s.nc"))
    for name, coord in back.coords.items():
        assert coord.attrs.get("long_name") and "units" in coord.attrs, name
    assert back.gamma_nu.attrs["units"] == "Pa/m" and back.probe_x.attrs["units"] == "m"


def test_a_reference_coarser_than_the_cases_is_warned_about():
    """reference={"k": 0.05} for cases of k = 0.02 and 0.01: the errors grew as k fell and the fitted order was
    -0.41, without a word. A warning names the coarser value and the cases' finest; a finer reference says nothing."""
    with pytest.warns(RuntimeWarning, match=r"reference: k = 0.05 \(the cases' finest: 0.01\) is coarser than"):
        Study("tp1", h=0.1, k=[0.02, 0.01], T=0.1, reference={"k": 0.05}, workers=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Study("tp1", h=0.1, k=[0.02, 0.01], T=0.1, reference={"k": 0.005}, workers=0)


def test_the_horizon_T_is_not_a_sweep_axis():
    """Swept, T's cases were all compared on [0, the scene's T]: the T = 2 cases of a rod gave the T = 1 errors
    exactly, and a T below the scene's was refused for snapshots the user never set. T is refused as an axis (sweep,
    couple, grids; the command line's --sweep), by name, before any work."""
    for kwargs in (dict(sweep={"T": [1.0, 2.0]}), dict(couple={"T": lambda v: 10 * v["k"]}),
                   dict(grids=[{"k": [0.04, 0.02], "T": [1.0]}])):
        with pytest.raises(workbench.ParameterError, match=r"T is the time every case is compared to"):
            Study("rod", **({"k": [0.04, 0.02]} if "grids" not in kwargs else {}), **kwargs)
    p = _cli("study", "rod", "--k", "0.04", "0.02", "--sweep", "T=0.5,1", "--workers", "0")
    assert p.returncode == 2 and p.stderr.startswith("error: sweep: T is the time every case"), p.stderr


@pytest.mark.slow
def test_study_set_of_a_swept_name():
    """`--set h=...` in a study was dropped silently: it is the scene value (honoured) unless --h sweeps it too."""
    p = _cli("study", "tp2", "--k", "0.02", "0.01", "--set", "k=0.01", "--reference", "ode", "--workers", "0")
    assert p.returncode == 2 and "k is given twice" in p.stderr
    st = Study("tp5", k=[0.02, 0.01], T=0.04, h=None, reference={"k": 0.005}, workers=0, **{"order": 1})
    assert st.hs == [0.0125]


def test_sweep_any_parameter_with_its_own_reference():
    """A physical parameter as an axis: each c_nu value gets its own reference run (not the finest of another c_nu);
    orders are fitted per c_nu."""
    st = Study("tp5", h=[0.05, 0.025], sweep={"c_nu": [1.0, 5.0]}, reference={"h": 0.0125}, k=[0.01], T=0.1,
               n_compare=2, workers=0)
    assert len(st.reference.cases()) == 2
    ds = st.run(progress=False)
    assert ds.error.dims == ("h", "k", "order", "scheme", "c_nu")
    assert np.isfinite(ds.error.values).all() and (ds.error.sel(h=0.025) < ds.error.sel(h=0.05)).all()
    assert ds.observed_order.sel(norm="error", along="h").dims == ("order", "scheme", "c_nu")


@pytest.mark.slow
def test_tolerance_sweep_of_error_controlled_runs(tmp_path):
    """An rtol axis: error-controlled runs have no fixed grid, so they are recorded and compared at the common
    comparison times (which the controller lands on); the achieved error falls with the tolerance and stays
    within a decade of it, BDF2 below backward Euler; the tolerance plot is drawn."""
    from workbench import plotting

    st = Study("tp1", sweep={"rtol": [1e-2, 1e-4]}, scheme=["implicit", "bdf2"], reference="exact", workers=0)
    ds = st.run(progress=False)
    err = ds.error.squeeze()
    assert err.dims == ("scheme", "rtol") and np.isfinite(err.values).all()
    assert (err.sel(rtol=1e-4) < err.sel(rtol=1e-2)).all()
    assert (err < 10 * err.rtol).all() and (err.sel(scheme="bdf2") < err.sel(scheme="implicit")).all()
    assert (ds.nsteps.squeeze().sel(rtol=1e-4) > ds.nsteps.squeeze().sel(rtol=1e-2)).all()
    plotting.tolerance(ds, tmp_path / "tol.png")
    assert os.path.getsize(tmp_path / "tol.png") > 10_000
    # (the command line's --plot draws convergence: for tolerances alone it is the tolerance plot; with k swept too
    # the fitted order, which has no rtol axis, was selected at each rtol: KeyError)
    plotting.convergence(ds, tmp_path / "conv.png")
    assert os.path.getsize(tmp_path / "conv.png") > 10_000
    both = Study("tp1", k=[0.1, 0.05], sweep={"rtol": [1e-2, 1e-4]}, scheme="bdf2", reference="exact", workers=0)
    plotting.convergence(both.run(progress=False), tmp_path / "both.png")
    assert os.path.getsize(tmp_path / "both.png") > 10_000


def test_errors_at_round_off_get_no_order_and_are_said():
    """tp1's stress and bonding are exact to round-off under both implicit schemes (errors 1e-16..1e-15); their
    fitted orders were -1.2 and -0.3 along k, printed beside the real ones. They are NaN now, with a warning naming
    them, while the displacement's order is fitted as before; the reference's norms are in the Dataset."""
    st = Study("tp1", h=0.1, k=[0.1, 0.05, 0.025], scheme=["implicit", "bdf2"], reference="exact", workers=0)
    with pytest.warns(RuntimeWarning, match=r"errors at round-off, at most 1e-11 of the reference's norm: error_Q "
                                            r"\(6 cases\), error_beta \(6 cases\), error_beta_end \(6 cases\)"):
        ds = st.run(progress=False)
    assert (ds.error_Q < 1e-12 * ds.reference_norm_Q).all() and (ds.reference_norm_Q > 0).all()
    order = ds.observed_order.sel(along="k").squeeze()
    assert np.isnan(order.sel(norm=["error_Q", "error_beta"])).all()
    assert 0.8 < float(order.sel(norm="error_V", scheme="implicit")) < 1.2
    assert 1.6 < float(order.sel(norm="error_V", scheme="bdf2")) < 2.2
    for name in ("reference_norm_V", "reference_norm_Q", "reference_norm_beta"):
        assert ds[name].attrs["units"] and ds[name].attrs["long_name"].startswith("max over compared times")


def test_the_command_line_says_what_an_order_along_rtol_is():
    """The orders printed along an rtol axis read as orders of the scheme; the command says that along rtol it is the
    error's slope against the tolerance. A sweep without rtol does not say it."""
    p = _cli("study", "tp1", "--sweep", "rtol=1e-2,1e-4", "--scheme", "implicit", "--reference", "exact", "--workers",
             "0", "--no-progress")
    assert p.returncode == 0, p.stderr
    assert "observed order of error: {'rtol': [" in p.stdout and "(along rtol: the slope of the error against the " \
        "tolerance" in p.stdout, p.stdout
    p = _cli("study", "tp1", "--k", "0.1", "0.05", "--reference", "exact", "--workers", "0", "--no-progress")
    assert p.returncode == 0 and "observed order of error: {'k': [" in p.stdout and "along rtol" not in p.stdout


def test_a_study_option_given_by_set_is_refused_naming_its_option(capsys):
    """``workbench study ... --set reference=finest`` (or workers, n_compare, ...) ended in a TypeError traceback
    (the value passed twice); ``--set order=2`` was refused with an example of a list of element sizes. Each is one
    error line naming the command's option that gives it, exit 2."""
    from workbench.cli import main

    for item, said in (("reference=finest", "give --reference"), ("n_compare=3", "give --compare"),
                       ("client=x", "give --scheduler"), ("couple=x", "give it to Study(...) in Python"),
                       ("order=2", "order is an axis of the study; give --order 2")):
        assert main(["study", "tp1", "--k", "0.1", "0.05", "--set", item, "--no-progress"]) == 2
        assert re.match(re.escape(f"error: --set {item}: ") + ".*" + re.escape(said), capsys.readouterr().err)
    p = _cli("study", "tp1", "--k", "0.1", "0.05", "--set", "workers=0", "--no-progress")
    assert p.returncode == 2 and p.stderr.startswith("error: --set workers=0: ") and "Traceback" not in p.stderr


def test_study_whose_first_case_is_refused():
    """The largest k above the explicit scheme's k_crit (0.0455 for the springs a step of 0.1 presses in on tp5 at
    h = 0.05) is refused; the study still evaluates (its probe coordinates came from the first case's Dataset, empty
    when refused: KeyError 'probe_x')."""
    st = Study("tp5", k=[0.1, 0.001], h=[0.05], scheme="explicit", reference={"k": 0.0005}, T=0.1, workers=0)
    ds = st.run(progress=False)
    status = ds.status.squeeze()
    assert status.sel(k=0.1) == "refused" and status.sel(k=0.001) == "complete"
    assert np.isnan(ds.error.sel(k=0.1)).all() and np.isfinite(ds.error.sel(k=0.001)).all()
    np.testing.assert_array_equal(ds.probe_x.values, [p[0] for p in workbench.scene("tp5")["probes"]])


def test_k_over_h_does_not_rebuild_the_scene(monkeypatch):
    """Study.__init__ rebuilt the already checked scene for nothing when k_over_h was given (an unused
    ``ratio = self.scene.with_()``): no call of Scene.with_ without overrides."""
    from workbench.input.scenes import Scene

    calls, real = [], Scene.with_

    def spy(self, **overrides):
        calls.append(overrides)
        return real(self, **overrides)

    monkeypatch.setattr(Scene, "with_", spy)
    st = Study("tp5", h=[0.05, 0.025], k_over_h=0.2, T=0.1, workers=0)
    assert [c.k for c in st.cases] == [0.01, 0.005]  # (0.2 h to 12 digits)
    assert calls and {} not in calls


@pytest.mark.slow
def test_couple_any_pair_of_axes():
    """A coupling of any parameter to any axis, not only k = C h (it was "must depend on h only"): gamma_nu = 0.1 c_nu
    makes c_nu and gamma_nu the coordinates of ``level`` (not a refinement series: orders are fitted along h, per
    level); h = 5 k makes k the driver of a refinement series (orders along k, h and h + k)."""
    st = Study("tp5", h=[0.05, 0.025], sweep={"c_nu": [1.0, 5.0]}, couple={"gamma_nu": lambda c: 0.1 * c["c_nu"]},
               k=[0.01], T=0.05, reference={"h": 0.0125}, n_compare=2, workers=0)
    ds = st.run(progress=False)
    assert ds.error.dims == ("level", "h", "k", "order", "scheme")
    assert ds.c_nu.values.tolist() == [1.0, 5.0] and ds.gamma_nu.values.tolist() == pytest.approx([0.1, 0.5])
    assert np.isfinite(ds.error.values).all() and (ds.error.sel(h=0.025) < ds.error.sel(h=0.05)).all()
    assert np.isfinite(ds.observed_order.sel(norm="error", along="h").values).all()
    st = Study("tp5", k=[0.02, 0.01], couple={"h": lambda c: 5 * c["k"]}, T=0.05, reference={"k": 0.005, "h": 0.025},
               n_compare=2, workers=0)
    assert st.layout.driver == "k" and [c.h for c in st.cases] == [0.1, 0.05]
    ds = st.run(progress=False)
    assert ds.error.dims == ("level", "order", "scheme") and ds.h.dims == ("level",)
    assert np.isfinite(ds.observed_order.sel(norm="error", along="h+k").values).all()
    with pytest.raises(workbench.ParameterError, match="must each be a function of one swept axis"):
        Study("tp5", h=[0.05, 0.025], order=[1, 2], couple={"k": lambda c: 0.2 * c["h"] / c["order"]}, T=0.1)


def test_overrides_are_checked_with_the_swept_values():
    """``Study("tp1", k=[1e-6], T=1e-3)`` was refused for the preset's k = 0.01 > T, a value no case uses: the
    overrides are checked with the axes applied, so the answer is the study's own (one case: nothing to compare), and
    two steps below T run. Overrides that no case can fix are still refused, naming the parameter, before any work."""
    with pytest.raises(workbench.ParameterError, match="single case"):
        Study("tp1", k=[1e-6], T=1e-3, reference="finest")
    ds = Study("tp1", k=[1e-5, 5e-6], T=1e-3, reference="ode", workers=0).run(progress=False)
    assert (ds.complete == 1).all() and np.isfinite(ds.error.values).all()
    st = Study("tp5", h=[0.05, 0.025], k_over_h=0.002, T=1e-3, reference={"h": 0.0125}, workers=0)
    assert [c.k for c in st.cases] == pytest.approx([1e-4, 5e-5])
    with pytest.raises(workbench.ParameterError, match="T = -1"):
        Study("tp1", k=[1e-5, 5e-6], T=-1)
    with pytest.raises(workbench.ParameterError, match="k = 0.1 is larger than T"):
        Study("tp1", k=[0.1, 0.05], T=0.01, reference="ode")


def test_case_history_abbreviates_long_record_times(tmp_path):
    """Each case archive's ``history`` is the call that made it; its record_times (501 here, thousands in fine
    sweeps) were written out in full (10 kB of ``np.float64(...)``): now the ends and the count."""
    Study("tp1", k=[0.002, 0.001], reference="ode", workers=0).run(tmp_path, progress=False)
    for path in sorted(tmp_path.glob("*.nc")):
        history = workbench.load(path).attrs["history"]
        # (the case's Scene is written as the call that makes it, with its values, snapshots abbreviated too)
        assert len(history) < 300 and "record_times=[0.0, 0.002, 0.004, ..., 0.998, 1.0] (501 values)" in history
        assert "snapshots=[0.1, 0.2, 0.3, ..., 0.9, 1.0] (10 values)" in history


@pytest.mark.slow
def test_case_files_are_keyed_by_scheme_options_and_versions(tmp_path):
    """A scheme option (here the tolerance of error-controlled steps, and the memory rule of Model B) and the
    package versions are inputs of a case too: a case file made otherwise is recomputed, and the reason names it."""
    import json
    import warnings

    from workbench.study.cases import read_case

    for scene, first, second in (("tp1", {"rtol": 1e-2, "scheme": "bdf2"}, {"rtol": 1e-3, "scheme": "bdf2"}),
                                 ("memory_rod", {"memory_rule": "rectangle"}, {"memory_rule": "trapezoid"})):
        folder = tmp_path / scene
        Study(scene, k=[0.04, 0.02], reference="ode" if scene != "tp1" else "exact", workers=0,
              **first).run(folder, progress=False)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            Study(scene, k=[0.04, 0.02], reference="ode" if scene != "tp1" else "exact", workers=0,
                  **second).run(folder, progress=False)
        said = " ".join(str(w.message) for w in caught)
        name, value = next(iter(second.items()))  # (the first entry is the one that differs)
        assert "recomputing" in said and f"{name} " in said and str(value) in said, said
    path = sorted((tmp_path / "tp1").glob("*.nc"))[0]
    expected = json.loads(workbench.load(path).attrs["case_inputs"])
    assert read_case(path, expected)[0] is not None
    other = dict(expected, workbench="0.0.0+other")
    ds, reason = read_case(path, other)
    assert ds is None and "workbench" in reason and "0.0.0+other" in reason


def test_cases_and_restarts_know_the_code_that_made_them(tmp_path, monkeypatch):
    """The version number is the same between releases, so after a change to the code a resumed study reused the
    cases of the code before without a word (tp1's order 1.007 from reused cases against -0.033 from the changed
    code's, an outside pass), and a restart went on across the change. The digest of the package's source is now an
    input of every case and an attribute of every run: a case made by other code is recomputed, naming it, and a
    restart across it is warned about."""
    import warnings

    from workbench.output import results

    study = dict(k=[0.1, 0.05], reference="exact", workers=0, T=0.2)
    Study("tp1", **study).run(tmp_path / "cases", progress=False)
    ds = workbench.run("tp1", h=0.1, k=0.05, T=0.2, progress=False)
    assert ds.attrs["version_workbench_code"] == results.code_digest() and len(results.code_digest()) == 16
    workbench.write(ds, tmp_path / "a.nc")
    other = dict(results.versions(), version_workbench_code="0123456789abcdef")
    monkeypatch.setattr(results, "versions", lambda: other)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        Study("tp1", **study).run(tmp_path / "cases", progress=False)
    said = " ".join(str(w.message) for w in caught)
    assert said.count("recomputing") >= 1 and "workbench_code" in said and "0123456789abcdef" in said, said
    with pytest.warns(RuntimeWarning, match="workbench_code .* -> 0123456789abcdef"):
        workbench.run(restart=tmp_path / "a.nc", T=0.3, progress=False)


def test_a_reference_run_takes_the_most_accurate_value_of_what_the_cases_differ_in():
    """The reference run took every option it left open from the first case: a memory_rule sweep listed rectangle
    first compared both rules with a rectangle-rule run (the trapezoid's order 1.09; 1.79 listed the other way), an
    h_contact sweep with its coarsest contact mesh. It takes the trapezoid rule, the kernel by quadrature and the
    smallest h_contact now, in either order; an option without such an order (the contact solver) is the first
    case's, and said."""
    for rules in (["rectangle", "trapezoid"], ["trapezoid", "rectangle"]):
        st = Study("memory_slab", h=0.25, k=[0.1, 0.05], T=0.2, sweep={"memory_rule": rules}, reference={"k": 0.01},
                   workers=0)
        (ref,) = st.reference.cases()
        assert ref["memory_rule"] == "trapezoid" and ref.k == 0.01
        assert st.reference.describe().endswith('the most accurate: {"memory_rule": "trapezoid"}')
    st = Study("memory_hertz", h=0.5, k=0.25, T=0.5, sweep={"h_contact": [0.04, 0.02]}, reference={"k": 0.125},
               workers=0)
    assert st.reference.cases()[0]["h_contact"] == 0.02
    st = Study("memory_rod", k=[0.1, 0.05], T=0.2, kernel="exp(-t/0.2)", kernel_E=0.5, prony=(),
               reference={"k": 0.01}, sweep={"kernel_approximation": ["exponentials", "quadrature"]}, workers=0)
    assert st.reference.cases()[0]["kernel_approximation"] == "quadrature"
    with pytest.warns(RuntimeWarning, match=r"the cases differ in contact_solver \(the reference takes 'condensed'\)"):
        Study("memory_slab", h=0.25, k=[0.1, 0.05], T=0.2, sweep={"contact_solver": ["condensed", "coupled"]},
              reference={"k": 0.01}, workers=0)


def test_an_extrapolated_reference_that_gives_no_estimate_says_so():
    """Model B's trapezoid rule at rtol 1e-2 and 1e-3 takes nearly the same steps: the differences between levels
    rise, the extrapolation gives no estimate, and the study returned NaN errors and an empty plot without a word.
    It warns now, naming the differences and a finer run to give instead; a series that converges does not warn."""
    with pytest.warns(RuntimeWarning, match=r"no error estimate for 1 series: the differences between their levels "
                                            r"of rtol do not fall \(.*\{'rtol': 1e-05\} or 'finest'"):
        ds = Study("memory_slab", h=0.25, T=0.3, memory_rule="trapezoid", sweep={"rtol": [1e-2, 1e-3, 1e-4]},
                   workers=0).run(progress=False)
    assert np.isnan(ds.error.values).all() and (ds.complete == 1).all()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        ds = Study("tp1", h=0.25, k=[0.04, 0.02, 0.01], T=0.4, reference="extrapolated", workers=0).run(progress=False)
    assert np.isfinite(ds.error.values).all()


def test_a_finer_run_reference_of_a_tolerance_sweep_takes_fixed_steps():
    """reference={"k": ...} in an rtol sweep is a fixed-step run at that k (it took the first case's tolerance, so
    every case was compared with an error-controlled run of rtol 1e-2)."""
    st = Study("tp5", h=[0.1], k=[0.02], sweep={"rtol": [1e-2, 1e-3]}, scheme="bdf2", reference={"k": 0.001}, T=0.1,
               workers=0)
    (ref,) = st.reference.cases()
    assert ref.values()["rtol"] == 0.0 and ref.k == 0.001
    assert Study("tp5", h=[0.1], k=[0.02], sweep={"rtol": [1e-2]}, scheme=["bdf2", "implicit"],
                 reference={"k": 0.001, "rtol": 1e-6}, T=0.1, workers=0).reference.cases()[0].values()["rtol"] == 1e-6


@pytest.mark.slow
def test_a_longer_T_continues_the_archived_cases(tmp_path):
    """A sweep run again with T doubled continues every archived case (the 2D slab with bonding, its finer-run
    reference too) from its final state instead of from t = 0: the errors and records equal those of a sweep run
    straight to the new T (to round-off), and the cost of the result covers both parts. A T whose comparison
    times the archives do not hold, an error-controlled case and ``extend=False`` are recomputed, saying why."""
    kw = dict(h=[0.05], k=[0.02, 0.01], reference={"k": 0.005}, workers=0, n_compare=4)
    cases = tmp_path / "cases"
    short = Study("tp5", T=0.1, **kw)
    short.run(cases, progress=False)
    long = Study("tp5", T=0.2, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # continuing says nothing
        extended = long.run(cases, progress=False)
    assert long.overhead["extended_cases"] == 3 and long.overhead["new_cases"] == 0
    straight = Study("tp5", T=0.2, **kw).run(tmp_path / "straight", progress=False)
    for name in ("error", "error_probe", "error_beta", "nsteps"):
        np.testing.assert_allclose(extended[name].values, straight[name].values, rtol=1e-10, atol=0)
    assert extended.nsteps.values.ravel().tolist() == [10, 20]
    one = workbench.load(next(cases.glob("h0.05_k0.01*.nc")))
    assert one.attrs["case_extended_from_T"] == 0.1 and one.attrs["restart_time"] == 0.1
    # (the comparison times: 4 equal parts of the common grid of k = 0.02; those up to 0.1 were T = 0.1's too)
    np.testing.assert_allclose(one.snapshot_time, [0.04, 0.1, 0.16, 0.2], rtol=1e-12)
    assert one.sizes["time"] == 11 and one.attrs["wall_time"] > 0
    # the same archive run again: read, not continued again
    again = Study("tp5", T=0.2, **kw)
    again.run(cases, progress=False)
    assert again.overhead["extended_cases"] == 0 and again.overhead["new_cases"] == 0
    # T = 0.3 puts the comparison times at 0.08, 0.16, 0.22, 0.3: the archives have no field at 0.08
    with pytest.warns(RuntimeWarning, match=r"no field at the comparison time.*recomputing") as record:
        odd = Study("tp5", T=0.3, **kw)
        odd.run(cases, progress=False)
    assert odd.overhead["new_cases"] == 3 and len([w for w in record if "recomputing" in str(w.message)]) == 3
    with pytest.warns(RuntimeWarning, match="T 0.3 -> 0.6.*recomputing"):
        off = Study("tp5", T=0.6, **kw)
        off.run(cases, progress=False, extend=False)
    assert off.overhead["new_cases"] == 3 and off.overhead["extended_cases"] == 0


@pytest.mark.slow
def test_an_error_controlled_case_is_not_extended(tmp_path):
    kw = dict(sweep={"rtol": [1e-2, 1e-3]}, scheme="implicit", reference="exact", workers=0)
    Study("tp1", T=0.5, **kw).run(tmp_path, progress=False)
    with pytest.warns(RuntimeWarning, match="error-controlled case is not continued.*recomputing"):
        st = Study("tp1", T=1.0, **kw)
        st.run(tmp_path, progress=False)
    assert st.overhead["new_cases"] == 2


@pytest.mark.slow
@pytest.mark.parametrize("scheme, order", [("implicit", 1.0), ("bdf2", 2.0)])
def test_default_orders_are_unbiased(scheme, order):
    """A Study without a named reference (the README's way): on tp1 the rod's exact reference, orders within 0.1 of
    the scheme's (the finest case as reference fitted 1.40 for backward Euler); the extrapolated reference (each case
    against the next finer one, Richardson) gives the same order within 0.1 and errors within 25 % of the exact ones
    (the finest case's extrapolated too), where comparing with the finest case overestimates the order. Model B with
    the trapezoid memory rule (the memory rod, its Volterra reference) fits >= 1.8."""
    ks = [0.02, 0.01, 0.005, 0.0025]  # (the README's)
    exact = Study("tp1", k=ks, scheme=scheme, workers=0).run(progress=False)
    assert exact.attrs["reference"].startswith("auto: the scene's own reference")
    p = float(exact.observed_order.sel(norm="error", along="k").squeeze())
    assert abs(p - order) <= 0.1, p
    extrapolated = Study("tp1", k=ks, scheme=scheme, workers=0, reference="extrapolated").run(progress=False)
    q = float(extrapolated.observed_order.sel(norm="error", along="k").squeeze())
    assert abs(q - order) <= 0.1, q
    ratio = extrapolated.error.values.ravel() / exact.error.values.ravel()
    assert np.all(np.abs(ratio - 1) < 0.25), ratio
    if scheme == "bdf2":  # Model B with the trapezoid memory rule, through all four contact states, the same way
        memory = Study("memory_rod", k=ks, memory_rule="trapezoid", workers=0).run(progress=False)
        assert memory.attrs["reference"].startswith("auto: the scene's own reference")
        assert float(memory.observed_order.sel(norm="error", along="k").squeeze()) >= 1.8  # (measured: 1.95)
    finest = Study("tp1", k=ks, scheme=scheme, workers=0, reference="finest").run(progress=False)
    biased = float(finest.observed_order.sel(norm="error", along="k").squeeze())
    assert biased > p + 0.1, (biased, p)  # (the bias the default removes)


def test_the_extrapolated_reference_on_unequal_refinement_ratios(tmp_path):
    """Found by an outside pass on tp1 (backward Euler), whose exact reference is the independent check: levels
    refined by unequal ratios (k = 0.1, 0.07, 0.05) got order 1.83 from the extrapolated reference, against the exact
    0.97, and errors 0.37-0.66 of the exact ones: the order was the slope of log d_i alone (right for one ratio
    throughout only), against the k asked for, not the step taken (0.0667 for 0.07). Now d_i = C x_i^p (1 - r_i^p)
    is fitted, against the steps taken (``k_step``): within 0.05 and 5 % (measured 0.944 against 0.971, 2-4 %).
    Also: the finest case's extrapolated error is no datum of the fit (three levels gave a standard error of 3e-15
    from two differences; now NaN, and four levels get the three differences' own); and a plot of a study whose
    reference gave no errors is written, saying so (it raised ValueError, and ``--plot`` ended in a traceback)."""
    from workbench import plotting

    ks = [0.1, 0.07, 0.05]
    exact = Study("tp1", k=ks, scheme="implicit", reference="exact", workers=0).run(progress=False)
    ds = Study("tp1", k=ks, scheme="implicit", reference="extrapolated", workers=0).run(progress=False)
    np.testing.assert_allclose(ds.k_step.values, [0.1, 1 / 15, 0.05])
    p, q = (float(d.observed_order.sel(norm="error", along="k").squeeze()) for d in (ds, exact))
    assert abs(p - q) <= 0.05 and abs(q - 1.0) <= 0.05, (p, q)
    np.testing.assert_allclose(ds.error.values.ravel(), exact.error.values.ravel(), rtol=0.05)
    assert np.isnan(ds.observed_order_stderr.sel(norm="error", along="k")).all()  # (two differences: no spread)
    four = Study("tp1", k=[0.04, 0.02, 0.01, 0.005], scheme="implicit", reference="extrapolated",
                 workers=0).run(progress=False)
    e = four.error.values.ravel()
    own = fit_order([0.04, 0.02, 0.01], e[:3])  # (the three errors measured from differences)
    got = four.observed_order_stderr.sel(norm="error", along="k").item()
    assert np.isfinite(got) and got > 1e-6 and got == pytest.approx(own[1], rel=1e-6)
    ds["error"][:] = np.nan
    for name in ("error_V", "error_Q", "error_beta"):
        ds[name][:] = np.nan
    plotting.convergence(ds, tmp_path / "none.png")
    assert (tmp_path / "none.png").stat().st_size > 0


@pytest.mark.parametrize("scheme", ["implicit", "bdf2"])
def test_a_stress_exact_to_round_off_gets_no_order(scheme):
    """tp1's stress is exact under the implicit schemes; at k = 0.04 ... 0.005 its error sat at 0.98-1.16e-12 of its
    norm, just above the old 1e-12 cut, and got orders of 0.06 and -0.04 (found by an outside pass)."""
    with pytest.warns(RuntimeWarning, match="round-off"):
        ds = Study("tp1", k=[0.04, 0.02, 0.01, 0.005], scheme=scheme, workers=0).run(progress=False)
    assert np.isnan(ds.observed_order.sel(norm="error_Q", along="k")).all()
    assert float((ds.error_Q / ds.reference_norm_Q).max()) < 1e-11
    assert np.isfinite(ds.observed_order.sel(norm="error_V", along="k")).all()


def test_grids_that_share_too_few_times_are_compared_at_their_own_or_refused():
    """Found by an outside pass: fields are compared where every case's grid has a point, and memory_rod at k = 0.08,
    0.04, 0.02 (13 steps of 0.0769 s beside 25 and 50) shared t = 1 alone; its errors came out 1.7e-5, 4.5e-7,
    1.5e-6 (the same k = 0.04 case: 1.3e-3 compared at ten times) and the order 1.75 for a first-order rule, without
    a word. Against a solution (the rod's Volterra one here), known at any time, each case is now compared at its own
    grid's points nearest the ten times: the k = 0.04 case's error is the one the nested sweep gives, and the order
    is the rule's. Against a run (the extrapolated reference, a finer run), such a sweep is refused before any work,
    naming the grids; n_compare = 1 asks for that time alone, and grids that nest, or unequal ones sharing enough
    points (0.1, 0.07, 0.05: five), are taken."""
    odd = Study("memory_rod", k=[0.08, 0.04, 0.02], workers=0).run(progress=False)
    nested = Study("memory_rod", k=[0.04, 0.02, 0.01], workers=0).run(progress=False)
    assert odd.sizes["compare"] == 10 and "its own grid's points" in odd.compare_time.attrs["long_name"]
    assert float(odd.error.sel(k=0.04).squeeze()) == pytest.approx(float(nested.error.sel(k=0.04).squeeze()),
                                                                   rel=1e-9)
    assert abs(float(odd.observed_order.sel(norm="error", along="k").squeeze()) - 1.0) < 0.1
    with pytest.raises(workbench.ParameterError, match=r"share 1 time to compare fields at \(t = 0.3\), of n_compare = "
                                                       r"10 asked for \(k = 0.08: 4 steps of 0.075 s"):
        Study("tp5", h=0.1, k=[0.08, 0.04, 0.02], T=0.3, workers=0)
    Study("tp5", h=0.1, k=[0.08, 0.04, 0.02], T=0.3, n_compare=1, workers=0)
    Study("tp1", k=[0.1, 0.07, 0.05], reference="extrapolated", workers=0)
    with pytest.raises(workbench.ParameterError, match="share 2 times"):  # (a finer run off the cases' grids)
        Study("tp5", h=0.1, k=[0.01, 0.005], T=0.3, reference={"k": 7e-5}, workers=0)
    p = _cli("study", "tp5", "--h", "0.1", "--k", "0.08", "0.04", "0.02", "--set", "T=0.3", "--workers", "0",
             "--no-progress")
    assert p.returncode == 2 and "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr

def test_a_case_too_large_for_the_machine_is_refused_before_any_case_runs(tmp_path):
    """A P2 block at a tiny h was accepted by a Study, its case to be refused in its worker after the others had run
    (found by an outside pass); the sweep is refused before any case runs, naming the case."""
    st = Study("block", h=[0.25, 0.002], order=2, k=0.005, T=0.01, workers=0)
    with pytest.raises(workbench.ParameterError, match=r"study case h = 0.002, order = 2, k = 0.005: h = 0.002 "
                                                       r"\(order 2\) gives about .* displacement dofs"):
        st.run(tmp_path, progress=False)
    assert not list(tmp_path.glob("*.nc"))


def test_h_contact_zero_in_a_sweep_is_refused():
    """h_contact = 0 stands for h / 10; in a sweep it was sorted as the finest value, so the coarsest mesh became the
    reference and every order NaN (found by an outside pass). Refused, naming the value."""
    with pytest.raises(workbench.ParameterError, match=r"0 stands for h / 10 and would be taken for the finest"):
        Study("memory_hertz", h=0.1, sweep={"h_contact": [0.0, 0.005, 0.0025]}, workers=0)


def test_coupled_steps_have_plain_names():
    """k = 0.2 h made k = 0.005000000000000001 at h = 0.025, in the case's file name (found by an outside pass)."""
    st = Study("tp5", h=[0.05, 0.025, 0.0125], k_over_h=0.2, T=0.3, workers=0)
    assert [c.key for c in st.cases] == ["h0.05_p1_explicit_k0.01", "h0.025_p1_explicit_k0.005",
                                         "h0.0125_p1_explicit_k0.0025"]


def test_a_study_without_a_folder_leaves_none(tmp_path, monkeypatch):
    """A study run without an archive folder left its cases in a new /tmp/workbench-study-* folder on every call, never
    removed nor named (1495 of them, 1.4 GB, found by an outside pass); it is removed when the study is done."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # (this test's own temporary folder: others run beside)
    # a study killed (SIGTERM, kill -9) still leaves its folder: the next one removes those whose process is gone
    dead = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True).stdout)
    folders = {name: tmp_path / name for name in (f"workbench-study-{dead}-ab12", f"workbench-study-{os.getppid()}-cd",
                                                   "workbench-study-old_name", "workbench-study-new_name")}
    for folder in folders.values():
        folder.mkdir()
        (folder / "case.nc").write_bytes(b"x")
    os.utime(folders["workbench-study-old_name"], (time.time() - 2 * 86400,) * 2)
    # a study's lock tells more than its process number (another PID namespace sharing /tmp): one held is kept
    # whatever its name's number, one left unlocked goes
    import fcntl

    held, left = tmp_path / f"workbench-study-{dead}-held", tmp_path / f"workbench-study-{os.getppid()}-left"
    for folder in (held, left):
        folder.mkdir()
        (folder / ".alive").write_text("")
    lock = open(held / ".alive")
    fcntl.flock(lock, fcntl.LOCK_EX)
    try:
        ds = Study("tp1", k=[0.04, 0.02], workers=0).run(progress=False)
    finally:
        lock.close()
    assert np.isfinite(ds.error.values).all()
    assert sorted(p.name for p in tmp_path.glob("workbench-study-*")) == \
        sorted([f"workbench-study-{os.getppid()}-cd", "workbench-study-new_name", held.name])


def test_a_resumed_study_counts_the_time_of_the_cases_it_ran_alone(tmp_path):
    """A resumed study said "running 1 new case(s) (... summed over workers: 80.1 s)" where the new case took 39 s:
    the reused cases' time was counted too (an outside pass)."""
    Study("tp1", k=[0.1, 0.05], reference="exact", workers=0).run(tmp_path, progress=False)
    st = Study("tp1", k=[0.1, 0.05, 0.025], reference="exact", workers=0)
    ds = st.run(tmp_path, progress=False)
    new = ds.sel(k=0.025).squeeze()
    assert st.overhead["new_cases"] == 1
    assert st.overhead["cases"] == pytest.approx(float(new.wall_time) + float(new.setup_time), rel=1e-9)


def test_the_code_digest_skips_an_editors_files(tmp_path):
    """A dangling link in the package, as Emacs leaves one while a file is edited (.#cli.py), made the digest fail
    with FileNotFoundError at the end of every run: no archive (an outside pass). An editor's files are not code."""
    import shutil
    from pathlib import Path

    from workbench.output import results

    package = Path(workbench.__file__).resolve().parent
    shutil.copytree(package, tmp_path / "workbench", ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "workbench" / ".#cli.py").symlink_to("user@host.1234:1700000000")
    (tmp_path / "workbench" / ".backup.py").write_text("x = 1\n")
    p = subprocess.run([sys.executable, "-c", "from workbench.output.results import code_digest; print(code_digest())"],
                       capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(tmp_path)), cwd=tmp_path)
    assert p.returncode == 0 and p.stdout.strip() == results.code_digest(), p.stderr


_EDITED_AFTER_IMPORT = """
import sys, workbench
from workbench.output import results
clean = results.code_digest()
with open(sys.argv[1], "a") as f:
    f.write("# edited\\n")
ds = workbench.run("tp1", h=0.5, k=0.1, T=0.2, progress=False)
print(clean, ds.attrs["version_workbench_code"], results.code_digest())
"""


def test_the_code_digest_says_where_the_sources_changed_after_the_import(tmp_path):
    """The digest was read from the files on disk at the first archive: a source edited after ``import workbench``
    (a notebook across a ``git pull``) stamped the archive, and the study's case keys, with code that had not made
    it (an outside pass). Now a digest of files changed since the import ends in ``+changed``."""
    import shutil
    from pathlib import Path

    package = Path(workbench.__file__).resolve().parent
    shutil.copytree(package, tmp_path / "workbench", ignore=shutil.ignore_patterns("__pycache__"))
    edited = tmp_path / "workbench" / "schemes" / "implicit_euler.py"
    p = subprocess.run([sys.executable, "-c", _EDITED_AFTER_IMPORT, str(edited)], capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=str(tmp_path)), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    clean, archived, now = p.stdout.split()
    assert len(clean) == 16 and "+" not in clean
    assert archived == now and archived.endswith("+changed") and not archived.startswith(clean), p.stdout


def test_a_cases_warnings_are_one_line_each(tmp_path):
    """Warnings from a study's worker processes came as Python prints them, the file, line and source line around
    the message (an outside pass); they are one ``warning:`` line each, as the command line's own."""
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "study", "slab", "--h", "0.2", "0.1", "--k", "0.01",
                        "--set", "T=0.02", "--workers", "1", "--no-progress", "-o", "s.nc"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    lines = [line for line in p.stderr.splitlines() if line.strip()]
    assert any(line.startswith("warning: slab: P1 elements on a thin body") for line in lines), p.stderr
    assert all(line.startswith("warning: ") for line in lines) and "RuntimeWarning" not in p.stderr, p.stderr
