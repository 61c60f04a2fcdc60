"""Bad input is refused before any work, with a message naming the parameter and the allowed range."""
import math
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

import workbench
from workbench import ParameterError
from workbench.expressions import ExpressionError, parse

BAD = [
    ("slab", dict(E=0), "E = 0 is outside the allowed range 0 < E"),
    ("slab", dict(E=-5), "0 < E"),
    ("slab", dict(a2=0), "0 < a2"),
    ("slab", dict(a1=-1), "0 <= a1"),
    ("rod", dict(a=0), "0 < a"),
    ("rod", dict(b=-1), "0 < b"),
    ("slab", dict(nu=0.5), "-1 < nu < 0.5"),
    ("slab", dict(nu=-1.0), "-1 < nu < 0.5"),
    ("tp1", dict(beta0=0.0), "0 < beta0 <= 1"),
    ("tp1", dict(beta0=1.5), "0 < beta0 <= 1"),
    ("tp1", dict(L=0), "0 < L"),
    ("tp1", dict(k=0), "0 < k"),
    ("tp1", dict(k=-0.1), "0 < k"),
    ("tp1", dict(k=2.0), "k = 2 is larger than T = 1"),
    ("tp1", dict(gamma_nu=-0.1), "0 <= gamma_nu"),
    ("tp1", dict(eps_a=-1e-3), "0 <= eps_a"),
    ("tp1", dict(c_nu=-1), "0 <= c_nu"),
    ("tp1", dict(gap=-0.01), "0 <= gap"),
    ("tp1", dict(h=0), "0 < h"),
    ("tp1", dict(T=float("nan")), "T = nan is not finite"),
    ("tp1", dict(gamma_nu=float("inf")), "not finite"),
    ("tp1", dict(order=0), "1 <= order <= 4"),
    ("tp1", dict(bonding_truncation="tensile"), "did you mean 'tension'"),
    ("tp1", dict(gama_nu=1), "unknown parameter 'gama_nu' for scene 'tp1'; did you mean 'gamma_nu'?"),
    ("tp1", dict(E=1000), "unknown parameter 'E'"),  # a rod has a, b, not E
    ("tp1", dict(delta="-0.6*x"), "unknown name 'x' (allowed variables: t"),
    ("tp1", dict(delta="sinn(t)"), "unknown function 'sinn'"),
    ("tp1", dict(u0="-0.5"), "compatibility"),
    ("slab", dict(traction_top="(0, 1"), "syntax error"),
    ("slab", dict(traction_top="(0, 1, 2)"), "has 3 component(s), 2 are needed"),
    ("slab", dict(traction_top="(0, __import__('os'))"), "unknown function"),
    ("slab", dict(traction_top="(0, t.real)"), "Attribute is not allowed"),
    ("slab", dict(traction_top="(0, tt)"), "unknown name 'tt'"),
    ("slab", dict(probes="(2, 0)"), "not inside the body"),
    ("slab", dict(snapshots="0.5, 3"), "after T"),
    ("slab", dict(contact="maybe"), "not a flag"),
]


@pytest.mark.parametrize("name, overrides, message", BAD)
def test_bad_input_named_error(name, overrides, message):
    with pytest.raises(ParameterError) as err:
        workbench.run(name, progress=False, **overrides)
    assert message in str(err.value)


def test_unknown_scene_suggests():
    with pytest.raises(ParameterError, match="unknown scene 'tp6'.*did you mean"):
        workbench.scene("tp6")


def test_toml_scene(tmp_path):
    f = tmp_path / "pulled.toml"
    f.write_text('scene = "slab"\ndescription = "pulled slab"\n[parameters]\nE = 2000\nk = 0.002\nT = 0.01\n'
                 '[traction]\ntop = "(0, 2*t)"\n')
    sc = workbench.scene(f, gamma_nu=0.5)
    assert sc.name == "pulled" and sc["E"] == 2000 and sc["gamma_nu"] == 0.5
    assert str(sc["traction_top"]) == "(0, 2*t)"
    ds = workbench.run(f, h=0.1, progress=False)
    assert ds.attrs["scene"] == "pulled" and ds.attrs["E"] == 2000


@pytest.mark.parametrize("text, message", [
    ('scene = "slab"\n[traction]\ntopp = "(0, 1)"\n', "unknown boundary 'topp' in [traction] for a slab; loadable boundaries: top, right; did you mean 'top'?"),
    ('scene = "slab"\n[parameters]\nEE = 5\n', "unknown parameter 'EE'"),
    ('scene = "slab"\n[params]\nE = 5\n', "unknown top-level key 'params'"),
    ('[parameters]\nE = 5\n', "give the built-in scene"),
    ('scene = "slab"\n[parameters]\nE = \n', "Invalid value"),
])
def test_bad_toml(tmp_path, text, message):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ParameterError) as err:
        workbench.scene(f)
    assert message in str(err.value)


