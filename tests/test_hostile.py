"""A hostile tester's inputs (issue 25), one representative of each class that failed, and more of the same kind.

Each command-line input must end in exactly one ``error:`` line and exit code 2 before any work (or run, where the
input is valid), with nothing written over what was there; each misuse of the Python API a ParameterError naming the
argument; nothing a run computed may be lost when an output fails. The whole set (925 inputs) is
``studies/hostile.py``; its counts before and after are in ``docs/hostile.md``.
"""
import os
import stat
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench import cli
from workbench.errors import ParameterError


def _cli(capsys, *args):
    """``workbench ARGS`` in this process: (exit code, stderr)."""
    code = cli.main(list(args))
    return code, capsys.readouterr().err


def _one_error(code, err, *words):
    lines = [line for line in err.strip().splitlines() if not line.startswith("warning:")]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:"), (code, err)
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0], (word, lines[0])


QUICK = ("--h", "0.1", "--k", "0.1", "--no-progress")


# -- data lost -------------------------------------------------------------------------------------------------------
def test_two_outputs_in_one_file_are_refused(capsys, tmp_path):
    """--plot out.nc -o out.nc left a PNG where the archive was (exit 0)."""
    out = tmp_path / "out.nc"
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "-o", str(out), "--plot", str(out)), "same path")
    assert not out.exists()


def test_an_option_given_twice_is_refused(capsys, tmp_path):
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "-o", str(tmp_path / "a.nc"), "-o", str(tmp_path / "b.nc")),
               "-o is given twice")
    _one_error(*_cli(capsys, "study", "tp1", "--k", "0.1", "0.05", "--workers", "0", "--workers", "1"), "twice")


@pytest.mark.parametrize("kind", ["fifo", "socket"])
def test_what_is_not_a_regular_file_is_never_replaced(capsys, tmp_path, kind):
    """-o naming a device replaced the device node by a regular file (the run was root): a pipe and a socket stand
    for it here (no root needed); the command, the API and the atomic write all leave it alone."""
    target = tmp_path / "special"
    if kind == "fifo":
        os.mkfifo(target)
    else:
        import socket

        s = socket.socket(socket.AF_UNIX)
        s.bind(str(target))
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "-o", str(target)), "not a regular file")
    with pytest.raises(ParameterError, match="not a regular file"):
        workbench.run("tp1", h=0.1, k=0.1, checkpoint=str(target), checkpoint_every=2, progress=False)
    ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    with pytest.raises(ParameterError, match="not a regular file"):
        workbench.write(ds, target)
    mode = target.stat().st_mode
    assert stat.S_ISFIFO(mode) if kind == "fifo" else stat.S_ISSOCK(mode)


@pytest.mark.parametrize("path, words", [("", "give a file name"), ("/proc/x.nc", "no permission"),
                                          ("a" * 300 + ".nc", "255")])
def test_impossible_output_paths_are_refused_before_the_run(capsys, tmp_path, path, words):
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "-o", path), words)


def test_a_full_disk_keeps_the_result_and_a_failing_checkpoint_lets_the_run_go_on(capsys, tmp_path, monkeypatch):
    """netCDF reports a full disk as RuntimeError ('NetCDF: HDF error'), which the keep-a-copy fallback did not catch:
    the archive was lost after 'complete'. Now the write is an OSError naming the target: the command keeps a copy in
    the temporary folder (exit 4), and a checkpoint that cannot be written is warned about while the run goes on."""
    import xarray as xr

    real = xr.Dataset.to_netcdf
    full = str(tmp_path / "full")

    def to_netcdf(self, path, *args, **kwargs):
        if str(path).startswith(os.path.join(full, "")) or os.path.basename(str(path)).startswith(".out.nc"):
            raise RuntimeError("NetCDF: HDF error")
        return real(self, path, *args, **kwargs)

    monkeypatch.setattr(xr.Dataset, "to_netcdf", to_netcdf)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    code, err = _cli(capsys, "run", "tp1", *QUICK, "-o", str(tmp_path / "out.nc"))
    assert code == cli.EXIT_NOT_WRITTEN and "could not be written" in err and "kept in" in err, err
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("workbench-kept-")]
    assert len(kept) == 1 and workbench.load(kept[0]).attrs["status"] == "complete"
    os.makedirs(full)
    with pytest.warns(RuntimeWarning, match="could not be written .* the run goes on"):
        ds = workbench.run("tp1", h=0.1, k=0.05, checkpoint=os.path.join(full, "c.nc"), checkpoint_every=3,
                           progress=False)
    assert ds.attrs["status"] == "complete"


