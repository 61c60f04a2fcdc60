"""Bodies from mesh files and netgen geometry, with their boundaries given roles (issue 12).

References: the built-in scene of the same body and mesh (a mesh written to a gmsh file and read back has
the same vertices and elements, so the runs must agree bitwise); the named errors of docs/conventions.md.
"""
import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import workbench
from workbench.input import meshes
from workbench.errors import ParameterError

SLAB_ROLES = {"bottom": "contact", "left": "clamped", "top": "traction", "right": "free"}


def _same(a, b):
    for name in ("u_probe", "u_contact", "beta", "u_dofs"):
        if name in a:
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


@pytest.fixture(scope="module")
def slab_msh(tmp_path_factory):
    """The built-in slab's mesh (h = 0.05) as a gmsh file."""
    sc = workbench.scene("slab", h=0.05)
    return meshes.write_gmsh(sc.body.mesh(), tmp_path_factory.mktemp("mesh") / "slab.msh")


@pytest.mark.parametrize("order,scheme", [(1, "explicit"), (2, "implicit")])
def test_a_gmsh_file_gives_the_built_in_result(slab_msh, order, scheme):
    """tp5's physics on the slab read from a gmsh file equals the built-in tp5 bit for bit (P1 explicit, P2
    implicit; bonding, compliance and the load on the top)."""
    kw = dict(T=0.05, k=0.001 if scheme == "explicit" else 0.01, order=order, scheme=scheme, snapshots=(),
              progress=False)
    built_in = workbench.run("tp5", h=0.05, **kw)
    tp5 = workbench.scene("tp5")
    physics = {n: tp5[n] for n in ("E", "nu", "a1", "a2", "c_nu", "gamma_nu", "L", "eps_a", "beta0",
                                   "bonding_truncation", "adhesion")}
    sc = workbench.scene(mesh=str(slab_msh), boundaries=SLAB_ROLES, traction=tp5["traction_top"].source,
                         probes=tp5["probes"], **physics)
    from_file = workbench.run(sc, **kw)
    assert sc.name == "mesh2d" and not sc.body.curved
    _same(built_in, from_file)


def test_a_mesh_object_and_a_netgen_file_give_the_built_in_result(tmp_path):
    """Model B: memory_slab's mesh passed as an NGSolve mesh (stored as a .vol in the cache) and named in a TOML
    file as a netgen .vol geometry give memory_slab's result."""
    ms = workbench.scene("memory_slab", h=0.25)
    kw = dict(T=0.1, k=0.05, progress=False)
    built_in = workbench.run(ms, **kw)
    roles = SLAB_ROLES
    physics = {n: ms[n] for n in ("E", "nu", "gap", "F", "c", "prony")}
    sc = workbench.scene(mesh=ms.body.mesh(), model="B", boundaries=roles, traction=ms["traction_top"].source,
                         probes=ms["probes"], **physics)
    assert sc.name == "memory_mesh2d" and sc["mesh"].endswith(".vol")
    _same(built_in, workbench.run(sc, **kw))
    toml = tmp_path / "body.toml"
    toml.write_text(f'geometry = "{sc["mesh"]}"\nmodel = "B"\n[boundaries]\n'
                    + "".join(f'{k} = "{v}"\n' for k, v in roles.items())
                    + "[parameters]\n" + f'traction = "{ms["traction_top"].source}"\nprony = [[-1000.0, 0.3, 0.5]]\n'
                    + f"gap = {ms['gap']}\nF = {ms['F']}\nc = {ms['c']}\n"
                    + f"probes = {[list(p) for p in ms['probes']]}\n")
    _same(built_in, workbench.run(str(toml), **kw))


