"""From a scene to NGSolve objects: mesh, spaces, constant matrices, load and boundary forms.

Built once per run, before time stepping. The volume matrices (viscous K_A,
elastic K_G) are assembled here once; the contact-boundary forms exist only
for the terms the scene declares (no contact and no adhesion: no boundary
form; no adhesion: no beta space). Index arrays into the dof vector (contact
nodes, probes, the point force, Dirichlet dofs) are computed here, so the time
loop does only vector work.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import ngsolve as ngs
import numpy as np

from . import meshes
from .physics import bonding, contact, kelvin_voigt
from .scenes import BOUNDARIES


@dataclass
class Discretisation:
    """Everything a scheme needs about one scene on one mesh (see :func:`build`)."""

    scene: object
    mesh: ngs.Mesh
    fes: ngs.FESpace
    t: ngs.Parameter
    u: ngs.GridFunction
    v: ngs.GridFunction
    viscous: ngs.BilinearForm
    elastic: ngs.BilinearForm
    contact_name: str
    beta: ngs.GridFunction | None = None
    loads: Loads | None = None
    contact_form: ngs.LinearForm | None = None
    rate_form: ngs.LinearForm | None = None
    facet_measure: np.ndarray | None = None
    beta_dofs: np.ndarray | None = None
    facet_xyz: np.ndarray | None = None
    node_dofs: np.ndarray = field(default=None)  # (node, component) -> dof
    node_xyz: np.ndarray = field(default=None)
    vertex_dofs: np.ndarray = field(default=None)  # (vertex, component) -> dof
    vertex_xyz: np.ndarray = field(default=None)
    memory_kind: str = "none"  # Model B: "prony", "kernel" or "none"
    memory: list = field(default_factory=list)
    contact_weights: np.ndarray | None = None  # Model B: w_i of the contact vertices
    dirichlet_dofs: np.ndarray = field(default=None)
    probe_points: object = None

    @property
    def dim(self) -> int:
        return self.scene.dim

    @property
    def ndof(self) -> int:
        return self.fes.ndof

    def load_vector(self, time: float, out) -> None:
        """out = F(time): tractions, body force and the point force (out is overwritten)."""
        self.loads.vector(time, out)

    def dirichlet_value(self, time: float) -> float:
        """Prescribed displacement on Gamma_1 at ``time`` (rod: delta(t); others: 0)."""
        return self.scene["delta"](t=time) if self.dim == 1 else 0.0

    def normal_displacement(self, uvec: np.ndarray) -> np.ndarray:
        """u_nu at the contact nodes from a dof vector (1D: u at the rod end)."""
        if self.dim == 1:
            return uvec[self.node_dofs[:, 0]]
        return -uvec[self.node_dofs[:, -1]]  # flat contact side with nu = -e_y (2D) or -e_z (3D)

    def probe_values(self) -> np.ndarray:
        """u at the probe points, shape (probe, component)."""
        vals = self.u(self.probe_points)
        return np.asarray(vals).reshape(len(self.scene["probes"]), self.dim)


def _vector_space(scene, mesh, order):
    clamp = BOUNDARIES[scene.geometry]["clamp"]
    if scene.dim == 1:
        return ngs.H1(mesh, order=order, dirichlet=clamp)
    return ngs.VectorH1(mesh, order=order, dirichlet=clamp)


def _vertex_dofs(fes, dim, nv):
    """dof of (vertex i, component c): vertex dofs come first in each component block."""
    per_comp = fes.ndof // dim
    table = np.arange(nv)[:, None] + per_comp * np.arange(dim)[None, :]
    probe = list(fes.GetDofNrs(ngs.NodeId(ngs.VERTEX, nv - 1)))
    assert probe == list(table[-1]), "unexpected dof numbering in the displacement space"
    return table


def _boundary_vertices(mesh, name):
    p1 = ngs.H1(mesh, order=1)
    return np.nonzero(np.array(p1.GetDofs(mesh.Boundaries(name)), dtype=bool))[0]


class Loads:
    """F(t) = (tractions and body force, w) plus a nodal point force, evaluated cheaply per step.

    A load whose expression does not depend on x, y, z is g(t) times a fixed
    vector: its per-component vectors are assembled once (stored sparse) and a
    step only evaluates g(t). Loads that vary in space and time are collected
    in one LinearForm assembled per step; space-only ones in one assembled once.
    """

    def __init__(self, scene, fes, t, vertex_dofs, vertex_xyz):
        self.scene, self.t = scene, t
        self.separable = []  # (expression, component, dof indices, values)
        varying = ngs.LinearForm(fes)
        fixed = ngs.LinearForm(fes)
        n_varying = n_fixed = 0
        w = fes.TestFunction()
        dim = scene.dim
        pieces = [(scene[f"traction_{side}"], ngs.ds(side)) for side in BOUNDARIES[scene.geometry]["traction"]]
        if dim > 1:
            pieces.append((scene["body_force"], ngs.dx))
        for expr, region in pieces:
            if expr.is_zero():
                continue
            if not expr.variables & {"x", "y", "z"}:
                for c in range(dim):
                    unit = ngs.LinearForm(fes)
                    unit += w[c] * region
                    unit.Assemble()
                    vec = unit.vec.FV().NumPy()
                    idx = np.nonzero(vec)[0]
                    self.separable.append((expr, c, idx, vec[idx].copy()))
            elif expr.depends_on("t"):
                varying += ngs.InnerProduct(expr.cf(t), w).Compile() * region
                n_varying += 1
            else:
                fixed += ngs.InnerProduct(expr.cf(t), w).Compile() * region
                n_fixed += 1
        self.varying = varying if n_varying else None
        self.fixed = None
        if n_fixed:
            fixed.Assemble()
            self.fixed = fixed.vec.FV().NumPy().copy()
        self.point_dofs = None
        if dim > 1 and not scene["point_force"].is_zero():
            at = np.asarray(scene["point_force_at"][0])
            nearest = int(np.argmin(np.sum((vertex_xyz - at) ** 2, axis=1)))
            self.point_dofs = vertex_dofs[nearest]

    @property
    def empty(self) -> bool:
        return not self.separable and self.varying is None and self.fixed is None and self.point_dofs is None

    def vector(self, time: float, out) -> None:
        """out = F(time) (an NGSolve vector, overwritten)."""
        arr = out.FV().NumPy()
        if self.varying is not None:
            self.t.Set(time)
            self.varying.Assemble()
            arr[:] = self.varying.vec.FV().NumPy()
        else:
            arr[:] = 0.0
        if self.fixed is not None:
            arr += self.fixed
        values = {}
        for expr, c, idx, vals in self.separable:
            if id(expr) not in values:  # evaluate each expression once per step
                values[id(expr)] = np.atleast_1d(expr(t=time))
            g = values[id(expr)][c]
            if g != 0.0:
                arr[idx] += g * vals
        if self.point_dofs is not None:
            arr[self.point_dofs] += np.atleast_1d(self.scene["point_force"](t=time))


def build(scene) -> Discretisation:
    """Assemble the scene's constant parts on its mesh (Model B: see :func:`build_memory`).

    Examples
    --------
    >>> from workbench.scenes import scene
    >>> d = build(scene("tp1", h=0.1))
    >>> d.ndof, d.beta_dofs.size, d.contact_form is not None
    (11, 1, True)
    """
    if scene.model == "B":
        return build_memory(scene)
    mesh = meshes.build(scene)
    dim, order = scene.dim, scene["order"]
    fes = _vector_space(scene, mesh, order)
    u_trial, w = fes.TnT()
    A, G = kelvin_voigt.tensors(scene)
    viscous = ngs.BilinearForm(fes, symmetric=True)
    viscous += kelvin_voigt.energy_product(A, u_trial, w, dim) * ngs.dx
    elastic = ngs.BilinearForm(fes, symmetric=True)
    elastic += kelvin_voigt.energy_product(G, u_trial, w, dim) * ngs.dx
    viscous.Assemble()
    elastic.Assemble()

    d = _new(scene, mesh, fes, viscous, elastic)
    u, contact_name = d.u, d.contact_name
    terms = scene.terms
    if "adhesion" in terms:
        _add_bonding(d)
    integrand = contact.boundary_integrand(terms, scene, u, d.beta, w)
    if integrand is not None:
        d.contact_form = ngs.LinearForm(fes)
        d.contact_form += integrand.Compile() * ngs.ds(contact_name)
    return d


def _new(scene, mesh, fes, viscous, elastic) -> Discretisation:
    """The state (u at u0, v = 0), time parameter and index arrays around the assembled matrices."""
    u, v = ngs.GridFunction(fes, "u"), ngs.GridFunction(fes, "velocity")
    if "u0" in scene.values:  # Model A's initial condition (Model B solves for u(0))
        u.Set(scene["u0"].cf())
    d = Discretisation(scene, mesh, fes, ngs.Parameter(0.0), u, v, viscous, elastic,
                       BOUNDARIES[scene.geometry]["contact"])
    _index_arrays(d)
    return d


def _index_arrays(d: Discretisation) -> None:
    """Vertex/contact-node dof tables, Dirichlet dofs, probe points and loads."""
    mesh, fes, scene, dim = d.mesh, d.fes, d.scene, d.dim
    ngmesh = mesh.ngmesh  # keep the wrapper alive: Coordinates() is a view into it
    coords = np.array(ngmesh.Coordinates())[:, :dim]
    d.vertex_xyz = coords
    d.vertex_dofs = _vertex_dofs(fes, dim, mesh.nv)
    nodes = _boundary_vertices(mesh, d.contact_name)
    d.node_dofs, d.node_xyz = d.vertex_dofs[nodes], coords[nodes]
    free = np.array(fes.FreeDofs(), dtype=bool)
    d.dirichlet_dofs = np.nonzero(~free)[0]

    xs = [np.array([p[i] for p in scene["probes"]]) for i in range(dim)]
    d.probe_points = mesh(*xs)

    d.loads = Loads(scene, fes, d.t, d.vertex_dofs, coords)


def build_memory(scene) -> Discretisation:
    """Model B: the elastic stiffness K_A, the memory stiffnesses and the nodal contact weights.

    ``viscous`` is None (no viscosity); ``elastic`` is K_A; ``memory`` holds
    (K_Ci, tau_i) for a Prony series or (K_C, b) for a general kernel;
    ``contact_weights`` are w_i = int_Gamma3 phi_i da of the contact vertices.
    """
    from .physics import memory

    mesh = meshes.build(scene)
    dim = scene.dim
    fes = _vector_space(scene, mesh, 1)
    u_trial, w = fes.TnT()

    def stiffness(tensor):
        form = ngs.BilinearForm(fes, symmetric=True)
        form += kelvin_voigt.energy_product(tensor, u_trial, w, dim) * ngs.dx
        form.Assemble()
        return form

    A = kelvin_voigt.scalar(scene["a"]) if dim == 1 else \
        memory.tensor_of(scene["E"], scene["nu"], dim)
    d = _new(scene, mesh, fes, None, stiffness(A))
    contact_name = d.contact_name
    d.memory_kind = "prony" if scene["prony"] else ("kernel" if "memory" in scene.terms else "none")
    if d.memory_kind == "prony":
        d.memory = [(stiffness(C), C, tau) for C, tau in memory.prony_tensors(scene)]
    elif d.memory_kind == "kernel":
        C, b = memory.kernel_tensor(scene)
        d.memory = [(stiffness(C), C, b)]
    else:
        d.memory = []
    p1 = ngs.H1(mesh, order=1)
    lf = ngs.LinearForm(p1)
    lf += p1.TestFunction() * ngs.ds(contact_name)
    lf.Assemble()
    vertices = _boundary_vertices(mesh, contact_name)
    d.contact_weights = lf.vec.FV().NumPy()[vertices].copy()
    return d


def bonding_space(mesh, dim: int, name: str):
    """The space of beta: P0 on the contact facets (a point value at the 1D rod end).

    Returns (space, beta_dofs, facet measures, facet midpoints): the dofs that
    live on the contact side, in the order the results store them.
    """
    if dim == 1:
        space = ngs.H1(mesh, order=1, definedon=mesh.Boundaries(name))
    else:
        space = ngs.SurfaceL2(mesh, order=0, definedon=mesh.Boundaries(name))
    q = space.TestFunction()
    measure = ngs.LinearForm(space)
    measure += q * ngs.ds(name)
    measure.Assemble()
    m = measure.vec.FV().NumPy().copy()
    dofs = np.nonzero(m > 0)[0]
    xyz = []
    for c in (ngs.x, ngs.y, ngs.z)[:dim]:
        lf = ngs.LinearForm(space)
        lf += c * q * ngs.ds(name)
        lf.Assemble()
        xyz.append(lf.vec.FV().NumPy()[dofs] / m[dofs])
    return space, dofs, m[dofs], np.stack(xyz, axis=1)


def _add_bonding(d: Discretisation) -> None:
    """The beta field and its rate form (bonding law, P_B = facet mean)."""
    scene, name = d.scene, d.contact_name
    space, d.beta_dofs, d.facet_measure, d.facet_xyz = bonding_space(d.mesh, d.dim, name)
    q = space.TestFunction()
    d.beta = ngs.GridFunction(space, "beta")
    d.beta.vec.FV().NumPy()[d.beta_dofs] = scene["beta0"]
    v = scene.values
    u_nu, _ = contact.normal_and_tangential(d.u, contact.outward_normal(d.dim), d.dim)
    rate = bonding.debonding_rate(d.beta, u_nu, v["gamma_nu"], v["eps_a"], v["L"], v["bonding_truncation"])
    d.rate_form = ngs.LinearForm(space)
    d.rate_form += (rate * q).Compile() * ngs.ds(name)
