"""From a model to NGSolve objects: mesh, spaces, constant matrices, loads and the contact side.

Built once per run, before time stepping. The volume matrices (Model A: viscous K_A
and elastic K_G; Model B: the elastic K_A and one stiffness per relaxation tensor)
are assembled here once; the contact side is prepared as quadrature points with
trace operators (:mod:`workbench.discrete.boundary`), only for the terms the model declares
(no contact and no adhesion: none; no adhesion: no beta field). Index arrays into
the dof vector (contact nodes, probes, the point force, Dirichlet dofs) are
computed here, so the time loop does only vector work.

The NGSolve forms of the boundary functional j and of the bonding rate
(:attr:`Discretisation.contact_form`, :attr:`Discretisation.rate_form`) remain the
definition the fast path is checked against; they are built only when asked for.

Examples
--------
>>> from workbench.input.scenes import scene
>>> d = build(scene("tp1", h=0.1))
>>> d.ndof, d.beta_dofs.size, d.contact_form is not None
(11, 1, True)
"""
from __future__ import annotations

from functools import cached_property

import ngsolve as ngs
import numpy as np

from ..input import numerics as numerics_of
from ..physics import kelvin_voigt
from ..physics.ops import NGS
from .boundary import ContactSide
from .exchange import Exchange
from .world import SERIAL


def stiffness(fes, tensor, dim: int, preconditioner: str | None = None) -> ngs.BilinearForm:
    """The assembled form (tensor eps(u), eps(w)): K_A, K_G or a relaxation stiffness; with ``preconditioner`` (e.g.
    "bddc"), (the form, NGSolve's preconditioner of that name, registered before the assembly as it must be)."""
    u, w = fes.TnT()
    form = ngs.BilinearForm(fes, symmetric=True)
    form += kelvin_voigt.energy_product(tensor, u, w, dim) * ngs.dx
    if preconditioner is None:
        return form.Assemble()
    pre = ngs.Preconditioner(form, preconditioner)
    return form.Assemble(), pre


