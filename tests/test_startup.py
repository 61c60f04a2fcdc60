"""What a ``workbench run`` process pays besides its work (issue 13, the lean start), and the record-time operators
that replaced per-record NGSolve evaluations. The timings themselves are measured by studies/bench_whole_process.py;
here: what is imported, and that the cheaper operators give the same numbers as NGSolve's own evaluation."""
import os
import subprocess
import sys

import numpy as np
import pytest

#: A ``workbench run`` as the console script starts it (``workbench.cli:console``), reporting at exit which of the
#: modules it must not need were loaded (``sys.modules[name] is None`` is Python's "counts as absent").
CONSOLE = """
import atexit, sys
watched = ("dask", "distributed", "tqdm", "matplotlib", "threadpoolctl", "pyamg", "meshio")
atexit.register(lambda: print("LOADED", [m for m in watched if sys.modules.get(m) is not None]))
sys.argv = ["workbench"] + sys.argv[1:]
from workbench.cli import console
sys.exit(console())
"""


def _console(args, tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    return subprocess.run([sys.executable, "-c", CONSOLE, *args], capture_output=True, text=True, env=env,
                          cwd=tmp_path, timeout=300)


def test_a_run_process_imports_nothing_it_does_not_use(tmp_path):
    """`workbench run tp5 -o X.nc --no-progress` with dask installed (the test extra installs it): xarray's lookup of
    dask (0.35 s), tqdm without a bar, threadpoolctl with every BLAS pool started at one thread, plots, AMG and mesh
    files are not imported; the archive is complete and reads back with the run's numbers."""
    pytest.importorskip("dask")
    import workbench

    out = tmp_path / "tp5.nc"
    p = _console(["run", "tp5", "--h", "0.05", "--k", "0.002", "--T", "0.1", "-o", str(out), "--no-progress"],
                 tmp_path)
    assert p.returncode == 0, p.stderr
    assert "LOADED []" in p.stdout, p.stdout
    ds = workbench.load(out)
    assert ds.attrs["status"] == "complete" and ds.sizes["time"] == 51
    again = workbench.run("tp5", h=0.05, k=0.002, T=0.1, progress=False)
    np.testing.assert_array_equal(ds.u_probe.values, again.u_probe.values)
    np.testing.assert_array_equal(ds.contact_pressure.values, again.contact_pressure.values)


def test_a_study_without_a_bar_does_not_import_tqdm():
    """``Study.run(progress=False)`` imported tqdm.auto, which in a notebook without ipywidgets prints a TqdmWarning in
    a cell that asked for no bar; a run without a bar never imported it."""
    code = ("import sys, workbench\nworkbench.Study('tp1', h=0.5, k=[0.5, 0.25], T=0.5, reference='exact', workers=0)"
            ".run(progress=False)\nprint('tqdm', sys.modules.get('tqdm') is not None)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and "tqdm False" in p.stdout, p.stdout + p.stderr


def test_a_study_process_keeps_dask():
    """`workbench study` may send its cases to a dask cluster (--scheduler): its process does not count dask as
    absent, and neither does a session that calls the library (a notebook may use dask later)."""
    code = ("import sys\nsys.argv = ['workbench', 'study', '--help']\nfrom workbench.cli import console\n"
            "try:\n    console()\nexcept SystemExit:\n    pass\nimport dask\nprint('dask', dask.__name__)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and "dask dask" in p.stdout, p.stderr
    from workbench import cli

    cli.main(["scenes"])
    assert sys.modules.get("dask", "absent") is not None


@pytest.mark.parametrize("scene, values", [
    ("tp1", {"h": 0.1}),                          # 1D rod
    ("tp5", {"h": 0.05}),                         # 2D slab, P1
    ("tp5", {"h": 0.05, "order": 2}),            # P2
    ("block", {"h": 0.25, "order": 2}),          # 3D
    ("hertz", {}),                                # curved, unstructured
    ("memory_slab", {"h": 0.1}),                 # Model B
])
def test_the_probe_operator_is_ngsolves_point_evaluation(scene, values):
    """The probes are recorded through P (taken once from the unit vectors of the probe cells' dofs): P u equals
    NGSolve's own evaluation u(mesh(x, y)) at the probe points for a random dof vector, to round-off."""
    from workbench.discrete import discretisation
    from workbench.input.scenes import scene as make

    d = discretisation.build(make(scene, **values))
    d.u.vec.FV().NumPy()[:] = np.random.default_rng(3).standard_normal(d.ndof)
    ngsolve_values = np.asarray(d.u(d.probe_points)).reshape(len(d.scene["probes"]), d.dim)
    np.testing.assert_allclose(d.fields.probe_values(), ngsolve_values, rtol=1e-13, atol=1e-13)
