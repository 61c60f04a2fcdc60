"""Restart and checkpoints (issue 14): a continued run is the uninterrupted run, bitwise.

A run to T/2 continued from its archive to T takes the same steps from the same state as the
run straight to T (the fixed grid of T, entered at the archive's step; the error controller's
state; the scheme's full state: u, v, beta, history, memory, active set, and the step sizes its
cached factorisations were built from), so every recorded number is the same bit for bit, not
only to round-off. The same holds for a run killed (SIGKILL) at random moments and continued
from its last checkpoint each time. Anything but T and the output options that differs from the
archive is refused before any work, with every difference listed.
"""
import json
import os
import random
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.running.restart import NoRestartState, has_state, without_state

ROOT = Path(__file__).resolve().parents[1]
#: What must be equal bitwise: every record (and, with error control, the steps) and the snapshot fields.
COMPARED = ("time", "step", "u_probe", "u_contact", "beta", "contact_pressure", "contact_state", "step_size",
            "error_estimate", "newton_iterations", "iterations", "u_dofs", "stress")

#: (scene, T, values): one per scheme and dimension; k = 0.01-like steps (not powers of 2), so that grid steps differ in
#: their last bits and a factorisation rebuilt from another step's a0 would show.
CASES = {
    "explicit-rod-1D": ("tp1", 1.0, dict(h=0.1, k=0.01)),
    "explicit-slab-2D": ("tp5", 0.2, dict(h=0.1, k=0.01)),
    "implicit-slab-2D": ("tp5", 0.2, dict(h=0.1, k=0.01, scheme="implicit")),
    "bdf2-slab-2D": ("tp5", 0.2, dict(h=0.1, k=0.01, scheme="bdf2")),
    # error control lands on T/2 as a snapshot in both runs (a run to T/2 lands on its T there)
    "adaptive-bdf2-slab": ("slab", 0.5, dict(h=0.1, order=1, k=1e-3, scheme="bdf2", rtol=1e-3, gamma_nu=20.0,
                                             traction_top="(0, 5*t)", snapshots=(0.25,))),
    "vi-prony-slab": ("memory_slab", 1.0, dict(h=0.25)),
    # (the banded factor: NGSolve's sparsecholesky, which auto picks here, factors one matrix differently from one
    # factorisation to the next, by 1e-14 relative, so no two runs with it agree bitwise; docs/conventions.md)
    # (the condensed contact solver: the coupled one remembers Krylov directions that an archive does not keep, so
    # its continued runs equal the straight run to the solver's tolerance, tests/test_coupled_contact.py)
    "vi-P2-hertz-curved": ("memory_hertz", 1.0, dict(order=2, h_contact=0.01, prony=((-300.0, 0.3, 0.5),),
                                                     solver="banded", contact_solver="condensed")),
    "vi-kernel-rod": ("memory_rod", 1.0, dict(h=0.1, kernel="exp(-t/0.2)", kernel_E=0.5, prony=())),
    "implicit-block-3D": ("block", 0.04, dict(h=0.25, k=0.005, scheme="implicit")),
}


def assert_same_run(ds, straight):
    for name in COMPARED:
        if name in straight:
            assert name in ds, name
            assert np.array_equal(ds[name].values, straight[name].values, equal_nan=True), name


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("case", list(CASES))
def test_continued_run_equals_the_straight_run(case, tmp_path):
    """run to T/2, archive, continue to T: every record, step and snapshot field equals the run straight to T."""
    scene, T, values = CASES[case]
    half = workbench.run(scene, T=T / 2, progress=False, **values)
    assert half.attrs["status"] == "complete" and has_state(half)
    path = workbench.write(half, tmp_path / "half.nc")
    ds = workbench.run(scene, restart=path, T=T, progress=False, **values)
    straight = workbench.run(scene, T=T, progress=False, **values)
    assert float(half.time[-1]) == T / 2 and ds.attrs["restart_time"] == T / 2
    assert ds.sizes["time"] == straight.sizes["time"] > half.sizes["time"]
    assert_same_run(ds, straight)
    if values.get("rtol"):
        assert ds.attrs["accepted_steps"] == straight.attrs["accepted_steps"]
        assert ds.attrs["rejected_steps"] == straight.attrs["rejected_steps"]
    assert ds.attrs["restarted_from"] == str(path) and len(ds.attrs["history"].splitlines()) == 2
    # the continued archive holds the final state: it is the straight run's (and can be continued again)
    # (the explicit scheme keeps no history of accepted states: it has no error control or multistep formula)
    names = ("state_u", "state_v") + (("state_history_u",) if ds.attrs["scheme"] != "explicit" else ())
    for name in names:
        assert np.array_equal(ds[name].values, straight[name].values), name
    assert ("state_history_u" in ds) == ("state_history_u" in straight)


