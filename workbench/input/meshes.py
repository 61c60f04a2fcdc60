"""Bodies from files and from netgen geometry: reading meshes with their boundary names.

A scene's body may come from

* a gmsh mesh file (``.msh``, format 2 or 4, read with meshio): its boundary
  names are the names of its physical groups (an unnamed group is ``bc<tag>``);
* a netgen mesh file (``.vol``, ``.vol.gz``);
* in Python, a netgen/OCC geometry (anything with ``GenerateMesh``: ``OCCGeometry``,
  ``SplineGeometry``, ``CSGeometry``), meshed with ``maxh = h``, or an NGSolve or
  netgen mesh. These are stored as a netgen mesh file in the user's cache folder,
  named by its content (:func:`store`), so that a scene stays data: it can be
  written to an archive, sent to a study worker and restarted.

The scene keeps the file's absolute path and the digest of its content
(``mesh_digest``), so a changed file is a changed scene for every cache and for
restart.

Examples
--------
>>> from netgen.occ import OCCGeometry, Rectangle, Y
>>> face = Rectangle(1.0, 0.2).Face()
>>> face.edges.Min(Y).name = "bottom"
>>> path = store(OCCGeometry(face, dim=2), h=0.1)
>>> m = read(path)
>>> m.dim, sorted(boundary_names(m))
(2, ['bottom', 'default'])
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from ..errors import ParameterError

#: File suffixes read as meshes.
SUFFIXES = (".msh", ".vol", ".vol.gz")


def cache_folder() -> Path:
    """Where meshes made from Python objects are stored (``$WORKBENCH_CACHE``, a leading ``~`` the home folder, or
    ~/.cache/workbench)."""
    root = os.environ.get("WORKBENCH_CACHE") or os.path.join("~", ".cache", "workbench")
    return Path(os.path.expanduser(root)) / "meshes"


#: Bump when a cached mesh's recipe changes (the key holds the recipe's arguments and netgen's version, not its code).
RECIPES = 1


def cached_netgen(key: str, make):
    """The netgen mesh ``make()`` returns, made once per ``key`` and kept in the cache folder (or, where that cannot
    be written, in the temporary folder, with a warning: :func:`_writable`).

    Pickled, since netgen's own .vol text rounds the coordinates (a loaded mesh gave other results in the last digits),
    behind a header with the key's tag and the sha256 of the pickle: a file whose digest or tag does not match (damaged
    on disk, cut short, another mesh's, an older format) is made again and replaced. Unpickled unchecked, a few bytes
    changed on disk gave a run a different mesh without a word (von Mises 28 % off), a segmentation fault on every
    later run, or a hang (found by an outside pass).

    >>> import netgen.meshing as nm
    >>> made = []
    >>> def make():
    ...     made.append(1)
    ...     m = nm.Mesh(dim=2)
    ...     m.AddPoints(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0 / 3.0, 0.0]]))
    ...     return m
    >>> a, b = cached_netgen("doctest triangle", make), cached_netgen("doctest triangle", make)
    >>> np.array_equal(a.Coordinates(), b.Coordinates()), len(made) <= 1
    (True, True)
    """
    import pickle

    tag = _tag(key)
    name = f"netgen-{tag}.pickle"
    folder = _writable(cache_folder())  # (the temporary folder only where the cache cannot be written: the user's own)
    payload = _checked(folder / name, tag)
    if payload is not None:
        try:
            return pickle.loads(payload)
        except Exception:  # (written by another netgen's pickling: make it again)
            pass
    mesh = make()
    payload = pickle.dumps(mesh)
    try:
        path = folder / name
        tmp = path.with_name(f".{path.name}.{os.getpid()}")
        tmp.write_bytes(CACHE_MAGIC + f"{tag} {hashlib.sha256(payload).hexdigest()}\n".encode() + payload)
        os.replace(tmp, path)
    except OSError:  # (a folder that cannot be written at all only costs the time to make the mesh)
        pass
    # (the mesh as a later run reads it: netgen refines an unpickled mesh's curved sides 1e-17 elsewhere than the mesh
    # it made, so an adaptive run on an empty cache differed from the same run after it by 1e-13, an outside pass)
    return pickle.loads(payload)


def _tag(key: str) -> str:
    """The cache's name for a mesh of ``key``, with netgen's version and :data:`RECIPES`."""
    import netgen

    return hashlib.sha256(f"{key}|netgen {netgen.__version__}|recipes {RECIPES}".encode()).hexdigest()[:24]


#: The first line of a cached mesh file; the second holds the key's tag and the pickle's sha256.
CACHE_MAGIC = b"workbench cached netgen mesh 1\n"


def _checked(path: Path, tag: str):
    """The pickle stored in ``path`` where its header names ``tag`` and its digest matches, else None."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if not data.startswith(CACHE_MAGIC):
        return None
    line, _, payload = data[len(CACHE_MAGIC):].partition(b"\n")
    if line != f"{tag} {hashlib.sha256(payload).hexdigest()}".encode():
        return None
    return payload


