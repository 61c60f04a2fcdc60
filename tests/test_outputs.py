"""What a researcher gets out: archive metadata, defaults that are not locked, figures and exports that show what they
claim (items 16-18 of the new-user defects issue)."""
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest
import xarray as xr

import workbench
from workbench.input.parameters import PARAMETERS


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=600)


@pytest.mark.slow
def test_archive_metadata_survives_the_round_trip(tmp_path):
    """CF Conventions, the full command in history, NAME_units for every parameter attribute that has a unit,
    long_name and units on every coordinate - in the archive a CLI run writes, read back from disk."""
    out = tmp_path / "r.nc"
    p = _cli("run", "tp1", "--h", "0.1", "--k", "0.05", "--set", "T=0.2", "-o", str(out), "--no-progress")
    assert p.returncode == 0, p.stderr
    with xr.open_dataset(out) as ds:
        a = ds.attrs
        assert a["Conventions"].startswith("CF-")
        assert "workbench run tp1 --h 0.1 --k 0.05 --set T=0.2" in a["history"]
        units = {name: p.unit for name, p in PARAMETERS.items()}
        with_unit = [name for name in a if name in units and units[name]]
        assert len(with_unit) >= 10 and all(a[f"{name}_units"] == units[name] for name in with_unit)
        for name, coord in ds.coords.items():
            assert coord.attrs.get("long_name") and "units" in coord.attrs, name


def test_the_history_of_a_run_from_a_scene_object_runs_it_again():
    """``workbench.run(workbench.scene("tp1", gamma_nu=0.9), h=0.1)`` recorded ``workbench.run('tp1', h=0.1)``: its
    history named another run. The call recorded now makes the same numbers."""
    for sc, values in ((workbench.scene("tp4", gamma_nu=0.9, traction_top="(0, -2*t)"), dict(h=0.1, T=0.03)),
                       (workbench.scene("memory_rod", prony=[[0.5, 0.2], [0.1, 1.0]]), dict(h=0.1, T=0.2))):
        ds = workbench.run(sc, progress=False, **values)
        call = ds.attrs["history"].split(" ", 1)[1]
        assert call.startswith(f"workbench.run(workbench.scene('{sc.name}', "), call
        again = eval(call, {"workbench": workbench})  # noqa: S307 (the package's own record)
        assert np.array_equal(again.u_probe.values, ds.u_probe.values), call


def test_generic_block_is_not_locked_and_p1_on_a_thin_body_warns(tmp_path):
    """The generic block defaults to P2 (its P1 default was ~50 % locked); P1 asked for on a thin generic body
    warns; the paper presets keep the paper's P1 and say nothing."""
    assert workbench.scene("block")["order"] == 2
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        workbench.run("slab", order=1, h=0.1, k=0.05, T=0.05, progress=False)
    assert any("lock" in str(w.message) for w in caught)
    for name in ("tp4", "tp5"):
        assert workbench.scene(name)["order"] == 1
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            workbench.run(name, h=0.1, k=0.02, T=0.04, progress=False)
        assert not any("lock" in str(w.message) for w in caught), name
    # nor when the paper's P1 comes back from an archive (a restart gives every value explicitly)
    path = workbench.write(workbench.run("tp4", h=0.1, k=0.02, T=0.04, progress=False), tmp_path / "tp4.nc")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        workbench.run(restart=path, T=0.08, progress=False)
    assert not any("lock" in str(w.message) for w in caught)


def test_a_figure_is_written_in_the_format_its_name_asks_for(tmp_path):
    """Every figure was PNG whatever its name (a .pdf that a PDF viewer or LaTeX then refused). The suffix says the
    format now (no suffix: PNG); a suffix matplotlib does not write is refused by name, on the command line before
    the run."""
    from workbench import plotting

    ds = workbench.run("tp1", h=0.5, k=0.05, T=0.2, progress=False)
    fig = plotting.overview(ds)
    for name, head in {"a.pdf": b"%PDF", "a.svg": b"<?xml", "a": b"\x89PNG", "a.EPS": b"%!PS"}.items():
        plotting._save(fig, tmp_path / name)  # (the one figure, saved as each plot function saves it)
        assert (tmp_path / name).read_bytes().startswith(head), name
    with pytest.raises(workbench.ParameterError, match=r"path = '.*a\.docx': a figure is written as png, pdf, svg"):
        plotting.overview(ds, tmp_path / "a.docx")
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "tp1", "--h", "0.5", "--T", "0.2", "-o",
                        str(tmp_path / "r.nc"), "--plot", str(tmp_path / "r.docx"), "--no-progress"],
                       capture_output=True, text=True)
    assert p.returncode == 2 and p.stderr.startswith("error: --plot = ") and not (tmp_path / "r.nc").exists()