def test_restart_from_the_archive_alone_on_the_command_line(tmp_path):
    """`workbench run --restart OLD.nc --set T=NEW_T -o NEW.nc` (no scene: the archive's) equals the straight run."""
    values = dict(h=0.1, k=0.01, scheme="implicit", snapshots=())
    workbench.write(workbench.run("tp5", T=0.1, progress=False, **values), tmp_path / "old.nc")
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "--restart", str(tmp_path / "old.nc"), "--set",
                        "T=0.2", "--no-progress", "-o", str(tmp_path / "new.nc")], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    ds = workbench.load(tmp_path / "new.nc")
    assert_same_run(ds, workbench.run("tp5", T=0.2, progress=False, **values))
    assert ds.attrs["history"].splitlines()[1].endswith(f"-o {tmp_path / 'new.nc'}")


def test_checkpoints_are_written_during_the_run_and_continue_it(tmp_path):
    """checkpoint_every = 7 leaves, in the checkpoint file, the archive at the last multiple of 7 steps (status
    'checkpoint', its state); continued from it, the run equals the uninterrupted one. Without a file: refused."""
    values = dict(h=0.1, k=0.01, T=0.2, scheme="bdf2", snapshots=(0.1,))
    path = tmp_path / "run.nc"
    straight = workbench.run("tp5", checkpoint=path, checkpoint_every=7, progress=False, **values)
    cp = workbench.load(path)
    assert cp.attrs["status"] == "checkpoint" and cp.attrs["nsteps"] == 14 and has_state(cp)
    assert np.isclose(float(cp.time[-1]), 0.14) and cp.sizes["snapshot"] == 1  # the snapshot at 0.1 s
    ds = workbench.run("tp5", restart=path, checkpoint=path, checkpoint_every=7, progress=False, **values)
    assert_same_run(ds, straight)
    with pytest.raises(workbench.ParameterError, match="^checkpoint_every = 7 needs a file"):
        workbench.run("tp5", checkpoint_every=7, progress=False, **values)


def test_a_checkpoint_continued_without_a_file_says_the_value_is_the_archives(tmp_path):
    """A checkpoint continued as the docs show, ``workbench.run(restart=PATH)``, inherits the archive's
    checkpoint_every: the refusal names it as the archive's and says how to go on (the archive's path, or
    checkpoint_every=0, which continues without checkpoints to the straight run's numbers)."""
    values = dict(h=0.1, k=0.01, T=0.1, scheme="bdf2")
    path = tmp_path / "run.nc"
    straight = workbench.run("tp5", checkpoint=path, checkpoint_every=4, progress=False, **values)
    refusal = r"^the archive's checkpoint_every = 4 needs a file.*checkpoint=PATH; the archive's own path.*= 0 to"
    with pytest.raises(workbench.ParameterError, match=refusal):
        workbench.run(restart=path, progress=False)
    assert_same_run(workbench.run(restart=path, checkpoint_every=0, progress=False), straight)


def test_a_checkpoint_file_without_checkpoint_every_is_warned_about(tmp_path):
    """``workbench.run(..., checkpoint=PATH)`` with checkpoint_every = 0 wrote nothing there, silently (the reverse is
    refused): a warning says so and how to write; the command line's -o, which is its archive, is not warned about."""
    from workbench import cli

    with pytest.warns(RuntimeWarning, match=r"checkpoint = '.*cp\.nc': nothing is written there, checkpoint_every"):
        workbench.run("tp1", h=0.5, k=0.5, checkpoint=tmp_path / "cp.nc", progress=False)
    assert not (tmp_path / "cp.nc").exists()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cli.main(["run", "tp1", "--h", "0.5", "--k", "0.5", "--no-progress", "-o", str(tmp_path / "a.nc")]) == 0


