"""Compare fields of two runs on the finer mesh: prolongation and the paper's error norm.

A coarse run's fields are carried onto the fine run's mesh:

* displacement (P1): the fine vertices are located in the coarse cells and the
  coarse field is evaluated there with barycentric weights (a sparse
  prolongation matrix built once per mesh pair). On nested meshes this is the
  exact prolongation (the coarse P1 field *is* a fine P1 field); on non-nested
  meshes it is nodal interpolation. Higher orders use NGSolve's ``Set``
  (element-wise L2 projection, exact on nested meshes);
* stress (P0 cells) and bonding field (P0 facets): the fine cell centroid /
  facet midpoint is located in the coarse mesh and takes that cell's value
  (exact on nested meshes).

The errors of P1 runs on meshes that are not nested (the Hertz bodies, which netgen meshes anew for each
h_contact) are not taken from the interpolated field: interpolating a coarse P1 field at the fine vertices changes
its strain wherever a fine cell straddles coarse cells, by as much as the error measured (the 2D Hertz sweep's
``error_V`` came out 25-59 % low and its order 0.70 against 0.27, found by an outside pass). Both fields' strains and
stresses are constant per cell there, so the norm of their difference is a sum over the cells' overlaps
(:class:`Overlap`): exact where a fine cell lies in one coarse cell, sampled at the centroids of its equal sub-cells
(256 in 2D, 64 in 3D) where it straddles several. The bonding field beta, constant per contact facet, is differenced
the same way over the facets' overlaps (:class:`FacetOverlap`: each fine facet cut into 64 equal pieces, each taken by
the coarse facet it lies on); a fine facet given the coarse value at its midpoint misplaced the coarse jumps of beta
by up to a fine facet wherever it straddled two coarse ones.

On a curved side, a fine vertex may lie just outside the coarser faceted mesh (by
O(h^2)): it takes its nearest coarse cell, whose field is extrapolated to it, and a
fine contact facet the nearest coarse one (:meth:`MeshInfo.locate`). Bodies that
are not boxes (mesh files, the Hertz bodies) are keyed by what determines their mesh.

Norms (docs/models.md; Corollary 6.7 of the 2003 paper): |u|_V = ||eps(u)||_L2(Omega), |sigma|_Q = ||sigma||_L2
(Frobenius), |beta|_L2(Gamma_3), evaluated on the fine mesh.
"""
from __future__ import annotations

from functools import lru_cache

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp

from ..input.geometry import of_run
from ..physics import kelvin_voigt
from .discretisation import bonding_space
from .fields import mesh_cells, p1_gradients, p1_strains


