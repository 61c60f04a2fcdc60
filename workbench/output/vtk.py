"""ParaView files from a result Dataset: ``.vtu`` per snapshot (written by meshio) plus ``.pvd`` time collections.

For a Dataset with snapshots, :func:`export` writes, for snapshot ``i`` (time ``t_i``):

* ``{stem}_{i:04d}.vtu`` — the mesh with point data ``displacement`` (a 3-vector,
  padded with zeros) and cell data ``von_mises`` and ``stress`` (the P0 components
  named by ``stress_component``); field data ``TimeValue`` = t_i. A P1 run gives
  linear cells (line, triangle, tetra); a run of order 2 or more gives quadratic
  cells (line3, triangle6, tetra10) whose edge-midpoint nodes carry the field's own
  values there (``u_edges``), so ParaView draws the P2 field, not its P1 interpolant.
* ``{stem}_contact_{i:04d}.vtu`` — the contact boundary Gamma_3 as its own grid: its
  facets as cells (a vertex for the rod end, lines in 2D, triangles in 3D), point
  data ``displacement`` and, for Model B, ``contact_pressure`` and ``contact_state``
  (at the recorded time nearest to t_i), cell data ``beta`` for Model A with
  adhesion (likewise; the time used is field data ``RecordTime``).
* ``{stem}.pvd`` and ``{stem}_contact.pvd`` — collections listing the files with
  their times (open these in ParaView to get the time series).

Every file is written atomically (:func:`workbench.output.files.atomic_write`); the stem (the
scene's name by default) is made safe for the file system, so files stay inside ``folder``.

Examples
--------
>>> import tempfile, workbench
>>> ds = workbench.run("tp1", h=0.25, k=0.5, snapshots=(0.5, 1.0), progress=False)
>>> files = export(ds, tempfile.mkdtemp())
>>> [p.name for p in files]  # doctest: +NORMALIZE_WHITESPACE
['tp1_0000.vtu', 'tp1_0001.vtu', 'tp1_contact_0000.vtu', 'tp1_contact_0001.vtu', 'tp1.pvd', 'tp1_contact.pvd']
>>> import meshio
>>> grid = meshio.read(files[0])
>>> grid.points.shape, grid.cells[0].type
((5, 3), 'line')
"""
from __future__ import annotations

from itertools import combinations
from pathlib import Path

import numpy as np

from .files import atomic_write, safe_name

#: meshio cell type of a volume cell by space dimension (linear, quadratic), and of a contact facet.
CELL_TYPE = {1: ("line", "line3"), 2: ("triangle", "triangle6"), 3: ("tetra", "tetra10")}
FACET_TYPE = {1: "vertex", 2: "line", 3: "triangle"}
#: The edges of a simplex in VTK's quadratic node order.
_EDGES = {1: [(0, 1)], 2: [(0, 1), (1, 2), (2, 0)], 3: [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]}
_COMPONENTS = ("x", "y", "z")


def _dim(ds) -> int:
    return int(ds.sizes["component"])


def _stem(ds, stem):
    return safe_name(stem or ds.attrs.get("scene") or "result")


def export_file_names(ds, folder, stem=None) -> list[Path]:
    """The files :func:`export` writes for ``ds`` into ``folder``, in the order it returns them."""
    folder, stem = Path(folder).expanduser(), _stem(ds, stem)
    n = ds.sizes["snapshot"]
    out = [folder / f"{stem}_{i:04d}.vtu" for i in range(n)]
    out += [folder / f"{stem}_contact_{i:04d}.vtu" for i in range(n)]
    return out + [folder / f"{stem}.pvd", folder / f"{stem}_contact.pvd"]


def _points3(ds, prefix):
    dim = _dim(ds)
    pts = np.zeros((ds.sizes[prefix], 3))
    for c in range(dim):
        pts[:, c] = ds[f"{prefix}_{_COMPONENTS[c]}"].values
    return pts