def test_expression_grammar():
    e = parse("(-10*sin(50*t), -sin(50*t))", name="traction_top", size=2)
    assert np.allclose(e(t=0.1), [-10 * math.sin(5), -math.sin(5)])
    assert parse("ifpos(x - 0.5, 2^2, exp(0))")(x=np.array([0.2, 0.7])).tolist() == [1.0, 4.0]
    assert parse("sqrt(abs(-4)) + pi")() == pytest.approx(2 + math.pi)
    for bad in ["", "lambda: 1", "[1, 2]", "x if t else y", "1 < 2", "'a'", "open('f')", "1e400"]:
        with pytest.raises(ExpressionError):
            parse(bad, name="f")


def test_archive_round_trip(tmp_path):
    ds = workbench.run("tp5", h=0.05, k=0.01, T=0.1, snapshots=(0.05,), progress=False)
    path = workbench.write(ds, tmp_path / "sub" / "tp5.nc")
    xr.testing.assert_identical(workbench.load(path), ds)
    assert not [p for p in path.parent.iterdir() if p.name != "tp5.nc"]  # no temporary left behind


def test_run_attrs_contract():
    ds = workbench.run("tp4", h=0.05, k=0.01, T=0.05, progress=False)
    for var in ("u_probe", "u_contact", "beta", "time"):
        assert ds[var].attrs["units"] and ds[var].attrs["long_name"]
    for key in ("gamma_nu", "eps_a", "L", "beta0", "c_nu", "m_nu", "gap", "c_tau", "bonding_truncation", "E",
                "nu", "a1", "a2", "T", "k", "h", "order", "scheme", "ndof", "wall_time", "version_ngsolve",
                "status", "h_max", "nsteps"):
        assert key in ds.attrs, key
    assert set(ds.u_probe.dims) == {"time", "probe", "component"} and "facet_x" in ds.coords
    assert ds.attrs["status"] == "complete" and ds.attrs["contact"] == 1


@pytest.mark.slow
def test_divergence_stops_and_keeps(tmp_path):
    """An unstable explicit run stops at the first bad step; the steps before are kept and marked."""
    with pytest.warns(RuntimeWarning, match="allow_unstable"), pytest.raises(workbench.Diverged) as err:
        workbench.run("slab", h=0.05, k=0.01, c_nu=1e7, traction_top="(0, -1)", allow_unstable=True, progress=False)
    ds = err.value.dataset
    assert ds.attrs["status"] == "incomplete" and "at step" in ds.attrs["failure"]
    assert f"step {err.value.step} " in str(err.value) and "t = " in str(err.value)
    assert 0 < ds.sizes["time"] <= err.value.step and np.isfinite(ds.u_probe.values).all()
    out = tmp_path / "bad.nc"
    proc = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "slab", "--h", "0.05", "--k", "0.01",
                           "--set", "c_nu=1e7", "--set", "traction_top=(0, -1)", "--set", "allow_unstable=true",
                           "-o", str(out), "--no-progress"],
                          capture_output=True, text=True)
    assert proc.returncode == 3 and "error:" in proc.stderr
    assert workbench.load(out).attrs["status"] == "incomplete"
    assert " of 100 steps" in proc.stdout  # the steps it kept, of those planned (it said "100 steps")
    proc = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "slab", "--h", "0.05", "--k", "0.01",
                           "--set", "c_nu=1e7", "--set", "traction_top=(0, -1)", "-o", str(tmp_path / "refused.nc")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "k_crit" in proc.stderr and not (tmp_path / "refused.nc").exists()


def test_divergence_message_states_the_limit_used():
    """The bound in the Diverged message is the one used: a given ``limit`` (it said "10 x the body" whatever the
    limit); the default, 10 x the body's largest extent, says so. A limit that is not a number > 0 is refused."""
    with pytest.raises(workbench.Diverged) as err:
        workbench.run("tp1", k=0.05, h=0.1, limit=1e-3, progress=False)
    message = str(err.value)
    assert "beyond the bound 0.001 m (limit = 0.001 m, as given)" in message and "10 x" not in message
    with pytest.raises(workbench.Diverged, match=r"beyond the bound 10 m \(10 x the body's largest extent, the "
                                                 r"default limit\)"):
        workbench.run("tp1", k=0.05, h=0.1, delta="-0.6 - 100*t", progress=False)
    for bad in (0, -1.0, "1"):
        with pytest.raises(ParameterError, match="limit = "):
            workbench.run("tp1", k=0.05, limit=bad, progress=False)


@pytest.mark.parametrize("module", ["workbench", "workbench.input.geometry", "workbench.physics.kelvin_voigt",
                                    "workbench.physics.laws", "workbench.input.scenes", "workbench.input.models", "workbench.cli"])
