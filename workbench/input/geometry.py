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

import functools
import math
from typing import TYPE_CHECKING

from ..errors import ParameterError

#: How many meshes (read from files, or of the Hertz bodies) a process keeps for reuse: a sweep over h meets each
#: mesh again for its reference and comparisons; an unbounded cache grew with every size a session tried.
MESH_CACHE = 8

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

    @property
    def bbox(self) -> tuple:
        """((lo, hi) per axis) of the body."""
        return tuple((0.0, e) for e in self.extent)

    def vertex_count(self) -> int:
        """Number of mesh vertices (an estimate before meshing)."""
        count = 1
        for n in self.cells():
            count *= n + 1
        return count

    @property
    def size_names(self) -> tuple:
        """The parameters that set how many cells the mesh has (named when a mesh would be too fine)."""
        return self.extent_names + ("h",) + self.cell_names

    def estimated_vertices(self) -> float:
        """The vertices the mesh would have, from the numbers alone (no meshing; inf for an overflowing count)."""
        count = 1.0
        for n, e in zip(self.requested_cells, self.extent):
            count *= (n if n > 0 else e / self.h) + 1.0
        return count if math.isfinite(count) else math.inf

    def band_cells(self) -> int:
        """Cells across the body's shorter side (sets the bandwidth of a banded factorisation)."""
        return min(self.cells())

    def dirichlet_flags(self) -> dict:
        """Keyword arguments of the displacement space that fix its Dirichlet dofs: the clamp, all components."""
        return {"dirichlet": self.boundaries["clamp"]}

    #: Whether the contact boundary may be curved: the initial gap to the foundation then varies along it.
    curved = False
    #: Whether a contact vertex is held in the normal direction where the contact holds it anyway (its contact
    #: force is the support's reaction; :class:`HalfDisc`): the origin, the indenters' apex.
    pins_contact = False
    #: The axes a of the planes x_a = 0 across which the modelled body is half of a symmetric one (rollers there):
    #: the half-space model of the contact compliance loads each point's mirror images too
    #: (:class:`~workbench.schemes.halfspace.HalfSpace`).
    mirror_axes: tuple = ()

    def gap0(self, xyz):
        """The initial gap to the foundation at boundary points ``xyz`` (point, axis): the distance along the
        foundation normal to the plane y = 0 (2D) / z = 0 (3D); None for a body whose contact side lies on it."""
        if not self.curved:
            return None
        import numpy as np

        return np.asarray(xyz, dtype=float)[..., self.normal_axis].copy()

    #: The radius of the refined zone of the curved contact side around its apex (a Hertz body), beyond which the
    #: side is free; None for a body whose whole contact side can touch.
    zone_radius = None
    #: Whether the body can be meshed anew from its geometry with local element sizes (``space_adapt = "remesh"``:
    #: :meth:`_Indenter.remeshed`); a box's structured mesh and a mesh file have no geometry to mesh again.
    remeshable = False

    def tractions(self, values: dict) -> dict:
        """The traction expressions by boundary name (the scene's ``traction_SIDE`` values)."""
        return {side: values[f"traction_{side}"] for side in self.loadable}

    def check_point(self, name: str, point) -> None:
        """A ParameterError unless ``point`` has dim coordinates inside the body's box."""
        point = tuple(point)
        if len(point) != self.dim:
            raise ParameterError(f"{name}: point {point} has {len(point)} coordinate(s); a {self.kind} needs "
                                 f"{self.dim} ({', '.join('xyz'[:self.dim])})")
        tol = 1e-12 * self.size
        if any(c < lo - tol or c > hi + tol for c, (lo, hi) in zip(point, self.bbox)):
            box = " x ".join(f"[{lo:g}, {hi:g}]" for lo, hi in self.bbox)
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


def _refuse_interfaces(mesh, cells, contact: list, dim: int) -> None:
    """A contact boundary must be a side of the body: one whose facets bound one cell. A named interface between two
    subdomains given the role contact was taken as a contact side inside the body (its vertices' shares added to
    node_weight, contact forces acting within the body)."""
    import itertools

    import numpy as np

    for name in contact:
        facets = {tuple(sorted(v.nr for v in el.vertices)) for el in mesh.Boundaries(name).Elements()}
        near = cells[np.isin(cells, list({v for f in facets for v in f})).any(axis=1)]  # (the cells at the side)
        faces = np.sort(np.concatenate([near[:, list(c)] for c in itertools.combinations(range(dim + 1), dim)]), axis=1)
        unique, counts = np.unique(faces, axis=0, return_counts=True)
        if facets & {tuple(f) for f in unique[counts > 1].tolist()}:
            raise ParameterError(f"boundaries: {name} = 'contact' is an interface between two parts of the mesh, not "
                                 "a side of the body; the contact side is an outer boundary")