def _pad3(u):
    out = np.zeros((u.shape[0], 3))
    out[:, : u.shape[1]] = u
    return out


def contact_facets(ds):
    """The contact facets as vertex-index tuples (in the order of ``ds.facet`` when the result has beta).

    The contact vertices are the mesh vertices at the ``node`` coordinates; a contact
    facet is a face of a cell (an end point in 1D, an edge in 2D, a triangle in 3D)
    whose corners are all contact vertices and that belongs to one cell only. With a
    bonding field, facets are matched to ``facet_x`` (and ``facet_y``) by their midpoints.

    Returns
    -------
    numpy.ndarray of int, shape (n_facet, dim)

    Raises
    ------
    ValueError
        If the facets cannot be matched one-to-one to the recorded ``beta`` facets.
    """
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
    if "facet" not in ds.dims:
        return faces
    axes = [c for c in range(dim) if f"facet_{_COMPONENTS[c]}" in ds.coords]
    mids = verts[faces].mean(axis=1)[:, axes]
    want = np.column_stack([ds[f"facet_{_COMPONENTS[c]}"].values for c in axes])
    if len(faces) != len(want):
        raise ValueError(f"found {len(faces)} contact facets in the mesh but the result has {len(want)} beta facets")
    dist, idx = cKDTree(mids).query(want)
    if len(set(idx.tolist())) != len(idx):
        raise ValueError("contact facets could not be matched one-to-one to the beta facets")
    return faces[idx]


def _oriented(points, cells, dim: int):
    """The cells with a positive volume (2D: counterclockwise), as VTK's cells are defined: two vertices swapped
    where the mesh has them the other way (netgen's tetrahedra all are: ParaView's cell sizes and integrals of a
    field over the body came out negative). Edge midpoints follow from the vertices' order (:func:`_quadratic`)."""
    if dim < 2 or not len(cells):
        return cells
    p = points[:, :dim][cells]
    edges = p[:, 1:] - p[:, :1]  # (cell, dim, dim): the edges from the first vertex
    flip = np.linalg.det(edges) < 0
    if not flip.any():
        return cells
    cells = cells.copy()
    cells[flip, 1], cells[flip, 2] = cells[flip, 2], cells[flip, 1].copy()
    return cells


def _quadratic(ds, cells):
    """Points and cells of the quadratic grid: vertices, then the edge midpoints of ``ds.edge_vertices``."""
    dim = _dim(ds)
    edges = ds.edge_vertices.values
    index = {tuple(sorted(e)): i for i, e in enumerate(edges.tolist())}
    nv = ds.sizes["vertex"]
    mid = np.array([[nv + index[tuple(sorted((c[a], c[b])))] for a, b in _EDGES[dim]] for c in cells.tolist()],
                   dtype=np.int64).reshape(len(cells), -1)
    return np.concatenate([cells, mid], axis=1)


def _write_vtu(path, points, cell_type, cells, point_data, cell_data, field_data):
    import meshio

    mesh = meshio.Mesh(points, [(cell_type, cells)], point_data=point_data,
                       cell_data={k: [v] for k, v in cell_data.items()})

    def write(tmp):
        mesh.write(tmp, file_format="vtu")
        # meshio's writer drops field data; ParaView reads a scalar TimeValue from the grid's FieldData
        arrays = "".join(f'<DataArray type="Float64" Name="{k}" NumberOfTuples="1" format="ascii">{float(v)!r}'
                         "</DataArray>" for k, v in field_data.items())
        text = tmp.read_text().replace("<UnstructuredGrid>", f"<UnstructuredGrid>\n<FieldData>{arrays}</FieldData>", 1)
        tmp.write_text(text)

    return atomic_write(path, write)


def _pvd(entries) -> str:
    rows = "\n".join(f'    <DataSet timestep="{float(t)!r}" group="" part="0" file="{name}"/>' for t, name in entries)
    return ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            f"{rows}\n  </Collection>\n</VTKFile>\n")