def test_huge_integers_are_refused_not_lost_at_the_end(capsys, tmp_path):
    """checkpoint_every = 1e308 ran the whole run and then failed writing the attribute."""
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "--set", "checkpoint_every=1e308", "-o", str(tmp_path / "a.nc")),
               "checkpoint_every")


# -- tracebacks, hangs: extreme values, degenerate input ---------------------------------------------------------------
@pytest.mark.parametrize("args, words", [
    (("slab", "--set", "width=1e308"), ("width = 1e+308",)),
    (("slab", "--h", "5e-324"), ("h = 4.94066e-324",)),
    (("rod", "--h", "1e-7"), ("h = 1e-07", "vertices")),                      # 1e7 cells: it meshed for ever
    (("hertz3d", "--set", "h_contact=1e-4"), ("h_contact = 0.0001",)),        # the memory check meshed it first
    (("hertz", "--set", "h_contact=1e-7"), ("h_contact = 1e-07",)),
    (("tp1", "--set", "T=1e6", "--k", "0.01"), ("time steps",)),                # 1e8 steps
    (("slab", "--set", "nx=1e308"), ("nx",)),
    (("tp1", "--threads", "100000"), ("--threads",)),
    (("slab", "--set", "traction_top=(0, (-1)**0.5)"), ("traction_top", "finite")),
    (("hertz", "--set", "tau=0"), ("tau = 0",)),                              # it named a2
    (("hertz", "--set", "tau=1e308"), ("tau = 1e308",)),                      # it named a1
    (("slab", "--h", "0.1", "--set", "a1=1e308"), ("a1 = 1e+308",)),           # a LinAlgError
    (("tp1", "--set", "a=1e308"), ("a = 1e+308",)),                            # ARPACK error -9999
])
def test_extreme_values_are_one_named_error(capsys, args, words):
    _one_error(*_cli(capsys, "run", *args), *words)


def test_silently_accepted_inputs_are_refused(capsys):
    _one_error(*_cli(capsys, "run", "slab", "--set", "traction_top=(0,)"), "traction_top", "2 are needed")
    with pytest.raises(ParameterError, match="grids"):
        workbench.Study("tp1", grids=[])


def test_a_long_sum_is_not_too_deep():
    """A load written as a sum of 120 terms was refused as 'nested more than 100 levels deep'; it is the sum."""
    load = "(0, " + "+".join(["0.001*t"] * 120) + ")"
    ds = workbench.run("slab", h=0.25, k=0.001, T=0.002, traction_top=load, progress=False)
    ref = workbench.run("slab", h=0.25, k=0.001, T=0.002, traction_top="(0, 0.12*t)", progress=False)
    np.testing.assert_allclose(ds.u_probe.values, ref.u_probe.values, rtol=1e-12, atol=1e-15)


def test_files_that_are_not_scene_files(capsys, tmp_path):
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)  # (reading it waited for ever)
    _one_error(*_cli(capsys, "run", str(fifo)), "not a regular file")
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")  # (a RecursionError)
    _one_error(*_cli(capsys, "show", str(deep)), "nested too deeply")


def _gmsh(path, points, triangles):
    """A gmsh 2.2 ASCII file: the points, the triangles, and the boundary lines of the unit square's sides."""
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", "5", "1 1 \"bottom\"", "1 2 \"right\"",
             "1 3 \"top\"", "1 4 \"left\"", "2 5 \"body\"", "$EndPhysicalNames", "$Nodes", str(len(points))]
    lines += [f"{i + 1} {x!r} {y!r} 0" for i, (x, y) in enumerate(points)]
    edges = [(1, 1, 2), (2, 2, 3), (3, 3, 4), (4, 4, 1)]
    lines += ["$EndNodes", "$Elements", str(len(edges) + len(triangles))]
    lines += [f"{i + 1} 1 2 {tag} {tag} {a} {b}" for i, (tag, a, b) in enumerate(edges)]
    lines += [f"{len(edges) + j + 1} 2 2 5 5 {a} {b} {c}" for j, (a, b, c) in enumerate(triangles)]
    lines += ["$EndElements"]
    path.write_text("\n".join(lines) + "\n")
    return path


SQUARE = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
ROLES = {"bottom": "contact", "left": "clamped", "top": "traction", "right": "free"}