def test_a_continuation_records_at_the_record_times_its_archive_was_given(tmp_path):
    """record_times off the grid of k (0.105, 0.155: the grid is made to contain them) are kept in the archive: a
    checkpoint continued without them takes the same steps and records at the same times as the straight run."""
    values = dict(h=0.1, k=0.01, T=0.2, scheme="bdf2", snapshots=())
    times = [0.0, 0.05, 0.105, 0.155, 0.2]
    path = tmp_path / "run.nc"
    straight = workbench.run("tp5", checkpoint=path, checkpoint_every=7, progress=False, record_times=times, **values)
    assert np.allclose(straight.time.values, times) and json.loads(straight.attrs["record_times"]) == times
    ds = workbench.run("tp5", restart=path, checkpoint=tmp_path / "on.nc", progress=False, **values)
    assert_same_run(ds, straight)


def test_a_run_on_a_grid_of_its_own_keeps_it_for_its_continuation(tmp_path):
    """A run given ``times=`` kept the grid nowhere (its history elides the middle of a long list): it could be
    neither continued nor run again from its archive (an outside pass). The grid is now in its restart state
    (``state_time_grid``): a checkpoint continued without ``times=`` takes the straight run's steps, and a later T
    off the grid is refused naming it."""
    grid = np.unique(np.r_[0.0, np.geomspace(1e-3, 0.2, 30), 0.1])
    values = dict(h=0.1, scheme="implicit", T=0.2, record_times=[0.1, 0.2], progress=False)
    path = tmp_path / "run.nc"
    straight = workbench.run("tp4", times=grid, checkpoint=path, checkpoint_every=9, **values)
    np.testing.assert_array_equal(straight.state_time_grid.values, grid)
    assert workbench.load(path).attrs["status"] == "checkpoint"
    ds = workbench.run(restart=path, checkpoint=tmp_path / "on.nc", progress=False)
    assert_same_run(ds, straight)
    with pytest.raises(workbench.ParameterError, match=r"its own time grid \(times=.*T = 0.3 is not one of its times"):
        workbench.run(restart=path, T=0.3, checkpoint_every=0, progress=False)
    # (a grid under error control, which chooses its own steps, was ignored without a word: an outside pass)
    with pytest.raises(workbench.ParameterError, match="a grid fixes the steps, error control chooses them"):
        workbench.run("tp4", times=grid, **(values | dict(rtol=1e-3)))


@pytest.mark.parametrize("how", ["continued in place", "checkpoints"])
def test_a_run_that_stops_leaves_the_state_it_went_on_from(tmp_path, capsys, how):
    """``workbench run --restart OUT.nc -o OUT.nc`` (and a run writing checkpoints to OUT.nc) that diverges wrote its
    incomplete archive over OUT.nc: an archive without a state, so the state it went on from (the last checkpoint)
    was gone. Now the stopped run goes beside it (OUT.stopped.nc, incomplete) and OUT.nc still continues."""
    from workbench import cli

    out = tmp_path / "out.nc"
    growing = ["run", "tp4", "--h", "0.1", "--k", "0.01", "--scheme", "implicit", "--no-progress",
               "--set", "point_force=(0, exp(8*t))"]  # (beyond 10 x the body's extent at t = 0.34)
    if how == "continued in place":
        assert cli.main([*growing, "--T", "0.2", "-o", str(out)]) == 0
        assert cli.main(["run", "--restart", str(out), "--T", "1", "-o", str(out), "--no-progress"]) == 3
        last = 0.2
    else:
        assert cli.main([*growing, "--T", "1", "--set", "checkpoint_every=10", "-o", str(out)]) == 3
        last = 0.3
    said = capsys.readouterr().out
    assert f"wrote {tmp_path / 'out.stopped.nc'} (incomplete" in said and f"{out} keeps the state" in said, said
    kept, stopped = workbench.load(out), workbench.load(tmp_path / "out.stopped.nc")
    assert has_state(kept) and float(kept.time[-1]) == pytest.approx(last)
    assert stopped.attrs["status"] == "incomplete" and float(stopped.time[-1]) == pytest.approx(0.33)
    assert workbench.run(restart=out, T=0.33, checkpoint_every=0, progress=False).attrs["status"] == "complete"


KILL_RUN = ["run", "tp5", "--scheme", "bdf2", "--h", "0.05", "--k", "0.001", "--T", "1", "--no-progress",
            "--set", "checkpoint_every=25"]


