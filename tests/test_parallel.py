"""One case on several MPI processes (issue 13, item 5): ``mpiexec -n N workbench run ...`` against the serial run.

The distributed run solves the same discrete problem (Model A's explicit scheme: K_A v_n = F_n - K_G u_{n-1}
- j(beta_{n-1}, u_{n-1}, .)) with NGSolve's BDDC-preconditioned conjugate gradients to a relative residual of 1e-10
where the serial run factors K_A: the archives must agree to that tolerance (a few 1e-10 after the steps), with the
same layout; the step limit, estimated by a Lanczos over the ranks, must agree with the serial ARPACK estimate. The
independent references are the serial runs of the same scenes, made in this process.
"""
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.discrete.world import alone

#: A block whose left half is pressed into the foundation and whose right half is pulled off it while the glue
#: (normal and tangential) debonds: every contact term and the bonding law act.
BLOCK = dict(h=0.1, order=1, T=0.2, k=0.004, c_nu=50.0, gamma_nu=20.0, c_tau=2.0,
             traction_top="(0.5*t, 0, 50*t*ifpos(x-0.5, 1, -1))", snapshots=(0.1,))
#: The paper's slab of problem 4 on P2, with its point force at the tip (applied once, by its owner).
SLAB = dict(h=0.05, order=2, T=0.1, k=0.002)


def _mpiexec():
    found = Path(sys.executable).parent / "mpiexec"
    return str(found) if found.exists() else shutil.which("mpiexec")


def _mpi_script(tmp_path, processes: int, timeout: float, source: str):
    """``source`` written to a script in ``tmp_path`` and run there on ``processes`` MPI processes (the finished
    process, its output captured)."""
    script = tmp_path / "fail.py"
    script.write_text(source)
    return subprocess.run([_mpiexec(), "-n", str(processes), sys.executable, str(script)], capture_output=True,
                          text=True, env=alone(), timeout=timeout, cwd=tmp_path)


def _run_distributed(n, scene, values, out, extra=()):
    """``mpiexec -n n workbench run scene --set name=value ... -o out [extra]``: (exit code, stdout, stderr); with
    ``--restart`` in ``extra`` the scene is the archive's."""
    sets = []
    for name, value in values.items():
        text = value if isinstance(value, str) else repr(list(value) if isinstance(value, tuple) else value)
        sets += ["--set", f"{name}={text}"]
    given = [] if "--restart" in extra else [scene]
    cmd = [_mpiexec(), "-n", str(n), sys.executable, "-m", "workbench.cli", "run", *given, *sets, "-o", str(out),
           "--no-progress", *extra]
    env = alone()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600, cwd=out.parent)
    return p.returncode, p.stdout, p.stderr


def _relative(a, b):
    """max |a - b| / max |b|, NaN where both are (the clamped contact vertices of Model B's pressure)."""
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    return float(np.nanmax(np.abs(a - b)) / max(np.nanmax(np.abs(b)), 1e-300))


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.parametrize("n, scene, values", [(2, "block", BLOCK), (3, "tp4", SLAB),
                                              (3, "block", dict(BLOCK, solver="sparsecholesky"))],
                         ids=["block-np2", "slab-P2-np3", "block-factor-np3"])