@pytest.mark.parametrize("case, points, triangles, words", [
    ("nan", [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (float("nan"), 1.0)], [(1, 2, 3), (1, 3, 4)], "not finite"),
    ("unused", SQUARE + [(0.5, 0.5)], [(1, 2, 3), (1, 3, 4)], "belong to no cell"),
    ("duplicate", SQUARE + [(1.0, 1.0)], [(1, 2, 5), (1, 3, 4)], "same place"),
    ("flat", SQUARE + [(0.5, 0.0)], [(1, 5, 2), (1, 2, 3), (1, 3, 4)], "no area"),
])
def test_degenerate_meshes_are_refused_by_name(case, points, triangles, words, tmp_path):
    """A NaN coordinate, a vertex no cell uses, duplicated vertices, a cell without area: tracebacks (or silently
    accepted) before."""
    path = _gmsh(tmp_path / f"{case}.msh", points, triangles)
    with pytest.raises(ParameterError, match=words):
        workbench.scene(mesh=str(path), boundaries=ROLES)


def test_a_one_cell_square_mesh_runs(tmp_path):
    """A valid two-triangle mesh was refused for an h the user never gave (its diagonal against the body's size)."""
    path = _gmsh(tmp_path / "square.msh", SQUARE, [(1, 2, 3), (1, 3, 4)])
    ds = workbench.run(workbench.scene(mesh=str(path), boundaries=ROLES, traction="(0, -t)", T=0.02, k=0.01),
                       progress=False)
    assert ds.attrs["status"] == "complete"


def test_a_damaged_restart_archive_is_a_named_error(capsys, tmp_path):
    import netCDF4

    path = tmp_path / "a.nc"
    workbench.write(workbench.run("tp1", h=0.1, k=0.1, progress=False), path)
    for attr, value in (("state_json", "{bad"), ("parameters_json", "[1, 2]")):
        damaged = tmp_path / f"{attr}.nc"
        damaged.write_bytes(path.read_bytes())
        with netCDF4.Dataset(damaged, "a") as d:
            d.setncattr(attr, value)
        _one_error(*_cli(capsys, "run", "--restart", str(damaged), "--set", "T=2"), "restart", str(damaged))


# -- the Python API ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("call, words", [
    (lambda: workbench.write("not a dataset", "x.nc"), "Dataset"),
    (lambda: workbench.load("nothing-here.nc"), "no such file"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], reference=42), "reference = 42"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], sweep={"nonexistent": [1, 2]}), "nonexistent"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], sweep=[1, 2]), "sweep"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], measures=5), "measures"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], couple={"gamma_nu": 3}), "couple"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], client=42), "client"),
    (lambda: workbench.run("tp1", record_times=5), "record_times"),
    (lambda: workbench.run("tp1", h=np.array([0.1, 0.2])), "h ="),
    (lambda: workbench.run("tp1", model="A"), "model"),
    (lambda: workbench.run("tp1", checkpoint=42), "checkpoint"),
    # the second round (the harness's run after the first round's fixes)
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], grids=[{}]), "empty dict"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], grids=[{"nonexistent": [1]}]), "nonexistent"),
    (lambda: workbench.Study("tp1", k=[0.1, 0.05], couple={"gamma_nu": lambda c: c["nonexistent"]}),
     "couple: the function for gamma_nu raised KeyError"),
    (lambda: workbench.run("tp1", h=0.1, k=0.1, progress="no"), "progress = 'no'"),
    (lambda: workbench.write(workbench.run("tp1", h=0.1, k=0.1, progress=False), "."), "is a directory"),
    (lambda: workbench.write(workbench.run("tp1", h=0.1, k=0.1, progress=False), "/proc/x.nc"), "no permission"),
])
def test_api_misuse_is_a_parameter_error(call, words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ParameterError, match=words):
        call()


def test_measures_that_return_text_are_named(tmp_path):
    st = workbench.Study("tp1", k=[0.1, 0.05], reference="ode", workers=0, measures=lambda ds: {"peak": "high"})
    with pytest.raises(ParameterError, match="measures returned peak"):
        st.run(tmp_path / "cases", progress=False)


def test_a_study_names_what_its_own_functions_raise(tmp_path):
    """measures raising, assert_order given text: tracebacks from inside the study before."""
    st = workbench.Study("tp1", k=[0.1, 0.05], reference="ode", workers=0, measures=lambda ds: 1 / 0)
    with pytest.raises(ParameterError, match="measures raised ZeroDivisionError") as info:
        st.run(tmp_path / "cases", progress=False)
    assert isinstance(info.value.__cause__, ZeroDivisionError)  # (the user's own traceback is kept as the cause)
    st = workbench.Study("tp1", k=[0.1, 0.05], reference="ode", workers=0)
    st.run(tmp_path / "cases2", progress=False)
    with pytest.raises(ParameterError, match="expected = 'abc'"):
        st.assert_order("abc")