@pytest.mark.slow
def test_killed_runs_continue_from_their_checkpoints(tmp_path):
    """SIGKILL at random moments, at least 10 times: just after a checkpoint, in the middle of writing one (its
    temporary file exists: the previous checkpoint must survive intact), or anywhere (start-up, steps). Each time the
    same command plus --restart OUT.nc goes on from the last checkpoint; the end result equals the uninterrupted run
    (without checkpoints)."""
    def launch(*extra):
        return subprocess.Popen([sys.executable, "-m", "workbench.cli", *KILL_RUN, *extra], stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)

    out = tmp_path / "out.nc"

    def version():
        try:
            st = os.stat(out)
            return st.st_ino, st.st_mtime_ns  # a checkpoint is a new file renamed over the old one
        except FileNotFoundError:
            return None

    rng = random.Random(14)
    kills, progress = 0, []
    while True:
        before = version()
        p = launch("-o", str(out), *(["--restart", str(out)] if before else []))
        mode, at, t0 = (kills % 3 if kills < 10 else None), rng.uniform(0.1, 1.3), time.perf_counter()
        while p.poll() is None and mode is not None:
            new = version() not in (None, before)
            if mode == 0 and new:  # a moment after a checkpoint: in the steps
                time.sleep(rng.uniform(0.0, 0.1))
                break
            if mode == 1 and new and any(f.startswith(f".out.nc.{p.pid}.") for f in os.listdir(tmp_path)):
                break  # while this process writes its next checkpoint
            if mode == 2 and time.perf_counter() - t0 > at:
                break
            time.sleep(0.001)
        if p.poll() is not None or mode is None:
            assert p.wait() == 0, p.stderr.read()
            break
        p.send_signal(signal.SIGKILL)
        p.wait()
        kills += 1
        if out.exists():  # whatever the moment, the file is a whole archive that can be continued
            cp = workbench.load(out)
            assert has_state(cp) and cp.attrs["status"] == "checkpoint"
            progress.append(int(cp.attrs["nsteps"]))
    assert kills >= 10 and len(set(progress)) >= 3, progress
    # the reference: the same run straight through, in this process and without checkpoints (writing them changes
    # nothing, and this saves a second process and its 40 checkpoint writes)
    ref_ds = workbench.run("tp5", scheme="bdf2", h=0.05, k=0.001, T=1, progress=False)
    ds = workbench.load(out)
    assert ds.attrs["status"] == "complete"
    assert_same_run(ds, ref_ds)
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]  # the killed writers' temporaries are gone


# -- refusals ---------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def archives(tmp_path_factory):
    folder = tmp_path_factory.mktemp("archives")
    return {"tp5": workbench.write(workbench.run("tp5", h=0.1, k=0.01, T=0.1, progress=False), folder / "tp5.nc"),
            "rod": workbench.write(workbench.run("memory_rod", h=0.1, T=0.2, kernel="exp(-t/0.2)", kernel_E=0.5,
                                                 prony=(), progress=False), folder / "rod.nc")}


@pytest.mark.parametrize("archive, change, listed", [
    ("tp5", {"E": 2000}, "E 1000 -> 2000"),
    ("tp5", {"h": 0.05}, "h 0.1 -> 0.05"),
    ("tp5", {"order": 2}, "order 1 -> 2"),
    ("tp5", {"scheme": "implicit"}, "scheme explicit -> implicit"),
    ("tp5", {"snapshots": (0.05,)}, "snapshots [0.1] -> [0.05]"),  # (one before the archive's time)
    ("rod", {"kernel": "exp(-t/0.3)"}, "kernel exp(-t/0.2) -> exp(-t/0.3)"),
])
def test_restart_refuses_any_other_value(archives, change, listed, archive, tmp_path):
    with pytest.raises(workbench.ParameterError, match="differs from the archive's in") as err:
        workbench.run(restart=archives[archive], checkpoint=tmp_path / "new.nc", progress=False, **change)
    assert listed in str(err.value)
    assert not (tmp_path / "new.nc").exists()


def test_restart_refuses_an_earlier_T_and_another_grid(archives, tmp_path):
    with pytest.raises(workbench.ParameterError, match="T = 0.05 is before the archive's time t = 0.1 s"):
        workbench.run(restart=archives["tp5"], T=0.05, progress=False)
    # without a snapshot at 0.1 s, the grid to 0.205 is 21 steps of 0.00976 s: 0.1 s is not one of its points
    path = workbench.write(workbench.run("tp5", h=0.1, k=0.01, T=0.1, snapshots=(), progress=False), tmp_path / "a.nc")
    with pytest.raises(workbench.ParameterError, match="is not step 10 of the time grid to T = 0.205"):
        workbench.run(restart=path, T=0.205, progress=False)
    # a snapshot at 0.1 s does not change that: it splits a step of the grid to 0.205 (whose steps do not move), so
    # 0.1 s is a point of that grid but the steps before it are not the archive's; to 0.2 s they are
    with pytest.raises(workbench.ParameterError, match="time grid to T = 0.205"):
        workbench.run(restart=archives["tp5"], T=0.205, progress=False)
    assert workbench.run(restart=archives["tp5"], T=0.2, progress=False).attrs["nsteps"] == 20