def test_figures_say_what_they_show(tmp_path):
    """Fields in a perceptually uniform map (not jet); the tp2 figure says that the paper's curves disagree with
    the reduced ODE; every convergence panel has a y-label with units."""
    from workbench import plotting
    from workbench.paper import figures
    from workbench.study import Study

    ds = workbench.run("tp5", h=0.1, k=0.01, T=0.1, snapshots=[0.1], progress=False)
    fig = figures.slab_von_mises(ds)
    cmaps = {im.get_cmap().name for ax in fig.axes for im in ax.collections + ax.images if im.get_array() is not None}
    assert "viridis" in cmaps and "jet" not in cmaps
    tp2 = workbench.run("tp2", h=0.1, k=0.05, progress=False)
    fig = figures.rod_displacement_evolution(tp2)
    titles = " ".join([fig._suptitle.get_text() if fig._suptitle else ""] + [ax.get_title() for ax in fig.axes])
    assert "disagree with the reduced ODE" in titles, titles
    adaptive = workbench.run("tp2", scheme="bdf2", rtol=1e-3, T=0.2, progress=False)  # (its title gave "k = 0.0908",
    title = plotting.overview(adaptive)._suptitle.get_text()  # the largest step, as if chosen: an outside pass)
    assert f"rtol = 0.001, {adaptive.attrs['accepted_steps']} steps" in title and "k = " not in title, title
    st = Study("tp1", k=[0.1, 0.05], h=[0.1], reference="exact", workers=0)
    study = st.run(progress=False)
    fig = plotting.convergence(study)
    labels = [ax.get_ylabel() for ax in fig.axes if ax.lines]
    assert labels and all("[" in y for y in labels), labels
    fig.canvas.draw()  # (k from 0.1 to 0.05, within a decade: its axis had no labelled tick at all)
    ticks = [t.get_text() for t in fig.axes[0].xaxis.get_ticklabels(which="both") if t.get_text()]
    assert any(t for t in ticks if "5" in t), ticks
    # the other kind of Dataset (or none) is a ParameterError naming the function; it was a KeyError or an
    # AttributeError from deep inside
    for draw, wrong, said in ((plotting.overview, study, "the Dataset is a study's"),
                              (plotting.convergence, tp2, "the Dataset is a run's"),
                              (plotting.pareto, tp2, "the Dataset is a run's"), (plotting.tolerance, tp2, "a run's"),
                              (plotting.overview, "tp2.nc", "give the xarray Dataset of a run, got str"),
                              (plotting.space, tp2, "the run is not adapted"),
                              (plotting.tolerance, study, "the study has no rtol axis")):
        with pytest.raises(workbench.ParameterError, match=f"^plotting.{draw.__name__}: .*{said}"):
            draw(wrong)


def test_model_b_overview_and_vtk_show_pressure_and_states(tmp_path):
    """Model B's overview shows contact pressure and states (no 'no adhesion' panel); its VTK export carries
    both as point data of the contact boundary."""
    import meshio

    from workbench import plotting
    from workbench.output import vtk

    ds = workbench.run("memory_slab", h=0.25, k=0.1, snapshots=[0.5], progress=False)
    fig = plotting.overview(ds)
    titles = " ".join(ax.get_title() for ax in fig.axes).lower()
    assert "pressure" in titles and "state" in titles and "adhesion" not in titles
    files = vtk.export(ds, tmp_path)
    mesh = meshio.read([f for f in files if str(f).endswith(".vtu")][-1])
    assert {"contact_pressure", "contact_state"} <= set(mesh.point_data)
    free = mesh.point_data["contact_state"] >= 0  # (-1: a clamped vertex, no contact unknown: NaN pressure)
    assert free.sum() >= 3 and np.isfinite(mesh.point_data["contact_pressure"][free]).all()
    assert np.isnan(mesh.point_data["contact_pressure"][~free]).all()