def test_a_distributed_run_equals_the_serial_run(tmp_path, n, scene, values):
    """The archive of `mpiexec -n N workbench run` (rank 0 records and writes; ranks 1..N-1 hold the body) has the
    serial archive's variables and coordinates, and its numbers to the solver's tolerance: u at the probes and the
    contact side, beta, the contact pressure, the snapshot fields, the restart state (in the serial order); the step
    limit agrees with the serial estimate (LOBPCG with BDDC, or Lanczos with the factor gathered on rank 0)."""
    out = tmp_path / "mpi.nc"
    code, stdout, stderr = _run_distributed(n, scene, values, out)
    assert code == 0, stderr
    assert stdout.count("wrote") == 1 and stderr.count("warning") <= 1, (stdout, stderr)  # rank 0 speaks alone
    mpi = workbench.load(out)
    serial = workbench.run(scene, progress=False, **values)
    assert mpi.attrs["status"] == "complete" and mpi.attrs["mpi_processes"] == n
    assert mpi.attrs["history"].split(" ", 1)[1].startswith(f"mpiexec -n {n} workbench run ")  # (the whole command)
    assert mpi.attrs["linear_solver"] == values.get("solver", "cg") and mpi.attrs["ndof"] == serial.attrs["ndof"]
    assert mpi.attrs["nsteps"] == serial.attrs["nsteps"]
    assert set(serial.variables) == set(mpi.variables) - {"cg_iterations"}  # (one process: a factor)
    for name in ("u_probe", "u_contact", "beta", "contact_pressure", "u_dofs", "u_nodes", "stress", "von_mises",
                 "state_u", "state_v", "state_beta", "state_step_limit_normal"):
        if name in serial:
            np.testing.assert_array_equal(mpi[name].shape, serial[name].shape)
            assert _relative(mpi[name].values, serial[name].values) < 1e-8, name
    for name in ("node_x", "facet_x", "vertex_x"):
        if name in serial.coords:
            np.testing.assert_array_equal(mpi[name].values, serial[name].values)
    assert abs(mpi.attrs["k_crit"] / serial.attrs["k_crit"] - 1) < 1e-3
    if scene == "block":  # (what the comparison is about: the laws act)
        assert float(serial.beta.isel(time=-1).min()) < 0.9 and float(serial.contact_pressure.max()) > 0
    if "cg_iterations" in mpi:
        assert int(mpi.cg_iterations.max()) >= 1


#: The implicit schemes on several processes: (processes, scene, values). The serial runs factor their operator and
#: condense the contact problem (the defaults on one process); the distributed ones solve it on rank 0's serial view
#: with the coupled solver, each back-substitution a CG solve over the ranks (or, last case, the gathered factor and
#: the condensed solver).
IMPLICIT = [(3, "block", dict(BLOCK, scheme="bdf2", T=0.1)),
            (2, "tp4", dict(h=0.1, order=2, T=0.1, k=0.01, scheme="implicit")),
            (3, "memory_block", dict(h=0.25, snapshots=(0.5, 1.0))),
            (2, "memory_slab", dict(h=0.25, order=2, solver="sparsecholesky", contact_solver="condensed",
                                    snapshots=(1.0,))),
            (2, "memory_hertz3d", dict(h_contact=0.02)),
            (3, "hertz", dict(T=0.2))]


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.parametrize("n, scene, values", IMPLICIT, ids=["block-bdf2-np3", "slab-P2-implicit-np2",
                                                             "memory_block-vi-np3", "memory_slab-P2-factor-np2",
                                                             "hemisphere-vi-np2", "hertz-implicit-np3"])
def test_the_implicit_schemes_distributed_equal_the_serial_run(tmp_path, n, scene, values):
    """Model A's backward Euler and BDF2 (normal compliance, the glue, debonding) and Model B's inequality (memory,
    the unilateral layer, P2's trace at the facet midpoints) on N processes: the archive has the serial one's
    variables, its numbers to the solvers' tolerance (CG 1e-10 against a factor), the same contact states, and
    the restart state (the memory's histories, the contact points' forces) in the serial order. The Hertz bodies
    hold their apex: its pressure is the support's reaction, summed over the ranks and gathered to rank 0."""
    out = tmp_path / "mpi.nc"
    code, stdout, stderr = _run_distributed(n, scene, values, out)
    assert code == 0, stderr
    assert stdout.count("wrote") == 1, stdout
    mpi = workbench.load(out)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (P1 on the thin block: said by the distributed run already)
        serial = workbench.run(scene, progress=False, **values)
    assert mpi.attrs["status"] == "complete" and mpi.attrs["mpi_processes"] == n
    assert mpi.attrs["ndof"] == serial.attrs["ndof"] and mpi.attrs["nsteps"] == serial.attrs["nsteps"]
    assert mpi.attrs["contact_solver_used"] == values.get("contact_solver", "coupled")
    assert set(serial.variables) - {"linear_iterations"} == set(mpi.variables) - {"linear_iterations"}
    compared = 0
    for name in ("u_probe", "u_contact", "beta", "contact_pressure", "contact_pressure_midpoint", "u_dofs", "stress",
                 "state_u", "state_v", "state_beta", "state_histories", "state_lam"):
        if name in serial:
            np.testing.assert_array_equal(mpi[name].shape, serial[name].shape)
            assert _relative(mpi[name].values, serial[name].values) < 1e-8, name
            compared += 1
    assert compared >= 7
    for name in ("contact_state", "state_states", "n_rigid", "n_separated"):
        if name in serial:
            np.testing.assert_array_equal(mpi[name].values, serial[name].values, err_msg=name)


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.parametrize("n, scene, values", [
    (2, "tp4", dict(scheme="bdf2", h=0.1, T=0.3, rtol=1e-3)),
    (3, "memory_slab", dict(h=0.25, T=0.4, rtol=1e-2, contact_solver="coupled"))], ids=["tp4-bdf2-np2", "vi-np3"])
