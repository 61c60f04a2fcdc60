"""Bodies: what a geometry knows about itself (boundaries and their roles, probes, mesh, contact normal).

A geometry is built from the scene's geometry and mesh values. It owns:

* its dimension, extent and the parameters that set them;
* its boundaries by role: the clamp Gamma_1, the contact side Gamma_3, the
  loadable sides Gamma_2;
* default probe points and the check that a point lies in the body;
* its mesh (structured simplices; cell counts n and 2n give nested meshes, so a
  coarse solution is exactly representable on the finer mesh), cell counts, h;
* **the foundation**: the rigid plane the contact side faces. It is the plane
  y = 0 (2D) or z = 0 (3D) with the outward normal -e_y / -e_z of the body, or,
  for the rod, the point beyond x = length with normal +1. So u_nu = u . nu is
  -u_y (2D), -u_z (3D), +u (rod), and the tangential part of u is its other
  components. This is the only place that says so.

Examples
--------
>>> g = Slab(width=1.0, height=0.1, h=0.05)
>>> g.cells(), g.boundaries["contact"], g.normal_sign, g.normal_axis
((20, 2), 'bottom', -1.0, 1)
>>> g.mesh().ne
80
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from .errors import ParameterError

if TYPE_CHECKING:  # NGSolve is imported where a mesh is made: a scene is checked without it
    import ngsolve as ngs


class Geometry:
    """A body (see the module docs). Subclasses set the class attributes and :meth:`mesh`."""

    kind = ""
    dim = 0
    #: Extent parameters in axis order, and the cell-count parameters that may override h.
    extent_names: tuple = ()
    cell_names: tuple = ()
    #: Boundary names by role.
    boundaries: dict = {}
    #: Axis of the foundation normal and its sign (u_nu = normal_sign * u[normal_axis]).
    normal_axis = 0
    normal_sign = 1.0
    #: The other axes: those along which the contact side extends (its facets' coordinates).
    facet_axes: tuple = ()

    def __init__(self, h: float, cells: tuple = (), **extent):
        self.h = float(h)
        self.extent = tuple(float(extent[n]) for n in self.extent_names)
        self.requested_cells = tuple(int(c) for c in cells) if cells else (0,) * len(self.extent_names)

    @classmethod
    def from_values(cls, values: dict) -> "Geometry":
        """The geometry of a scene's checked values."""
        return cls(values["h"], tuple(values.get(n, 0) for n in cls.cell_names),
                   **{n: values[n] for n in cls.extent_names})

    @property
    def size(self) -> float:
        """The largest extent (the scale of 'unbounded' in blow-up detection)."""
        return max(self.extent)

    @property
    def loadable(self) -> tuple:
        return self.boundaries["traction"]

    def cells(self) -> tuple:
        """Cells per direction: the explicit counts where given (> 0), else round(side / h), at least 1."""
        return tuple(n if n > 0 else max(1, round(e / self.h)) for n, e in zip(self.requested_cells, self.extent))

    def n_cells(self) -> int:
        """Number of simplices of the mesh."""
        per_box = {1: 1, 2: 2, 3: 6}[self.dim]
        count = per_box
        for n in self.cells():
            count *= n
        return count

    def h_max(self) -> float:
        """Longest cell side along the axes (the h of a refinement study)."""
        return max(e / n for e, n in zip(self.extent, self.cells()))

    def aspect(self) -> float:
        """Thickness over length (small: a thin body, where P1 simplices lock in bending)."""
        return min(self.extent) / max(self.extent)

    def default_probes(self) -> tuple:
        raise NotImplementedError

    def check_point(self, name: str, point) -> None:
        """A ParameterError unless ``point`` has dim coordinates inside the body's box."""
        point = tuple(point)
        if len(point) != self.dim:
            raise ParameterError(f"{name}: point {point} has {len(point)} coordinate(s); a {self.kind} needs "
                                 f"{self.dim} ({', '.join('xyz'[:self.dim])})")
        tol = 1e-12 * self.size
        if any(c < -tol or c > e + tol for c, e in zip(point, self.extent)):
            box = " x ".join(f"[0, {e:g}]" for e in self.extent)
            raise ParameterError(f"{name}: point {point} is not inside the body {box}")

    def mesh(self) -> ngs.Mesh:
        raise NotImplementedError

    def nested_in(self, finer: "Geometry") -> bool:
        """True when every cell count divides the finer one's (structured meshes are then nested)."""
        return type(self) is type(finer) and self.extent == finer.extent and \
            all(f % c == 0 for c, f in zip(self.cells(), finer.cells()))

    def key(self) -> tuple:
        """What determines the mesh (for caches)."""
        return (self.kind, self.extent, self.cells())

    def normal_displacement(self, u_nodes):
        """u_nu from displacement components (..., component): normal_sign * u[..., normal_axis]."""
        return self.normal_sign * u_nodes[..., self.normal_axis]