def _fallback_folder() -> Path:
    """Where meshes go when the cache folder cannot be written."""
    import tempfile

    return Path(tempfile.gettempdir()) / f"workbench-{os.getuid()}" / "meshes"


def _writable(folder: Path) -> Path:
    """``folder``, made; or, when it cannot be written, a folder in the temporary directory (with a warning): the
    user's own there (made 0700), or where another user made or can write that one, a new private folder (a mesh file
    planted in a shared folder was read as the user's, and a pickle runs code: found by an outside pass)."""
    import tempfile
    import warnings

    try:
        folder.mkdir(parents=True, exist_ok=True)
        if os.access(folder, os.W_OK | os.X_OK) and not str(folder.resolve()).startswith(("/proc/", "/sys/")):
            return folder
        reason = "no permission to write there"
    except OSError as err:
        reason = err.strerror or str(err)
    fallback, shared = _fallback_folder(), ""
    try:
        for part in (fallback.parent, fallback):
            part.mkdir(mode=0o700, exist_ok=True)
            mode = part.lstat()
            if part.is_symlink() or mode.st_uid != os.getuid() or mode.st_mode & 0o022:
                shared = (f"; {str(part)!r} is not this user's alone (a link, another's, or writable by others: "
                          "chmod 700 it, or remove it), so each run makes a new folder")
                raise PermissionError(shared)
    except OSError:
        fallback = Path(tempfile.mkdtemp(prefix="workbench-meshes-"))
    warnings.warn(f"the mesh cache {str(folder)!r} cannot be written ({reason}; set WORKBENCH_CACHE to a writable "
                  f"folder): meshes are stored in {str(fallback)!r}{shared}", RuntimeWarning, stacklevel=3)
    return fallback