def test_error_controlled_steps_distributed_are_the_serial_ones(tmp_path, n, scene, values):
    """Error control on several processes: the local error estimates (maxima and sums over the ranks), the first
    step's Richardson check and the events (the kinks crossed, gathered from every rank) give every rank the same
    decisions, and the same steps as one process: accepted and rejected counts, the step sizes, and the records to
    the solver's tolerance (the serial run with the same contact solver: the condensed one lands on other kinks)."""
    out = tmp_path / "mpi.nc"
    code, _, stderr = _run_distributed(n, scene, values, out)
    assert code == 0, stderr
    mpi, serial = workbench.load(out), workbench.run(scene, progress=False, **values)
    for key in ("accepted_steps", "rejected_steps"):
        assert mpi.attrs[key] == serial.attrs[key], key
    assert serial.attrs["rejected_steps"] > 0 or scene != "tp4"  # (the controller rejected steps: it was exercised)
    np.testing.assert_allclose(mpi.step_size.values, serial.step_size.values, rtol=1e-9)
    for name in ("u_probe", "u_contact", "beta", "u_dofs"):
        if name in serial:
            assert _relative(mpi[name].values, serial[name].values) < 1e-8, name


@pytest.mark.mpi
@pytest.mark.slow
def test_the_implicit_schemes_continue_across_process_counts(tmp_path):
    """BDF2 (its restart state holds the accepted history, gathered into the serial order) checkpointed on 2 processes
    continues on 3; Model B (the memory's histories per dof, the contact points' states and forces held on rank 0)
    archived on one process continues on 3. Both equal the uninterrupted one-process run to the solver's tolerance."""
    bdf2 = dict(h=0.25, order=1, k=0.004, T=0.08, c_nu=50.0, gamma_nu=20.0, scheme="bdf2",
                traction_top="(0.5*t, 0, 50*t*ifpos(x-0.5, 1, -1))")
    code, _, stderr = _run_distributed(2, "block", bdf2 | {"checkpoint_every": 7}, tmp_path / "cp.nc")
    assert code == 0, stderr
    cp = workbench.load(tmp_path / "cp.nc")
    assert cp.attrs["status"] == "complete" and cp.attrs["mpi_processes"] == 2 and "state_history_u" in cp
    memory = dict(h=0.25, T=0.5)
    workbench.write(workbench.run("memory_block", progress=False, **memory), tmp_path / "serial.nc")
    for archive, scene, T, values in ((cp, "block", 0.12, bdf2), (None, "memory_block", 1.0, memory)):
        path = tmp_path / ("cp.nc" if archive is not None else "serial.nc")
        out = tmp_path / f"on3-{scene}.nc"
        code, _, stderr = _run_distributed(3, scene, {}, out, extra=["--restart", str(path), "--set", f"T={T}"])
        assert code == 0, stderr
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            straight = workbench.run(scene, progress=False, **(values | {"T": T}))
        ds = workbench.load(out)
        assert ds.attrs["mpi_processes"] == 3 and ds.sizes["time"] == straight.sizes["time"]
        for name in ("u_probe", "u_contact", "beta", "u_dofs", "state_u"):
            if name in straight:
                assert _relative(ds[name].values, straight[name].values) < 1e-8, (scene, name)


