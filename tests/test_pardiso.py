"""MKL PARDISO (ctypes): its factor, its Schur complements, and the condensed contact stiffness made inside one
factorization instead of one back-substitution per contact point, against dense linear algebra and the solves."""
import sys

import numpy as np
import pytest
import scipy.sparse as sp

import workbench
from workbench.discrete import condensation, discretisation, pardiso, solvers
from workbench.errors import ParameterError

needs_mkl = pytest.mark.skipif(not pardiso.available(), reason="MKL could not be loaded")


def _spd(n=400, seed=0):
    A = sp.random(n, n, 0.01, random_state=seed)
    return (A @ A.T + sp.diags(np.linspace(0.5, 3.0, n))).tocsr()


@needs_mkl
def test_factor_schur_complement_and_compliance_against_dense_algebra():
    A = _spd()
    dense_inverse = np.linalg.inv(A.toarray())
    rng = np.random.default_rng(1)
    b = rng.standard_normal((A.shape[0], 3))
    f = pardiso.Factor(A)
    assert np.abs(A @ f.solve(b) - b).max() < 1e-12 * np.abs(b).max()
    assert np.abs(A @ f.solve(b[:, 1]) - b[:, 1]).max() < 1e-12 * np.abs(b).max()  # (one right-hand side)
    keep = rng.choice(A.shape[0], 30, replace=False)  # (unsorted: the result is in this order)
    S = pardiso.schur_complement(A, keep)
    assert np.abs(S - np.linalg.inv(dense_inverse[np.ix_(keep, keep)])).max() < 1e-10 * np.abs(S).max()
    B = sp.random(20, A.shape[0], 0.05, random_state=2).tocsr()
    C = pardiso.compliance(A, B)
    reference = B @ dense_inverse @ B.T.toarray()
    assert np.abs(C - reference).max() < 1e-10 * np.abs(reference).max()


@needs_mkl
def test_a_singular_matrix_is_refused_by_name():
    A = sp.diags([1.0, 0.0, 1.0]).tocsr()
    with pytest.raises(RuntimeError, match="PARDISO"):
        pardiso.Factor(A)


@needs_mkl
@pytest.mark.parametrize("name, kw", [("memory_hertz3d", {}), ("memory_hertz", dict(order=2)), ("slab", {})])
def test_the_condensed_stiffness_equals_the_one_made_by_back_substitutions(name, kw):
    """P1 vertices (dofs C) and P2 traces (B), with the banded and the PARDISO factor."""
    from workbench.schemes.contact_nodes import ContactNodes

    d = discretisation.build(workbench.scene(name, **kw))
    discretisation.assemble(d)
    if name == "slab":
        from workbench.discrete.condensation import ContactOperator

        C, B = ContactOperator(d).C, None
    else:
        nodes = ContactNodes(d)
        C, B = nodes.C, nodes.B
    for method in ("banded", "pardiso"):
        s = solvers.factor(d.elastic.mat, d.fes.FreeDofs(), d.u.vec, method)
        inside = s.condensed_stiffness(C, B)
        by_solves = condensation.CondensedSystem._by_solves(s, d.ndof, C, 64, B)
        assert inside.shape == by_solves.shape and inside.shape[0] > 10
        assert np.abs(inside - by_solves).max() < 1e-8 * np.abs(by_solves).max(), method


@needs_mkl
def test_a_run_with_pardiso_equals_the_run_with_ngsolves_factor():
    """The 3D hemisphere's Signorini run, condensed, with auto (PARDISO's factor and Schur complement) and with
    NGSolve's factor and one back-substitution per contact point."""
    runs = {s: workbench.run("memory_hertz3d", contact_solver="condensed", solver=s, progress=False)
            for s in ("auto", "sparsecholesky")}
    assert runs["auto"].attrs["linear_solver"] == "pardiso"
    a, b = (runs[s].contact_pressure.values for s in ("auto", "sparsecholesky"))
    assert np.abs(a - b).max() < 1e-7 * np.abs(b).max()


def test_without_mkl_pardiso_is_refused_before_any_work_and_auto_keeps_ngsolves_factor(monkeypatch):
    monkeypatch.setattr(pardiso, "available", lambda: False)
    with pytest.raises(ParameterError, match="solver = 'pardiso' needs Intel MKL"):
        workbench.run("memory_hertz3d", solver="pardiso", progress=False)
    ds = workbench.run("memory_hertz3d", progress=False)
    assert ds.attrs["linear_solver"] == "sparsecholesky"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/maps")
def test_import_workbench_does_not_load_mkl():
    """MKL is loaded at its first use in a run, so importing workbench leaves a user's process (and an MKL it may
    load later, with its own threading) as it was."""
    import subprocess

    code = "import workbench; print('libmkl' in open('/proc/self/maps').read())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