def test_a_netgen_geometry_is_meshed_at_h(tmp_path):
    """An OCC geometry is meshed with maxh = h; the scene keeps the file (by content) and its digest, so the same
    geometry and h give the same file, and a changed file is refused by name."""
    from netgen.occ import X, Y, OCCGeometry, Rectangle

    face = Rectangle(1.0, 0.2).Face()
    face.edges.Min(Y).name, face.edges.Min(X).name, face.edges.Max(Y).name = "bottom", "left", "top"
    roles = {"bottom": "contact", "left": "clamped", "top": "traction", "default": "free"}
    a = workbench.scene(mesh=OCCGeometry(face, dim=2), h=0.05, boundaries=roles)
    b = workbench.scene(mesh=OCCGeometry(face, dim=2), h=0.05, boundaries=roles)
    c = workbench.scene(mesh=OCCGeometry(face, dim=2), h=0.1, boundaries=roles)
    assert a["mesh"] == b["mesh"] != c["mesh"] and a.body.n_cells() > c.body.n_cells()
    assert len(a["mesh_digest"]) == 64
    ds = workbench.run(a, T=0.02, k=0.01, progress=False)
    assert ds.attrs["status"] == "complete" and ds.attrs["mesh_digest"] == a["mesh_digest"]
    copy = tmp_path / "copy.vol"
    copy.write_bytes(open(a["mesh"], "rb").read())
    s = workbench.scene(mesh=str(copy), boundaries=roles)
    copy.write_bytes(open(c["mesh"], "rb").read())
    with pytest.raises(ParameterError, match="the file has changed"):
        s.with_(T=0.5)


def _run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, cwd=cwd)


def test_an_interface_inside_the_body_is_not_a_contact_side(tmp_path):
    """Two glued parts with their interface named: given the role contact it was taken as a contact side inside
    the body (its vertices in node_weight). Refused by name; free (or clamped) it runs."""
    from netgen.occ import X, Y, Glue, MoveTo, OCCGeometry

    a, b = MoveTo(0, 0).Rectangle(0.5, 0.2).Face(), MoveTo(0.5, 0).Rectangle(0.5, 0.2).Face()
    for face in (a, b):
        face.edges.Min(Y).name, face.edges.Max(Y).name = "bottom", "top"
    a.edges.Min(X).name, b.edges.Max(X).name, a.edges.Max(X).name = "left", "right", "iface"
    path = str(tmp_path / "two.vol")
    OCCGeometry(Glue([a, b]), dim=2).GenerateMesh(maxh=0.1).Save(path)
    roles = {"bottom": "contact", "left": "clamped", "top": "traction", "right": "free"}
    with pytest.raises(ParameterError, match="iface = 'contact' is an interface between two parts of the mesh"):
        workbench.scene(mesh=path, boundaries=roles | {"iface": "contact"})
    assert workbench.scene(mesh=path, boundaries=roles | {"iface": "free"}).body.boundaries["contact"] == "bottom"


def test_a_run_on_a_mesh_file_continues_after_its_folder_moved(slab_msh, tmp_path):
    """A project folder moved (to a cluster, a new checkout): the archive names its mesh by the old path, and
    continuing it with the scene file at its new place was refused ("no such file"). The same mesh (its digest) at a
    new path is the archive's mesh: the continuation equals the run straight to the new T. Without the scene, the
    refusal says to give it."""
    import shutil

    project = tmp_path / "project"
    project.mkdir()
    shutil.copy(slab_msh, project / "slab.msh")
    (project / "slab.toml").write_text('geometry = "slab.msh"\n[boundaries]\n'
                                       + "".join(f'{k} = "{v}"\n' for k, v in SLAB_ROLES.items())
                                       + '[parameters]\ntraction = "(0, -t)"\nT = 0.1\nk = 0.05\nscheme = "implicit"\n')
    archive = workbench.write(workbench.run(str(project / "slab.toml"), progress=False), tmp_path / "run.nc")
    straight = workbench.run(str(project / "slab.toml"), T=0.2, progress=False)
    project.rename(tmp_path / "moved")
    with pytest.raises(ParameterError, match="no such file.*give the scene at its new place"):
        workbench.run(restart=archive, T=0.2, progress=False)
    more = workbench.run(str(tmp_path / "moved" / "slab.toml"), restart=archive, T=0.2, progress=False)
    np.testing.assert_array_equal(more.u_probe.values, straight.u_probe.values)