class MeshInfo:
    """A run's mesh with the arrays the transfer needs (rebuilt from its geometry: meshes are deterministic)."""

    def __init__(self, geometry, order: int):
        self.geometry = geometry
        self.dim = geometry.dim
        self.order = order
        self.mesh = geometry.mesh()
        ngm = self.mesh.ngmesh
        self.xyz = np.array(ngm.Coordinates())[:, : self.dim]
        self.cells = mesh_cells(self.mesh, self.dim)
        self.centroids = self.xyz[self.cells].mean(axis=1)
        self.contact = geometry.boundaries["contact"]
        self.fes = (ngs.H1 if self.dim == 1 else ngs.VectorH1)(self.mesh, order=self.order)
        self.p0 = ngs.L2(self.mesh, order=0)
        self.bspace, self.beta_dofs, self.facet_measure, self.facet_xyz = bonding_space(self.mesh, self.dim, self.contact)
        self._strain_matrix = None
        self._facet_vertices = None

    def facet_vertices(self) -> np.ndarray:
        """The coordinates of each contact facet's vertices (facet, vertex, coordinate), facets in beta's order
        (:func:`~workbench.discrete.discretisation.bonding_space`: the contact side's elements in order)."""
        if self._facet_vertices is None:
            elements = self.mesh.Boundaries(self.contact).Elements()
            at = np.array([[v.nr for v in el.vertices] for el in elements], dtype=np.int64)
            self._facet_vertices = self.xyz[at.reshape(-1, self.dim)]
        return self._facet_vertices

    def locate_on_contact(self, points: np.ndarray) -> np.ndarray:
        """The contact facet (position in beta's order) each of ``points`` lies on: among the facets of the 16
        nearest midpoints, the one inside which its projection lies, or least outside (on a curved side, two faceted
        meshes differ by O(h^2)). A point farther out than half a facet is an error."""
        from scipy.spatial import cKDTree

        V = self.facet_vertices()
        k, tree, out = min(16, len(V)), cKDTree(self.facet_xyz), np.empty(len(points), dtype=np.int64)
        for start in range(0, len(points), 20_000):  # (a block at a time: 16 candidates' edges are 0.8 kB a point)
            p = points[start:start + 20_000]
            near = np.asarray(tree.query(p, k=k)[1]).reshape(len(p), k)
            a = V[near, 0]  # (point, candidate, coordinate)
            E = V[near, 1:] - a[:, :, None, :]  # (point, candidate, edge, coordinate)
            gram = np.einsum("pced,pcfd->pcef", E, E)
            lam = np.linalg.solve(gram, np.einsum("pced,pcd->pce", E, p[:, None, :] - a)[..., None])[..., 0]
            least = np.minimum(lam.min(axis=2), 1.0 - lam.sum(axis=2))  # (the smallest barycentric coordinate)
            best = np.argmax(least, axis=1)
            if least[np.arange(len(p)), best].min() < -0.5:
                raise ValueError("transfer: a contact facet of the fine mesh is off the coarse mesh's contact side")
            out[start:start + len(p)] = near[np.arange(len(p)), best]
        return out

    def locate(self, points: np.ndarray, vb=ngs.VOL):
        """Cell numbers of ``points`` (n x dim) in this mesh (boundary elements with ``vb = BND``).

        A point outside the mesh, as a fine mesh's vertex on a curved side is outside a coarser faceted one
        (by O(h^2)), takes the nearest cell: among the cells of the 8 nearest centroids, the one its barycentric
        coordinates leave least (the field is then extrapolated linearly from it). A point farther out than a
        cell's size is an error.
        """
        pts = [points[:, i] for i in range(self.dim)]
        mp = self.mesh(*pts, VOL_or_BND=vb) if vb == ngs.BND else self.mesh(*pts)
        nr = np.asarray(mp["nr"], dtype=np.int64)
        out = np.nonzero(nr < 0)[0]
        if out.size and vb == ngs.VOL:
            from scipy.spatial import cKDTree

            k = min(8, len(self.cells))
            _, near = cKDTree(self.centroids).query(points[out], k=k)
            near = np.asarray(near).reshape(len(out), k)
            for j, i in enumerate(out):
                lam = self.barycentric(np.repeat(points[i:i + 1], k, axis=0), near[j])
                best = int(np.argmax(lam.min(axis=1)))
                if lam[best].min() < -0.5:
                    raise ValueError(f"transfer: the fine mesh's point {points[i].tolist()} is outside the coarse mesh")
                nr[i] = near[j][best]
        elif out.size:
            raise ValueError("transfer: some boundary points of the fine mesh are off the coarse mesh's boundary")
        return nr

    def barycentric(self, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
        verts = self.xyz[self.cells[cells]]  # (n, d+1, d)
        T = np.transpose(verts[:, 1:, :] - verts[:, :1, :], (0, 2, 1))  # (n, d, d)
        lam = np.linalg.solve(T, (points - verts[:, 0, :])[..., None])[..., 0]
        return np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)

    def strain_matrix(self):
        """K_eps with u^T K_eps u = ||eps(u)||^2 (assembled once)."""
        if self._strain_matrix is None:
            u, w = self.fes.TnT()
            form = ngs.BilinearForm(self.fes, symmetric=False)
            form += kelvin_voigt.energy_product(lambda e: e, u, w, self.dim) * ngs.dx
            form.Assemble()
            rows, cols, vals = form.mat.COO()
            self._strain_matrix = sp.csr_matrix((np.asarray(vals), (np.asarray(rows), np.asarray(cols))),
                                                shape=(self.fes.ndof,) * 2)
        return self._strain_matrix

    def cell_volumes(self) -> np.ndarray:
        verts = self.xyz[self.cells]
        T = verts[:, 1:, :] - verts[:, :1, :]
        fact = {1: 1.0, 2: 0.5, 3: 1.0 / 6.0}[self.dim]
        return np.abs(np.linalg.det(T)) * fact if self.dim > 1 else np.abs(T[:, 0, 0])


def mesh_info(scene, ds=None) -> MeshInfo:
    """The (cached) MeshInfo of a scene's mesh: keyed by everything that determines it (geometry, cells, order); with
    ``ds``, of the mesh that run was computed on (an adapted one, :func:`workbench.input.geometry.of_run`)."""
    body = scene.body if ds is None else of_run(scene.body, ds)
    if not body.extent_names or body.curved or body is not scene.body:  # (the body itself says what its mesh is)
        return _body_info(body, scene["order"])
    return _mesh_info(body.kind, body.extent, body.cells(), scene["order"])


