"""A posteriori estimate of the error in space: per element and in total, in the energy norm of the elastic tensor.

The error a mesh makes in a contact problem lives at a few places (the edges of the contact zone, a debonding
front, a clamp's corner). This estimator finds them from the discrete solution alone, in two parts:

* **volume** (Zienkiewicz–Zhu): the strain eps(u_h), discontinuous across elements, is recovered as a continuous
  field eps* of the displacement's order (NGSolve's ``Set`` into H1: local projections averaged at shared dofs), and
  eta_K^2 = int_K C (eps* - eps_h) : (eps* - eps_h) dx, with C the elastic tensor (Model A's G, Model B's A);
* **contact** (the residual of the traction balance on the contact side): eta_E^2 = (h_E / C_ref) int_E
  (sigma_h nu . nu + p_h)^2 da on each contact facet E, where sigma_h is the whole stress of the scheme (viscous and
  memory parts included) taken from the element E bounds, p_h the contact pressure the run records (P1: interpolated
  linearly between the contact vertices, the recovered one where there is one; Model B on P2: the quadratic through
  the vertex and facet-midpoint pressures) and C_ref the largest diagonal entry of C's Voigt matrix (the scale that
  turns a traction into energy). A facet's share joins the element it bounds.

The total is eta = sqrt(sum eta_K^2 + sum eta_E^2); a run reports it relative to the largest energy norm
||u_h||_C = (int C eps(u_h) : eps(u_h))^(1/2) over the run (:mod:`workbench.running.adapt`: relative to the norm at the
same time, a body just loaded would have an arbitrary relative error).
How well eta tracks the true error (its effectivity index) is measured, not assumed: ``docs/adaptivity.md``.

Examples
--------
>>> import numpy as np, workbench
>>> from workbench.discrete.discretisation import build
>>> from workbench.schemes import scheme_class
>>> d = build(workbench.scene("memory_hertz", h=0.2, h_contact=0.02, T=0.1, k=0.1))
>>> s = scheme_class("vi")(d)
>>> s.start(0.0); s.step(0.0, 0.1)
>>> est = Estimator(d, s.observer(d))
>>> e = est.evaluate(0.1)
>>> 0 < e.total < e.norm, e.volume.shape == (d.mesh.ne,), bool(np.all(e.contact >= 0))
(True, True, True)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.kelvin_voigt import strain


@dataclass(frozen=True)
class Estimate:
    """One evaluation of the estimator: eta_K^2 per element (``volume``, ``contact``: the element's contact facets),
    the total eta, the energy norm of u_h, with a goal the dual problem's eta_K(z)^2 (``weights``) and, where the
    edge of the contact zone is watched (``edge_tol``), how finely the mesh resolves it (``edge``)."""

    volume: np.ndarray
    contact: np.ndarray
    total: float
    norm: float
    weights: np.ndarray | None = None
    edge: Edge | None = None

    @property
    def indicators(self) -> np.ndarray:
        """eta_K^2, both parts, per element."""
        return self.volume + self.contact

    @property
    def marking(self) -> np.ndarray:
        """What marking uses, per element: eta_K^2, or with a goal eta_K(u) eta_K(z), the dual's ``weights`` being
        eta_K(z)^2 (:class:`PressureGoal`)."""
        if self.weights is None:
            return self.indicators
        return np.sqrt(self.indicators * self.weights)


class Estimator:
    """The estimator of one discretisation and the scheme's observer (module docs); :meth:`evaluate` reads the state
    the scheme holds now."""

    def __init__(self, disc, observer, goal: str = "energy", edge: bool = False):
        import ngsolve as ngs

        d, dim = disc, disc.dim
        self.d, self.observer = d, observer
        tensor = d.model.elastic
        self._zz = RecoveredStrain(d.u, tensor, dim, d.numerics.order)
        eps = strain(d.u, dim)
        self._energy = ngs.InnerProduct(tensor(eps), eps)
        self._contact = None
        if d.contact_name and len(d.node_dofs):
            self._contact_part(ngs, tensor)
        self.goal = PressureGoal(d) if goal == "pressure" and self._contact is not None else None
        self.edges = ContactEdge(d) if edge and self._contact is not None else None

    def _contact_part(self, ngs, tensor) -> None:
        """The traction residual on the contact facets and the element each facet bounds."""
        d, dim, mesh = self.d, self.d.dim, self.d.mesh
        self.c_ref = float(np.max(np.diag(tensor.voigt(dim))))
        self.parts = [(t, ngs.GridFunction(d.fes)) for t, _ in self.observer.stress_parts()]
        stresses = [t(strain(g, dim)) for t, g in self.parts]
        sigma = stresses[0]
        for more in stresses[1:]:  # (Python's sum starts from the number 0, which a matrix CF cannot add)
            sigma = sigma + more
        self._region = mesh.Boundaries(d.contact_name)
        points = self.observer.contact_points()  # (Model B on P2: the facet midpoints carry pressures too)
        self.pressure = ngs.GridFunction(ngs.H1(mesh, order=2 if "midpoint_x" in points else 1))
        self._midpoints = self._midpoint_dofs(ngs, points) if "midpoint_x" in points else None
        n = ngs.specialcf.normal(dim)
        # (the stress from the element the facet bounds: on a boundary element NGSolve differentiates a field along
        # the boundary only, and sigma nu . nu then missed the normal derivative: it carried a third of the pressure
        # on Hertz, and the residual measured the rest)
        sigma = ngs.BoundaryFromVolumeCF(sigma)
        residual = ngs.InnerProduct(sigma * n, n) + self.pressure
        g = d.geometry
        gap = ((ngs.x, ngs.y, ngs.z)[g.normal_axis] if g.curved else ngs.CF(0.0)) - g.normal_sign * d.u[g.normal_axis]
        # (complementarity: a pressure where the side is open; between the vertices only, at the contact zone's edge)
        open_pressed = ngs.IfPos(self.pressure, self.pressure, 0.0) * ngs.IfPos(gap, gap, 0.0)
        self._contact = ngs.specialcf.mesh_size / self.c_ref * residual * residual + open_pressed
        facets = np.array([el.nr for el in self._region.Elements()], dtype=np.int64)
        self._facet_elements = facets, np.array([_volume_element(mesh, i) for i in facets], dtype=np.int64)

    def _midpoint_dofs(self, ngs, points: dict):
        """(edge dof, its two vertices, the edge function's value there) of each recorded facet midpoint, in the
        observer's point order: the P2 pressure whose vertex and midpoint values are the recorded ones (NGSolve's P2
        edge functions are hierarchical: the midpoint value is the vertices' mean plus the edge dof times its
        function's value there, read off by the one-point rule, which is the rule the midpoints were taken with)."""
        d, mesh, fes = self.d, self.d.mesh, self.pressure.space
        where = np.column_stack([points[f"midpoint_{c}"] for c in "xyz"[: d.dim]])
        facets = list(self._region.Elements())
        centres = np.array([np.mean([mesh[v].point for v in el.vertices], axis=0) for el in facets])
        nearest = np.argmin(((where[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2), axis=1)
        edges = [facets[j].edges[0].nr for j in nearest]
        dofs = np.array([fes.GetDofNrs(ngs.NodeId(ngs.EDGE, e))[0] for e in edges], dtype=np.int64)
        ends = np.array([[v.nr for v in facets[j].vertices] for j in nearest], dtype=np.int64)
        probe = ngs.GridFunction(fes)
        probe.vec.FV().NumPy()[dofs] = 1.0
        mine = np.array([el.nr for el in facets])[nearest]

        def midpoint_rule(cf):
            return np.asarray(ngs.Integrate(cf, mesh, ngs.BND, order=1, element_wise=True, definedon=self._region))[mine]

        return dofs, ends, midpoint_rule(probe) / midpoint_rule(ngs.CF(1.0))

    def evaluate(self, t: float | None = None, goal: bool = True) -> Estimate:
        """The estimate of the state the scheme holds at time ``t`` (with the goal's weights if it has a goal and
        ``goal``)."""
        import ngsolve as ngs

        mesh = self.d.mesh
        volume = self._zz.indicators()
        contact, weights, edge = np.zeros(mesh.ne), None, None
        if self._contact is not None:
            values = self.observer.node_values(t)
            contact = self._contact_indicators(t, values)
            if self.goal is not None and goal:
                weights = self.goal.weights(values.get("contact_pressure_recovered", values.get("contact_pressure")))
            if self.edges is not None:
                edge = self.edges.measure(values.get("contact_pressure"))
        norm = float(np.sqrt(max(ngs.Integrate(self._energy, mesh), 0.0)))
        return Estimate(volume, contact, float(np.sqrt(volume.sum() + contact.sum())), norm, weights, edge)

    def _contact_indicators(self, t, values: dict) -> np.ndarray:
        import ngsolve as ngs

        d, mesh = self.d, self.d.mesh
        for (_, g), (_, vector) in zip(self.parts, self.observer.stress_parts()):
            g.vec.FV().NumPy()[:] = vector
        # (P2: the vertices' own pressures, which the midpoints' complete; P1: the recovered one where there is one)
        p = values.get("contact_pressure") if self._midpoints is not None else \
            values.get("contact_pressure_recovered", values.get("contact_pressure"))
        nodal = self.pressure.vec.FV().NumPy()
        nodal[:] = 0.0
        if p is not None:
            nodal[d.vertex_numbers] = np.nan_to_num(np.asarray(p, dtype=float))
        if self._midpoints is not None:
            dofs, ends, value = self._midpoints
            mid = np.nan_to_num(np.asarray(self.observer.point_values(t)["contact_pressure_midpoint"], dtype=float))
            nodal[dofs] = (mid - nodal[ends].mean(axis=1)) / value
        per_facet = np.asarray(ngs.Integrate(self._contact, mesh, ngs.BND, element_wise=True, definedon=self._region))
        facets, elements = self._facet_elements
        out = np.zeros(mesh.ne)
        np.add.at(out, elements, np.maximum(per_facet[facets], 0.0))
        return out


@dataclass(frozen=True)
class Edge:
    """The contact zone's edge at one time (:class:`ContactEdge`): ``resolution``, the longest facet across it over
    the zone's size; ``points``, those facets' centroids; ``zone``, the zone's size."""

    resolution: float
    points: np.ndarray
    zone: float


class ContactEdge:
    """How finely the mesh resolves the edge of the contact zone (``edge_tol``).

    A facet of the contact side with a pressed vertex (lumped pressure > 0) and a free one holds the zone's edge: the
    discrete zone ends at one of its vertices, so the facet's size bounds how well the mesh can place the edge. Its
    longest edge over the zone's size, the pressed vertices' share of the side to the power 1/(d-1) (a 2D zone modelled
    by its half: its half-width; a 3D quarter of a circular zone: 0.89 times its radius), is the ``resolution``.
    That is a resolution, not an error: the discrete solution may place the edge elsewhere by its own error, which
    the energy estimate watches (measured on Lee and Radok's Hertz in ``docs/adaptivity.md``).

    >>> import numpy as np, workbench
    >>> from workbench.discrete.discretisation import build
    >>> d = build(workbench.scene("memory_hertz", h=0.2, h_contact=0.02, T=0.1, k=0.1))
    >>> edges = ContactEdge(d)
    >>> x = d.node_xyz[:, 0]
    >>> e = edges.measure(np.where(x < 0.1, 1.0, 0.0))  # (pressed up to the vertex at x = 0.086, free from 0.107)
    >>> len(e.points), round(float(e.points[0, 0]), 4), round(e.zone, 4), round(e.resolution, 3)
    (1, 0.0962, 0.0964, 0.216)
    """

    def __init__(self, disc):
        mesh = disc.mesh
        node = np.full(mesh.nv, -1, dtype=np.int64)
        node[disc.vertex_numbers] = np.arange(len(disc.vertex_numbers))
        vertices = np.array([[v.nr for v in el.vertices] for el in mesh.Boundaries(disc.contact_name).Elements()],
                            dtype=np.int64)
        self._facets = node[vertices]  # (each facet's contact nodes)
        corners = disc.vertex_xyz[vertices]
        self._centroids, self._sizes = corners.mean(axis=1), longest_edges(corners)
        self._weights, self._dim = disc.node_weights, disc.dim

    def measure(self, pressure) -> Edge | None:
        """The edge where ``pressure`` (lumped, at the contact nodes) ends, or None: nothing pressed, or the whole
        side (no edge on it)."""
        if pressure is None:
            return None
        pressed = np.nan_to_num(np.asarray(pressure, dtype=float)) > 0
        on = pressed[self._facets]
        across = on.any(axis=1) & ~on.all(axis=1)
        if not across.any():
            return None
        zone = float(self._weights[pressed].sum()) ** (1.0 / (self._dim - 1))
        return Edge(float(self._sizes[across].max()) / zone, self._centroids[across], zone)


def longest_edges(corners: np.ndarray) -> np.ndarray:
    """The longest edge of each simplex, from its ``corners`` (simplices x vertices x coordinates).

    >>> longest_edges(np.array([[[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]]])).tolist()
    [5.0]
    """
    n = corners.shape[1]
    return np.max([np.linalg.norm(corners[:, i] - corners[:, j], axis=1) for i in range(n) for j in range(i)], axis=0)


class RecoveredStrain:
    """The Zienkiewicz–Zhu part of a displacement ``field``: eta_K^2 = int_K C (eps* - eps_h) : (eps* - eps_h) dx,
    with eps* the strain recovered continuous (NGSolve's ``Set`` into H1 of ``order``) and C the ``tensor``."""

    def __init__(self, field, tensor, dim: int, order: int):
        import ngsolve as ngs

        self.mesh = field.space.mesh
        eps = strain(field, dim)
        self._flat = ngs.CF(tuple(eps[i, j] for i in range(dim) for j in range(dim)))
        self.recovered = ngs.GridFunction(ngs.H1(self.mesh, order=order, dim=dim * dim))
        star = ngs.CF(tuple(self.recovered[i] for i in range(dim * dim)), dims=(dim, dim))
        self._form = ngs.InnerProduct(tensor(star - eps), star - eps)

    def indicators(self) -> np.ndarray:
        """eta_K^2 per element, of the field as it is now."""
        import ngsolve as ngs

        self.recovered.Set(self._flat)
        return np.maximum(np.asarray(ngs.Integrate(self._form, self.mesh, element_wise=True)), 0.0)


#: The fewest pressed contact vertices for which :class:`PressureGoal` weighs: a zone of fewer is a point to the mesh,
#: and moving a point holds infinite energy (the discrete dual is then the mesh's own singularity there: at the first
#: step of Model A's Hertz, one vertex pressed, one element carried 28 % of the dual's weight).
MIN_PRESSED = 3


class PressureGoal:
    """The weights that aim refinement at the contact pressure (``space_goal = "pressure"``): a dual problem.

    The contact pressure is the reaction of the side where it presses. The dual solution z is the elastic body
    (the tensor C, the body's own supports) whose normal displacement on the pressed side is the pressure's shape
    psi = p_h / max p_h (interpolated linearly between the pressed vertices, in the direction of the contact),
    free elsewhere. So z is large where a residual of u_h would move the pressure: near the pressed side and
    under it, decaying into the body. Its own recovered-strain indicators eta_K(z)^2 are the weights; marking then
    uses eta_K(u) eta_K(z), the product of the two energy errors that bounds the error of such a goal (Mommer and
    Stevenson 2009). One sparse factorization per evaluation (the pressed set changes); a side that presses nowhere
    gives no weights (marking falls back to the energy), nor one that presses at fewer than ``MIN_PRESSED``
    vertices.

    Examples
    --------
    >>> import numpy as np, workbench
    >>> from workbench.discrete.discretisation import build
    >>> d = build(workbench.scene("memory_hertz", h=0.2, h_contact=0.02))
    >>> goal = PressureGoal(d)
    >>> w = goal.weights(np.where(np.abs(d.node_xyz[:, 0]) < 0.05, 1.0, 0.0))
    >>> w.shape == (d.mesh.ne,), bool(np.all(w >= 0)), goal.weights(np.zeros(len(d.node_dofs))) is None
    (True, True, True)
    """

    def __init__(self, disc):
        import ngsolve as ngs

        from .discretisation import stiffness

        d, g = disc, disc.geometry
        self.d, self.sign = d, float(g.normal_sign)
        self.K = stiffness(d.fes, d.model.elastic, d.dim).mat
        self.z = ngs.GridFunction(d.fes)
        self._zz = RecoveredStrain(self.z, d.model.elastic, d.dim, d.numerics.order)
        scalar = ngs.H1(d.mesh, order=d.numerics.order)
        offset = g.normal_axis * (d.fes.ndof // d.dim)  # (the normal component's block of the vector space)
        region = d.mesh.Boundaries(d.contact_name)
        # (each contact facet: its vertices, and every normal-component dof on it, P2's edge dofs included)
        self._facets = [(np.array([v.nr for v in el.vertices]),
                         offset + np.array(scalar.GetDofNrs(el), dtype=np.int64)) for el in region.Elements()]
        self._vertex_dof = offset + np.asarray(d.vertex_numbers, dtype=np.int64)  # (H1: vertex v's dof is v)

    def held(self, pressed: np.ndarray) -> np.ndarray:
        """The normal-component dofs the dual holds for the contact vertices ``pressed`` (a mask in node order): the
        pressed vertices' and every dof of a facet whose vertices all press."""
        vertices = set(np.asarray(self.d.vertex_numbers)[pressed].tolist())
        on_facets = [dofs for corners, dofs in self._facets if vertices.issuperset(corners.tolist())]
        return np.unique(np.concatenate([self._vertex_dof[pressed]] + on_facets))

    def _unpinned(self, p: np.ndarray, pressed: np.ndarray) -> np.ndarray:
        """``p`` with the values at a held vertex (the Hertz apex, whose force is the support's reaction) and at the
        vertices of its contact facets replaced by the nearest other pressed vertex's. The reaction is a spike on the
        scale of its elements, and the recovered pressure spreads it over that patch; as data of the dual it is a
        feature that refinement would chase, on each finer mesh again (measured on Model A's Hertz half-disc: the
        loop's 15 meshes went from 456 to only 716 dofs, each refined at the apex)."""
        if not len(self.d.pinned_nodes):
            return p
        node_of = {v: i for i, v in enumerate(np.asarray(self.d.vertex_numbers).tolist())}
        pinned = set(np.asarray(self.d.vertex_numbers)[self.d.pinned_nodes].tolist())
        spiked = {node_of[v] for corners, _ in self._facets if pinned & set(corners.tolist()) for v in corners.tolist()}
        spiked = np.array(sorted(spiked & set(np.flatnonzero(pressed).tolist())), dtype=np.int64)
        others = np.setdiff1d(np.flatnonzero(pressed), spiked)
        if not len(spiked) or not len(others):
            return p
        xyz = self.d.node_xyz
        nearest = others[np.argmin(((xyz[spiked][:, None, :] - xyz[others][None, :, :]) ** 2).sum(axis=2), axis=1)]
        out = p.copy()
        out[spiked] = p[nearest]
        return out

    def weights(self, pressure) -> np.ndarray | None:
        """eta_K(z)^2 per element for the contact ``pressure`` (per contact vertex, node order), or None where it
        presses at fewer than ``MIN_PRESSED`` vertices."""
        p = np.nan_to_num(np.asarray(pressure, dtype=float)) if pressure is not None else np.zeros(0)
        pressed = p > 0
        if pressed.sum() < MIN_PRESSED:
            return None
        import ngsolve as ngs

        p = self._unpinned(p, pressed)
        held = self.held(pressed)
        mask = np.array(self.d.fes.FreeDofs(), dtype=bool)
        mask[held] = False
        free = ngs.BitArray(mask.tolist())
        z = self.z.vec
        values = z.FV().NumPy()
        values[:] = 0.0
        values[self._vertex_dof[pressed]] = self.sign * p[pressed] / p.max()  # (other held dofs: 0, linear between)
        residual = z.CreateVector()
        residual.data = -self.K * z
        z.data += self.K.Inverse(free, inverse="sparsecholesky") * residual
        return self._zz.indicators()


def _volume_element(mesh, facet: int) -> int:
    """The volume element a boundary element of the mesh bounds."""
    import ngsolve as ngs

    el = mesh[ngs.ElementId(ngs.BND, facet)]
    shared = mesh[el.facets[0]].elements
    return shared[0].nr


def energy_error(body, ds, fine_body, fine_ds, tensor, snapshot: int = -1) -> float:
    """||u - u_ref||_C / ||u_ref||_C at a snapshot: the run ``ds`` on ``body`` against a finer run ``fine_ds`` on
    ``fine_body``, on the finer mesh. The coarse field is carried there as the studies carry it
    (:class:`workbench.discrete.transfer.Transfer`: exact where the meshes are nested; a fine vertex just outside a
    coarser curved side, by O(h^2), takes the field extrapolated from the nearest cell, not zero).

    Examples
    --------
    >>> import workbench
    >>> sc = workbench.scene("memory_hertz", h=0.2, h_contact=0.02, T=0.5, k=0.5)
    >>> ds = workbench.run(sc, progress=False)
    >>> body = sc.model_of().geometry
    >>> round(energy_error(body, ds, body, ds, sc.model_of().elastic), 12)
    0.0
    """
    import ngsolve as ngs

    from . import transfer
    from .discretisation import stiffness

    order = int(ds.attrs["order"])
    coarse, fine = transfer.MeshInfo(body, order), transfer.MeshInfo(fine_body, int(fine_ds.attrs["order"]))
    carried = transfer.Transfer(coarse, fine).displacement(ds.u_dofs.values[snapshot], ds.u_nodes.values[snapshot])
    u_ref = fine_ds.u_dofs.values[snapshot]
    K = stiffness(fine.fes, tensor, fine.dim).mat
    diff = ngs.BaseVector(len(u_ref))
    image = diff.CreateVector()

    def energy(vector):
        diff.FV().NumPy()[:] = vector
        image.data = K * diff
        return float(np.dot(vector, image.FV().NumPy()))

    return float(np.sqrt(max(energy(u_ref - carried), 0.0) / energy(u_ref)))