@pytest.mark.parametrize("scene, model", [("mesh2d", "B"), ("memory_mesh2d", "A")])
def test_a_mesh_scene_named_with_the_other_model_is_refused(slab_msh, tmp_path, scene, model):
    """A TOML file with scene = "mesh2d" and model = "B" ran Model A without a word (and the other way round); in
    Python the refusal said a built-in scene has its own model, where a mesh was given. Both name the contradiction
    and the scene of the model asked for."""
    said = f"model = '{model}' contradicts scene = '{scene}'"
    other = {"mesh2d": "memory_mesh2d", "memory_mesh2d": "mesh2d"}[scene]
    toml = tmp_path / "both.toml"
    toml.write_text(f'scene = "{scene}"\nmodel = "{model}"\ngeometry = "{slab_msh}"\n[boundaries]\n'
                    + "".join(f'{k} = "{v}"\n' for k, v in SLAB_ROLES.items()))
    with pytest.raises(ParameterError, match=re.escape(said) + f".*scene = '{other}' for Model {model}"):
        workbench.scene(str(toml))
    with pytest.raises(ParameterError, match=re.escape(said)):
        workbench.scene(scene, mesh=str(slab_msh), boundaries=SLAB_ROLES, model=model)
    assert workbench.scene(other, mesh=str(slab_msh), boundaries=SLAB_ROLES).model == model


@pytest.mark.slow
@pytest.mark.parametrize("case,message", [
    ("missing", "no such file"),
    ("unknown", "'botom' is not a boundary of the mesh.*did you mean 'bottom'"),
    ("unassigned", "the mesh's boundary 'right' has no role"),
    ("role", "bottom = 'contacts' is not a role; allowed: clamped \\| traction \\| contact \\| free"),
    ("dimension", "is a 2D mesh; this scene needs a 3D one"),
    ("no contact", "no boundary has the role contact"),
    ("below", "the contact boundary reaches y = -0.05 < 0"),
    ("h", "a mesh body's element size is its mesh's"),
])
def test_bad_mesh_input_is_refused_by_name(slab_msh, tmp_path, case, message):
    """Each mistake gets a ParameterError naming it, before any work; on the command line one 'error:' line (exit
    code 2), no traceback."""
    roles = dict(SLAB_ROLES)
    kw = {}
    mesh, scene = str(slab_msh), None
    if case == "missing":
        mesh = str(tmp_path / "nothing.msh")
    elif case == "unknown":
        roles["botom"] = roles.pop("bottom")
    elif case == "unassigned":
        roles.pop("right")
    elif case == "role":
        roles["bottom"] = "contacts"
    elif case == "dimension":
        scene = "mesh3d"
    elif case == "no contact":
        roles["bottom"] = "free"
    elif case == "below":
        m = workbench.scene("slab", h=0.05).body.mesh()
        import ngsolve as ngs

        ngm = m.ngmesh
        for p in ngm.Points():
            x, y, z = p.p
            p[1] = y - 0.05
        mesh = str(meshes.write_gmsh(ngs.Mesh(ngm), tmp_path / "low.msh"))
    elif case == "h":
        kw["h"] = 0.01
    with pytest.raises(ParameterError, match=message):
        workbench.scene(scene, mesh=mesh, boundaries=roles, **kw) if scene else \
            workbench.scene(mesh=mesh, boundaries=roles, **kw)
    toml = tmp_path / "bad.toml"
    toml.write_text(f'geometry = "{mesh}"\n' + (f'scene = "{scene}"\n' if scene else "")
                    + "[boundaries]\n" + "".join(f'{k} = "{v}"\n' for k, v in roles.items())
                    + ("[parameters]\nh = 0.01\n" if kw else ""))
    p = _run_cli("run", str(toml), "-o", str(tmp_path / "out.nc"))
    assert p.returncode == 2, p.stderr
    assert p.stderr.startswith("error: ") and "Traceback" not in p.stderr and len(p.stderr.splitlines()) == 1
    assert not (tmp_path / "out.nc").exists()


@pytest.mark.slow
@pytest.mark.parametrize("scene,measure", [("memory_hertz", math.pi / 4), ("memory_hertz3d", math.pi / 6),
                                           ("tp5", 0.1)])