_MESH_INFOS: dict = {}


def _body_info(body, order) -> MeshInfo:
    """The MeshInfo of a body that is not a box (a mesh file, a Hertz body), keyed by what determines its mesh."""
    key = (body.key(), order)
    if key not in _MESH_INFOS:
        if len(_MESH_INFOS) >= 16:
            _MESH_INFOS.pop(next(iter(_MESH_INFOS)))
        _MESH_INFOS[key] = MeshInfo(body, order)
    return _MESH_INFOS[key]


@lru_cache(maxsize=16)
def _mesh_info(kind, extent, cells, order) -> MeshInfo:
    from ..input.geometry import GEOMETRIES

    cls = GEOMETRIES[kind]
    return MeshInfo(cls(h=1.0, cells=cells, **dict(zip(cls.extent_names, extent))), order)


def nested(coarse: MeshInfo, fine: MeshInfo) -> bool:
    """True when every coarse cell count divides the fine one (structured meshes are then nested)."""
    return coarse.geometry.nested_in(fine.geometry)


class Transfer:
    """Carries coarse-run fields onto the fine run's mesh (see the module docs)."""

    def __init__(self, coarse: MeshInfo, fine: MeshInfo):
        self.coarse, self.fine = coarse, fine
        self.exact = nested(coarse, fine)
        self.method = "nested prolongation (exact)" if self.exact else "interpolation (meshes not nested)"
        same = coarse is fine
        self.identity = same
        self.P = None  # P1 on both: the vertex interpolation matrix (else NGSolve interpolates)
        self._overlap, self._vertex_cells = None, None  # (P1 on both, not nested: :meth:`difference_norms`' own)
        self._facet_overlap = None  # (not nested, 2D and 3D: beta's, :meth:`difference_norms`)
        if same:
            return
        if coarse.order == 1 and fine.order == 1:
            cells = coarse.locate(fine.xyz)
            lam = coarse.barycentric(fine.xyz, cells)
            nf, nc = len(fine.xyz), len(coarse.xyz)
            rows = np.repeat(np.arange(nf), coarse.dim + 1)
            self.P = sp.csr_matrix((lam.ravel(), (rows, coarse.cells[cells].ravel())), shape=(nf, nc))
            if not self.exact and coarse.dim > 1:  # (the overlaps made when errors are asked for, not to move fields)
                self._vertex_cells = cells
                self.method = Overlap.DESCRIPTION.format(samples=len(subcell_centroids(fine.dim,
                                                                                       SUBCELL_LEVELS[fine.dim])))
        self.cell_map = coarse.locate(fine.centroids)
        if coarse.dim == 1:
            self.facet_map = np.zeros(len(fine.facet_xyz), dtype=np.int64)
        else:
            if coarse.geometry.curved:  # (a fine facet midpoint is off the coarse facets): the nearest coarse facet
                from scipy.spatial import cKDTree

                self.facet_map = cKDTree(coarse.facet_xyz).query(fine.facet_xyz)[1]
            else:
                bnd_el = coarse.locate(fine.facet_xyz, vb=ngs.BND)
                position = np.full(coarse.bspace.ndof, -1)
                position[coarse.beta_dofs] = np.arange(len(coarse.beta_dofs))
                elements, inverse = np.unique(bnd_el, return_inverse=True)
                dofs = np.array([coarse.bspace.GetDofNrs(ngs.ElementId(ngs.BND, int(e)))[0] for e in elements])
                self.facet_map = position[dofs][inverse]
                if np.any(self.facet_map < 0):
                    raise ValueError("transfer: a contact facet of the fine mesh is not on the coarse contact side")

    def displacement(self, u_dofs: np.ndarray, u_nodes: np.ndarray) -> np.ndarray:
        """The coarse displacement as a fine dof vector."""
        if self.identity:
            return u_dofs
        c, f = self.coarse, self.fine
        if self.P is not None:
            vals = self.P @ u_nodes  # (fine vertex, component)
            out = np.zeros(f.fes.ndof)
            per = f.fes.ndof // f.dim
            for comp in range(f.dim):
                out[comp * per + np.arange(len(f.xyz))] = vals[:, comp] if vals.ndim > 1 else vals
            return out
        gc, gf = ngs.GridFunction(c.fes), ngs.GridFunction(f.fes)
        gc.vec.FV().NumPy()[:] = u_dofs
        gf.Set(gc)
        return gf.vec.FV().NumPy().copy()

    def cells(self, values: np.ndarray) -> np.ndarray:
        return values if self.identity else values[self.cell_map]

    def facets(self, values: np.ndarray) -> np.ndarray:
        return values if self.identity else values[..., self.facet_map]

    def difference_norms(self, fine_fields, coarse_fields, betas=None) -> tuple:
        """(|du|_V, |dsigma|_Q, |dbeta|_L2(Gamma3)) of the fine run's fields less the coarse run's, each given as
        (u_dofs, u_nodes, stress) of one snapshot, and ``betas`` (the fine run's beta, the coarse run's) where the
        model has one: over the cells' and the contact facets' overlaps where the meshes are not nested (module
        docs), else on the fine mesh with the coarse fields carried there."""
        (uf, nf, sf), (uc, nc, sc) = fine_fields, coarse_fields
        beta = np.nan if betas is None else self._beta_norm(*betas)
        if self._vertex_cells is None:
            V, Q, _ = norms(self.fine, uf - self.displacement(uc, nc), sf - self.cells(sc), None)
            return V, Q, beta
        if self._overlap is None:
            self._overlap = Overlap(self.coarse, self.fine, self._vertex_cells)
        o = self._overlap
        return o.norm(p1_cell_strains(self.fine, nf), p1_cell_strains(self.coarse, nc)), o.norm(sf, sc), beta

    def _beta_norm(self, fine_beta: np.ndarray, coarse_beta: np.ndarray) -> float:
        if self.exact or self.identity or self.fine.dim == 1:
            return norms(self.fine, None, None, fine_beta - self.facets(coarse_beta))[2]
        if self._facet_overlap is None:
            self._facet_overlap = FacetOverlap(self.coarse, self.fine)
        return self._facet_overlap.norm(fine_beta, coarse_beta)