class MeshBody(Geometry):
    """A body from a mesh file (:mod:`workbench.input.meshes`), its boundaries given roles.

    ``roles`` maps every boundary name of the mesh to ``clamped`` (all components fixed),
    ``traction`` (carries the scene's ``traction``), ``contact`` (faces the foundation) or
    ``free``. The foundation is the plane y = 0 (2D) / z = 0 (3D) and the body lies above it;
    a contact side off that plane is curved (:meth:`gap0`).
    """

    kind = "mesh"
    extent_names, cell_names = (), ()
    ROLES = ("clamped", "traction", "contact", "free")

    def __init__(self, h: float, path: str, roles: dict, digest: str = ""):
        import numpy as np

        self.path, self.roles, self.digest = str(path), dict(roles), digest
        self._ngmesh = _read_mesh(self.path, digest)
        mesh_dim = self._ngmesh.dim
        if mesh_dim != self.dim:
            raise ParameterError(f"mesh = {self.path!r} is a {mesh_dim}D mesh; this scene needs a {self.dim}D one "
                                 f"(workbench.scene(mesh=...) and a TOML geometry pick the scene by the mesh's "
                                 "dimension)")
        import ngsolve as ngs

        from . import meshes

        mesh = ngs.Mesh(self._ngmesh)
        names = sorted(meshes.boundary_names(mesh))
        for name, role in self.roles.items():
            if name not in names:
                raise ParameterError(f"boundaries: {name!r} is not a boundary of the mesh {self.path!r}; its "
                                     f"boundaries: {', '.join(names)}" + _closest(name, names))
            if role not in self.ROLES:
                raise ParameterError(f"boundaries: {name} = {role!r} is not a role; allowed: "
                                     f"{' | '.join(self.ROLES)}" + _closest(role, self.ROLES))
        missing = [n for n in names if n not in self.roles]
        if missing:
            raise ParameterError(f"boundaries: the mesh's boundary {missing[0]!r} has no role; give every boundary "
                                 f"one of {' | '.join(self.ROLES)} (free: no condition)"
                                 + (f" (also {', '.join(missing[1:])})" if len(missing) > 1 else ""))
        by_role = {r: [n for n in names if self.roles[n] == r] for r in self.ROLES}
        if not by_role["contact"]:
            raise ParameterError("boundaries: no boundary has the role contact (the side that faces the foundation)")
        if not by_role["clamped"]:
            raise ParameterError("boundaries: no boundary has the role clamped, so the body would float (a singular "
                                 "stiffness); clamp one")
        self.boundaries = {"clamp": "|".join(by_role["clamped"]), "contact": "|".join(by_role["contact"]),
                           "traction": tuple(by_role["traction"])}
        self.normal_axis, self.normal_sign = self.dim - 1, -1.0
        self.facet_axes = tuple(range(self.dim - 1))
        xyz = np.array(self._ngmesh.Coordinates())[:, : self.dim]
        self._bbox = tuple((float(lo), float(hi)) for lo, hi in zip(xyz.min(axis=0), xyz.max(axis=0)))
        self.extent = tuple(hi - lo for lo, hi in self._bbox)
        p1 = ngs.H1(mesh, order=1)
        on = np.nonzero(np.array(p1.GetDofs(mesh.Boundaries(self.boundaries["contact"])), dtype=bool))[0]
        lowest = float(xyz[on, self.normal_axis].min())
        axis = "yz"[self.dim - 2]
        if lowest < -1e-12 * self.size:
            raise ParameterError(f"mesh = {self.path!r}: the contact boundary reaches {axis} = {lowest:g} < 0; the "
                                 f"body must lie above the foundation {axis} = 0")
        self.curved = bool(xyz[on, self.normal_axis].max() > 1e-12 * self.size)
        self._contact_vertices = on
        self._clamped_vertices = np.nonzero(np.array(p1.GetDofs(mesh.Boundaries(self.boundaries["clamp"])),
                                                     dtype=bool))[0]
        self._xyz = xyz
        cells = {2: self._ngmesh.Elements2D, 3: self._ngmesh.Elements3D}[self.dim]().NumPy()
        nodes = np.asarray(cells["nodes"][:, : self.dim + 1], dtype=np.int64) - 1
        edges = [(a, b) for a in range(self.dim + 1) for b in range(a + 1, self.dim + 1)]
        self._h = float(max(np.linalg.norm(xyz[nodes[:, a]] - xyz[nodes[:, b]], axis=1).max() for a, b in edges))
        self._ne = len(nodes)
        _refuse_interfaces(mesh, nodes, by_role["contact"], self.dim)
        self.h, self.requested_cells = (float(h) if h else self._h), ()

    @classmethod
    def from_values(cls, values):
        return cls(values["h"], values["mesh"], values["boundaries"], values.get("mesh_digest", ""))

    @property
    def bbox(self):
        return self._bbox

    def cells(self):
        return (self._ne,)

    def n_cells(self):
        return self._ne

    def h_max(self):
        return self._h

    def vertex_count(self):
        return len(self._xyz)

    size_names = ("mesh",)

    def estimated_vertices(self):
        return float(len(self._xyz))

    def band_cells(self):
        return max(1, round(len(self._xyz) ** (1.0 / self.dim)))

    def default_probes(self):
        """The contact vertex that touches first (the lowest; of those, the farthest from the clamp) and the vertex of
        the body farthest from the clamp (a cantilever's tip): probes on the clamp would record zeros."""
        import numpy as np

        xyz, axis = self._xyz, self.normal_axis
        clamp = xyz[self._clamped_vertices]
        far = np.min(np.linalg.norm(xyz[:, None, :] - clamp[None, ::max(1, len(clamp) // 200), :], axis=2), axis=1)
        on = self._contact_vertices
        lowest = xyz[on, axis] <= xyz[on, axis].min() + 1e-9 * self.size
        low = on[lowest][int(far[on[lowest]].argmax())]
        farthest = np.nonzero(far >= far.max() - 1e-9 * self.size)[0]
        tip = int(farthest[xyz[farthest, axis].argmax()])  # (of those, the highest: the top of the tip)
        return tuple(tuple(float(c) for c in xyz[i]) for i in dict.fromkeys((low, tip)))

    def mesh(self):
        import ngsolve as ngs

        return ngs.Mesh(self._ngmesh.Copy())

    def nested_in(self, finer):
        return False

    def key(self):
        return (self.kind, self.path, self.digest)

    def tractions(self, values):
        return {side: values["traction"] for side in self.loadable}


class MeshBody2D(MeshBody):
    kind, dim = "mesh2d", 2


class MeshBody3D(MeshBody):
    kind, dim = "mesh3d", 3


def _read_mesh(path, digest):
    """The netgen mesh of a file, read once per process while it is among the last few used (keyed by the file's
    content)."""
    from . import meshes

    return _cached_mesh(path, digest or meshes.digest(path))


@functools.lru_cache(maxsize=MESH_CACHE)
def _cached_mesh(path, digest):
    from . import meshes

    return meshes.read(path)


def _closest(name, known):
    from ..values import closest_name

    return closest_name(name, known)


class _Indenter(Geometry):
    """A body with a curved contact side touching the foundation at the origin (Hertz), modelled by symmetry.

    Its symmetry planes hold the normal component (rollers), and its apex, which the contact holds in any
    case under a compressive load, is held in the foundation's normal direction: this removes the rigid
    motions a load-driven frictionless body has. The apex's contact force is the support's reaction
    (``pins_contact``). The mesh is graded from ``h_contact`` at the apex to ``h``.
    """

    extent_names, cell_names = ("radius",), ()
    curved, pins_contact, remeshable = True, True, True

    @property
    def mirror_axes(self) -> tuple:
        """The symmetry planes through the apex, one per axis along the contact side."""
        return self.facet_axes

    def __init__(self, h, cells=(), radius=1.0, h_contact=0.0, contact_zone=None):
        super().__init__(h, cells, radius=radius)
        self.h_contact = float(h_contact) if h_contact else self.h / 10.0
        self.contact_zone = float(contact_zone) if contact_zone else CONTACT_ZONE

    @classmethod
    def from_values(cls, values):
        return cls(values["h"], (), radius=values["radius"], h_contact=values.get("h_contact", 0.0),
                   contact_zone=values.get("contact_zone"))

    @property
    def bbox(self):
        R = self.extent[0]
        return ((0.0, R),) * self.dim

    def _netgen(self):
        return _indenter_mesh(self.kind, self.extent[0], self.h, self.h_contact, self.contact_zone)

    def mesh(self):
        import ngsolve as ngs

        return ngs.Mesh(self._netgen().Copy())

    def remeshed(self, points, sizes, grading: float) -> "Geometry":
        """The body on a new mesh of its geometry whose element size near each of ``points`` (point, axis) is at most
        its ``sizes``, and at most h everywhere (netgen grows the sizes between them by ``grading``): what
        ``space_adapt = "remesh"`` makes of the estimate, finer or coarser than the mesh before, not nested in it.

        Examples
        --------
        >>> import numpy as np, workbench
        >>> body = workbench.scene("memory_hertz", h=0.2, h_contact=0.02).model_of().geometry
        >>> m = body.remeshed([(0.0, 0.0)], [0.004], grading=0.3).mesh()  # (fine at the apex only)
        >>> sorted(set(m.GetBoundaries())), m.ne < body.mesh().ne
        (['axis', 'curved', 'flank', 'interface', 'top'], True)
        >>> edge = lambda e: np.linalg.norm(np.subtract(m[e.vertices[0]].point, m[e.vertices[1]].point))
        >>> bool(min(edge(e) for e in m.edges) < 0.005)
        True
        """
        return on_mesh(self, _remeshed_indenter(self.kind, self.extent[0], self.h, self.contact_zone, points, sizes,
                                                grading))

    def cells(self):
        return (self.n_cells(),)

    def n_cells(self):
        m = self._netgen()
        return len(m.Elements2D() if self.dim == 2 else m.Elements3D())

    def vertex_count(self):
        return len(self._netgen().Points())

    size_names = ("radius", "h", "h_contact")

    def estimated_vertices(self):
        """The body at h, the contact zone's side at h_contact and the body beneath it at ZONE_FACTOR h_contact."""
        R, zone, d = self.extent[0], self.zone_radius, self.dim
        count = (R / self.h) ** d + (zone / self.h_contact) ** (d - 1) + (zone / (ZONE_FACTOR * self.h_contact)) ** d
        return count if math.isfinite(count) else math.inf

    def band_cells(self):
        return max(1, round(self.vertex_count() ** (1.0 / self.dim)))

    def h_max(self):
        return self.h

    def aspect(self):
        return 1.0

    def key(self):
        return (self.kind, self.extent, self.h, self.h_contact, self.contact_zone)

    @property
    def zone_radius(self) -> float:
        return self.contact_zone * self.extent[0]

    def nested_in(self, finer):
        return False


class HalfDisc(_Indenter):
    """The 2D Hertz body: the half-disc x^2 + (y - R)^2 <= R^2, y <= R, flat side y = R on top, touching y = 0 at
    the origin; modelled as its half x >= 0 (roller on the axis x = 0, the apex held in y)."""

    kind, dim = "halfdisc", 2
    boundaries = {"clamp": "", "contact": "curved", "traction": ("top",)}
    normal_axis, normal_sign, facet_axes = 1, -1.0, (0,)

    def dirichlet_flags(self):
        return {"dirichletx": "axis", "dirichlety_bbnd": "apex"}

    def default_probes(self):
        """On the axis above the apex (the apex itself is held: its u is 0 by construction), and the top's corner."""
        R = self.extent[0]
        return ((0.0, 0.1 * R), (0.0, 0.5 * R), (0.0, R), (R, R))

    def tractions(self, values):
        from ..expressions import parse

        R = self.extent[0]  # the total load over the whole flat side (width 2R), per unit thickness
        return {"top": parse(f"(0, -({values['load'].source}) / {2.0 * R!r})", name="load", size=2)}


class Hemisphere(_Indenter):
    """The 3D Hertz body: the lower half of the ball of radius R centred at (0, 0, R), flat side z = R on top;
    modelled as its quarter x, y >= 0 (rollers on x = 0 and y = 0, the apex held in z)."""

    kind, dim = "hemisphere", 3
    boundaries = {"clamp": "", "contact": "curved", "traction": ("top",)}
    normal_axis, normal_sign, facet_axes = 2, -1.0, (0, 1)

    def dirichlet_flags(self):
        return {"dirichletx": "symx", "dirichlety": "symy", "dirichletz_bbbnd": "apex"}

    def default_probes(self):
        """On the axis above the apex (the apex itself is held: its u is 0 by construction)."""
        R = self.extent[0]
        return ((0.0, 0.0, 0.1 * R), (0.0, 0.0, 0.5 * R), (0.0, 0.0, R))

    def tractions(self, values):
        from ..expressions import parse

        # the total load over the whole flat disc: 4 x the meshed quarter's area (its polygon, not pi R^2 / 4, so
        # that the force is the load exactly)
        area = 4.0 * _flat_boundary_area(self._netgen(), "top")
        return {"top": parse(f"(0, 0, -({values['load'].source}) / {area!r})", name="load", size=3)}


def _flat_boundary_area(ngmesh, name: str) -> float:
    """The area of the boundary ``name`` of a netgen mesh of straight triangles, from its vertices (making an NGSolve
    mesh to integrate over it took 0.5 s at 193k dofs; this, 2 ms)."""
    import numpy as np

    elements = ngmesh.Elements2D().NumPy()
    names = np.array([ngmesh.GetBCName(i) for i in range(ngmesh.GetNFaceDescriptors())])
    corners = np.asarray(ngmesh.Coordinates())[elements["nodes"][names[elements["index"] - 1] == name] - 1]
    return float(0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
                                      axis=1).sum())


#: The zone around the apex (the default of the scene parameter ``contact_zone``): the contact side within
#: CONTACT_ZONE R of it is meshed with h_contact, the body beneath it (CONTACT_ZONE R wide, half that deep) with
#: ZONE_FACTOR h_contact; the mesh is graded to h beyond.
#: Only that part of the curved side is the contact boundary (``curved``; the rest, ``flank``, is free, with an
#: initial gap of at least R (1 - sqrt(1 - CONTACT_ZONE^2)) = 0.046 R): the scene warns when Hertz's contact
#: radius for the largest load comes near the zone's edge.
#: (Grading from the boundary alone left the body above the contact coarse: measured on memory_hertz, the
#: pressure's L2 error stalled at 3-5 %; with the zone it falls 1.9, 0.83, 0.50 % as h_contact halves.)
CONTACT_ZONE, ZONE_FACTOR = 0.3, 4.0


@functools.lru_cache(maxsize=MESH_CACHE)
def _indenter_mesh(kind, R, h, h_contact, contact_zone=CONTACT_ZONE):
    """The netgen mesh of a Hertz body (OCC), refined in the contact zone (``contact_zone`` R around the apex); made
    once per size and kept in the cache folder (the hemisphere at h_contact = 0.005: 7.5 s to make, 0.1 s to load),
    and in the process while it is among the last few used."""
    from .meshes import cached_netgen

    # (the faces named by their vertices: a mesh cached before named the zone's wall "curved")
    key = (f"indenter {kind} R={R!r} h={h!r} h_contact={h_contact!r} zone={contact_zone!r} sides named by their "
           "vertices")
    return cached_netgen(key, lambda: _make_indenter_mesh(kind, R, h, h_contact, contact_zone))


def _make_indenter_mesh(kind, R, h, h_contact, contact_zone):
    return _indenter_geometry(kind, R, h_contact, contact_zone).GenerateMesh(maxh=h, grading=0.25)


def _indenter_geometry(kind, R, h_contact, contact_zone):
    """The OCC geometry of a Hertz body, its contact zone's sizes set for ``h_contact``, its apex named."""
    from netgen.occ import OCCGeometry

    shape = (_halfdisc_shape if kind == "halfdisc" else _quarter_ball_shape)(R, h_contact, contact_zone)
    tol = 1e-9 * R
    for v in shape.vertices:
        p = v.p
        if abs(p.x) < tol and abs(p.y) < tol and abs(p.z) < tol:
            v.name = "apex"
    return OCCGeometry(shape, dim=2) if kind == "halfdisc" else OCCGeometry(shape)


def _remeshed_indenter(kind, R, h, contact_zone, points, sizes, grading):
    """The netgen mesh of a Hertz body at h with the local sizes ``sizes`` at ``points`` (no contact zone of its own:
    its faces and the contact side take h, the sizes do the rest)."""
    from netgen.meshing import MeshingParameters

    mp = MeshingParameters(maxh=h, grading=grading)
    for point, size in zip(points, sizes):
        x, y, z = (tuple(float(c) for c in point) + (0.0,))[:3]
        mp.RestrictH(x=x, y=y, z=z, h=float(size))
    return _indenter_geometry(kind, R, h, contact_zone).GenerateMesh(mp=mp)


def _on_circle(part, kind, R):
    """Whether the OCC edge or face ``part`` lies on the indenter's curved side (the circle or sphere of radius R
    about the centre R above the apex): its vertices on it, and its centre near it (a curved part's centre of mass
    lies inside, the flank's 0.13 R). The centre alone (within 0.1 R) took the wall of the 3D contact zone, inside
    the body, for the contact side: 40 % of the side's area, on which a glue pulled."""
    import math

    def off(p):
        return abs(math.sqrt(p.x ** 2 + p.y ** 2 + p.z ** 2 - 2 * R * (p.y if kind == "halfdisc" else p.z) + R * R)
                   - R)

    return off(part.center) < 0.2 * R and all(off(v.p) < 1e-6 * R for v in part.vertices)


def _halfdisc_shape(R, h_contact, contact_zone):
    """The OCC half-disc of the 2D Hertz body, its contact zone glued in with finer maxh, its edges named."""
    import math

    from netgen.occ import ArcOfCircle, Face, Glue, MoveTo, Pnt, Segment, Wire

    tol, w = 1e-9 * R, contact_zone * R
    phi = math.asin(contact_zone)
    arc = lambda a: Pnt(R * math.sin(a), R - R * math.cos(a), 0.0)  # noqa: E731 (the angle from the apex)
    apex, corner, centre = Pnt(0.0, 0.0, 0.0), Pnt(R, R, 0.0), Pnt(0.0, R, 0.0)
    body = Face(Wire([ArcOfCircle(apex, arc(phi / 2), arc(phi)),
                      ArcOfCircle(arc(phi), arc((phi + math.pi / 2) / 2), corner),
                      Segment(corner, centre), Segment(centre, apex)]))
    zone = MoveTo(0.0, 0.0).Rectangle(w, w / 2).Face()
    shape = Glue([body * zone, body - zone])
    for f in shape.faces:
        if f.center.y < w / 2 and f.center.x < w:
            f.maxh = ZONE_FACTOR * h_contact
    for e in shape.edges:
        c = e.center
        e.name = "axis" if abs(c.x) < tol else "top" if abs(c.y - R) < tol \
            else "curved" if _on_circle(e, "halfdisc", R) \
            else "interface"  # (between the zone and the rest: not a boundary of the body)
        if e.name == "curved":
            if c.x < w:
                e.maxh = h_contact
            else:
                e.name = "flank"
    return shape


def _quarter_ball_shape(R, h_contact, contact_zone):
    """The OCC quarter ball of the 3D Hertz body, its contact zone glued in with finer maxh, its faces named."""
    import math

    from netgen.occ import Box, Cylinder, Glue, Pnt, Sphere, Z

    tol, w = 1e-9 * R, contact_zone * R
    quarter = Sphere(Pnt(0.0, 0.0, R), R) * Box(Pnt(0.0, 0.0, 0.0), Pnt(R, R, R))
    zone = Cylinder(Pnt(0.0, 0.0, 0.0), Z, r=w, h=w / 2)
    shape = Glue([quarter * zone, quarter - zone])
    for solid in shape.solids:
        if solid.center.z < w / 2:
            solid.maxh = ZONE_FACTOR * h_contact
    for f in shape.faces:
        c = f.center
        if abs(c.x) < tol:
            f.name = "symx"
        elif abs(c.y) < tol:
            f.name = "symy"
        elif abs(c.z - R) < tol:
            f.name = "top"
        elif _on_circle(f, "hemisphere", R) and math.hypot(c.x, c.y) < w:
            f.name, f.maxh = "curved", h_contact
        elif _on_circle(f, "hemisphere", R):
            f.name = "flank"
        else:
            f.name = "interface"
            if c.z < w / 2 - tol:  # (the zone's wall keeps the size it had when taken for the contact side, so
                f.maxh = h_contact  # the meshes, and what was measured on them, are the same)
    return shape


class _OnMesh:
    """A body on a mesh given to it (by the adaptive loop: its own mesh, refined), in place of the one it makes
    (:func:`on_mesh`); everything else is the body's."""

    adapted_mesh = None  # (the netgen mesh)
    base_key = ()
    body_class = Geometry

    def mesh(self):
        import ngsolve as ngs

        return ngs.Mesh(self.adapted_mesh.Copy())

    def _netgen(self):  # (a Hertz body measures its loaded side on it)
        return self.adapted_mesh

    def n_cells(self):
        m = self.adapted_mesh
        return len(m.Elements2D() if self.dim == 2 else m.Elements3D())

    def h_max(self):
        """The longest cell side along the axes, as for the body's own mesh: the largest coordinate difference
        along a cell edge (the cells the refinement left are as long as the given mesh's; counting the cells along
        a side, as a box does, would give the refined mesh's mean)."""
        import itertools

        import numpy as np

        m = self.adapted_mesh
        cells = (m.Elements2D() if self.dim == 2 else m.Elements3D()).NumPy()["nodes"][:, : self.dim + 1] - 1
        xyz = np.asarray(m.Coordinates(), dtype=float)[:, : self.dim]
        return float(max(np.abs(xyz[cells[:, i]] - xyz[cells[:, j]]).max()
                         for i, j in itertools.combinations(range(self.dim + 1), 2)))

    def cells(self):
        return (self.n_cells(),)

    def vertex_count(self):
        return len(self.adapted_mesh.Points())

    def estimated_vertices(self):
        return float(self.vertex_count())

    def band_cells(self):
        return max(1, round(self.vertex_count() ** (1.0 / self.dim)))

    def nested_in(self, finer):
        return False

    def key(self):
        """The body's own key and the digest of the mesh's points (caches must not mix a body's meshes)."""
        import hashlib

        import numpy as np

        points = np.ascontiguousarray(self.adapted_mesh.Coordinates(), dtype=float)
        return self.base_key + ("on mesh", self.n_cells(), hashlib.sha256(points.tobytes()).hexdigest()[:16])


_ON_MESH: dict = {}


def on_mesh(body: Geometry, ngmesh) -> Geometry:
    """The body ``body`` on the netgen mesh ``ngmesh`` (its own mesh refined: the boundaries keep their names).

    Examples
    --------
    >>> g = Slab(width=1.0, height=0.1, h=0.05)
    >>> m = g.mesh()
    >>> m.Refine()
    >>> fine = on_mesh(g, m.ngmesh)
    >>> fine.mesh().ne, fine.cells(), fine.kind, fine.key() != g.key()
    (320, (320,), 'slab', True)
    """
    import copy

    if body.dim < 2:
        raise ParameterError(f"a {body.kind} cannot be refined adaptively: netgen refines meshes in 2D and 3D only")
    base = body.body_class if isinstance(body, _OnMesh) else type(body)
    cls = _ON_MESH.setdefault(base, type(f"{base.__name__}OnMesh", (_OnMesh, base), {"body_class": base}))
    out = copy.copy(body)
    out.base_key = body.base_key if isinstance(body, _OnMesh) else body.key()
    out.__class__, out.adapted_mesh = cls, ngmesh
    return out


def adapted_mesh(body: Geometry):
    """The netgen mesh ``body`` was put on (:func:`on_mesh`: by an adaptive run, or read from its archive), or None
    for a body on the mesh it makes itself."""
    return body.adapted_mesh if isinstance(body, _OnMesh) else None


def of_run(body: Geometry, ds) -> Geometry:
    """The body a run was computed on: ``body`` (the scene's), on the run's adapted mesh where the run refined it
    (``space_tol > 0``; the archive's ``adapted_mesh``)."""
    if "adapted_mesh" not in ds:
        return body
    from .meshes import from_text

    return on_mesh(body, from_text(str(ds.adapted_mesh.values)))


#: The built-in geometries by name.
GEOMETRIES = {g.kind: g for g in (Rod, Slab, Block, MeshBody2D, MeshBody3D, HalfDisc, Hemisphere)}