# -- the second round: what the harness still found after the first ---------------------------------------------------
def test_second_round_command_line_inputs(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _one_error(*_cli(capsys, "run", "x" * 300), "unknown scene", "300 characters")     # File name too long
    _one_error(*_cli(capsys, "run", "x" * 3000 + ".toml"), "cannot be read")
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "-o", "/".join(["d" * 200] * 25)), "4095")
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "--set", "snapshots=[[0.1]]"), "snapshots", "flat list")
    _one_error(*_cli(capsys, "run", "--restart", ""), "--restart ''")
    (tmp_path / "empty.msh").write_text("")  # (meshio printed an error and called sys.exit(1))
    _one_error(*_cli(capsys, "run", "mesh2d", "--set", f"mesh={tmp_path / 'empty.msh'}"), "empty.msh",
               "cannot be read")
    monkeypatch.setenv("MPLBACKEND", "bogus_backend")  # (matplotlib's import failed after the run)
    _one_error(*_cli(capsys, "run", "tp1", *QUICK, "--plot", "p.png"), "MPLBACKEND")
    assert not (tmp_path / "p.png").exists()


def test_a_restart_archive_without_its_record_is_named(capsys, tmp_path):
    path = tmp_path / "a.nc"
    ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
    workbench.write(ds.drop_vars(["u_probe", "u_contact", "beta", "step"]).drop_dims("time"), path)
    _one_error(*_cli(capsys, "run", "--restart", str(path), "--set", "T=2"), str(path), "no record over time")


def test_a_scene_file_with_long_comments_runs(tmp_path):
    """A 2 MB scene file (comments) was refused by a 1 MB limit meant for /dev/zero (now: not a regular file)."""
    path = tmp_path / "long.toml"
    path.write_text(("# " + "c" * 98 + "\n") * 20000 + 'scene = "tp1"\n[parameters]\nh = 0.1\nk = 0.1\n')
    assert path.stat().st_size > 2e6
    assert workbench.run(str(path), progress=False).attrs["status"] == "complete"


def test_a_tolerance_below_round_off_stops_cleanly():
    """rtol = 1e-12, atol = k_min = 1e-300: the steps shrank until t + k == t and a ZeroDivisionError followed; now
    the smallest step is the one time resolves (1e-10 T) and the run stops there, keeping what it computed."""
    with pytest.raises(workbench.Diverged, match="the smallest step time resolves") as info:
        workbench.run("tp5", h=0.1, k=0.01, T=0.05, scheme="bdf2", rtol=1e-12, atol=1e-300, k_min=1e-300,
                      progress=False)
    assert info.value.dataset.attrs["status"] == "incomplete"


def test_an_unwritable_mesh_cache_falls_back_to_the_temporary_folder(tmp_path, monkeypatch):
    from netgen.occ import OCCGeometry, Rectangle, X, Y

    monkeypatch.setenv("WORKBENCH_CACHE", "/proc/cache")
    face = Rectangle(1.0, 0.2).Face()
    face.edges.Min(Y).name, face.edges.Min(X).name, face.edges.Max(Y).name = "bottom", "left", "top"
    with pytest.warns(RuntimeWarning, match="mesh cache '/proc/cache/meshes' cannot be written"):
        sc = workbench.scene(mesh=OCCGeometry(face, dim=2), h=0.25, traction="(0, -t)", T=0.02, k=0.01,
                             boundaries={"bottom": "contact", "left": "clamped", "top": "traction",
                                         "default": "free"})
    assert workbench.run(sc, progress=False).attrs["status"] == "complete"


def test_unwritable_case_archives_do_not_stop_a_study(tmp_path, monkeypatch):
    """The case archives are a cache: when they cannot be written (a full disk) the study warns and finishes with the
    runs in memory (a traceback lost the whole study before)."""
    from workbench.output import results

    real = results.write

    def write(ds, path):
        if str(path).endswith(".nc") and "cases" in str(path):
            raise OSError(28, "No space left on device", str(path))
        return real(ds, path)

    monkeypatch.setattr(results, "write", write)
    st = workbench.Study("tp1", k=[0.1, 0.05], reference="ode", workers=0)
    with pytest.warns(RuntimeWarning, match="could not be written .* goes on"):
        ds = st.run(tmp_path / "cases", progress=False)
    assert np.isfinite(ds.error.values).all()


def test_reproduce_keeps_its_run_when_the_folder_cannot_be_written(capsys, tmp_path, monkeypatch):
    def full(ds, path):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(workbench, "write", full)  # (what the reproduction writes its archive with)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    code, err = _cli(capsys, "reproduce", "tp1", "--h", "0.1", "--k", "0.1", "--no-side", "--out",
                     str(tmp_path / "full"))
    assert code == cli.EXIT_NOT_WRITTEN and "Traceback" not in err and "kept in" in err, err
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("workbench-kept-")]
    assert len(kept) == 1 and workbench.load(kept[0]).attrs["status"] == "complete"