class Discretisation:
    """Everything a scheme needs about one model on one mesh (see :func:`build`).

    Attributes
    ----------
    model : ModelA or ModelB
    scene : Scene
        For its probes, snapshots and name.
    numerics : workbench.input.numerics.Numerics
        The element order, the solver and the scheme's options.
    world : workbench.discrete.world.Serial
        The processes that hold the body (one: :data:`workbench.discrete.world.SERIAL`; a body distributed over MPI
        processes is a :class:`workbench.parallel.DistributedDiscretisation`, which overrides the methods of the
        section "where the data lives" below).
    geometry : workbench.input.geometry.Geometry
    mesh, fes : the mesh and the displacement space (H1 in 1D, VectorH1 otherwise)
    t : ngsolve.Parameter
        The time at which space- and time-dependent loads are assembled.
    u, v : ngsolve.GridFunction
        Displacement and velocity.
    viscous, elastic : ngsolve.BilinearForm
        Model A: K_A and K_G; Model B: ``viscous`` is None and ``elastic`` is K_A.
    side, rate_side : ContactSide or None
        Model A: the contact side at the quadrature points of the boundary functional
        and at the facet midpoints (the bonding rate).
    beta : ngsolve.GridFunction or None
        The bonding field (P0 on the contact facets); ``beta_dofs`` its dofs in facet order,
        ``facet_measure`` and ``facet_xyz`` (midpoints) alongside.
    memory : list
        Model B: (K_C, C, tau_or_shape) per relaxation tensor (``memory_scale``: where the terms of a fitted
        kernel share one K_C, the stiffness of term i is memory_scale[i] K_C).
    contact_weights : ndarray
        Model B: w_i = int_Gamma3 phi_i da at the contact vertices.
    """

    world = SERIAL

    def __init__(self, model, scene, mesh, fes, numerics=None):
        self.model, self.scene, self.geometry = model, scene, model.geometry
        self.numerics = numerics or numerics_of.from_scene(scene)
        self.mesh, self.fes = mesh, fes
        self.dim = self.geometry.dim
        self.contact_name = self.geometry.boundaries["contact"]
        self.t = ngs.Parameter(0.0)
        self.u, self.v = ngs.GridFunction(fes, "u"), ngs.GridFunction(fes, "velocity")
        self.viscous = self.elastic = None
        self.side = self.rate_side = self.beta = None
        self.beta_dofs = self.facet_measure = self.facet_xyz = None
        self.memory, self.memory_kind, self.contact_weights = [], "none", None
        self.memory_scale = None  # K_i = memory_scale[i] * memory[i][0] when terms share a stiffness (else 1)
        self._index_arrays()
        self.loads = Loads(model.loads, fes, self.t, self.geometry, self.vertex_dofs, self.vertex_xyz)

    @property
    def ndof(self) -> int:
        return self.fes.ndof

    # -- where the data lives (one process here; a distributed body overrides these) -------------------------------
    @property
    def ndof_global(self) -> int:
        """The dofs of the whole body (on several processes: of the serial run)."""
        return self.ndof

    def owned(self):
        """True at the dofs whose sums this process counts (each shared dof once over the processes); None: all."""
        return None

    def viscous_solver(self, iterative: bool = True):
        """K_A factored (or, ``iterative`` and in 3D beyond the factor's memory, solved by AMG-preconditioned CG) with
        the scene's ``solver`` (:func:`workbench.discrete.solvers.choose`)."""
        from . import solvers

        method = solvers.choose(self.numerics.solver, self.dim, self.ndof, iterative=iterative)
        return solvers.factor(self.viscous.mat, self.fes.FreeDofs(), self.u.vec, method, fes=self.fes)

    def step_solver(self) -> str:
        """The linear solver of the implicit schemes' step operators: the scene's ``solver``, with ``auto`` resolved
        to ``cg`` in 3D where the sparse factor would exceed :data:`workbench.discrete.solvers.FACTOR_BYTES` and the
        contact is solved on the whole body (:func:`workbench.input.numerics.may_iterate`)."""
        from ..input.numerics import may_iterate
        from . import solvers

        n = self.numerics
        return solvers.choose(n.solver, self.dim, self.ndof, iterative=may_iterate(n.scheme, n.contact_solver))

    def step_factor(self, M):
        """The solver of an implicit step's operator ``M`` (assembled on K_A's pattern) by :meth:`step_solver`."""
        from . import solvers

        return solvers.factor(M, self.fes.FreeDofs(), self.u.vec, self.step_solver(), fes=self.fes)

    def exchange(self):
        """How the contact solver of an implicit step reaches the body (:mod:`workbench.discrete.exchange`)."""
        return Exchange(self)

    def springs(self, solver):
        """The operators of the body on boundary springs with K_A solved by ``solver``: the explicit scheme's step
        limit (:class:`workbench.discrete.eigen.SpringOperators`)."""
        from .eigen import SpringOperators

        return SpringOperators(self, solver)

    def gather_state(self, state: dict, layout: dict):
        """A scheme's state in the order of the whole body (:meth:`workbench.schemes.base.Scheme.state`; ``layout``:
        where its extra arrays live), on the process that records (None on the others)."""
        return state

    def scatter_state(self, state: dict, layout: dict) -> dict:
        """This process's part of a state in the order of the whole body (:meth:`gather_state`)."""
        return state

    def recording(self, make, observer=None):
        """The recorder of a run, ``make(disc)`` for the discretisation that records (several processes: rank 0's
        serial view, fed with the gathered states and the snapshot vectors of ``observer``, the scheme's own)."""
        return make(self)

    def _index_arrays(self) -> None:
        """Vertex/contact-node dof tables, Dirichlet dofs and probe points."""
        mesh, fes, dim = self.mesh, self.fes, self.dim
        ngmesh = mesh.ngmesh  # keep the wrapper alive: Coordinates() is a view into it
        coords = np.array(ngmesh.Coordinates()).reshape(mesh.nv, ngmesh.dim)[:, :dim]  # (MPI's rank 0: no vertices)
        self.vertex_xyz = coords
        self.vertex_dofs = _vertex_dofs(fes, dim, mesh.nv)
        nodes = _boundary_vertices(mesh, self.contact_name)
        self.vertex_numbers = nodes  # the contact vertices (mesh vertex numbers), in node order
        self.node_dofs, self.node_xyz = self.vertex_dofs[nodes], coords[nodes]
        free = np.array(fes.FreeDofs(), dtype=bool)
        self.dirichlet_dofs = np.nonzero(~free)[0]
        probes = self.scene["probes"]
        self.probe_points = mesh(*[np.array([p[i] for p in probes]) for i in range(dim)])

    # -- the prescribed end and the contact nodes ---------------------------------------------------------------
    def dirichlet_value(self, time: float) -> float:
        """Prescribed displacement on Gamma_1 at ``time`` (rod: delta(t); others: 0)."""
        delta = self.model.loads.delta
        return delta(t=time) if delta is not None else 0.0

    @cached_property
    def moves_clamp(self) -> bool:
        """Whether the prescribed displacement on Gamma_1 is non-zero somewhere in time (the rod's delta)."""
        delta = self.model.loads.delta
        return delta is not None and not delta.is_zero()

    def lift(self, time: float, out: np.ndarray) -> np.ndarray:
        """``out`` = the dof vector that is delta(time) on the Dirichlet dofs and 0 elsewhere."""
        out[:] = 0.0
        out[self.dirichlet_dofs] = self.dirichlet_value(time)
        return out

    def normal_displacement(self, uvec: np.ndarray) -> np.ndarray:
        """u_nu at the contact nodes from a dof vector."""
        g = self.geometry
        return g.normal_sign * uvec[self.node_dofs[:, g.normal_axis]]

    @property
    def normal_dofs(self) -> np.ndarray:
        """The dof of the normal component at each contact node."""
        return self.node_dofs[:, self.geometry.normal_axis]

    @cached_property
    def node_weights(self) -> np.ndarray:
        """w_i = int_Gamma3 phi_i da at the contact vertices (phi_i the P1 hat function): a vertex's share of the
        contact side, by which a nodal contact force becomes a pressure (lumped quadrature)."""
        if self.dim == 1:
            return np.ones(len(self.node_dofs))
        p1 = ngs.H1(self.mesh, order=1)
        lf = ngs.LinearForm(p1)
        lf += p1.TestFunction() * ngs.ds(self.contact_name)
        lf.Assemble()
        return lf.vec.FV().NumPy()[self.vertex_numbers].copy()

    @cached_property
    def pressure_recovery(self):
        """The contact pressure averaged over the vertices' patches (:class:`workbench.discrete.pressure.Recovery`)."""
        from .pressure import Recovery

        fit = self.geometry.normal_axis if self.dim == 2 else None  # (a fit on a contact curve only: pressure.py)
        return Recovery(self.mesh, self.contact_name, self.vertex_numbers, fit, self.pinned_nodes)

    @cached_property
    def _normal_rows(self):
        """The rows of T_nu^T at the contact vertices' normal dofs (:meth:`nodal_pressure`)."""
        return self.side.T_nu_t[self.normal_dofs].tocsr()

    def nodal_pressure(self, p: np.ndarray) -> np.ndarray:
        """The lumped contact pressure at the contact vertices for a normal traction ``p`` at the contact side's
        points: the nodal force int p phi_i da in u_nu's direction (u_nu = sign u_normal: sign * the normal dof's
        entry of T_nu^T (w p)) over the vertex's share w_i of the side."""
        return self.geometry.normal_sign * (self._normal_rows @ (self.side.weights * p)) / self.node_weights

    @cached_property
    def pinned_nodes(self) -> np.ndarray:
        """The contact vertices held in the normal direction where the contact holds them anyway (the Hertz apex,
        ``pins_contact``): their contact force is the support's reaction. Empty for every other body."""
        if not self.geometry.pins_contact:
            return np.zeros(0, dtype=np.int64)
        free = np.array(self.fes.FreeDofs(), dtype=bool)
        return np.nonzero(~free[self.normal_dofs])[0]

    def load_vector(self, time: float, out) -> None:
        """out = F(time): tractions, body force and the point force (out is overwritten)."""
        self.loads.vector(time, out)

    @cached_property
    def fields(self):
        """The operators that read whole fields off the dof vectors (probes, cell strains, edge midpoints), taken once:
        what a run records (:class:`workbench.discrete.fields.FieldOperators`)."""
        from .fields import FieldOperators

        return FieldOperators(self)

    # -- Model A's contact side ---------------------------------------------------------------------------------
    @cached_property
    def contact_form(self):
        """The NGSolve LinearForm of j(beta, u, .) at the current u and beta (the definition; None without terms)."""
        contact = self.model.contact
        if not contact:
            return None
        w = self.fes.TestFunction()
        u_nu, u_tau = self._normal_and_tangential(self.u)
        w_nu, w_tau = self._normal_and_tangential(w)
        gap0 = None
        if self.geometry.curved:  # the initial gap as a coefficient function (the distance to the foundation)
            gap0 = (ngs.x, ngs.y, ngs.z)[self.geometry.normal_axis]
        integrand = contact.integrand(u_nu, u_tau, self.beta, w_nu, w_tau, gap0)
        if integrand is None:
            return None
        form = ngs.LinearForm(self.fes)
        form += integrand.Compile() * ngs.ds(self.contact_name)
        return form

    @cached_property
    def rate_form(self):
        """The NGSolve LinearForm of the bonding rate tested with the facet indicators (None without adhesion)."""
        bonding = self.model.bonding
        if bonding is None:
            return None
        q = self.beta.space.TestFunction()
        u_nu, _ = self._normal_and_tangential(self.u)
        form = ngs.LinearForm(self.beta.space)
        form += (bonding.rate(NGS, self.beta, u_nu) * q).Compile() * ngs.ds(self.contact_name)
        return form

    def _normal_and_tangential(self, u):
        """(u_nu, u_tau) as coefficient functions, with the foundation's normal (:mod:`workbench.input.geometry`)."""
        g = self.geometry
        if self.dim == 1:
            return g.normal_sign * u, None
        u_nu = g.normal_sign * u[g.normal_axis]
        return u_nu, ngs.CF(tuple(u[a] for a in g.facet_axes))