@pytest.mark.slow
def test_run_with_output_prints_one_status_line(tmp_path):
    """`workbench run ... -o` says what happened: status, steps and time in one line, then where it wrote."""
    p = _cli("run", "tp1", "--h", "0.1", "--k", "0.05", "-o", str(tmp_path / "r.nc"), "--no-progress")
    assert p.returncode == 0, p.stderr
    lines = [li for li in p.stdout.splitlines() if li.strip()]
    assert len(lines) == 2 and lines[1].startswith("wrote "), p.stdout
    assert lines[0].startswith("tp1: complete, 20 steps") and " s " in lines[0], p.stdout


@pytest.mark.parametrize("kw, said", [
    (dict(k=0.05), r"tp1: incomplete at t = 0\.5 of T = 0\.6 s, 10 of 12 steps of the explicit scheme"),
    (dict(scheme="implicit", rtol=1e-3, k_min=1e-4), r"tp1: incomplete at t = 0\.54\d* of T = 0\.6 s, \d+ steps of the "
                                                     r"implicit scheme"),
])
def test_the_status_line_of_a_stopped_run_says_where_it_stopped(kw, said):
    """An error-controlled run that stopped said "12292 of 12292 steps" (its steps are not planned: N of N said
    nothing). The line now says the time it reached, of T, and the steps planned only where they were. (Error control
    follows the rod end's pole to t = 0.549 s, where u passes the bound; it stopped at k_min at 0.39 s while it read
    the prescribed motion's curvature as error.)"""
    from workbench.cli import _status_line

    with pytest.raises(workbench.Diverged) as caught:
        workbench.run("tp1", h=0.25, T=0.6, delta="0.01/(t-0.55)", u0="0.01/(-0.55)", progress=False, **kw)
    assert re.match(said, _status_line(caught.value.dataset)), _status_line(caught.value.dataset)


@pytest.mark.parametrize("name, kw", [("memory_hertz3d", {}), ("slab", dict(h=0.1)), ("block", dict(h=0.1, order=1))])
def test_the_p1_strain_operator_from_the_cells_equals_the_assembled_cell_means(name, kw):
    """The P1 strain per cell from the barycentric gradients (what a P1 run's snapshots use, with no operator stored)
    against NGSolve's mixed forms integrating eps(u) over each cell."""
    from workbench.discrete import discretisation

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (P1 on the thin block)
        d = discretisation.build(workbench.scene(name, **kw))
    u = np.random.default_rng(0).standard_normal(d.ndof)
    assert d.fields._p1
    fast, assembled = d.fields.cell_strains(u), np.stack([B @ u for B in d.fields._assembled_strains()], axis=1)
    assert fast.shape == assembled.shape == (d.mesh.ne, {2: 3, 3: 6}[d.dim])
    assert np.abs(fast - assembled).max() < 1e-12 * np.abs(assembled).max()


def test_an_interrupt_inside_a_record_keeps_the_records_before(monkeypatch):
    """Found by an outside pass: Ctrl-C (or SIGTERM on the command line) landing while a record was taken, inside the
    contact pressure's evaluation, left the recorder's lists of unequal lengths; the Dataset could not be made, and
    the whole run was lost, with "its steps are kept" (1 in 12 timed interrupts on a P2 block). The record cut short
    is taken back: the records before are the Dataset, and the message names their last time."""
    from workbench.schemes.model_a import KelvinVoigtObserver

    node_values, calls = KelvinVoigtObserver.node_values, []

    def interrupted(self, t=None):
        calls.append(t)
        if len(calls) == 10:
            raise KeyboardInterrupt
        return node_values(self, t)

    monkeypatch.setattr(KelvinVoigtObserver, "node_values", interrupted)
    with pytest.raises(workbench.Interrupted, match=r"its steps to t = 0.08 s are kept") as err:
        workbench.run("tp4", h=0.1, T=0.2, progress=False)
    ds = err.value.dataset
    assert ds is not None and ds.sizes["time"] == 9 and float(ds.time[-1]) == pytest.approx(0.08)
    assert ds.attrs["status"] == "incomplete" and all(ds[n].sizes["time"] == 9 for n in ds.data_vars
                                                      if "time" in ds[n].dims)