def test_archives_describe_their_mesh_by_ugrid(tmp_path, scene, measure):
    """An archive read back knows its body by the UGRID conventions alone: the variable with cf_role mesh_topology
    names the vertex coordinates and the cell connectivity, from which the body's measure is that of the quarter
    disc (pi/4), the quarter hemisphere (pi/6; faceted: 2.2 % less at h = 0.25) or the slab (0.1 x 1), and exactly
    NGSolve's measure of the scene's mesh."""
    import xarray as xr

    kw = dict(h_contact=0.04) if scene == "memory_hertz3d" else dict(h=0.05) if scene == "tp5" else {}
    path = workbench.write(workbench.run(scene, T=0.25 if scene != "tp5" else 0.02, progress=False, **kw),
                           tmp_path / "a.nc")
    ds = xr.open_dataset(path)
    assert "UGRID-1.0" in ds.attrs["Conventions"]
    (topo,) = [v for v in ds.variables.values() if v.attrs.get("cf_role") == "mesh_topology"]
    dim = int(topo.attrs["topology_dimension"])
    xyz = np.stack([ds[n].values for n in topo.attrs["node_coordinates"].split()], axis=1)
    role = {2: "face_node_connectivity", 3: "volume_node_connectivity"}[dim]
    cells = ds[topo.attrs[role]]
    assert cells.attrs["cf_role"] == role
    nodes = cells.values - int(cells.attrs.get("start_index", 0))
    edges = xyz[nodes[:, 1:]] - xyz[nodes[:, :1]]
    total = np.abs(np.linalg.det(edges)).sum() / math.factorial(dim)
    assert total == pytest.approx(measure, rel=0.03 if dim == 3 else 2e-3)  # the body's own (faceted) measure:
    import ngsolve as ngs

    sc = workbench.scene(scene, **kw)
    assert total == pytest.approx(ngs.Integrate(ngs.CF(1.0), sc.body.mesh()), rel=1e-10)
    assert ds.u_nodes.attrs["mesh"] == "mesh" and ds.u_nodes.attrs["location"] == "node"


def test_a_3d_gmsh_file_gives_the_built_in_block(tmp_path):
    """The block's mesh (h = 0.25) through a gmsh file: the implicit run with compliance and bonding equals the
    built-in block's bit for bit."""
    b = workbench.scene("block", h=0.25, order=1)
    path = meshes.write_gmsh(b.body.mesh(), tmp_path / "block.msh")
    kw = dict(T=0.02, k=0.005, scheme="implicit", snapshots=(), progress=False)
    phys = {n: b[n] for n in ("adhesion", "c_nu", "gamma_nu", "L", "E", "nu", "a1", "a2")}
    roles = {"left": "clamped", "bottom": "contact", "top": "traction", "right": "free", "front": "free",
             "back": "free"}
    sc = workbench.scene(mesh=str(path), boundaries=roles, traction=b["traction_top"].source, probes=b["probes"],
                         order=1, **phys)
    assert sc.name == "mesh3d"
    with pytest.warns(RuntimeWarning, match="lock in bending"):
        built_in = workbench.run(b, **kw)
    with pytest.warns(RuntimeWarning, match="lock in bending"):
        _same(built_in, workbench.run(sc, **kw))


def test_the_memory_preflight_counts_a_mesh_bodys_own_vertices(slab_msh):
    """The estimate before a run (which refuses a run that cannot fit) takes the mesh's vertices, not its element
    count as if it were a box's cells: P1 dofs exactly, for a file and for a Hertz body."""
    from workbench.discrete import discretisation
    from workbench.running import preflight

    for sc in (workbench.scene(mesh=str(slab_msh), boundaries=SLAB_ROLES),
               workbench.scene("memory_hertz3d", h_contact=0.04)):
        est = preflight.estimate(sc.body, 1)
        assert est.ndof == discretisation.build(sc.with_(order=1)).ndof