def test_checking_a_scene_does_not_import_ngsolve(module):
    """``import workbench`` is lazy so that ``workbench scenes`` / ``show`` and a scene's checks start at once; the
    geometry and the material tensors imported NGSolve at module level (so did every scene). NGSolve is imported
    where a mesh or a form is made. Each in a fresh interpreter."""
    code = (f"import sys, workbench; import {module}; sc = workbench.scene('slab', plane='strain'); sc.model_of(); "
            "print('ngsolve' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["False"], f"importing {module} (and checking a scene) imported ngsolve"


@pytest.mark.slow
def test_cli(tmp_path):
    run = lambda *a: subprocess.run([sys.executable, "-m", "workbench.cli", *a], capture_output=True, text=True)  # noqa: E731
    p = run("scenes")
    assert p.returncode == 0 and all(n in p.stdout for n in ("tp1", "tp5", "block"))
    p = run("show", "tp5")
    assert p.returncode == 0 and "gamma_nu" in p.stdout and "Pa/m" in p.stdout
    p = run("run", "tp1", "--set", "gama_nu=1")
    assert p.returncode == 2 and "did you mean 'gamma_nu'" in p.stderr
    out, png = tmp_path / "tp1.nc", tmp_path / "tp1.png"
    p = run("run", "tp1", "--k", "0.05", "--set", "gamma_nu=0.5", "-o", str(out), "--plot", str(png))
    assert p.returncode == 0, p.stderr
    ds = workbench.load(out)
    assert ds.attrs["gamma_nu"] == 0.5 and ds.attrs["k"] == 0.05 and png.stat().st_size > 10_000


def test_cli_main_in_a_session_does_not_leak_its_command_line(tmp_path):
    """`workbench.cli.main([...])` called in-process (a notebook, a test) marks its own archives with its command, and
    a later library call is recorded as that call, not as the command that ran before it."""
    from workbench import cli

    assert cli.main(["run", "tp1", "--h", "0.1", "--k", "0.1", "-o", str(tmp_path / "a.nc"), "--no-progress"]) == 0
    assert "workbench run tp1" in workbench.load(tmp_path / "a.nc").attrs["history"]
    later = workbench.run("tp1", h=0.1, k=0.1, progress=False).attrs["history"]
    assert "workbench.run('tp1', h=0.1, k=0.1)" in later and "workbench run" not in later


@pytest.mark.parametrize("text", [
    "(0, 5*t*ifpos(x - 0.5, 1, 0))", "2**-1 + pi*sin(t)^2 - -3", "sqrt(abs(x - y)) / (1 + t)**1.5 + exp(-z)",
    "ifpos(sin(2*pi*t), -x, +y) * log(2 + x*x)", "1/3*x + 2/7", "(1 + t/0.05)**(-1.5)", "-(-(x))", "7",
])
def test_compiled_expressions_equal_the_tree_walk_bitwise(text):
    """Loads are evaluated every step from the checked trees compiled once; the result is the tree walk's, bit for
    bit, on scalars and arrays (numbers taken as floats alike)."""
    from workbench.expressions import _walk

    expr = parse(text, allowed=("x", "y", "z", "t"))
    rng = np.random.default_rng(3)
    x, y, z = rng.uniform(-1, 2, (3, 50))
    funcs = {"sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp, "log": np.log, "sqrt": np.sqrt,
             "abs": np.abs, "ifpos": lambda a, b, c: np.where(np.asarray(a) > 0, b, c)}
    for env in ({"x": x, "y": y, "z": z, "t": 0.37}, {"x": 0.3, "y": -0.2, "z": 1.0, "t": 2.0}):
        walked = [np.asarray(_walk(term, env, funcs, float), dtype=float) for term in expr.terms]
        got = np.asarray(expr(**env), dtype=float)
        want = walked[0] if len(walked) == 1 else np.stack([np.broadcast_to(w, np.broadcast(*walked).shape)
                                                            for w in walked])
        assert np.array_equal(got, want, equal_nan=True), (text, got, want)


def test_expressions_pickle_after_use():
    """Scenes travel to study workers by pickle: an expression that has been evaluated (and so compiled) pickles,
    and evaluates alike after the trip."""
    import pickle

    expr = parse("(0, 5*t*ifpos(x - 0.5, 1, 0))", allowed=("x", "y", "z", "t"))
    before = expr(x=np.array([0.2, 0.7]), t=0.3)
    again = pickle.loads(pickle.dumps(expr))
    assert again.source == expr.source and np.array_equal(again(x=np.array([0.2, 0.7]), t=0.3), before)
    sc = workbench.scene("tp5")
    workbench.run(sc, h=0.1, k=0.05, T=0.1, progress=False)
    pickle.loads(pickle.dumps(sc))