def vector_space(geometry, mesh, order):
    """The displacement space of order ``order`` with the body's Dirichlet conditions (H1 in 1D, VectorH1 otherwise)."""
    flags = geometry.dirichlet_flags()
    if geometry.dim == 1:
        return ngs.H1(mesh, order=order, **flags)
    return ngs.VectorH1(mesh, order=order, **flags)


def _vertex_dofs(fes, dim, nv):
    """dof of (vertex i, component c): vertex dofs come first in each component block."""
    per_comp = fes.ndof // dim
    table = np.arange(nv)[:, None] + per_comp * np.arange(dim)[None, :]
    if nv == 0:  # (MPI's rank 0 holds no part of the body)
        return table
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

    def __init__(self, loads, fes, t, geometry, vertex_dofs, vertex_xyz):
        self.t = t
        self.separable = []  # (expression, component, dof indices, values)
        varying = ngs.LinearForm(fes)
        fixed = ngs.LinearForm(fes)
        n_varying = n_fixed = 0
        w = fes.TestFunction()
        dim = geometry.dim
        pieces = [(expr, ngs.ds(side)) for side, expr in loads.tractions.items()]
        if dim > 1 and loads.body_force is not None:
            pieces.append((loads.body_force, ngs.dx))
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
        self.point_dofs, self.point_force, self.point_vertex = None, loads.point_force, None
        self.vertex_dofs = vertex_dofs
        if dim > 1 and loads.point_force is not None and not loads.point_force.is_zero() and len(vertex_xyz):
            at = np.asarray(loads.point_force_at[0])
            self.relocate_point_force(int(np.argmin(np.sum((vertex_xyz - at) ** 2, axis=1))))
        self._values = {}

    def relocate_point_force(self, vertex) -> None:
        """Apply the point force at the vertex ``vertex`` (None: not here; on several MPI processes it is added once,
        by the rank that owns the serial run's vertex)."""
        self.point_vertex = vertex
        self.point_dofs = None if vertex is None else self.vertex_dofs[vertex]

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
        values = self._values
        values.clear()
        for expr, c, idx, vals in self.separable:
            key = id(expr)
            if key not in values:  # evaluate each expression once per step
                values[key] = np.atleast_1d(expr(t=time))
            g = values[key][c]
            if g != 0.0:
                arr[idx] += g * vals
        if self.point_dofs is not None:
            arr[self.point_dofs] += np.atleast_1d(self.point_force(t=time))