def test_the_hertz_mesh_cache_gives_the_mesh_it_would_make(tmp_path, monkeypatch):
    """A Hertz body's mesh is made once and kept in the cache folder: the cached one is the made one bit for bit
    (coordinates, elements, boundary names), and a damaged cache file is made again."""
    import pickle

    from workbench.input import geometry, meshes

    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path))
    args = ("hemisphere", 1.0, 0.25, 0.04, 0.3)
    made = geometry._make_indenter_mesh(*args)
    geometry._indenter_mesh.cache_clear()
    first = geometry._indenter_mesh(*args)  # made and stored
    geometry._indenter_mesh.cache_clear()
    stored = list((tmp_path / "meshes").glob("netgen-*.pickle"))
    assert len(stored) == 1
    again = geometry._indenter_mesh(*args)  # loaded
    for m in (first, again):
        assert np.array_equal(np.array(m.Coordinates()), np.array(made.Coordinates()))
        assert [tuple(e.vertices) for e in m.Elements3D()] == [tuple(e.vertices) for e in made.Elements3D()]
        assert [m.GetBCName(i) for i in range(m.GetNFaceDescriptors())] == \
            [made.GetBCName(i) for i in range(made.GetNFaceDescriptors())]
    good = stored[0].read_bytes()
    # damaged on disk (4 bytes of its pickle changed: unchecked, a run got another mesh without a word, or a
    # segmentation fault on every later run), cut short, an old unchecked pickle, another mesh's file: made again
    other = geometry._make_indenter_mesh("hemisphere", 1.0, 0.25, 0.05, 0.3)
    flipped = bytearray(good)
    flipped[len(good) // 3: len(good) // 3 + 4] = bytes(b ^ 0x5A for b in good[len(good) // 3: len(good) // 3 + 4])
    for damaged in (b"not a pickle", bytes(flipped), good[: len(good) // 2], pickle.dumps(other),
                    good.split(b"\n", 2)[0] + b"\n" + b"0" * 24 + good.split(b"\n", 2)[1][24:] + b"\n"
                    + pickle.dumps(other)):
        stored[0].write_bytes(damaged)
        geometry._indenter_mesh.cache_clear()
        repaired = geometry._indenter_mesh(*args)
        assert np.array_equal(np.array(repaired.Coordinates()), np.array(made.Coordinates()))
        header, line, payload = stored[0].read_bytes().split(b"\n", 2)  # (replaced by a good file)
        assert header + b"\n" == meshes.CACHE_MAGIC and line.split()[0] == good.split(b"\n")[1].split()[0]
        assert np.array_equal(np.array(pickle.loads(payload).Coordinates()), np.array(made.Coordinates()))
    assert meshes.RECIPES >= 1


def test_the_mesh_cache_reads_only_the_users_own_folders(tmp_path, monkeypatch):
    """Every lookup read the shared temporary folder's meshes too, without checking who made it: a mesh planted
    there (with its tag and digest, which anyone can compute) was taken for another, and a pickle runs code (an
    outside pass). The temporary folder is now read only where the cache cannot be written, and only where it is
    this user's alone; else a private folder is made."""
    import hashlib
    import pickle
    import tempfile

    import netgen.meshing as nm

    def triangle(n):
        m = nm.Mesh(dim=2)
        m.AddPoints(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0 / n, 0.0]]))
        return m

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    shared = meshes._fallback_folder()
    shared.mkdir(parents=True)
    payload = pickle.dumps(triangle(5))  # (planted where another user could put it)
    (shared / f"netgen-{meshes._tag('planted')}.pickle").write_bytes(
        meshes.CACHE_MAGIC + f"{meshes._tag('planted')} {hashlib.sha256(payload).hexdigest()}\n".encode() + payload)
    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path / "cache"))
    got = meshes.cached_netgen("planted", lambda: triangle(3))
    assert float(np.array(got.Coordinates())[2, 1]) == pytest.approx(1.0 / 3.0)
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path / "file"))  # (cannot be written: the temporary folder ...)
    os.chmod(shared.parent, 0o777)  # (... which is not this user's alone: not read, a private one made)
    with pytest.warns(RuntimeWarning, match="workbench-meshes-.*is not this user's alone.*chmod 700"):
        got = meshes.cached_netgen("planted", lambda: triangle(3))
    assert float(np.array(got.Coordinates())[2, 1]) == pytest.approx(1.0 / 3.0)


def test_a_mesh_cache_that_cannot_be_written_falls_back_to_the_temporary_folder(tmp_path, monkeypatch):
    """A cache folder that cannot be written made the Hertz meshes again on every run without a word (6.3 s against
    0.8 s, found by an outside pass): now the temporary folder keeps them, with a warning naming WORKBENCH_CACHE."""
    from workbench.input import geometry

    (tmp_path / "file").write_text("")
    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path / "file"))  # (a file: no folder can be made under it)
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    (tmp_path / "tmp").mkdir()
    args = ("hemisphere", 1.0, 0.25, 0.05, 0.3)
    geometry._indenter_mesh.cache_clear()
    with pytest.warns(RuntimeWarning, match="WORKBENCH_CACHE"):
        first = geometry._indenter_mesh(*args)
    assert len(list((tmp_path / "tmp").rglob("netgen-*.pickle"))) == 1
    made = []
    monkeypatch.setattr(geometry, "_make_indenter_mesh", lambda *a: made.append(a))
    geometry._indenter_mesh.cache_clear()
    again = geometry._indenter_mesh(*args)  # (read from the temporary folder, not made)
    assert not made and np.array_equal(np.array(again.Coordinates()), np.array(first.Coordinates()))