def test_an_archive_whose_records_were_cut_is_not_continued(archives, tmp_path):
    """An archive cut with ``ds.isel(time=...)`` keeps its state at the run's last time: continued, its records went
    on from there with a gap from the cut, without a word. Refused, saying where its records end and where its run
    recorded up to; the archive as written continues."""
    ds = workbench.load(archives["tp5"])
    cut = workbench.write(ds.isel(time=slice(0, 4)), tmp_path / "cut.nc")
    with pytest.raises(NoRestartState, match=r"its records end at t = 0\.03 s, but its run recorded up to "
                                                       r"t = 0\.1 s \(records cut"):
        workbench.run(restart=cut, T=0.2, progress=False)
    assert workbench.run(restart=archives["tp5"], T=0.2, progress=False).attrs["status"] == "complete"


@pytest.mark.parametrize("archive, sets, listed", [
    ("tp5", ["E=2000", "h=0.05", "order=2", "scheme=implicit"],
     ["E 1000 -> 2000", "h 0.1 -> 0.05", "order 1 -> 2", "scheme explicit -> implicit"]),
    ("rod", ["kernel=exp(-t/0.3)"], ["kernel exp(-t/0.2) -> exp(-t/0.3)"]),
])
def test_cli_refusal_is_one_line_listing_every_difference_and_writes_nothing(archives, sets, listed, archive, tmp_path):
    old = Path(archives[archive])
    stamp = old.stat().st_mtime_ns
    args = [a for s in sets for a in ("--set", s)]
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "--restart", str(old), *args, "--no-progress",
                        "-o", str(tmp_path / "new.nc")], capture_output=True, text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: restart"), p.stderr
    assert all(item in lines[0] for item in listed), lines[0]
    assert not (tmp_path / "new.nc").exists() and old.stat().st_mtime_ns == stamp


def test_a_restart_naming_its_scene_goes_on_with_the_archives_values(archives, tmp_path):
    """Found as a new user would type it: ``workbench run tp5 --restart a.nc --T 0.2`` compared the preset's defaults
    (h = 0.0125, the archive's 0.1) with the archive and was refused for values the user never gave. The scene's name
    now names the archive's run: it goes on with the archive's values, as without the name (bitwise); another
    built-in name is refused, naming both, in one line and without a traceback."""
    plain = workbench.run(restart=archives["tp5"], T=0.2, progress=False)
    named = workbench.run("tp5", restart=archives["tp5"], T=0.2, progress=False)
    assert named.attrs["h"] == plain.attrs["h"] == 0.1 and named.attrs["nsteps"] == plain.attrs["nsteps"] == 20
    np.testing.assert_array_equal(named.u_contact.values, plain.u_contact.values)
    with pytest.raises(workbench.ParameterError, match="differs from the archive's in h 0.1 -> 0.05"):
        workbench.run("tp5", restart=archives["tp5"], T=0.2, h=0.05, progress=False)  # (a value given still counts)
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "tp1", "--restart", archives["tp5"], "--T", "0.2",
                        "--no-progress", "-o", str(tmp_path / "new.nc")], capture_output=True, text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert "the archive is a run of 'tp5', not 'tp1'" in p.stderr and not (tmp_path / "new.nc").exists()