@pytest.mark.mpi
@pytest.mark.slow
def test_a_contact_solve_that_fails_on_rank_0_stops_every_rank(tmp_path):
    """The contact problem is solved on rank 0 while the others serve its back-substitutions: a Newton failure there
    (injected at the fourth step) ends the serving, every rank stops at that step, rank 0 says it once (exit code 3)
    and writes the steps computed before."""
    p = _mpi_script(tmp_path, 3, 300, "import sys\nfrom workbench.discrete import condensation\n"
                    "from workbench.errors import "
                    "NewtonFailed\norig = condensation.CoupledNewton.solve\ncalls = []\n\n\n"
                    "def failing(self, u_C, z_C, time, label=''):\n    calls.append(time)\n"
                    "    if len(calls) == 4:\n        raise NewtonFailed(f'injected at t = {time:g}', time=time)\n"
                    "    return orig(self, u_C, z_C, time, label)\n\n\n"
                    "condensation.CoupledNewton.solve = failing\nsys.argv = ['workbench', 'run', 'tp4', '--scheme', "
                    "'implicit', '--set', 'h=0.1', '--set', 'T=0.1', '--set', 'k=0.01', '-o', 'out.nc', "
                    "'--no-progress']\nfrom workbench.cli import console\nsys.exit(console())\n")
    assert p.returncode == 3 and p.stderr.count("injected") == 1, p.stderr
    ds = workbench.load(tmp_path / "out.nc")
    assert ds.attrs["status"] == "incomplete" and ds.sizes["time"] == 4  # (t = 0 and the three steps before)


@pytest.mark.mpi
@pytest.mark.slow
def test_a_distributed_run_stops_as_the_serial_one(tmp_path):
    """A state whose springs exceed the step (the stiff slab of the stability issue at k = 0.002): every rank stops
    at the same step, rank 0 says it once (exit code 3) and writes the steps computed, as the serial run does."""
    values = dict(h=0.05, k=0.002, T=0.3, c_nu=100.0, gamma_nu=20.0)
    out = tmp_path / "stop.nc"
    code, stdout, stderr = _run_distributed(2, "tp5", values, out)
    assert code == 3 and stderr.count("error:") == 1 and "stability limit" in stderr, stderr
    mpi = workbench.load(out)
    with pytest.raises(workbench.Diverged) as err:
        workbench.run("tp5", progress=False, **values)
    serial = err.value.dataset
    assert mpi.attrs["status"] == "incomplete" and mpi.sizes["time"] == serial.sizes["time"]
    assert _relative(mpi.u_probe.values, serial.u_probe.values) < 1e-8


@pytest.mark.mpi
def test_what_does_not_run_distributed_is_refused_once(tmp_path):
    """Adaptive refinement in space on two processes: one `error:` line naming the parameter, exit code 2, before
    any work, nothing written."""
    out = tmp_path / "x.nc"
    code, stdout, stderr = _run_distributed(2, "tp4", dict(h=0.1, T=0.02, scheme="implicit", space_tol=0.1), out)
    assert code == 2 and stderr.count("error:") == 1, stderr
    assert "space_tol = 0.1" in stderr and "one process" in stderr
    assert not out.exists()


