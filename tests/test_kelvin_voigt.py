"""Without contact the scheme is the paper's IMEX Euler for the linear Kelvin–Voigt system.

Reference (independent of the time stepping): the exact-in-time solution of the
semi-discrete system K_A u' + K_G u = t F1, u(0) = 0, by generalised eigenvectors
K_G phi = lambda K_A phi (workbench.references.modal_linear). The time error
must be O(k): observed order in [0.9, 1.1] and an absolute cap.
"""
import numpy as np
import pytest
import scipy.sparse as sp

import workbench
from workbench.discrete import discretisation
from workbench.references import modal_linear


def dense(mat):
    rows, cols, vals = mat.COO()
    n = mat.height
    return sp.csr_matrix((np.asarray(vals), (np.asarray(rows), np.asarray(cols))), shape=(n, n)).toarray()


CASES = {
    "slab": dict(h=0.1, traction_top="(0, t)", traction_right="(t, 0)"),
    "block": dict(h=0.25, nx=4, ny=1, nz=1, traction_top="(0, 0, t)", traction_right="(0, t, 0)"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_linear_kelvin_voigt_order_in_k(name, order_of):
    """2D plane stress and 3D: first order in k to the modal solution (max over recorded steps)."""
    sc = workbench.scene(name, contact=False, adhesion=False, T=0.2, snapshots=(0.05, 0.1, 0.2), **CASES[name])
    d = discretisation.build(sc)
    assert d.contact_form is None and d.beta is None  # nothing declared, nothing assembled
    F1 = d.u.vec.CreateVector()
    d.load_vector(1.0, F1)  # the load is t * F1
    F1 = np.array(F1.FV().NumPy())
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    exact = modal_linear(dense(d.viscous.mat), dense(d.elastic.mat), F1, free)
    ks = [0.01, 0.005, 0.0025]
    errors = []
    for k in ks:
        ds = workbench.run(sc.with_(k=k), progress=False)
        assert ds.sizes["snapshot"] == 3
        err = max(np.abs(ds.u_dofs.isel(snapshot=i).values - exact(float(t))).max()
                  for i, t in enumerate(ds.snapshot_time.values))
        errors.append(err)
    scale = np.abs(exact(0.2)).max()
    assert 0.9 <= order_of(ks, errors) <= 1.1
    assert errors[-1] < 0.02 * scale


def test_plane_strain_von_mises_includes_sigma33():
    """Plane strain, homogeneous state by hand: eps33 = 0, so sigma33 = lam tr(eps) enters the von Mises norm.

    E = 1000, nu = 0.25: lam = two_mu / 2 = 400. eps = (1e-3, -2e-3, e12 = 5e-4): sigma = (0.4, -2.0, 0.4),
    sigma33 = -0.4. The viscous part a1 = 10, a2 = 20 at eps' = (0.01, 0, 0) adds (0.3, 0.1, 0) and sigma33 0.1.
    vM^2 = ((s11 - s22)^2 + (s22 - s33)^2 + (s33 - s11)^2) / 2 + 3 s12^2: 4.96 (elastic), 5.64 (both);
    without sigma33 (plane stress's formula) it would be 4.88 and 5.55.
    """
    from workbench.physics import kelvin_voigt as kv

    elastic = kv.from_young(1000.0, 0.25, dim=2, plane="strain")
    viscous = kv.Isotropic(10.0, 20.0, plane_strain=True)
    eps, rate = np.array([[1e-3, -2e-3, 5e-4]]), np.array([[0.01, 0.0, 0.0]])
    stress, vm = kv.stress_and_von_mises([(elastic, eps)], dim=2)
    np.testing.assert_allclose(stress, [[0.4, -2.0, 0.4]], rtol=1e-12)
    assert vm[0] == pytest.approx(np.sqrt(4.96), rel=1e-12)
    stress, vm = kv.stress_and_von_mises([(viscous, rate), (elastic, eps)], dim=2)
    np.testing.assert_allclose(stress, [[0.7, -1.9, 0.4]], rtol=1e-12)
    assert vm[0] == pytest.approx(np.sqrt(5.64), rel=1e-12)
    # plane stress: sigma33 = 0, the familiar form
    _, vm = kv.stress_and_von_mises([(kv.from_young(1000.0, 0.25, dim=2), eps)], dim=2)
    s11, s22, s12 = kv.from_young(1000.0, 0.25, dim=2).apply(eps)[0]
    assert vm[0] == pytest.approx(np.sqrt(s11 ** 2 + s22 ** 2 - s11 * s22 + 3 * s12 ** 2), rel=1e-12)
    # a scene in plane strain builds both of its Kelvin-Voigt tensors so
    model = workbench.scene("slab", plane="strain").model_of()
    assert model.elastic.plane_strain and model.viscous.plane_strain


def test_plane_strain_von_mises_of_a_run():
    """Model B without memory, plane strain: sigma = A eps(u) isotropic, so sigma33 = nu (sigma11 + sigma22) in every
    cell, and the recorded von_mises is the norm with it."""
    sc = workbench.scene("memory_slab", plane="strain", kernel="0", prony=(), h=0.25, T=0.2, k=0.1)
    ds = workbench.run(sc, progress=False)
    s = ds.stress.isel(snapshot=-1).values
    s11, s22, s12 = s[:, 0], s[:, 1], s[:, 2]
    s33 = sc["nu"] * (s11 + s22)
    expected = np.sqrt(0.5 * ((s11 - s22) ** 2 + (s22 - s33) ** 2 + (s33 - s11) ** 2) + 3 * s12 ** 2)
    assert np.abs(s33).max() > 0.1 * np.abs(s).max()
    np.testing.assert_allclose(ds.von_mises.isel(snapshot=-1).values, expected, rtol=1e-10)