def test_an_archive_without_state_is_a_named_error(archives, tmp_path):
    """An older archive (no state), one written without it, one of a diverged run: NoRestartState, saying so."""
    plain = workbench.write(without_state(workbench.load(archives["tp5"])), tmp_path / "plain.nc")
    with pytest.raises(NoRestartState, match="has no restart state: it was written before"):
        workbench.run(restart=plain, progress=False)
    older = ROOT / "data" / "refinement" / "rod_tp1.nc"  # a study's archive, written before restart states existed
    with pytest.raises(NoRestartState, match="has no restart state"):
        workbench.run(restart=older, progress=False)
    with pytest.raises(workbench.Diverged) as err, pytest.warns(RuntimeWarning, match="allow_unstable"):
        workbench.run("tp5", h=0.1, k=0.1, allow_unstable=True, progress=False)
    diverged = workbench.write(err.value.dataset, tmp_path / "diverged.nc")
    with pytest.raises(NoRestartState, match="its run stopped"):
        workbench.run(restart=diverged, progress=False)
    with pytest.raises(workbench.ParameterError, match="no such archive"):
        workbench.run(restart=tmp_path / "missing.nc", progress=False)
    p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "--restart", str(plain), "--no-progress"],
                       capture_output=True, text=True)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "no restart state" in p.stderr


def test_longer_T_is_refused_for_a_fitted_kernel_and_said_for_error_control(tmp_path):
    """Tried as a user would, on cases unlike the others (a loaded start, a power-law kernel, error control):
    an exponential-sum kernel is fitted on [0, T], so its memory histories do not continue to a longer T (continued
    anyway, u was 1 % off): refused, naming the fit; the quadrature of the same kernel continues bitwise. An
    error-controlled run landed on its own T, which a run straight to a longer T does not: continued, it warns that
    it is not bitwise (and stays within the tolerance's reach of the straight run)."""
    kw = dict(memory_rule="trapezoid", prony=(), kernel="(1 + t/0.05)**(-1.5)", kernel_E=-1000.0, kernel_nu=0.3,
              h=0.25, k=0.05, traction_top="(0, -20 - 10*t)", progress=False)
    fitted = workbench.write(workbench.run("memory_slab", T=0.5, kernel_approximation="exponentials", **kw),
                             tmp_path / "fitted.nc")
    with pytest.raises(workbench.ParameterError, match="fitted on \\[0, 0.5\\]"):
        workbench.run(restart=fitted, T=1.0, progress=False)
    quad = workbench.write(workbench.run("memory_slab", T=0.5, **kw), tmp_path / "quad.nc")
    a, b = workbench.run(restart=quad, T=1.0, progress=False), workbench.run("memory_slab", T=1.0, **kw)
    assert np.array_equal(a.u_contact, b.u_contact) and np.array_equal(a.contact_state, b.contact_state)
    slab = dict(scheme="bdf2", rtol=1e-3, k=0.02, order=2, h=0.1, traction_top="(0, 2 + 5*t)", progress=False)
    adaptive = workbench.write(workbench.run("slab", T=0.3, **slab), tmp_path / "adaptive.nc")
    with pytest.warns(RuntimeWarning, match="landed on its own T = 0.3"):
        c = workbench.run(restart=adaptive, T=0.6, progress=False)
    d = workbench.run("slab", T=0.6, **slab)
    tip = lambda ds: float(ds.u_probe.isel(probe=-1, time=-1).sel(component="y"))  # noqa: E731
    assert abs(tip(c) - tip(d)) <= 1e-3 * abs(tip(d))


@pytest.mark.parametrize("scene, values, T1, T2", [
    ("memory_slab", dict(h=0.2, k=0.02), 0.4, 0.8),        # the preset's snapshots 0.25, 0.75 split steps of 0.02
    ("hertz", dict(h=0.2, k=0.02), 0.3, 1.0),               # its snapshots 0.25, 0.75 too; Model A, implicit
    ("tp4", dict(T=0.1, k=0.01), 0.1, 0.37),                 # a T2 off the snapshot times, explicit
])
def test_a_run_to_any_later_T_continues_bitwise(tmp_path, scene, values, T1, T2):
    """Restart for every T: a run to T1 continued to T2 equals the run straight to T2, bitwise, also
    where the preset's snapshot times split steps (they were refused: the grid divided the stretches between
    snapshots evenly, so T1's steps were not T2's) and where the preset's snapshots beyond T1 come back at T2."""
    path = tmp_path / "first.nc"
    workbench.write(workbench.run(scene, progress=False, **dict(values, T=T1)), path)
    continued = workbench.run(restart=path, T=T2, progress=False)
    straight = workbench.run(scene, progress=False, **dict(values, T=T2))
    np.testing.assert_array_equal(continued.time.values, straight.time.values)
    np.testing.assert_array_equal(continued.u_contact.values, straight.u_contact.values)
    np.testing.assert_array_equal(continued.snapshot_time.values, straight.snapshot_time.values)
    np.testing.assert_array_equal(continued.u_dofs.values, straight.u_dofs.values)