def test_a_long_quadrature_memory_says_its_cost_before_the_run():
    """memory_rod, a general kernel by quadrature, 1e5 steps: O(n^2), about 5 min, with no word before (a 'hang')."""
    from workbench.running import preflight

    sc = workbench.scene("memory_rod", T=100, k=0.001, kernel="exp(-t)", kernel_E=0.5, prony=[])
    (message,) = [w for w in preflight.warnings_for(sc, sc.model_of()) if "quadrature" in w]
    assert "1e+05 steps" in message and "exponentials" in message
    assert not [w for w in preflight.warnings_for(sc.with_(T=10), sc.model_of()) if "quadrature" in w]


@pytest.mark.parametrize("text", ["-0.6" + "/1" * 1300, "-" * 1300 + "0.6", "2" + "**1" * 1300])
def test_a_long_chain_of_divisions_or_signs_is_refused_in_one_line(capsys, text):
    """Found by an outside pass: 1300 divisions (or unary minuses, or powers), under the 4000 characters allowed,
    recursed past Python's limit while the expression was checked: a RecursionError traceback, exit 1."""
    _one_error(*_cli(capsys, "run", "tp1", "--set", f"delta={text}", "--no-progress"), "nested too deeply")


def test_an_output_naming_the_runs_own_input_is_refused(capsys, tmp_path, monkeypatch):
    """Found by an outside pass: ``workbench run rocker.toml -o rocker.msh`` replaced the mesh with the archive, and
    ``-o rocker.toml`` the scene file, silently (exit 0). Refused before any work; both files are left as they were."""
    import shutil

    for name in ("rocker.toml", "rocker.msh"):
        shutil.copy(Path(__file__).resolve().parents[1] / "docs" / "examples" / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    before = {name: (tmp_path / name).read_bytes() for name in ("rocker.toml", "rocker.msh")}
    _one_error(*_cli(capsys, "run", "rocker.toml", "--T", "0.1", "-o", "rocker.msh", "--no-progress"),
               "-o 'rocker.msh' is the run's own mesh file")
    _one_error(*_cli(capsys, "run", "rocker.toml", "--T", "0.1", "-o", "./rocker.toml", "--no-progress"),
               "is the run's own scene file")
    assert {name: (tmp_path / name).read_bytes() for name in before} == before


def test_reproduce_all_checks_every_problem_before_running_any(capsys, tmp_path):
    """``reproduce all --set a=2`` ran and wrote tp1-tp3 before tp4 refused the rods' parameter (found by an outside
    pass): every problem's values are checked first."""
    out = tmp_path / "rep"
    _one_error(*_cli(capsys, "reproduce", "all", "--set", "a=2", "--no-side", "--out", str(out)),
               "tp4: unknown parameter 'a'")
    assert not out.exists() or not any(out.iterdir())


def test_reproduce_all_refuses_a_step_above_a_later_problems_stability_limit_before_running_any(capsys, tmp_path):
    """``reproduce all --k 0.5``: tp1-tp3 (rods, k_crit = 2 s) ran and were written before tp4's explicit step was
    found above its stability limit (k_crit = 0.052 s), which needs the slab's matrices: each problem's scheme is now
    set up and checked, with no step, before the first runs."""
    out = tmp_path / "rep"
    _one_error(*_cli(capsys, "reproduce", "all", "--k", "0.5", "--no-side", "--out", str(out)),
               "tp4: k = ", "exceeds the predicted stability limit", "k_crit = 0.052")
    assert not out.exists() or not any(out.iterdir())
    # (every scheme's checks: the first version of the check knew the explicit scheme's alone, and every other
    # scheme's reproduction ended in an AttributeError, an outside pass)
    assert cli.main(["reproduce", "tp4", "--h", "0.2", "--k", "0.02", "--no-side", "--set", "scheme=implicit",
                     "--out", str(out)]) == 0
    assert (out / "tp4.nc").exists()
    # (two more found only after the run, as tracebacks: a rod whose reference ODE cannot be made, no bonding field)
    for problem, value, words in (("tp2", "u0=-0.1+0.01*x", "rod_ode needs u0 = delta(0)"),
                                  ("tp4", "adhesion=false", "adhesion = false")):
        _one_error(*_cli(capsys, "reproduce", problem, "--set", value, "--no-side", "--out", str(tmp_path / "no")),
                   f"{problem}: ", words)
        assert not (tmp_path / "no").exists()
