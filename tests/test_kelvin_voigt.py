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
from workbench import discretisation
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