def test_an_archive_that_does_not_say_what_its_user_gave_warns_of_nothing_they_did_not_give(tmp_path):
    """Archives written before ``set_by_user_json`` took every archived value as given on continuation, so each
    continued run warned about atol, k_min and k_max "without rtol", and space_adapt and the rest "without space_tol",
    values their user never set (found on data/reproduction's old archives). What the user gave is now read off the
    values: those the scene would not make by itself from the others (here h, k and T given; not the defaults, nor a
    Hertz scene's viscosity derived from its tau, nor snapshot times derived from T)."""
    from workbench.input import scenes
    from workbench.running.restart import archived_scene

    ds = workbench.run("tp1", h=0.1, k=0.02, T=0.2, progress=False)
    del ds.attrs["set_by_user_json"]
    old = workbench.write(ds, tmp_path / "old.nc")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (any warning fails the continuation)
        went_on = workbench.run(restart=old, T=0.4, progress=False)
    straight = workbench.run("tp1", h=0.1, k=0.02, T=0.4, progress=False)
    assert_same_run(went_on, straight)
    hertz = scenes.make("hertz3d", {"tau": 0.3, "load": "2*t"})
    archived = ds.copy()
    archived.attrs.update(scene="hertz3d", base_scene="hertz3d", parameters_json=json.dumps(hertz.plain()))
    assert archived_scene(archived).set_by_user == {"tau", "load"}
    assert archived_scene(archived).plain() == hertz.plain()
    assert archived_scene(archived, whole=True).set_by_user >= {"atol", "k_min", "tau", "a1"}


def test_an_archive_of_an_older_code_without_a_record_goes_on(tmp_path):
    """An archive of an older code that recorded no contact pressure (data/reproduction/tp4.nc as committed in
    2d3df64) was continued to its end and then failed: its pressure column was shorter than time's (found by an
    outside pass). The records it does not have are NaN, as for a diagnostic column, and the rest is the straight
    run's."""
    ds = workbench.run("tp4", h=0.1, k=0.01, T=0.1, progress=False)
    old = workbench.write(ds.drop_vars(["contact_pressure"]), tmp_path / "old.nc")
    went_on = workbench.run(restart=old, T=0.2, progress=False)
    straight = workbench.run("tp4", h=0.1, k=0.01, T=0.2, progress=False)
    n = ds.sizes["time"]
    assert went_on.sizes["time"] == straight.sizes["time"] and np.isnan(went_on.contact_pressure[:n]).all()
    np.testing.assert_array_equal(went_on.contact_pressure[n:], straight.contact_pressure[n:])
    np.testing.assert_array_equal(went_on.u_contact, straight.u_contact)


def test_a_restart_asking_for_later_snapshots_alone_says_what_to_give_and_a_stopped_run_its_steps(tmp_path):
    """Found by an outside pass: a restart asking only for a snapshot after the archive's time was refused as
    "snapshots [0.33] -> []", which named neither why nor what to give; and a stopped run's ``nsteps`` was the count
    planned, with nothing saying how many it took."""
    ds = workbench.run("memory_rod", h=0.25, k=0.1, T=1, snapshots=(0.3,), progress=False)
    workbench.write(ds, tmp_path / "a.nc")
    with pytest.raises(workbench.ParameterError, match=r"give them with the later ones, snapshots = 0.3, 1.5\)"):
        workbench.run(restart=tmp_path / "a.nc", T=2, snapshots=(1.5,), progress=False)
    assert workbench.run(restart=tmp_path / "a.nc", T=2, snapshots=(0.3, 1.5), progress=False).sizes["snapshot"] == 3
    assert ds.attrs["steps_taken"] == ds.attrs["nsteps"] == 10
    from workbench.schemes import stepping

    advance = stepping._advance

    def stop_after_four(scheme, steps, t_prev, t):
        if t_prev >= 0.35:
            raise KeyboardInterrupt
        return advance(scheme, steps, t_prev, t)

    stepping._advance = stop_after_four
    try:
        with pytest.raises(KeyboardInterrupt) as err:
            workbench.run("memory_rod", h=0.25, k=0.1, T=1, snapshots=(), progress=False)
    finally:
        stepping._advance = advance
    stopped = err.value.dataset.attrs
    assert stopped["nsteps"] == 10 and stopped["steps_taken"] == 4 and stopped["steps_taken_units"] == "1"
