"""The contact pressure recovered from the nodal forces: smooth on unstructured meshes, with the same resultant.

The lumped pressure p_i = F_i / w_i of a contact vertex (its nodal force over its share w_i = int phi_i da of the
side) depends on the triangles around the vertex, and on an unstructured surface mesh F_i does not follow w_i
closely: the 3D pressures scatter by several percent about a smooth profile. :class:`Recovery` averages over each
vertex's patch (the vertex and its neighbours on the contact side) by the forces, over the vertices in contact only,
and scales the result to the nodal forces' resultant (docs/models.md). On a contact curve (2D) a vertex whose patch
is all in contact takes a linear fit instead (:func:`_linear_fit`: second order where the facets change size). Not in
3D: there the nodal forces scatter about the hats' centroids too, and a plane through a patch kept the scatter (the
hemisphere's peak at h_contact = 0.01: +4.3 % against the average's +0.6 %).

Examples
--------
>>> import numpy as np, workbench
>>> from workbench.discrete import discretisation
>>> d = discretisation.build(workbench.scene("memory_hertz3d"))
>>> w = d.node_weights
>>> p = np.where(np.arange(len(w)) % 2 == 0, 9.0, 11.0)  # a scattered pressure about 10
>>> q = d.pressure_recovery(p, w)
>>> bool(np.std(q) < np.std(p)), bool(np.isclose(q @ w, p @ w))
(True, True)
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from ngsolve import VERTEX, NodeId


#: Lumped pressures at or below this share of the largest one are round-off: not in contact for the recovery.
ROUND_OFF = 1e-9


class Recovery:
    """The recovered contact pressure on the contact vertices ``vertex_numbers`` of the side ``contact_name`` (module
    docs); call it with the lumped pressures and the vertices' weights. ``normal_axis``: the coordinate along the
    foundation's normal (the fit is in the others); None: patch averages only."""

    def __init__(self, mesh, contact_name: str, vertex_numbers, normal_axis: int | None = None, pinned=()):
        index = {int(v): i for i, v in enumerate(vertex_numbers)}
        rows, cols, facets = [], [], []
        for el in mesh.Boundaries(contact_name).Elements():
            vs = [index[v.nr] for v in el.vertices]
            facets.append(vs)
            rows += [a for a in vs for _ in vs]
            cols += [b for _ in vs for b in vs]
        n = len(index)
        patches = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)) + sp.identity(n, format="csr")
        patches.data[:] = 1.0  # (0/1: a vertex and its neighbours, each once)
        self.patches = patches
        self.fit = None
        if normal_axis is not None and n:
            xyz = np.array([mesh[NodeId(VERTEX, int(v))].point for v in vertex_numbers], dtype=float)
            self.fit = _linear_fit(patches, facets, xyz, normal_axis, np.asarray(pinned, dtype=int))

    def __call__(self, pressure: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Per vertex in contact: the value at the vertex of the linear fit to the lumped pressures of its patch
        (all in contact), else sum_j F_j / sum_j w_j over its patch's vertices in contact (F_j = p_j w_j); scaled to
        the same resultant. Vertices not in contact keep their value, NaN (clamped) stays."""
        known = np.isfinite(pressure)
        # (no pressure leaks out of the contact zone, its edge is not smeared; a vertex pressed by round-off is not in
        # it: as in contact it took its patch's average, and a lumped 2e-12 Pa became 73 Pa, where 0 on another
        # number of MPI processes stayed 0 (an outside pass, December 2026))
        floor = ROUND_OFF * np.abs(pressure[known]).max(initial=0.0)
        pressing = known & (pressure > floor)
        F = np.where(pressing, pressure, 0.0) * weights
        w = np.where(pressing, weights, 0.0)
        out = np.where(known, pressure, np.nan)
        out[pressing] = (self.patches @ F)[pressing] / (self.patches @ w)[pressing]
        if self.fit is not None:
            fitted, operator = self.fit
            whole = fitted & (self.patches @ (~pressing).astype(float) == 0) & pressing  # (the patch all in contact)
            out[whole] = (operator @ np.where(pressing, pressure, 0.0))[whole]
        if pressing.any():  # the same resultant as the nodal forces (averaging moves force between patches)
            out[pressing] *= F.sum() / (out[pressing] @ weights[pressing])
        return out


def _linear_fit(patches, facets: list, xyz: np.ndarray, normal_axis: int, pinned: np.ndarray):
    """(which vertices have a fit, the sparse operator from the lumped pressures to the fitted values at the
    vertices). A lumped pressure F_j / w_j is the mean of the pressure over vertex j's hat function phi_j, which is
    the pressure at the hat's centroid c_j = int x phi_j / int phi_j to second order; at the vertex only to first
    order where the facets beside it differ in size (an adapted mesh). So the values are fitted by a linear function
    of the tangential coordinates (``xyz`` without ``normal_axis``) at the centroids, weighted by int phi_j, and the
    fit is read at the vertex: exact for a linear pressure on any mesh of straight facets. A vertex whose patch
    (without the ``pinned`` vertices, whose forces are reactions) is too small for a fit, or degenerate, has none."""
    xy = np.delete(xyz, normal_axis, axis=1)
    n, k = xy.shape
    centroid, mass = np.zeros((n, k)), np.zeros(n)
    # (on a straight facet E of m vertices: int phi_j = |E| / m, int x phi_j = |E| (x_j + sum x) / (m (m + 1)))
    for vs in facets:
        pts = xy[vs]
        size = _measure(xyz[vs])  # (the facet's own size: the pressure is a force per area of the side)
        total = pts.sum(axis=0)
        m = len(vs)
        for a, j in enumerate(vs):
            mass[j] += size / m
            centroid[j] += size * (pts[a] + total) / (m * (m + 1))
    centroid /= np.where(mass > 0, mass, 1.0)[:, None]
    rows, cols, vals, fitted = [], [], [], np.zeros(n, dtype=bool)
    for i in range(n):
        nb = np.setdiff1d(patches.indices[patches.indptr[i]:patches.indptr[i + 1]], pinned)
        if len(nb) < k + 2:  # (at least one more value than the fit's unknowns: a fit, not an interpolation)
            continue
        A = np.column_stack([np.ones(len(nb)), centroid[nb] - xy[i]]) * np.sqrt(mass[nb])[:, None]
        if np.linalg.matrix_rank(A) < k + 1:
            continue
        row = np.linalg.pinv(A)[0] * np.sqrt(mass[nb])  # (the fit's value at the vertex, per lumped value)
        rows += [i] * len(nb)
        cols += nb.tolist()
        vals += row.tolist()
        fitted[i] = True
    return fitted, sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _measure(pts: np.ndarray) -> float:
    """The length of a segment or the area of a triangle."""
    if len(pts) < 2:  # (a point: the rod's end)
        return 1.0
    if len(pts) == 2:
        return float(np.linalg.norm(pts[1] - pts[0]))
    e1, e2 = pts[1] - pts[0], pts[2] - pts[0]
    return float(abs(e1[0] * e2[1] - e1[1] * e2[0]) / 2 if len(e1) == 2 else np.linalg.norm(np.cross(e1, e2)) / 2)