@pytest.mark.mpi
@pytest.mark.slow
def test_a_python_script_under_the_launcher(tmp_path):
    """`mpiexec -n 2 python script.py` with `workbench.run` in it, as the docs say: the Dataset on rank 0, None on the
    other rank, and a warning (P1 on the thin block) given once, by rank 0."""
    script = tmp_path / "script.py"
    script.write_text("import workbench\nfrom workbench.parallel import world\n"
                      "ds = workbench.run('block', h=0.25, order=1, T=0.01, k=0.002, progress=False)\n"
                      "print('RANK', world().rank, ds is None, None if ds is None else ds.attrs['mpi_processes'])\n")
    p = subprocess.run([_mpiexec(), "-n", "2", sys.executable, str(script)], capture_output=True, text=True,
                       env=alone(), timeout=300, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "RANK 0 False 2" in p.stdout and "RANK 1 True None" in p.stdout, p.stdout
    assert p.stderr.count("lock in bending") == 1, p.stderr


@pytest.mark.mpi
@pytest.mark.slow
def test_restarts_and_checkpoints_across_process_counts(tmp_path):
    """The restart state of a distributed run is stored in the serial order: a checkpoint written by 2 processes
    (checkpoint_every = 7: the archive at step 14 of 20) continues on 3 processes and on one, and a one-process archive
    continues on 2; each equals the uninterrupted one-process run to the solver's tolerance, and the checkpoint holds
    the one-process run's state."""
    values = dict(h=0.25, order=2, k=0.002, T=0.04, c_nu=50.0, traction_top="(0, 0, 20*t*ifpos(x-0.5, 1, -1))")
    script = tmp_path / "checkpoints.py"
    script.write_text(f"import workbench\nworkbench.run('block', checkpoint='cp.nc', checkpoint_every=7, "
                      f"progress=False, **{values!r})\n")
    p = subprocess.run([_mpiexec(), "-n", "2", sys.executable, str(script)], capture_output=True, text=True,
                       env=alone(), timeout=300, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    cp = workbench.load(tmp_path / "cp.nc")
    assert cp.attrs["status"] == "checkpoint" and cp.attrs["nsteps"] == 14 and cp.attrs["mpi_processes"] == 2
    straight = workbench.run("block", progress=False, **values)
    serial_cp = workbench.run("block", progress=False, **(values | {"T": 0.028}))
    assert _relative(cp.state_u.values, serial_cp.state_u.values) < 1e-8
    np.testing.assert_allclose(cp.state_step_limit_normal.values, serial_cp.state_step_limit_normal.values,
                               rtol=1e-8)
    code, _, stderr = _run_distributed(3, "block", {}, tmp_path / "on3.nc",
                                       extra=["--restart", str(tmp_path / "cp.nc"), "--set", "T=0.04"])
    assert code == 0, stderr
    on_one = workbench.run(restart=tmp_path / "cp.nc", T=0.04, checkpoint_every=0, progress=False)
    workbench.write(serial_cp, tmp_path / "serial.nc")
    code, _, stderr = _run_distributed(2, "block", {}, tmp_path / "from_one.nc",
                                       extra=["--restart", str(tmp_path / "serial.nc"), "--set", "T=0.04"])
    assert code == 0, stderr
    for ds in (workbench.load(tmp_path / "on3.nc"), on_one, workbench.load(tmp_path / "from_one.nc")):
        assert ds.attrs["restart_time"] == pytest.approx(0.028) and ds.sizes["time"] == straight.sizes["time"]
        for name in ("u_probe", "beta", "u_dofs", "state_u"):
            assert _relative(ds[name].values, straight[name].values) < 1e-8, name


@pytest.mark.mpi
def test_a_distributed_run_starts_mpi_polling_less_unless_the_user_said_otherwise(tmp_path):
    """Before MPI starts, world() sets MPICH's progress throttle (workbench.parallel.MPI_ENVIRONMENT: waiting ranks
    poll less and leave the cores to those that compute), and keeps a value the user gave (here rank 1's)."""
    script = tmp_path / "env.py"
    script.write_text("import os, sys\nfrom workbench.parallel import world\nw = world()\nassert 'mpi4py.MPI' in "
                      "sys.modules and w.size == 2\nopen(f'rank{w.rank}', 'w').write(os.environ["
                      "'MPIR_CVAR_CH4_PROGRESS_THROTTLE'])\n")  # (a file each: two ranks' prints interleaved)
    env = {key: value for key, value in alone().items() if not key.startswith("MPIR_CVAR_")}
    p = subprocess.run([_mpiexec(), "-n", "1", sys.executable, str(script), ":", "-n", "1", "-env",
                        "MPIR_CVAR_CH4_PROGRESS_THROTTLE", "0", sys.executable, str(script)], capture_output=True,
                       text=True, env=env, timeout=120, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert [(tmp_path / f"rank{rank}").read_text() for rank in (0, 1)] == ["1", "0"], p.stdout


@pytest.mark.mpi
def test_an_error_on_one_rank_ends_every_rank(tmp_path):
    """An unexpected error on rank 0 alone (injected in its serial view's setup) while rank 1 waits for it in an
    exchange: the command prints the traceback, says which rank failed and ends the job with a non-zero code, at once
    (before, rank 1 waited for ever)."""
    p = _mpi_script(tmp_path, 2, 120, "import sys\nimport workbench.parallel as p\norig = p.Shell.__init__\n\n\n"
                    "def failing(self, d, serial_mesh):\n    if p.world().root:\n"
                    "        raise RuntimeError('injected on rank 0')\n    orig(self, d, serial_mesh)\n\n\n"
                    "p.Shell.__init__ = failing\nsys.argv = ['workbench', 'run', 'block', '--h', '0.25', '--T', "
                    "'0.01', '--no-progress']\nfrom workbench.cli import console\nsys.exit(console())\n")
    assert p.returncode != 0 and "injected on rank 0" in p.stderr and "rank 0 of 2 failed" in p.stderr, p.stderr


@pytest.mark.mpi
def test_a_sweep_is_not_started_on_several_processes(tmp_path):
    """`mpiexec -n 2 workbench study ...` would run the whole sweep on every rank: one `error:` line, exit code 2."""
    cmd = [_mpiexec(), "-n", "2", sys.executable, "-m", "workbench.cli", "study", "tp1", "--k", "0.1", "0.05"]
    env = alone()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path)
    assert p.returncode == 2 and p.stderr.count("error:") == 1 and "one case" in p.stderr, p.stderr


def test_the_distributed_eigenvalue_iterations_agree_with_the_exact_eigenpair():
    """The step limit's eigenvalue on several processes comes from :func:`workbench.discrete.eigen.lanczos_largest`
    (Lanczos in the K_A inner product, full reorthogonalisation; with the gathered factor) or from
    :func:`workbench.discrete.eigen.lobpcg_smallest` (LOBPCG with the CG's preconditioner, no solves). Run here in one
    process on the slab's matrices with springs on the whole contact side (LOBPCG with a Jacobi preconditioner, far
    weaker than BDDC), both give the largest eigenvalue of K x = lambda K_A x of a dense solve (LAPACK) to 1e-6 and its
    eigenvector (1 - cos of the angle in the K inner product below 1e-6), and ARPACK's estimate (the serial one)."""
    import scipy.linalg as la
    import scipy.sparse as sp

    from workbench.discrete import discretisation, eigen, solvers

    d = discretisation.build(workbench.scene("tp5", h=0.05, c_nu=100.0))
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    KA = solvers.to_scipy(d.viscous.mat)[free][:, free]
    T = d.side.T_nu[:, free]
    K = (solvers.to_scipy(d.elastic.mat)[free][:, free] + T.T @ sp.diags(100.0 * d.side.weights) @ T).tocsr()
    mu, V = la.eigh(KA.toarray(), K.toarray())  # the smallest mu = 1 / lambda_max
    exact, v = 1.0 / mu[0], V[:, 0]
    factor = solvers.BandedCholesky(KA, np.arange(free.size))

    def solve(y):
        out = np.zeros_like(y)
        factor.solve(y, out)
        return out

    def angle(x):
        return 1.0 - abs(x @ (K @ v)) / np.sqrt((x @ (K @ x)) * (v @ (K @ v)))

    start = np.ones(free.size)
    lam, vec = eigen.lanczos_largest(lambda x: K @ x, lambda x: KA @ x, solve, lambda x, y: x @ y, start)
    assert abs(lam / exact - 1) < 1e-6 and angle(vec) < 1e-6
    jacobi = KA.diagonal()
    m, vec = eigen.lobpcg_smallest(lambda x: KA @ x, lambda x: K @ x, lambda r: r / jacobi, lambda x, y: x @ y,
                                   start)
    assert abs(1.0 / m / exact - 1) < 1e-6 and angle(vec) < 1e-6
    arpack, _ = eigen.largest_eigenvalue(K, KA, solve, start)
    assert abs(arpack / exact - 1) < 1e-6


@pytest.mark.slow
@pytest.mark.parallel(nprocs=[1, 2, 3])
def test_the_explicit_scheme_converges_to_the_semi_discrete_solution_on_any_number_of_processes(nprocs):
    """One test body, run on one process and under mpiexec (the ``parallel`` marker, tests/conftest.py): the block
    without contact under the traction t (0, 0, 1) on its top is K_A u' + K_G u = t F1, whose exact-in-time solution
    on the same mesh is the modal sum (:func:`workbench.references.modal_linear`, each rank builds it on the serial
    mesh). The explicit scheme at k and k/2 converges to it at first order (observed 0.9-1.1; measured 1.02 with
    errors 13 % and 6.5 % of max |u| at T = 0.05, capped at 8 %), the same on every process count (the distributed
    solve: BDDC-preconditioned CG)."""
    from workbench.discrete import discretisation, solvers
    from workbench.parallel import world
    from workbench.references import modal_linear

    values = dict(h=0.25, order=2, contact=False, adhesion=False, traction_top="(0, 0, t)", T=0.05, snapshots=())
    sc = workbench.scene("block", **values)
    runs = []
    for k in (0.005, 0.0025):
        ds = workbench.run(sc, k=k, progress=False)
        assert (ds is None) == (not world().root)  # rank 0 holds the Dataset
        if ds is not None:
            assert ds.attrs["mpi_processes"] == nprocs
            runs.append(ds.u_dofs.values[-1])
    if runs:  # (the reference on rank 0 alone, on the serial mesh: the other ranks would only compete for the cores)
        d = discretisation.build(sc)
        F1 = d.u.vec.CreateVector()
        d.load_vector(1.0, F1)
        free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
        exact = modal_linear(solvers.to_scipy(d.viscous.mat).toarray(), solvers.to_scipy(d.elastic.mat).toarray(),
                             F1.FV().NumPy().copy(), free)(sc["T"])
        errors = [np.abs(u - exact).max() / np.abs(exact).max() for u in runs]
        order = np.log(errors[0] / errors[1]) / np.log(2.0)
        assert 0.9 <= order <= 1.1 and errors[1] < 0.08, (errors, order)


_SIGNALLED_ON_RANK_1 = """
import os, sys
from workbench.cli import console
from workbench.schemes import stepping

advance, SIGNAL = stepping._advance, int(sys.argv.pop(1))
rank = int(os.environ.get("PMI_RANK", os.environ.get("OMPI_COMM_WORLD_RANK", "0")))

def advance_then_signal(scheme, steps, t_prev, t):
    if rank == 1 and t_prev >= 0.1 and not getattr(advance_then_signal, "sent", False):
        advance_then_signal.sent = True
        os.kill(os.getpid(), SIGNAL)
    return advance(scheme, steps, t_prev, t)

stepping._advance = advance_then_signal
sys.exit(console())
"""


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.parametrize("signum, code", [(2, 130), (15, 143)], ids=["SIGINT", "SIGTERM"])
def test_a_distributed_run_stopped_by_a_signal_writes_the_steps_it_took(tmp_path, signum, code):
    """Ctrl-C or SIGTERM under ``mpiexec -n 2``: each rank raised where it happened to be, so there was nothing to
    gather; nothing was written, every rank said "interrupted", and on two processes the run hung (an outside pass,
    December 2026). Now a signal asks every rank to stop after the current step, together: the steps recorded are
    written as a diverged run's are, with one error line and 128 + the signal's number, here with the signal sent to
    rank 1 alone at t = 0.1."""
    script = tmp_path / "signalled.py"
    script.write_text(_SIGNALLED_ON_RANK_1)
    p = subprocess.run([_mpiexec(), "-n", "2", sys.executable, str(script), str(signum), "run", "block", "--h", "0.2",
                        "--k", "0.01", "--T", "1", "--set", "scheme=implicit", "--no-progress", "-o", "a.nc"],
                       cwd=tmp_path, capture_output=True, text=True, env=alone(), timeout=300)
    assert p.returncode == code and "Traceback" not in p.stderr, p.stderr
    assert p.stderr.count("error:") == 1, p.stderr
    ds = workbench.load(tmp_path / "a.nc")
    assert ds.attrs["status"] == "incomplete" and ds.attrs["failure_type"] == "Interrupted"
    t = float(ds.time[-1])
    assert 0.1 < t < 0.3 and f"its steps to t = {t:g} s are kept" in ds.attrs["failure"]


@pytest.mark.mpi
@pytest.mark.slow
def test_a_step_far_above_the_limit_is_refused_as_such_on_several_processes(tmp_path):
    """The P2 block at h = 0.2 with k = 0.2 (about 4 k_crit): on one process a StepTooLarge with k_crit = 0.0519 s; on
    two, the state one trial step reaches made LOBPCG's mu settle so slowly that it was refused as "cannot be
    estimated", and allow_unstable could not run it (an outside pass, December 2026). Now the same refusal, with the
    same k_crit to 1e-2, and allow_unstable runs until the blow-up is caught, as on one process."""
    values = dict(h=0.2, k=0.2, T=1.0)
    code, _, stderr = _run_distributed(2, "block", values, tmp_path / "a.nc")
    assert code == 2 and "exceeds the predicted stability limit" in stderr, stderr
    with pytest.raises(workbench.ParameterError, match="exceeds the predicted stability limit") as serial:
        workbench.run("block", progress=False, **values)
    k_crit = [float(re.search(r"k_crit = ([0-9.e-]+) s", text).group(1)) for text in (stderr, str(serial.value))]
    assert k_crit[0] == pytest.approx(k_crit[1], rel=1e-2), k_crit
    code, _, stderr = _run_distributed(2, "block", dict(values, allow_unstable=True), tmp_path / "b.nc")
    assert code == 3 and workbench.load(tmp_path / "b.nc").attrs["status"] == "incomplete", stderr