def digest(path) -> str:
    """sha256 of a file's content (what a cached result made from it is keyed by)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def check_file(path, name: str = "mesh") -> Path:
    """The absolute path of an existing mesh file of a known kind, or a ParameterError naming ``name``."""
    from ..values import check_utf8_path

    check_utf8_path(path, f"{name} =")  # (its path is an attribute of the archive)
    p = Path(path).expanduser()
    if not p.exists():
        raise ParameterError(f"{name} = {str(path)!r}: no such file")
    if p.is_dir():
        raise ParameterError(f"{name} = {str(path)!r} is a directory, not a mesh file")
    if not p.resolve().is_file():  # (a pipe would wait for ever, /dev/zero fill memory)
        raise ParameterError(f"{name} = {str(path)!r} is not a regular file (a device, a pipe or a socket)")
    if not any(p.name.endswith(s) for s in SUFFIXES):
        raise ParameterError(f"{name} = {str(path)!r}: unknown mesh format; give a gmsh .msh or a netgen .vol/.vol.gz "
                             "file (in Python also a netgen/OCC geometry or a mesh object)")
    return p.resolve()


def read(path):
    """The netgen mesh of a file (boundary names as in the file); ParameterError if it cannot be read."""
    p = check_file(path)
    try:
        if p.name.endswith(".msh"):
            m = _from_gmsh(p)
        else:
            import netgen.meshing as nm

            m = nm.Mesh()
            m.Load(str(p))
        _check_cells(m, p)
        return m
    except ParameterError:
        raise
    except Exception as err:  # any failure of the readers: not a mesh we can use
        raise ParameterError(f"mesh = {str(path)!r} cannot be read as a mesh ({type(err).__name__}: "
                             f"{str(err).splitlines()[0][:100] if str(err) else 'no detail'})") from None


def _check_cells(m, path) -> None:
    """Refuse a mesh no run can use: no cells, a coordinate that is not finite, a vertex no cell uses, two vertices at
    one place, a cell without volume (all its vertices on a line or a plane)."""
    import numpy as np

    label = f"mesh = {str(path)!r}"
    dim = m.dim
    xyz = np.array(m.Coordinates()).reshape(-1, m.dim) if len(m.Points()) else np.zeros((0, dim))
    cells = {1: m.Elements1D, 2: m.Elements2D, 3: m.Elements3D}[dim]().NumPy()
    nodes = np.asarray(cells["nodes"][:, : dim + 1], dtype=np.int64) - 1 if len(cells) else np.zeros((0, dim + 1),
                                                                                                     dtype=np.int64)
    if not len(nodes):
        raise ParameterError(f"{label}: the file holds no {dim}D cells (an empty or damaged mesh)")
    if not np.all(np.isfinite(xyz)):
        raise ParameterError(f"{label}: a vertex coordinate is not finite (NaN or inf)")
    unused = len(xyz) - len(np.unique(nodes))
    if unused:
        raise ParameterError(f"{label}: {unused} vertices belong to no cell; remove them from the file")
    size = float(np.ptp(xyz, axis=0).max()) or 1.0
    if len(np.unique(np.round(xyz / (1e-12 * size)), axis=0)) < len(xyz):
        raise ParameterError(f"{label}: two vertices lie at the same place (duplicated nodes); merge them")
    edges = xyz[nodes[:, 1:]] - xyz[nodes[:, :1]]
    measure = np.abs(np.linalg.det(edges)) if dim > 1 else np.abs(edges[:, 0, 0])
    if measure.min() <= 1e-12 * size ** dim:
        raise ParameterError(f"{label}: {int(np.sum(measure <= 1e-12 * size ** dim))} cell(s) have no "
                             f"{('length', 'area', 'volume')[dim - 1]} (their vertices on a line or a plane)")


def boundary_names(mesh) -> set:
    """The names of the boundary regions (codimension 1) that hold elements."""
    import ngsolve as ngs

    m = mesh if isinstance(mesh, ngs.Mesh) else ngs.Mesh(mesh)
    return {name for name in m.GetBoundaries()}


def store(obj, h: float | None = None) -> Path:
    """A netgen mesh file in the cache folder for a netgen/OCC geometry (meshed with ``maxh = h``) or a mesh object.

    The file is named by the digest of its content and written atomically, so equal meshes share one file.
    """
    import netgen.meshing as nm
    import ngsolve as ngs

    if isinstance(obj, nm.NetgenGeometry):
        if h is None:
            raise ParameterError("mesh = a geometry: give h, the element size to mesh it with")
        ngmesh = obj.GenerateMesh(maxh=float(h))
    elif isinstance(obj, ngs.Mesh):
        ngmesh = obj.ngmesh
    elif isinstance(obj, nm.Mesh):
        ngmesh = obj
    else:
        raise ParameterError(f"mesh = {type(obj).__name__} object: give a mesh file path (.msh, .vol), a netgen/OCC "
                             "geometry or an NGSolve/netgen mesh")
    folder = _writable(cache_folder())
    tmp = folder / f".store.{os.getpid()}.vol"
    ngmesh.Save(str(tmp))
    final = folder / f"{digest(tmp)[:24]}.vol"
    os.replace(tmp, final)
    return final


def is_stored(path) -> bool:
    """Whether ``path`` names a mesh file :func:`store` made from a Python object: in a cache folder, which may be
    cleared, so an archive of a run on it keeps its text (``stored_mesh``, :func:`restore`).

    >>> is_stored("/home/me/.cache/workbench/meshes/22ac0b6b2f9c4d3e8a1b7c5d.vol"), is_stored("part.vol")
    (True, False)
    >>> is_stored("/home/me/project/22ac0b6b2f9c4d3e8a1b7c5d.vol")  # (a user's own file so named)
    False
    """
    p = Path(str(path))  # (in a folder "meshes", as the cache's and its fallback in the temporary folder are)
    return p.suffix == ".vol" and len(p.stem) == 24 and all(c in "0123456789abcdef" for c in p.stem) and \
        p.parent.name == "meshes"


def restore(text: str) -> Path:
    """The mesh file :func:`store` made, written again from its text (an archive's ``stored_mesh``) in this
    machine's cache folder, where it is gone (the cache cleared, another machine): the archive's run can then be
    continued, or made again, from the archive alone (it could not: an outside pass)."""
    folder = _writable(cache_folder())
    tmp = folder / f".restore.{os.getpid()}.vol"
    tmp.write_text(text)
    final = folder / f"{digest(tmp)[:24]}.vol"
    os.replace(tmp, final)
    return final


def _from_gmsh(path: Path):
    """A netgen mesh of a gmsh file (linear simplices; the names of the physical groups as region names)."""
    import meshio
    import netgen.meshing as nm

    # (the format's reader itself: meshio.read prints the reader's error and calls sys.exit(1) when it fails)
    data = meshio.gmsh.read(str(path))
    names = {(int(v[1]), int(v[0])): k for k, v in data.field_data.items()}  # (dim, tag) -> name
    pts = np.asarray(data.points, dtype=float)
    dim = 3 if any(b.type.startswith("tetra") for b in data.cells) else 2
    if dim == 2 and pts.shape[1] > 2 and np.abs(pts[:, 2]).max(initial=0.0) > 0:
        raise ParameterError(f"mesh = {str(path)!r}: a 2D mesh must lie in the plane z = 0")
    mesh = nm.Mesh(dim=dim)
    xyz = np.zeros((len(pts), 3))
    xyz[:, : min(3, pts.shape[1])] = pts[:, :3]
    mesh.AddPoints(np.ascontiguousarray(xyz))  # (in file order: point i is netgen's point i + 1)
    tags = data.cell_data.get("gmsh:physical") or data.cell_data.get("gmsh:geometrical")
    volume_type, facet_type = ("tetra", "triangle") if dim == 3 else ("triangle", "line")
    found_volume = False
    regions = {}  # (dim, tag) -> netgen index
    for block, tag in zip(data.cells, tags or [None] * len(data.cells)):
        if block.type not in (volume_type, facet_type):
            if block.type in ("vertex",) or (dim == 3 and block.type == "line"):
                continue  # points and 3D edges carry no role
            raise ParameterError(f"mesh = {str(path)!r}: elements of type {block.type!r} are not supported; give a "
                                 "mesh of linear triangles (2D) or tetrahedra (3D)")
        cdim = dim if block.type == volume_type else dim - 1
        tag = np.zeros(len(block.data), dtype=int) if tag is None else np.asarray(tag, dtype=int)
        for t in np.unique(tag):
            key = (cdim, int(t))
            if key not in regions:
                regions[key] = len([r for r in regions if r[0] == cdim]) + 1
                idx = regions[key]
                name = names.get(key, f"bc{t}" if cdim < dim else f"domain{t}")
                if cdim == dim:
                    mesh.SetMaterial(idx, name)
                elif dim == 3:
                    mesh.Add(nm.FaceDescriptor(bc=idx, domin=1, domout=0, surfnr=idx))
                    mesh.SetBCName(idx - 1, name)
                else:
                    mesh.SetBCName(idx - 1, name)
        nodes = np.asarray(block.data, dtype=np.int32)
        if len(np.unique(tag)) == 1:  # (one region: in file order, in one call)
            mesh.AddElements(cdim, regions[(cdim, int(tag[0]))], np.ascontiguousarray(nodes), base=0)
        else:  # (elements keep the file's order: runs of equal tags, each in one call)
            cuts = np.flatnonzero(np.diff(tag)) + 1
            for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(tag)]):
                mesh.AddElements(cdim, regions[(cdim, int(tag[a]))], np.ascontiguousarray(nodes[a:b]), base=0)
        found_volume |= cdim == dim
    if not found_volume:
        raise ParameterError(f"mesh = {str(path)!r} has no {'tetrahedra' if dim == 3 else 'triangles'}")
    return mesh


def write_gmsh(mesh, path) -> Path:
    """Write an NGSolve mesh (linear simplices) as a gmsh 2.2 file with its boundary names as physical groups.

    The inverse of :func:`read` (vertex and element order kept), e.g. to hand a built-in body to gmsh tools.
    """
    import meshio
    import ngsolve as ngs

    m = mesh if isinstance(mesh, ngs.Mesh) else ngs.Mesh(mesh)
    ngm = m.ngmesh
    dim = m.dim
    pts = np.array(ngm.Coordinates())
    pts = np.hstack([pts, np.zeros((len(pts), 3 - pts.shape[1]))])
    vol = (ngm.Elements3D() if dim == 3 else ngm.Elements2D()).NumPy()
    bnd = (ngm.Elements2D() if dim == 3 else ngm.Elements1D()).NumPy()
    nv = dim + 1
    vol_nodes = np.asarray(vol["nodes"][:, :nv], dtype=np.int64) - 1
    bnd_nodes = np.asarray(bnd["nodes"][:, :dim], dtype=np.int64) - 1
    vol_index = np.asarray(vol["index"], dtype=np.int64)
    bnd_index = np.asarray(bnd["index"], dtype=np.int64)  # 3D: the face descriptor
    if dim == 3:
        bc_names = {int(i): ngm.FaceDescriptor(int(i)).bcname for i in np.unique(bnd_index)}
    else:
        bc_names = {int(i): ngm.GetBCName(int(i) - 1) for i in np.unique(bnd_index)}
    mats = {int(i): ngm.GetMaterial(int(i)) for i in np.unique(vol_index)}
    field_data = {}
    for i, name in bc_names.items():
        field_data.setdefault(name, np.array([100 + i, dim - 1]))
    for i, name in mats.items():
        field_data.setdefault(name, np.array([i, dim]))
    tag_bnd = np.array([field_data[bc_names[int(i)]][0] for i in bnd_index], dtype=int)
    tag_vol = np.array([field_data[mats[int(i)]][0] for i in vol_index], dtype=int)
    # boundary elements first, then the volume (the reader keeps each block's element order)
    cells = [("line" if dim == 2 else "triangle", bnd_nodes), ("triangle" if dim == 2 else "tetra", vol_nodes)]
    out = meshio.Mesh(pts, cells, cell_data={"gmsh:physical": [tag_bnd, tag_vol],
                                             "gmsh:geometrical": [tag_bnd, tag_vol]}, field_data=field_data)
    path = Path(path)
    meshio.write(str(path), out, file_format="gmsh22", binary=False)
    return path


def to_text(ngmesh) -> str:
    """A netgen mesh as the text of its .vol file (what an archive keeps of an adapted mesh)."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mesh.vol"
        ngmesh.Save(str(path))
        return path.read_text()


def from_text(text: str):
    """The netgen mesh of :func:`to_text`'s text (points, elements and boundary names in the same order).

    >>> import netgen.geom2d as g2
    >>> m = g2.unit_square.GenerateMesh(maxh=0.5)
    >>> back = from_text(to_text(m))
    >>> len(back.Points()) == len(m.Points()), len(back.Elements2D()) == len(m.Elements2D())
    (True, True)
    """
    import tempfile

    import netgen.meshing as nm

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mesh.vol"
        path.write_text(text)
        out = nm.Mesh()
        out.Load(str(path))
        return out