def export(ds, folder, stem=None) -> list[Path]:
    """Write the snapshots of ``ds`` as ParaView files into ``folder`` (see the module docs).

    Parameters
    ----------
    ds : xarray.Dataset
        A result with snapshots (``u_nodes``, ``cell_vertices``, ``von_mises``).
    folder : str or Path
        Created if missing.
    stem : str, optional
        File name stem (default: the scene name, made safe for the file system).

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
    folder, stem = Path(folder).expanduser(), _stem(ds, stem)  # (~: home, as for archives)
    dim = _dim(ds)
    points, cells, cell_type, quadratic = _volume_grid(ds)
    facets, used, renumber, node_of_vertex = _contact_grid(ds)
    times = ds.time.values
    written, main, contact = [], [], []
    for i, t in enumerate(ds.snapshot_time.values):
        u = ds.u_nodes.isel(snapshot=i).values
        if quadratic:
            u = np.concatenate([u, ds.u_edges.isel(snapshot=i).values])
        s = ds.stress.isel(snapshot=i).values
        cell_data = {"von_mises": ds.von_mises.isel(snapshot=i).values, "stress": s if s.shape[1] > 1 else s[:, 0]}
        name = f"{stem}_{i:04d}.vtu"
        written.append(_write_vtu(folder / name, points, cell_type, cells, {"displacement": _pad3(u)}, cell_data,
                                  {"TimeValue": t}))
        main.append((t, name))
        j = int(np.argmin(np.abs(times - t)))  # contact data live on the record axis: nearest recorded time
        point_data = {"displacement": _pad3(ds.u_nodes.isel(snapshot=i).values[used])}
        for var in ("contact_pressure", "contact_state"):
            if var in ds:
                point_data[var] = ds[var].isel(time=j).values[node_of_vertex].astype(float)
        cdata = {"beta": ds.beta.isel(time=j).values} if "beta" in ds else {}
        cname = f"{stem}_contact_{i:04d}.vtu"
        path = _write_vtu(folder / cname, points[used], FACET_TYPE[dim], renumber[facets], point_data, cdata,
                          {"TimeValue": t, "RecordTime": times[j]})
        contact.append((path, (t, cname)))
    written += [p for p, _ in contact]
    written.append(atomic_write(folder / f"{stem}.pvd", lambda tmp: tmp.write_text(_pvd(main))))
    written.append(atomic_write(folder / f"{stem}_contact.pvd", lambda tmp: tmp.write_text(_pvd([e for _, e in contact]))))
    return written


def _volume_grid(ds):
    """Points, cells and meshio cell type of the body's grid, and whether it is quadratic (a run of order >= 2: the
    edge midpoints appended as nodes, so ParaView draws the field's own values there)."""
    dim = _dim(ds)
    points = _points3(ds, "vertex")
    cells = _oriented(points, ds.cell_vertices.values[:, : dim + 1], dim)
    quadratic = "u_edges" in ds
    if quadratic:
        edges = ds.edge_vertices.values
        points = np.concatenate([points, points[edges].mean(axis=1)])
        cells = _quadratic(ds, cells)
    return points, cells, CELL_TYPE[dim][int(quadratic)], quadratic


def _contact_grid(ds):
    """The contact grid: its facets (mesh vertex indices), the vertices they use, the map from mesh vertex to grid
    point (-1 where unused), and each used vertex's index on the ``node`` axis (where the contact data live)."""
    facets = contact_facets(ds)
    used = np.unique(facets)
    renumber = np.full(ds.sizes["vertex"], -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    return facets, used, renumber, _node_order(ds, used)


def _node_order(ds, used):
    """For each used contact vertex (in ``used`` order), its index on the ``node`` axis."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(_points3(ds, "node")).query(_points3(ds, "vertex")[used])
    return idx


__all__ = ["export", "export_file_names", "contact_facets", "CELL_TYPE", "FACET_TYPE"]
