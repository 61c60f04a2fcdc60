"""Structured meshes for the built-in geometries, with named boundaries.

Boundary names: ``left`` (x = 0, the clamp Gamma_1), the contact side
(``right`` of the rod, ``bottom`` of the slab and block) and the loadable sides
(``top``, ``right``, and in 3D ``front`` (y = 0) / ``back`` (y = depth)).
Meshes with cell counts n and 2n are nested (each coarse cell is a union of
fine cells), so a coarse solution is exactly representable on the finer mesh.

Examples
--------
>>> from workbench.scenes import scene
>>> mesh = build(scene("slab", h=0.1))
>>> mesh.ne, sorted(set(mesh.GetBoundaries()))
(20, ['bottom', 'left', 'right', 'top'])
"""
from __future__ import annotations

import ngsolve as ngs
from ngsolve.meshes import Make1DMesh, MakeStructured2DMesh, MakeStructured3DMesh


def cells(scene) -> tuple:
    """Cell counts per direction: explicit ``nx/ny/nz`` or ``round(side / h)`` (at least 1)."""
    v, h = scene.values, scene["h"]
    if scene.geometry == "rod":
        return (max(1, round(v["length"] / h)),)
    sides = (("nx", "width"), ("ny", "height")) if scene.geometry == "slab" else \
        (("nx", "width"), ("ny", "depth"), ("nz", "height"))
    return tuple(v[n] if v[n] > 0 else max(1, round(v[side] / h)) for n, side in sides)


def build(scene) -> ngs.Mesh:
    """The scene's mesh (simplices: intervals, triangles, tetrahedra)."""
    n = cells(scene)
    v = scene.values
    if scene.geometry == "rod":
        length = v["length"]
        return Make1DMesh(n[0], mapping=lambda x: length * x)
    if scene.geometry == "slab":
        W, H = v["width"], v["height"]
        mesh = MakeStructured2DMesh(quads=False, nx=n[0], ny=n[1], mapping=lambda x, y: (W * x, H * y))
        return mesh  # netgen's names already are bottom/right/top/left
    W, D, H = v["width"], v["depth"], v["height"]
    mesh = MakeStructured3DMesh(hexes=False, nx=n[0], ny=n[1], nz=n[2],
                                mapping=lambda x, y, z: (W * x, D * y, H * z))
    # netgen calls x = 0 'back', x = W 'front', y = 0 'left', y = D 'right'
    rename = {"back": "left", "front": "right", "left": "front", "right": "back"}
    ngm = mesh.ngmesh
    indices = {ngm.GetBCName(i): i for i in range(len(set(mesh.GetBoundaries())))}
    for old, new in rename.items():
        ngm.SetBCName(indices[old], new)
    return ngs.Mesh(ngm)


def h_max(scene) -> float:
    """Longest cell side along the axes (the h of a refinement study)."""
    n = cells(scene)
    v = scene.values
    sides = {"rod": ("length",), "slab": ("width", "height"), "block": ("width", "depth", "height")}[scene.geometry]
    return max(v[s] / c for s, c in zip(sides, n))