class Overlap:
    """The overlaps of a fine mesh's cells with a coarse mesh's that is not nested in it, as (fine cell, coarse cell,
    volume) triples: a fine cell whose vertices lie in one coarse cell (``vertex_cells``: the coarse cell of each fine
    vertex) lies in it whole; one that straddles several is cut into equal sub-cells (:func:`subcell_centroids`),
    each in the coarse cell of its centroid."""

    def __init__(self, coarse: MeshInfo, fine: MeshInfo, vertex_cells: np.ndarray):
        at = vertex_cells[fine.cells]
        whole = (at == at[:, :1]).all(axis=1)
        volume = fine.cell_volumes()
        cut = np.flatnonzero(~whole)
        lam = subcell_centroids(fine.dim, SUBCELL_LEVELS[fine.dim])
        points = np.einsum("mk,ckd->cmd", lam, fine.xyz[fine.cells[cut]]).reshape(-1, fine.dim)
        self.fine_cell = np.concatenate([np.flatnonzero(whole), np.repeat(cut, len(lam))])
        self.coarse_cell = np.concatenate([at[whole, 0], coarse.locate(points) if len(points) else []]).astype(int)
        self.volume = np.concatenate([volume[whole], np.repeat(volume[cut] / len(lam), len(lam))])
        self.weights = STRESS_WEIGHTS[fine.dim]

    def norm(self, fine_values: np.ndarray, coarse_values: np.ndarray) -> float:
        """The L2 norm of a cellwise constant field on the fine mesh less one on the coarse mesh, (cell, component)
        each, the components weighted as a symmetric tensor's in Voigt order."""
        d = fine_values[self.fine_cell] - coarse_values[self.coarse_cell]
        return float(np.sqrt(np.sum(self.volume[:, None] * self.weights[None, :] * d ** 2)))

    DESCRIPTION = ("cell overlaps (meshes not nested): exact where a fine cell lies in one coarse cell, sampled at "
                   "{samples} points where it straddles several")