def bonding_space(mesh, dim: int, name: str):
    """The space of beta: P0 on the contact facets (a point value at the 1D rod end).

    Returns (space, facet measures, facet midpoints, dof of each facet) for the
    facets in element order.
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
    if dim == 1:
        dofs = np.nonzero(m > 0)[0]
    else:
        dofs = np.array([space.GetDofNrs(el)[0] for el in mesh.Boundaries(name).Elements()], dtype=np.int64)
    xyz = []
    for c in (ngs.x, ngs.y, ngs.z)[:dim]:
        lf = ngs.LinearForm(space)
        lf += c * q * ngs.ds(name)
        lf.Assemble()
        xyz.append(lf.vec.FV().NumPy()[dofs] / m[dofs])
    return space, dofs, m[dofs], np.stack(xyz, axis=1)


def build(model_or_scene, scene=None, numerics=None) -> Discretisation:
    """Assemble the constant parts of a model on its mesh (a Scene is turned into its model first; ``numerics``:
    :func:`workbench.input.numerics.from_scene` by default). One process: a body distributed over MPI processes is built by
    :func:`workbench.parallel.discretise`.

    Examples
    --------
    >>> from workbench.input.scenes import scene
    >>> d = build(scene("memory_slab", h=0.25))
    >>> d.viscous is None, d.memory_kind, round(float(d.contact_weights.sum()), 12)
    (True, 'prony', 2.0)
    """
    from ..input.scenes import Scene

    if isinstance(model_or_scene, Scene):
        scene, model = model_or_scene, model_or_scene.model_of()
    else:
        model = model_or_scene
    numerics = numerics or numerics_of.from_scene(scene)
    mesh = model.geometry.mesh()
    d = Discretisation(model, scene, mesh, vector_space(model.geometry, mesh, numerics.order), numerics)
    assemble(d)
    return d


def probes_outside(d: Discretisation) -> str:
    """A sentence naming the scene's probes that no cell of the mesh holds ("" where each lies in one): a scene checks
    them against the body's box, and a curved or meshed body does not fill its box.

    >>> from workbench.input.scenes import scene
    >>> probes_outside(build(scene("hertz", h=0.25, probes=((0.0, 0.5), (0.9, 0.1)))))
    "probes: point (0.9, 0.1) lies in the body's box but outside its mesh; give points inside the body"
    """
    probes = d.scene["probes"]
    outside = [tuple(float(c) for c in probes[i]) for i in np.flatnonzero(np.atleast_1d(d.probe_points["nr"]) < 0)]
    if not outside:
        return ""
    return (f"probes: point{'s' if len(outside) > 1 else ''} {', '.join(map(str, outside))} "
            f"lie{'' if len(outside) > 1 else 's'} in the body's box but outside its mesh; give points inside the body")


def assemble(d: Discretisation, matrices: bool = True, preconditioner: str | None = None) -> None:
    """The constant parts of the terms the model declares, and no others: the stiffness of each tensor (the elastic
    one, the viscous one of a Kelvin-Voigt body, those of a relaxation kernel), the contact side where contact laws
    act, the bonding field where a bonding law does, the contact vertices' weights where a layer constrains them,
    and the initial displacement. ``matrices=False``: the tables only (the serial view of a distributed body);
    ``preconditioner``: K_A (Model A's viscous stiffness, Model B's elastic one) assembled with NGSolve's
    preconditioner of that name (``d.viscous_pre``)."""
    m = d.model
    if matrices:
        if m.viscous is not None and preconditioner is not None:
            d.viscous, d.viscous_pre = stiffness(d.fes, m.viscous, d.dim, preconditioner)
        elif m.viscous is not None:
            d.viscous = stiffness(d.fes, m.viscous, d.dim)
        if m.viscous is None and preconditioner is not None:  # (Model B's steps solve with K_A = the elastic one)
            d.elastic, d.viscous_pre = stiffness(d.fes, m.elastic, d.dim, preconditioner)
        else:
            d.elastic = stiffness(d.fes, m.elastic, d.dim)
        if m.memory is not None:
            _memory_parts(d)
    if m.contact or m.bonding is not None:
        d.side = ContactSide(d.fes, d.contact_name, d.geometry, rule=d.numerics.order)
    if m.bonding is not None:
        d.rate_side = ContactSide(d.fes, d.contact_name, d.geometry, rule=0)
        space, d.beta_dofs, d.facet_measure, d.facet_xyz = bonding_space(d.mesh, d.dim, d.contact_name)
        d.beta = ngs.GridFunction(space, "beta")
        d.beta.vec.FV().NumPy()[d.beta_dofs] = m.beta0
    if m.layer is not None:
        d.contact_weights = d.node_weights
    if m.loads.u0 is not None:  # an initial condition (a quasistatic model solves for u(0) instead)
        d.u.Set(m.loads.u0.cf())


def _memory_parts(d: Discretisation) -> None:
    """The stiffnesses of a relaxation kernel."""
    m = d.model
    d.memory_kind = m.memory.kind
    if m.memory.kind == "prony" and m.memory.base is not None:
        # a fitted kernel: C_i = c_i C, so one stiffness serves all terms (and one matvec per step)
        K = stiffness(d.fes, m.memory.base[0], d.dim)
        d.memory = [(K, C, tau) for C, tau in m.memory.terms]
        d.memory_scale = list(m.memory.base[1])
    elif m.memory.kind == "prony":
        d.memory = [(stiffness(d.fes, C, d.dim), C, tau) for C, tau in m.memory.terms]
    else:
        d.memory = [(stiffness(d.fes, m.memory.tensor, d.dim), m.memory.tensor, m.memory.shape)]