class Rod(Geometry):
    """The 1D rod (0, length): clamp (or prescribed delta(t)) at x = 0, contact at x = length."""

    kind, dim = "rod", 1
    extent_names, cell_names = ("length",), ()
    boundaries = {"clamp": "left", "contact": "right", "traction": ()}
    normal_axis, normal_sign, facet_axes = 0, 1.0, ()

    def default_probes(self):
        L = self.extent[0]
        return tuple((f * L,) for f in (0.25, 0.5, 1.0))

    def mesh(self):
        from ngsolve.meshes import Make1DMesh

        length = self.extent[0]
        return Make1DMesh(self.cells()[0], mapping=lambda x: length * x)


class Slab(Geometry):
    """The 2D plane slab (0, width) x (0, height): clamped at x = 0, contact on y = 0, loadable top and right."""

    kind, dim = "slab", 2
    extent_names, cell_names = ("width", "height"), ("nx", "ny")
    boundaries = {"clamp": "left", "contact": "bottom", "traction": ("top", "right")}
    normal_axis, normal_sign, facet_axes = 1, -1.0, (0,)

    def default_probes(self):
        W, H = self.extent
        return ((0.25 * W, 0.0), (0.5 * W, 0.0), (0.75 * W, 0.0), (W, 0.0), (W, H))

    def mesh(self):
        from ngsolve.meshes import MakeStructured2DMesh

        W, H = self.extent
        nx, ny = self.cells()
        return MakeStructured2DMesh(quads=False, nx=nx, ny=ny, mapping=lambda x, y: (W * x, H * y))


class Block(Geometry):
    """The 3D block (0, width) x (0, depth) x (0, height): clamped at x = 0, contact on z = 0."""

    kind, dim = "block", 3
    extent_names, cell_names = ("width", "depth", "height"), ("nx", "ny", "nz")
    boundaries = {"clamp": "left", "contact": "bottom", "traction": ("top", "right", "front", "back")}
    normal_axis, normal_sign, facet_axes = 2, -1.0, (0, 1)

    def default_probes(self):
        W, D, H = self.extent
        return ((0.25 * W, D / 2, 0.0), (0.5 * W, D / 2, 0.0), (0.75 * W, D / 2, 0.0), (W, D / 2, 0.0), (W, D / 2, H))

    def mesh(self):
        import ngsolve as ngs
        from ngsolve.meshes import MakeStructured3DMesh

        W, D, H = self.extent
        nx, ny, nz = self.cells()
        mesh = MakeStructured3DMesh(hexes=False, nx=nx, ny=ny, nz=nz, mapping=lambda x, y, z: (W * x, D * y, H * z))
        # netgen calls x = 0 'back', x = W 'front', y = 0 'left', y = D 'right'
        rename = {"back": "left", "front": "right", "left": "front", "right": "back"}
        ngm = mesh.ngmesh
        indices = {ngm.GetBCName(i): i for i in range(len(set(mesh.GetBoundaries())))}
        for old, new in rename.items():
            ngm.SetBCName(indices[old], new)
        return ngs.Mesh(ngm)


#: The built-in geometries by name.
GEOMETRIES = {g.kind: g for g in (Rod, Slab, Block)}