def test_vtk_of_a_run_stopped_before_its_first_snapshot_keeps_the_exit_code(tmp_path):
    """``--vtk`` on a run that diverged before its first snapshot ended in a traceback and exit 1, after the archive
    was written (found by an outside pass): it says no VTK files were written, and the exit code is the run's (3)."""
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "tp5", "--h", "0.1", "--k", "0.1", "--set",
                        "allow_unstable=true", "--set", "snapshots=0.9", "--no-progress", "-o", str(tmp_path / "b.nc"),
                        "--vtk", str(tmp_path / "vtk")], capture_output=True, text=True)
    assert p.returncode == 3 and "Traceback" not in p.stderr, p.stderr
    assert "no VTK files written" in p.stdout and (tmp_path / "b.nc").exists()


def test_a_path_from_the_home_folder_is_the_home_folder(tmp_path, monkeypatch):
    """``workbench.write(ds, "~/x.nc")`` made a folder named ``~``, failed, and left its full-size temporary in the home
    folder, through xarray, which reads ``~`` as home (found by an outside pass); load refused the file. ``~`` is the
    home folder now, for archives, figures and loads, and nothing is left beside the file."""
    from workbench import plotting

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "home").mkdir()
    ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    written = workbench.write(ds, "~/runs/x.nc")
    assert written == tmp_path / "home" / "runs" / "x.nc" and written.is_file()
    xr.testing.assert_identical(workbench.load("~/runs/x.nc"), ds)
    plotting.overview(ds, "~/runs/x.png")
    assert sorted(p.name for p in (tmp_path / "home" / "runs").iterdir()) == ["x.nc", "x.png"]
    assert not (tmp_path / "~").exists()


def test_plotting_refuses_what_it_cannot_draw_by_name(tmp_path):
    """An outside pass: overview of a Dataset that is neither a run's nor a study's raised AttributeError, and an empty
    path an unclear OSError; both are a ParameterError naming what to give."""
    from workbench import plotting

    with pytest.raises(workbench.ParameterError, match="neither a run's nor a study's"):
        plotting.overview(xr.Dataset({"a": ("x", [1.0, 2.0])}))
    ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    with pytest.raises(workbench.ParameterError, match="path = '': give a file name"):
        plotting.overview(ds, "")


@pytest.mark.slow
@pytest.mark.parametrize("gap", [0.0, 0.01, 0.05])
def test_a_second_ctrl_c_does_not_lose_the_archive(tmp_path, gap):
    """Found by an outside pass: a second Ctrl-C while the interrupted run's records became a Dataset or its archive
    was written lost the archive ("its steps are kept" said first), hung the process on netCDF's lock, or ended it by
    the signal after the archive was written (exit -2). The first stops the run; the later ones are ignored. (A
    Ctrl-C inside a checkpoint's write, which took netCDF's lock for good, waits for the write's end.)"""
    import os
    import signal
    import time

    out = tmp_path / "x.nc"
    p = subprocess.Popen([sys.executable, "-m", "workbench.cli", "run", "slab", "--T", "20", "--no-progress", "--set",
                          "traction_top=(0, sin(t))", "--set", "checkpoint_every=5", "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(600):  # (the loop runs once its first checkpoint is there)
            if out.exists() or p.poll() is not None:
                break
            time.sleep(0.1)
        os.kill(p.pid, signal.SIGINT)
        time.sleep(gap)
        os.kill(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=300)
    finally:
        p.kill()
    assert p.returncode == 130 and "Traceback" not in err, (p.returncode, err)
    ds = workbench.load(tmp_path / "x.stopped.nc")  # (beside the checkpoint, which keeps the state to go on from)
    # (the steps it took, not its records: 20 s of steps are recorded every tenth, so a Ctrl-C soon after the first
    # checkpoint, as on a loaded machine, finds t = 0 alone recorded)
    assert ds.attrs["status"] == "incomplete" and ds.attrs["steps_taken"] >= 5
    assert workbench.load(out).attrs["status"] == "checkpoint"
