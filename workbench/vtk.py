"""ParaView files from a result Dataset: XML ``.vtu`` per snapshot plus ``.pvd`` time collections.

Pure numpy and the standard library (ASCII XML VTK, readable by ParaView and VisIt).
For a Dataset with snapshots, :func:`export` writes, for snapshot ``i`` (time ``t_i``):

* ``{stem}_{i:04d}.vtu`` — the mesh: vertex coordinates padded to 3D; cells
  ``VTK_LINE`` (3) in 1D, ``VTK_TRIANGLE`` (5) in 2D, ``VTK_TETRA`` (10) in 3D;
  point data ``displacement`` (3-vector, padded with zeros); cell data
  ``von_mises`` and ``stress`` (the P0 components named by ``stress_component``);
  field data ``TimeValue`` = t_i.
* ``{stem}_contact_{i:04d}.vtu`` (only if the result has ``beta``) — the contact
  boundary Gamma_3 as its own grid: its facets as cells (``VTK_VERTEX`` (1) for the
  rod end, ``VTK_LINE`` in 2D, ``VTK_TRIANGLE`` in 3D), point data ``displacement``,
  cell data ``beta`` taken at the *recorded time nearest to t_i* (beta is recorded on
  the ``time`` axis, not with the snapshots; the time used is field data ``BetaTime``).
* ``{stem}.pvd`` and ``{stem}_contact.pvd`` — collections listing the files with
  their times (open these in ParaView to get the time series).

Every file is written atomically (temporary file in the same folder, then ``os.replace``).

Examples
--------
>>> import tempfile, workbench
>>> ds = workbench.run("tp1", h=0.25, k=0.5, snapshots=(0.5, 1.0), progress=False)
>>> files = export(ds, tempfile.mkdtemp())
>>> [p.name for p in files]  # doctest: +NORMALIZE_WHITESPACE
['tp1_0000.vtu', 'tp1_0001.vtu', 'tp1_contact_0000.vtu', 'tp1_contact_0001.vtu', 'tp1.pvd', 'tp1_contact.pvd']
>>> grid = read_vtu(files[0])
>>> grid["points"].shape, grid["cell_types"].tolist()
((5, 3), [3, 3, 3, 3])
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .files import atomic_write

#: VTK cell type of a volume cell by space dimension, and of a contact facet by space dimension.
CELL_TYPE = {1: 3, 2: 5, 3: 10}
FACET_TYPE = {1: 1, 2: 3, 3: 5}
_COMPONENTS = ("x", "y", "z")


def _dim(ds) -> int:
    return int(ds.sizes["component"])


def _stem(ds, stem):
    return stem or str(ds.attrs.get("scene") or "result")


def export_file_names(ds, folder, stem=None) -> list[Path]:
    """The paths :func:`export` writes for ``ds`` (in that order), without writing anything."""
    if "snapshot_time" not in ds.coords:
        return []
    folder, stem = Path(folder), _stem(ds, stem)
    n = ds.sizes["snapshot"]
    out = [folder / f"{stem}_{i:04d}.vtu" for i in range(n)]
    if "beta" in ds:
        out += [folder / f"{stem}_contact_{i:04d}.vtu" for i in range(n)]
    out.append(folder / f"{stem}.pvd")
    if "beta" in ds:
        out.append(folder / f"{stem}_contact.pvd")
    return out


def _points3(ds, prefix):
    """Coordinates ``{prefix}_x/y/z`` padded to (n, 3)."""
    dim = _dim(ds)
    first = ds[f"{prefix}_x"].values
    pts = np.zeros((len(first), 3))
    for c in range(dim):
        pts[:, c] = ds[f"{prefix}_{_COMPONENTS[c]}"].values
    return pts


def _pad3(u):
    out = np.zeros((u.shape[0], 3))
    out[:, : u.shape[1]] = u
    return out


def contact_facets(ds):
    """The contact facets as vertex-index tuples, in the order of ``ds.facet``.

    The contact vertices are the mesh vertices at the ``node`` coordinates; a
    contact facet is a face of a cell (an end point in 1D, an edge in 2D, a
    triangle in 3D) whose corners are all contact vertices and that belongs to one
    cell only. Facets are matched to ``facet_x`` (and ``facet_y`` in 3D) by their
    midpoints.

    Returns
    -------
    numpy.ndarray of int, shape (n_facet, dim)
        Vertex indices (into ``vertex``) of each facet's corners.

    Raises
    ------
    ValueError
        If the facets cannot be matched one-to-one to the recorded ``beta`` facets.
    """
    from itertools import combinations

    from scipy.spatial import cKDTree

    dim = _dim(ds)
    verts = _points3(ds, "vertex")
    nodes = _points3(ds, "node")
    scale = max(float(np.ptp(verts, axis=0).max()), 1.0)
    dist, contact = cKDTree(verts).query(nodes)
    if np.any(dist > 1e-9 * scale):
        raise ValueError("contact nodes do not coincide with mesh vertices")
    if dim == 1:
        faces = contact.reshape(-1, 1)
    else:
        is_contact = np.zeros(len(verts), dtype=bool)
        is_contact[contact] = True
        cells = ds.cell_vertices.values[:, : dim + 1]
        counts = {}
        for combo in combinations(range(dim + 1), dim):
            for face in np.sort(cells[:, combo], axis=1)[is_contact[cells[:, combo]].all(axis=1)]:
                key = tuple(face.tolist())
                counts[key] = counts.get(key, 0) + 1
        faces = np.array([f for f, c in counts.items() if c == 1], dtype=np.int64).reshape(-1, dim)
    ncoord = 2 if dim == 3 else 1  # facets lie on y = 0 (2D) or z = 0 (3D)
    mids = verts[faces].mean(axis=1)[:, :ncoord]
    want = np.column_stack([ds[f"facet_{_COMPONENTS[c]}"].values for c in range(ncoord)])
    if len(faces) != len(want):
        raise ValueError(f"found {len(faces)} contact facets in the mesh but the result has {len(want)} beta facets")
    dist, idx = cKDTree(mids).query(want)
    if len(set(idx.tolist())) != len(idx):
        raise ValueError("contact facets could not be matched one-to-one to the beta facets")
    return faces[idx]


def _fmt(arr, integer=False):
    arr = np.asarray(arr)
    if integer:
        return " ".join(str(int(v)) for v in arr.ravel())
    return " ".join(map(repr, arr.astype(float).ravel().tolist()))  # shortest round-trip text


def _data_array(parent, name, arr, ncomp=None, dtype="Float64", component_names=None):
    el = ET.SubElement(parent, "DataArray", type=dtype, format="ascii")
    if name is not None:
        el.set("Name", name)
    if ncomp is not None:
        el.set("NumberOfComponents", str(ncomp))
    for i, cname in enumerate(component_names or ()):
        el.set(f"ComponentName{i}", cname)
    if dtype.startswith("Float"):
        el.set("NumberOfTuples", str(np.asarray(arr).shape[0]))
    el.text = _fmt(arr, integer=not dtype.startswith("Float"))
    return el


def _vtu(points, cells, cell_type, point_data, cell_data, field_data):
    """An UnstructuredGrid VTKFile element tree (ASCII)."""
    root = ET.Element("VTKFile", type="UnstructuredGrid", version="1.0", byte_order="LittleEndian",
                      header_type="UInt64")
    grid = ET.SubElement(root, "UnstructuredGrid")
    fd = ET.SubElement(grid, "FieldData")
    for name, value in field_data.items():
        _data_array(fd, name, np.atleast_1d(np.asarray(value, dtype=float)))
    piece = ET.SubElement(grid, "Piece", NumberOfPoints=str(len(points)), NumberOfCells=str(len(cells)))
    pd = ET.SubElement(piece, "PointData", Vectors="displacement")
    for name, arr in point_data.items():
        _data_array(pd, name, arr, ncomp=arr.shape[1] if arr.ndim > 1 else None)
    cd = ET.SubElement(piece, "CellData")
    for name, (arr, comp_names) in cell_data.items():
        _data_array(cd, name, arr, ncomp=arr.shape[1] if arr.ndim > 1 else None, component_names=comp_names)
    pts = ET.SubElement(piece, "Points")
    _data_array(pts, "Points", points, ncomp=3)
    cl = ET.SubElement(piece, "Cells")
    cells = np.asarray(cells, dtype=np.int64)
    _data_array(cl, "connectivity", cells.ravel(), dtype="Int64")
    _data_array(cl, "offsets", np.arange(1, len(cells) + 1) * cells.shape[1], dtype="Int64")
    _data_array(cl, "types", np.full(len(cells), cell_type), dtype="UInt8")
    return root


def _write_atomic(path: Path, text: str) -> Path:
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def _xml_text(root) -> str:
    ET.indent(root, space=" ")
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _pvd(entries) -> str:
    root = ET.Element("VTKFile", type="Collection", version="0.1")
    coll = ET.SubElement(root, "Collection")
    for t, name in entries:
        ET.SubElement(coll, "DataSet", timestep=repr(float(t)), group="", part="0", file=name)
    return _xml_text(root)


def export(ds, folder, stem=None) -> list[Path]:
    """Write the snapshots of ``ds`` as ``.vtu`` files with ``.pvd`` collections (see the module docstring).

    Parameters
    ----------
    ds : xarray.Dataset
        A result with snapshots (``u_nodes``, ``cell_vertices``, ``von_mises``).
    folder : str or Path
        Created if missing.
    stem : str, optional
        File name stem (default: the scene name).

    Returns
    -------
    list of Path
        The written files, as :func:`export_file_names` lists them.

    Raises
    ------
    ValueError
        If ``ds`` has no snapshots.
    """
    if "snapshot_time" not in ds.coords:
        raise ValueError("export: the result has no snapshots (u_nodes) to write")
    folder, stem = Path(folder), _stem(ds, stem)
    dim = _dim(ds)
    points = _points3(ds, "vertex")
    cells = ds.cell_vertices.values[:, : dim + 1]
    stress_names = [str(s) for s in ds.stress_component.values] if "stress" in ds else []
    snap_t = ds.snapshot_time.values
    has_beta = "beta" in ds
    if has_beta:
        facets = contact_facets(ds)
        used = np.unique(facets)
        renumber = np.full(len(points), -1, dtype=np.int64)
        renumber[used] = np.arange(len(used))
        times = ds.time.values
    written, main, contact = [], [], []
    for i, t in enumerate(snap_t):
        u = _pad3(ds.u_nodes.isel(snapshot=i).values)
        cell_data = {"von_mises": (ds.von_mises.isel(snapshot=i).values, None)}
        if stress_names:
            s = ds.stress.isel(snapshot=i).values
            cell_data["stress"] = (s if s.shape[1] > 1 else s[:, 0], stress_names if s.shape[1] > 1 else None)
        name = f"{stem}_{i:04d}.vtu"
        root = _vtu(points, cells, CELL_TYPE[dim], {"displacement": u}, cell_data, {"TimeValue": t})
        written.append(_write_atomic(folder / name, _xml_text(root)))
        main.append((t, name))
        if has_beta:
            j = int(np.argmin(np.abs(times - t)))  # beta lives on the record axis: nearest recorded time
            beta = ds.beta.isel(time=j).values
            cname = f"{stem}_contact_{i:04d}.vtu"
            root = _vtu(points[used], renumber[facets], FACET_TYPE[dim], {"displacement": u[used]},
                        {"beta": (beta, None)}, {"TimeValue": t, "BetaTime": times[j]})
            contact.append((t, cname, _xml_text(root)))
    for t, cname, text in contact:
        written.append(_write_atomic(folder / cname, text))
    written.append(_write_atomic(folder / f"{stem}.pvd", _pvd(main)))
    if has_beta:
        written.append(_write_atomic(folder / f"{stem}_contact.pvd", _pvd([(t, n) for t, n, _ in contact])))
    return written


def read_vtu(path) -> dict:
    """Read back an ASCII ``.vtu`` written by :func:`export` (for checks; not a general VTK reader).

    Returns
    -------
    dict
        ``points`` (n, 3), ``connectivity``, ``offsets``, ``cell_types`` (int arrays),
        ``point_data`` / ``cell_data`` / ``field_data``: name -> array (n, ncomp) or (n,),
        and ``n_points``, ``n_cells`` as declared in the header.
    """
    root = ET.parse(path).getroot()
    if root.get("type") != "UnstructuredGrid":
        raise ValueError(f"{path}: not an UnstructuredGrid VTK file")
    piece = root.find("UnstructuredGrid/Piece")

    def arr(el):
        dtype = float if el.get("type", "").startswith("Float") else np.int64
        a = np.array((el.text or "").split(), dtype=dtype)
        ncomp = int(el.get("NumberOfComponents", "1"))
        return a.reshape(-1, ncomp) if ncomp > 1 else a

    def group(tag, where=piece):
        node = where.find(tag)
        return {} if node is None else {el.get("Name"): arr(el) for el in node.findall("DataArray")}

    cells = group("Cells")
    return {
        "n_points": int(piece.get("NumberOfPoints")), "n_cells": int(piece.get("NumberOfCells")),
        "points": arr(piece.find("Points/DataArray")),
        "connectivity": cells["connectivity"], "offsets": cells["offsets"], "cell_types": cells["types"],
        "point_data": group("PointData"), "cell_data": group("CellData"),
        "field_data": group("FieldData", root.find("UnstructuredGrid")),
    }


def read_pvd(path) -> list[tuple[float, str]]:
    """The (time, file name) entries of a ``.pvd`` collection."""
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


__all__ = ["export", "export_file_names", "contact_facets", "read_vtu", "read_pvd", "CELL_TYPE", "FACET_TYPE"]
