"""The banded Cholesky (RCM order) solves the same systems as NGSolve's sparse Cholesky."""
import numpy as np
import pytest

import workbench
from workbench import discretisation, solvers


@pytest.mark.parametrize("name, kw", [("slab", dict(h=0.05)), ("block", dict(h=0.1)), ("tp1", dict(h=0.1)),
                                      ("slab", dict(h=0.1, order=2))])
def test_banded_matches_sparsecholesky(name, kw):
    d = discretisation.build(workbench.scene(name, **kw))
    rhs = np.random.default_rng(0).standard_normal(d.ndof)
    out = {}
    for method in ("banded", "sparsecholesky"):
        s = solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, method)
        out[method] = np.zeros(d.ndof)
        s.solve(rhs, out[method])
    free = np.array(d.fes.FreeDofs(), dtype=bool)
    assert np.all(out["banded"][~free] == 0)
    assert np.allclose(out["banded"], out["sparsecholesky"], rtol=1e-9, atol=1e-12 * np.abs(out["banded"]).max())
    K = solvers.to_scipy(d.viscous.mat)
    residual = (K @ out["banded"] - rhs)[free]
    assert np.abs(residual).max() < 1e-9 * np.abs(rhs).max()


def test_auto_takes_the_band_only_when_it_is_narrow_and_small(monkeypatch):
    """auto: the thin slab's narrow band is factored banded; a band that would need more than BAND_BYTES of storage
    (3D: it grows like n^(5/3); the P2 block at 118k dofs needed 2.2 GB, 4.6 GB peak) goes to the sparse factor."""
    d = discretisation.build(workbench.scene("slab", h=0.05))
    K = solvers.to_scipy(d.viscous.mat)
    free = np.nonzero(np.array(d.fes.FreeDofs(), dtype=bool))[0]
    _, bandwidth = solvers.rcm(K, free)
    band = 8.0 * (bandwidth + 1) * free.size
    assert solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec).name == "banded"
    monkeypatch.setattr(solvers, "BAND_BYTES", 0.5 * band)
    assert solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec).name == "sparsecholesky"
    assert solvers.factor(d.viscous.mat, d.fes.FreeDofs(), d.u.vec, "banded").name == "banded"  # asked for: kept