class FacetOverlap:
    """The overlaps of a fine mesh's contact facets with a coarse mesh's not nested in it: each fine facet cut into
    64 equal pieces (segments in 2D, a triangle's red refinement three times in 3D), each piece taken by the coarse
    facet its centre lies on (:meth:`MeshInfo.locate_on_contact`)."""

    PIECES = 64

    def __init__(self, coarse: MeshInfo, fine: MeshInfo):
        if fine.dim == 2:
            s = (np.arange(self.PIECES) + 0.5) / self.PIECES
            lam = np.stack([1.0 - s, s], axis=1)
        else:
            lam = subcell_centroids(2, 3)
        V = fine.facet_vertices()
        points = np.einsum("mk,fkd->fmd", lam, V).reshape(-1, fine.dim)
        self.fine_facet = np.repeat(np.arange(len(V)), len(lam))
        self.coarse_facet = coarse.locate_on_contact(points)
        self.measure = np.repeat(fine.facet_measure / len(lam), len(lam))

    def norm(self, fine_values: np.ndarray, coarse_values: np.ndarray) -> float:
        """The L2 norm over the contact side of a field constant per facet on the fine mesh less one on the coarse."""
        d = fine_values[self.fine_facet] - coarse_values[self.coarse_facet]
        return float(np.sqrt(np.sum(self.measure * d ** 2)))


#: Levels of equal halving of a straddling cell's edges (:func:`subcell_centroids`): 4^4 = 256 sub-triangles in 2D,
#: 8^2 = 64 sub-tetrahedra in 3D.
SUBCELL_LEVELS = {2: 4, 3: 2}


@lru_cache(maxsize=None)
def subcell_centroids(dim: int, levels: int) -> np.ndarray:
    """Barycentric coordinates (sub-cell, dim + 1) of the centroids of a simplex's red refinement, ``levels`` times:
    2^dim children of equal volume each time (the octahedron of a tetrahedron cut along one diagonal).

    >>> subcell_centroids(2, 1).round(4).tolist()[-1]  # (the inner triangle's centroid is the parent's)
    [0.3333, 0.3333, 0.3333]
    >>> bool(np.allclose(subcell_centroids(3, 2).mean(axis=0), 0.25)), len(subcell_centroids(3, 2))
    (True, 64)
    """
    simplices = [np.eye(dim + 1)]
    for _ in range(levels):
        simplices = [child for s in simplices for child in _red(s, dim)]
    return np.array([s.mean(axis=0) for s in simplices])


def _red(s: np.ndarray, dim: int) -> list:
    """The 2^dim children of equal volume of the simplex with vertices ``s`` (rows)."""
    m = {(i, j): 0.5 * (s[i] + s[j]) for i in range(dim + 1) for j in range(i + 1, dim + 1)}
    if dim == 2:
        return [np.array(v) for v in ((s[0], m[0, 1], m[0, 2]), (m[0, 1], s[1], m[1, 2]), (m[0, 2], m[1, 2], s[2]),
                                      (m[0, 1], m[1, 2], m[0, 2]))]
    corners = [(s[0], m[0, 1], m[0, 2], m[0, 3]), (m[0, 1], s[1], m[1, 2], m[1, 3]),
               (m[0, 2], m[1, 2], s[2], m[2, 3]), (m[0, 3], m[1, 3], m[2, 3], s[3])]
    ring = [m[0, 1], m[0, 3], m[2, 3], m[1, 2]]  # (around the diagonal m02 - m13, each beside the next)
    inner = [(m[0, 2], m[1, 3], ring[i], ring[(i + 1) % 4]) for i in range(4)]
    return [np.array(v) for v in corners + inner]


def p1_cell_strains(info: MeshInfo, u_nodes: np.ndarray) -> np.ndarray:
    """The strain of the P1 field with vertex values ``u_nodes`` (vertex, component), per cell (cell, component in
    Voigt order: :data:`workbench.physics.kelvin_voigt.COMPONENTS`)."""
    U = np.asarray(u_nodes, dtype=float).reshape(len(info.xyz), info.dim).T
    return p1_strains(U, info.cells, p1_gradients(info.xyz[info.cells]))


STRESS_WEIGHTS = {1: np.array([1.0]), 2: np.array([1.0, 1.0, 2.0]), 3: np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])}


def norms(fine: MeshInfo, du: np.ndarray | None, dsigma: np.ndarray | None, dbeta: np.ndarray | None):
    """(|du|_V, |dsigma|_Q, |dbeta|_L2(Gamma3)) of differences given on the fine mesh."""
    out = []
    if du is not None:
        out.append(float(np.sqrt(max(du @ (fine.strain_matrix() @ du), 0.0))))
    else:
        out.append(np.nan)
    if dsigma is not None:
        w = STRESS_WEIGHTS[fine.dim]
        out.append(float(np.sqrt(np.sum(fine.cell_volumes()[:, None] * w[None, :] * dsigma ** 2))))
    else:
        out.append(np.nan)
    if dbeta is not None:
        out.append(float(np.sqrt(np.sum(fine.facet_measure * dbeta ** 2))))
    else:
        out.append(np.nan)
    return tuple(out)