def test_the_hemispheres_load_is_spread_over_its_meshed_top():
    """The flat top's area, from the netgen mesh's triangles (what the load is divided by), against NGSolve's
    integral over the same boundary, and against the quarter disc it approximates (the polygon is a little smaller)."""
    import ngsolve as ngs

    from workbench.input import geometry

    ngmesh = geometry._indenter_mesh("hemisphere", 1.0, 0.25, 0.04)
    mesh = ngs.Mesh(ngmesh)
    integral = ngs.Integrate(ngs.CF(1.0), mesh, ngs.BND, definedon=mesh.Boundaries("top"))
    area = geometry._flat_boundary_area(ngmesh, "top")
    assert area == pytest.approx(integral, rel=1e-13)
    assert 0.98 * math.pi / 4 < area < math.pi / 4


def test_an_adaptive_run_on_an_empty_mesh_cache_equals_one_on_a_filled_cache(tmp_path):
    """netgen refines an unpickled mesh's curved side 5.6e-17 elsewhere than the mesh it has just made: an adaptive
    Hertz run on an empty cache differed from every later one by 1 ulp in the vertices, 4e-14 in u (an outside pass).
    The mesh made is now the one a later run reads back."""
    import xarray as xr

    env = dict(os.environ, WORKBENCH_CACHE=str(tmp_path / "cache"))
    for name in ("cold", "warm"):
        p = subprocess.run([sys.executable, "-m", "workbench.cli", "run", "memory_hertz", "--set", "h_contact=0.02",
                            "--set", "space_tol=0.15", "--T", "0.5", "--no-progress", "-o", f"{name}.nc"],
                           cwd=tmp_path, env=env, capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
    cold, warm = (xr.load_dataset(tmp_path / f"{name}.nc") for name in ("cold", "warm"))
    assert cold.attrs["space_levels"] > 1  # (the given mesh and at least one refined)
    for name in ("u_dofs", "node_x", "node_y", "contact_pressure", "space_error_estimate"):
        np.testing.assert_array_equal(cold[name].values, warm[name].values, err_msg=name)


def test_an_archive_of_a_mesh_given_as_a_python_object_continues_after_the_cache_is_cleared(tmp_path, monkeypatch):
    """A mesh given as an OCC geometry (or a mesh object) lives in a file in the cache folder: once the cache was
    cleared, its archive could be neither continued nor run again ("no such file"; the hint spoke of a mesh file the
    user never had; an outside pass). The archive now keeps the file's text (``stored_mesh``), and a continuation
    writes it back, to the same digest."""
    import shutil

    from netgen.occ import X, Y, OCCGeometry, Rectangle

    from workbench.running.restart import archived_scene

    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path / "cache"))
    face = Rectangle(1.0, 0.2).Face()
    face.edges.Min(Y).name, face.edges.Min(X).name, face.edges.Max(Y).name = "bottom", "left", "top"
    sc = workbench.scene(mesh=OCCGeometry(face, dim=2), h=0.1, traction="(0, -t)", T=0.2, k=0.05,
                         boundaries={"bottom": "contact", "left": "clamped", "top": "traction", "default": "free"})
    half = workbench.run(sc.with_(T=0.1), progress=False)
    assert "stored_mesh" in half
    workbench.write(half, tmp_path / "half.nc")
    straight = workbench.run(sc, progress=False)
    shutil.rmtree(tmp_path / "cache")
    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path / "elsewhere"))  # (another machine's cache folder, too)
    on = workbench.run(restart=tmp_path / "half.nc", T=0.2, progress=False)
    np.testing.assert_array_equal(on.u_dofs.values[-1], straight.u_dofs.values[-1])
    again = archived_scene(workbench.load(tmp_path / "half.nc"))
    assert again["mesh_digest"] == sc["mesh_digest"] and again["mesh"].startswith(str(tmp_path / "elsewhere"))
