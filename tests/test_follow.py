"""The mesh that follows the solution during the run (``space_adapt = "during"``, workbench/running/follow.py): the
state carried onto a refined mesh is the same field, the run meets its tolerance at every estimate time, and the
archive on the final mesh holds what every mesh computed."""
from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import ngsolve as ngs
import numpy as np
import pytest
from scipy.spatial import cKDTree

import workbench
from workbench.discrete import discretisation
from workbench.discrete.transfer import MeshInfo
from workbench.errors import ParameterError
from workbench.input.geometry import of_run, on_mesh
from workbench.running import adapt, follow
from workbench.schemes import scheme_class


def _refined_half(body):
    """The body with every other element bisected (a graded, nested refinement)."""
    mesh = body.mesh()
    return on_mesh(body, adapt.refine(mesh, np.arange(mesh.ne) % 2 == 0))


@pytest.mark.parametrize("name, scheme", [("tp4", "implicit"), ("tp4", "bdf2"), ("memory_slab", "vi")])
def test_the_carried_state_is_the_same_field_on_the_finer_mesh(name, scheme):
    """A few steps on the given mesh, the state carried onto a nested finer one: u, v, every displacement the scheme
    keeps (history, Model B's memory histories) have the same strain energy on both meshes, and the bonding field
    the same integral over the contact side (to round-off: the coarse fields are fields of the finer spaces)."""
    sc = workbench.scene(name, h=0.25, k=0.05, scheme=scheme)
    coarse = discretisation.build(sc)
    s_c = scheme_class(scheme)(coarse)
    s_c.start(0.0)
    s_c.accept(0.0)
    for n in range(3):
        s_c.step(0.05 * n, 0.05 * (n + 1))
        s_c.accept(0.05 * (n + 1))
    model = dataclasses.replace(sc.model_of(), geometry=_refined_half(sc.model_of().geometry))
    fine = discretisation.build(model, sc, workbench.input.numerics.from_scene(sc))
    s_f = scheme_class(scheme)(fine)
    carried = follow.carry({"scheme": s_c.state(restart=True)}, (coarse, s_c), (fine, s_f))
    s_f.restore(carried["scheme"])
    state_c, state_f = s_c.state(), s_f.state()
    assert fine.ndof > 1.3 * coarse.ndof and carried["ndof"] == fine.ndof

    K_c, K_f = (MeshInfo(d.geometry, 1).strain_matrix() for d in (coarse, fine))

    def energies(state):
        vectors = [state["u"], state["v"]] + [u for _, u, _ in state["history"]]
        vectors += list(state["extra"].get("histories", []))
        return vectors

    pairs = list(zip(energies(state_c), energies(state_f)))
    assert len(pairs) >= 3 and any(np.any(a) for a, _ in pairs)
    for a, b in pairs:
        ea, eb = a @ (K_c @ a), b @ (K_f @ b)
        assert eb == pytest.approx(ea, rel=1e-10, abs=1e-14 * max(1.0, ea))
    if state_c["beta"] is not None:
        assert state_f["beta"] @ fine.facet_measure == pytest.approx(state_c["beta"] @ coarse.facet_measure, rel=1e-12)
        assert np.ptp(state_c["beta"]) > 0  # (the slab debonds: beta is not uniform)


def test_a_run_that_follows_its_solution_meets_the_tolerance_at_every_estimate():
    """tp4's slab (Model A, backward Euler) refined during the run: the estimate within space_tol at every estimate
    time, the meshes only finer, the records on the final mesh (at the contact vertices a coarser mesh did not have,
    its P1 field), the snapshots carried exactly (the field at the probes is the one recorded then), and the result
    closer to a straight run on the final mesh than the given mesh's run is."""
    kw = dict(scheme="implicit", T=0.3, h=0.05, snapshots=(0.01, 0.02, 0.3), progress=False)
    tol = 0.1
    ds = workbench.run("tp4", space_tol=tol, space_adapt="during", **kw)
    assert ds.attrs["space_stop"] == "met" and ds.sizes["refinement"] >= 2
    assert np.nanmax(ds.space_error_estimate.values) <= tol * (1 + 1e-9)
    assert np.all(np.diff(ds.time.values) > 0) and np.all(np.diff(ds.ndof.values) >= 0)
    assert int(ds.ndof[-1]) == ds.attrs["ndof"] == ds.sizes["dof"] == int(ds.refinement_ndof[-1])
    assert int(ds.ndof[0]) < ds.attrs["ndof"]
    assert 0.01 < ds.attrs["h_max"] <= 0.05 + 1e-12  # (the longest cell side, not the side over the cell count)
    first, last = ds.ndof.values == ds.ndof.values[0], ds.ndof.values == ds.attrs["ndof"]
    u_contact = ds.u_contact.values  # (at the vertices a coarser mesh did not have: its P1 field there)
    assert np.isfinite(u_contact[first]).all() and np.isfinite(u_contact[last]).all()
    pressure = ds.contact_pressure.values  # (NaN only where a record on the final mesh has NaN too: none here)
    assert np.isnan(pressure[first]).sum(axis=1).max() <= np.isnan(pressure[last]).sum(axis=1).min()
    # the snapshots: the carried field at the probes is what the run recorded at that time, on whatever mesh
    body = of_run(workbench.scene("tp4", **{k: v for k, v in kw.items() if k != "progress"}).model_of().geometry, ds)
    mesh = body.mesh()
    gf = ngs.GridFunction(ngs.VectorH1(mesh, order=1))
    at = [int(ds.ndof.values[np.argmin(np.abs(ds.time.values - t))]) for t in ds.snapshot_time.values]
    assert min(at) < ds.attrs["ndof"] == at[-1]  # (a snapshot made on a coarser mesh)
    assert ds.snapshot_ndof.values.tolist() == at
    # the mesh each snapshot was made on, by UGRID: nested in the final mesh, with the dofs of its records
    final = np.column_stack([ds.vertex_x.values, ds.vertex_y.values])
    for name, ndof in zip(ds.snapshot_mesh.values, at):
        pre = "" if name == "mesh" else f"{name}_"
        assert ds[name].attrs["node_coordinates"] == f"{pre}vertex_x {pre}vertex_y"
        xy = np.column_stack([ds[f"{pre}vertex_x"].values, ds[f"{pre}vertex_y"].values])
        cells = ds[ds[name].attrs["face_node_connectivity"]].values
        assert 2 * len(xy) == ndof and cells.max() == len(xy) - 1 and set(np.unique(cells)) == set(range(len(xy)))
        assert cKDTree(final).query(xy)[0].max() < 1e-12
    assert ds.snapshot_mesh.values[0] != "mesh" and ds.snapshot_mesh.values[-1] == "mesh"
    for i, t in enumerate(ds.snapshot_time.values):
        gf.vec.FV().NumPy()[:] = ds.u_dofs.values[i]
        j = int(np.argmin(np.abs(ds.time.values - t)))
        for p in range(ds.sizes["probe"]):
            x, y = float(ds.probe_x[p]), float(ds.probe_y[p])
            np.testing.assert_allclose(gf(mesh(x, y)), ds.u_probe.values[j, p], rtol=1e-9, atol=1e-12)
    model = dataclasses.replace(workbench.scene("tp4", **{k: v for k, v in kw.items() if k != "progress"}).model_of(),
                                geometry=body)
    straight = workbench.run("tp4", model=model, **kw)
    given = workbench.run("tp4", **kw)
    tip = (ds.u_probe.values[-1], straight.u_probe.values[-1], given.u_probe.values[-1])
    assert np.abs(tip[0] - tip[1]).max() < 0.5 * np.abs(tip[2] - tip[1]).max()


def test_model_b_follows_and_a_met_tolerance_leaves_the_mesh_as_given():
    """Model B (the Hertz half-disc, Signorini): refined during the run, the tolerance met at every estimate time;
    with a tolerance the given mesh meets, the run is the plain run on that mesh."""
    ds = workbench.run("memory_hertz", h_contact=0.01, space_tol=0.05, space_adapt="during", progress=False)
    assert ds.attrs["space_stop"] == "met" and ds.sizes["refinement"] >= 1
    assert np.nanmax(ds.space_error_estimate.values) <= 0.05 * (1 + 1e-9)
    assert ds.attrs["ndof"] > int(ds.ndof[0]) and "adapted_mesh" in ds
    loose = workbench.run("memory_hertz", h_contact=0.01, space_tol=0.4, space_adapt="during", progress=False)
    plain = workbench.run("memory_hertz", h_contact=0.01, progress=False)
    assert loose.sizes["refinement"] == 0 and loose.attrs["ndof"] == plain.attrs["ndof"]
    np.testing.assert_array_equal(loose.u_probe.values, plain.u_probe.values)


def test_p2_and_3d_follow_their_solution():
    """P2 (the edge values of the snapshots carried too, read back at the probes) and the 3D hemisphere (Model B):
    the tolerance met at every estimate time, a snapshot made on a coarser mesh carried onto the final one."""
    kw = dict(scheme="implicit", T=0.3, h=0.1, order=2, snapshots=(0.01, 0.05, 0.3))
    ds = workbench.run("tp4", space_tol=0.05, space_adapt="during", progress=False, **kw)
    at = [int(ds.ndof.values[np.argmin(np.abs(ds.time.values - t))]) for t in ds.snapshot_time.values]
    assert min(at) < ds.attrs["ndof"] and ds.u_edges.shape[0] == ds.sizes["snapshot"]
    mesh = of_run(workbench.scene("tp4", **kw).model_of().geometry, ds).mesh()
    gf = ngs.GridFunction(ngs.VectorH1(mesh, order=2))
    for i, t in enumerate(ds.snapshot_time.values):
        gf.vec.FV().NumPy()[:] = ds.u_dofs.values[i]
        j = int(np.argmin(np.abs(ds.time.values - t)))
        for p in range(ds.sizes["probe"]):
            np.testing.assert_allclose(gf(mesh(float(ds.probe_x[p]), float(ds.probe_y[p]))), ds.u_probe.values[j, p],
                                       rtol=1e-9, atol=1e-12)
    three = workbench.run("memory_hertz3d", space_tol=0.15, space_adapt="during", snapshots=(0.25, 1.0),
                          progress=False)
    assert three.attrs["space_stop"] == "met" and np.nanmax(three.space_error_estimate.values) <= 0.15 * (1 + 1e-9)
    first = int(three.ndof.values[np.argmin(np.abs(three.time.values - 0.25))])
    assert first < three.attrs["ndof"] == three.sizes["dof"]
    assert np.isfinite(three.u_nodes.values).all() and np.abs(three.u_nodes.values[0]).max() > 0


def test_a_run_that_diverges_keeps_what_every_mesh_computed():
    """A bound on the displacement that the run crosses on a refined mesh (measured: at t = 0.07 s, after the
    refinements): the error carries the records of every mesh up to the last step before, marked incomplete."""
    kw = dict(scheme="implicit", T=0.3, h=0.05, space_tol=0.1, space_adapt="during", progress=False)
    with pytest.raises(workbench.Diverged) as caught:
        workbench.run("tp4", limit=3.0, **kw)
    ds = caught.value.dataset
    assert ds.attrs["status"] == "incomplete" and ds.sizes["refinement"] >= 1
    assert int(ds.ndof[0]) < int(ds.ndof[-1]) and np.all(np.diff(ds.time.values) > 0)
    assert np.abs(ds.u_probe.values).max() <= 3.0
    with pytest.raises(workbench.Diverged) as caught:  # (on the given mesh, in the first pass)
        workbench.run("tp4", limit=0.5, **kw)
    assert "ndof" in caught.value.dataset and caught.value.dataset.attrs["status"] == "incomplete"


def test_a_run_that_stops_at_its_first_step_on_a_finer_mesh_keeps_the_other_meshes_records(monkeypatch):
    """A run that stops at its first step on a finer mesh has recorded nothing there. Building its Dataset failed
    ("need at least one array to stack": a traceback, every mesh's records lost); it stops as a diverged run with the
    records of the meshes before. Made to stop as Model B's rectangle rule under rtol did before its carried state
    was solved again on the finer mesh (``MemoryVI.settle`` left out: the first step's estimate is charged with the
    jump of the finer solution away from the carried one, and no step meets rtol)."""
    from workbench.schemes.memory_vi import MemoryVI

    monkeypatch.setattr(MemoryVI, "settle", lambda self, t: None)
    with pytest.raises(workbench.Diverged, match="error control needs a step below k_min") as caught:
        workbench.run("memory_slab", h=0.25, T=0.3, rtol=1e-3, space_tol=0.15, space_adapt="during", progress=False)
    ds = caught.value.dataset
    assert ds.attrs["status"] == "incomplete" and ds.sizes["time"] > 100 and ds.sizes["refinement"] == 1


@pytest.mark.slow
def test_error_control_on_a_kelvin_voigt_body_goes_on_after_a_refinement():
    """Backward Euler under rtol, the mesh following the run: the predictor of the first step on a finer mesh came
    from the coarse mesh's states and charged it with the velocity's jump onto the finer mesh, an error no step
    shrinks (k was cut to k_min at t = 3.9e-5 s, and the run ended in a traceback). That step is judged by halving
    now, as a first step is; the run ends complete, refined."""
    ds = workbench.run("tp4", h=0.1, T=0.3, scheme="implicit", rtol=1e-3, space_tol=0.15, space_adapt="during",
                       progress=False)
    assert ds.attrs["status"] == "complete" and ds.attrs["space_refinements"] >= 1
    assert float(ds.time[-1]) == pytest.approx(0.3) and int(ds.ndof[-1]) > int(ds.ndof[0])


def test_the_force_of_a_record_made_on_a_coarser_mesh_closes_with_the_final_weights():
    """An archive adapted during the run holds every record on its final mesh's contact vertices, with the final
    mesh's node_weight. The vertices a record's mesh did not have were NaN, and sum(node_weight * contact_pressure)
    came out 34 % low on the coarse records. They take the coarse mesh's P1 field on the contact side now, so the sum
    is the coarse record's own force: that of the run on the given mesh at the same times, to round-off (the first
    pass and the records before the first refinement are that run). The states are not interpolated (-1 there)."""
    kw = dict(h=0.25, T=0.2, k=0.02, progress=False)
    plain = workbench.run("memory_slab", **kw)
    during = workbench.run("memory_slab", space_tol=0.1, space_adapt="during", max_dofs=3000, **kw)
    coarse = np.nonzero(during.ndof.values == during.ndof.values[0])[0]
    assert during.ndof.values[-1] > during.ndof.values[0] and coarse.size >= 3 and during.sizes["node"] > \
        plain.sizes["node"]

    def force(ds, i):
        return float(np.nansum(ds.contact_pressure.values[i] * ds.node_weight.values))

    for i in coarse[1:]:
        t = float(during.time[i])
        j = int(np.argmin(np.abs(plain.time.values - t)))
        assert plain.time.values[j] == pytest.approx(t, abs=1e-12) and force(plain, j) > 0
        assert force(during, i) == pytest.approx(force(plain, j), rel=1e-12)
        assert (during.contact_state.values[i] >= 0).sum() == (plain.contact_state.values[j] >= 0).sum()


def test_error_control_on_a_body_with_memory_goes_on_after_a_refinement():
    """Model B's rectangle rule under rtol, the mesh following the run: the estimate of the first step on the finer
    mesh read u_(n-1) of the coarse mesh, and the memory integrated its jump onto the finer mesh over the step, an
    error per unit step that no step size shrinks (k was cut to k_min = 1e-9 at t = 0.225 s). The carried state is
    now solved again on the finer mesh (``MemoryVI.settle``): the run ends complete, and the step after each
    refinement is not cut below a tenth of the one before it."""
    ds = workbench.run("memory_slab", h=0.25, T=0.3, rtol=1e-3, space_tol=0.15, space_adapt="during", progress=False)
    assert ds.attrs["status"] == "complete" and ds.attrs["space_refinements"] >= 1
    assert float(ds.time[-1]) == pytest.approx(0.3) and int(ds.ndof[-1]) > int(ds.ndof[0])
    t = ds.time.values
    for when in ds.refinement_time.values:
        at = int(np.searchsorted(t, when))
        assert np.diff(t[at:at + 3]).min() > 0.1 * (t[at] - t[at - 1])


@pytest.mark.parametrize("adapt", ["repeat", "during"])
def test_an_adapted_archive_has_units_and_a_long_name_on_every_variable(adapt):
    """level, level_ndof, level_space_error_estimate, ndof(time) of the repeated loop had no attributes, its
    level_wall_time no long_name, the refinement coordinate of a run that follows its solution none, and Model B's
    state_histories and state_lam no units; only the meshes' own variables go without units (docs/conventions.md)."""
    ds = workbench.run("memory_slab", h=0.25, T=0.2, space_tol=0.1, space_adapt=adapt, progress=False)
    meshes = {"mesh", "snapshot_mesh", "adapted_mesh"}
    for name, var in ds.variables.items():
        assert var.attrs.get("long_name"), name
        assert "units" in var.attrs or name in meshes, name
    assert ds.state_histories.attrs["units"] == "m s" and ds.state_lam.attrs["units"] == "N"


def test_max_dofs_stops_the_refinement_with_a_warning():
    """A refinement that would exceed max_dofs is not made: the run goes on on its mesh and says so."""
    with pytest.warns(RuntimeWarning, match=r"space_tol = 0.05 not met: .* \(max_dofs reached\)"):
        ds = workbench.run("tp4", scheme="implicit", T=0.3, h=0.05, space_tol=0.05, space_adapt="during",
                           max_dofs=1000, progress=False)
    assert ds.attrs["space_stop"] == "max_dofs" and ds.attrs["ndof"] <= 1000
    assert ds.attrs["space_error_estimate"] > 0.05


def test_the_space_plot_draws_both_modes(tmp_path):
    """plotting.space: the estimate over time and, for 'during', the dofs over time; for 'repeat', the loop's meshes;
    a run without space_tol is refused by name."""
    from workbench import plotting

    during = workbench.run("memory_hertz", h_contact=0.01, space_tol=0.05, space_adapt="during", progress=False)
    fig = plotting.space(during, tmp_path / "during.png")
    assert (tmp_path / "during.png").stat().st_size > 0
    assert [ax.get_title() for ax in fig.axes] == ["estimate in space", "dofs over time"]
    steps = fig.axes[1].lines[0].get_ydata()
    assert steps[0] < steps[-1] == during.attrs["ndof"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        repeat = workbench.run("memory_hertz", h_contact=0.01, space_tol=0.05, progress=False)
    assert [ax.get_title() for ax in plotting.space(repeat).axes] == ["estimate in space", "meshes of the loop"]
    with pytest.raises(ValueError, match="space_tol > 0"):
        plotting.space(workbench.run("memory_hertz", h_contact=0.01, progress=False))


def test_space_adapt_refused_where_it_cannot_work():
    with pytest.raises(ParameterError, match="space_adapt = 'during' carries the state of the schemes"):
        workbench.scene("tp4", space_tol=0.1, space_adapt="during")
    with pytest.raises(ParameterError, match="space_adapt"):
        workbench.scene("tp4", scheme="implicit", space_tol=0.1, space_adapt="sometimes")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (without space_tol the option changes nothing, and says nothing)
        workbench.scene("tp4", scheme="implicit", space_adapt="during")


def test_edge_tol_is_refused_without_a_mesh_that_follows_the_run():
    for kw in (dict(edge_tol=0.05), dict(edge_tol=0.05, space_tol=0.2), dict(edge_tol=0.05, space_adapt="during")):
        with pytest.raises(ParameterError, match="edge_tol = 0.05 is judged by a mesh that follows the run"):
            workbench.scene("memory_hertz", **kw)
    with pytest.raises(ParameterError, match=r"edge_tol = 0.7 is outside the allowed range 0 <= edge_tol <= 0.5"):
        workbench.scene("memory_hertz", edge_tol=0.7)


def test_the_edge_of_a_pressed_disc_is_where_the_pressure_ends():
    """ContactEdge on the hemisphere's curved side (3D, a quarter of the zone) with the pressure of a zone of radius
    0.1: the zone's size is the quarter disc's sqrt(pi/4) 0.1 and the edge facets lie on r = 0.1, each to within
    one facet."""
    from workbench.discrete.estimator import ContactEdge

    d = discretisation.build(workbench.scene("memory_hertz3d", T=0.25, k=0.25))
    r = np.hypot(d.node_xyz[:, 0], d.node_xyz[:, 1])
    e = ContactEdge(d).measure(np.where(r < 0.1, 1.0, 0.0))
    facet = e.resolution * e.zone
    assert abs(e.zone - np.sqrt(np.pi / 4) * 0.1) < facet
    assert np.all(np.abs(np.hypot(e.points[:, 0], e.points[:, 1]) - 0.1) < facet)
    assert ContactEdge(d).measure(np.ones(len(r))) is None and ContactEdge(d).measure(np.zeros(len(r))) is None


def test_edge_tol_resolves_the_contact_zone_s_edge_at_every_estimate_time():
    """The Hertz half-disc whose energy estimate meets space_tol = 0.2 on the given mesh, where the last vertex in
    contact is 8.6 % inside Hertz's a: with edge_tol = 0.05 every recorded resolution is at most 0.05, the mesh is
    refined toward the edge only, and the last vertex in contact is within 1.5 % of a."""
    from workbench.references import hertz

    base = dict(h_contact=0.01, space_tol=0.2, space_adapt="during", progress=False)
    plain = workbench.run("memory_hertz", **base)
    ds = workbench.run("memory_hertz", **base, edge_tol=0.05)
    assert plain.attrs["space_refinements"] == 0 and "contact_edge_resolution" not in plain
    assert abs(hertz.profile(plain)["a_last"] / hertz.profile(plain)["a"] - 1) > 0.05
    resolution = ds.contact_edge_resolution.values
    assert np.isnan(resolution[0]) and np.all(resolution[1:] <= 0.05), resolution  # (at rest, t = 0: no edge)
    assert ds.attrs["space_refinements"] > 0 and ds.attrs["contact_edge_resolution"] <= 0.05
    assert abs(hertz.profile(ds)["a_last"] / hertz.profile(ds)["a"] - 1) < 0.015
    body = workbench.scene("memory_hertz", h_contact=0.01).model_of().geometry
    a = hertz.profile(ds)["a"]
    (where, h), (given_where, given_h) = (adapt.element_sizes(m) for m in (
        ngs.Mesh(of_run(body, ds).adapted_mesh), body.mesh()))
    near, given_near = (np.hypot(w[:, 0] - a, w[:, 1]) < 0.02 for w in (where, given_where))
    # (graded toward the edge, the rest as given)
    assert np.median(h[near]) < 0.5 * np.median(given_h[given_near])
    assert np.isclose(h[~near].max(), given_h[~given_near].max(), rtol=1e-9)


def test_a_study_sweeps_edge_tol_and_takes_the_smallest_as_the_finest():
    """edge_tol is a refinement axis of a Study: with two levels the reference is the smaller edge_tol (not the
    first listed, as before edge_tol was one), and the other case is compared with it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (the finest-case reference of a two-level sweep is biased)
        ds = workbench.Study("memory_hertz", h_contact=0.01, space_tol=0.2, space_adapt="during",
                             sweep={"edge_tol": [0.2, 0.05]}, workers=0).run(progress=False)
    error = ds.error.sel(edge_tol=[0.2, 0.05]).values.ravel()
    assert error[0] > 0 and np.isnan(error[1]), error  # (0.05 is the reference, not reported)


def test_a_continuation_from_a_checkpoint_is_the_run_straight_through(tmp_path, monkeypatch):
    """checkpoint_every with space_adapt = 'during': the checkpoints fall on estimate times that met the tolerance,
    so a continuation goes back where the run itself would; from the first checkpoint, on a mesh the run refined
    again afterwards, the continuation reproduces the straight run bitwise (records, meshes, refinements, snapshots)."""
    from workbench.output import results

    # (the banded factor and the condensed contact solver: NGSolve's sparse factor and the coupled solver's
    # remembered directions make two straight runs differ by 1e-12 already, tests/test_restart.py)
    kw = dict(scheme="implicit", T=0.3, h=0.05, space_tol=0.1, space_adapt="during", snapshots=(0.01, 0.3),
              solver="banded", contact_solver="condensed", progress=False)
    kept, write = [], results.write

    def keeping(ds, path, *args, **kwargs):
        out = write(ds, path, *args, **kwargs)
        copy = tmp_path / f"checkpoint{len(kept)}.nc"
        copy.write_bytes(Path(path).read_bytes())
        kept.append((float(ds.time[-1]), int(ds.attrs["ndof"]), copy))
        return out

    monkeypatch.setattr(results, "write", keeping)
    straight = workbench.run("tp4", checkpoint_every=2, checkpoint=tmp_path / "run.nc", **kw)
    monkeypatch.undo()
    t, ndof, first = kept[0]
    assert len(kept) >= 3 and ndof < straight.attrs["ndof"] and 0 < t < 0.3
    more = workbench.run(restart=first, checkpoint=tmp_path / "more.nc", progress=False)
    assert more.attrs["restart_time"] == t
    for name in ("time", "ndof", "u_probe", "beta", "space_error_estimate", "refinement_time", "refinement_ndof",
                 "snapshot_time"):
        np.testing.assert_array_equal(more[name].values, straight[name].values, err_msg=name)
    final = straight.ndof.values == straight.ndof.values[-1]
    np.testing.assert_array_equal(more.u_contact.values[final], straight.u_contact.values[final])
    # (a snapshot made before the checkpoint reaches the final mesh through the checkpoint's mesh: the composed
    # prolongation rounds differently, by an ulp; so do the contact vertices a record's mesh did not have, which take
    # its P1 field there)
    for name in ("u_dofs", "stress", "u_contact", "contact_pressure"):
        np.testing.assert_allclose(more[name].values, straight[name].values, rtol=1e-13, atol=1e-15, err_msg=name)
    # (the meshes of the snapshots made before the checkpoint, kept from its archive)
    np.testing.assert_array_equal(more.snapshot_mesh.values, straight.snapshot_mesh.values)
    assert more.snapshot_mesh.values[0] != "mesh"
    for name in [n for n in straight.variables if n.startswith("mesh_")]:
        np.testing.assert_array_equal(more[name].values, straight[name].values, err_msg=name)
    with pytest.raises(ParameterError, match="refined adaptively"):  # (repeated runs cannot be continued)
        path = tmp_path / "repeat.nc"
        workbench.write(workbench.run("memory_hertz", h_contact=0.01, space_tol=0.2, T=0.5, progress=False), path)
        workbench.run(restart=path, T=1.0, progress=False)


def test_a_continuation_that_refines_no_further_can_be_continued_again(tmp_path):
    """A run continued from a 'during' archive kept its mesh only where the continuation itself refined: the archive
    of a continuation on the archive's last mesh had no ``adapted_mesh``, so continuing it again was refused as "an
    archive of another workbench version", and its ``space_indicator`` held only the indicators since the restart
    (2.5 % off the straight run's; an outside pass). Continued twice, T = 0.2 -> 0.25 -> 0.3, it now equals the run
    straight to 0.3."""
    kw = dict(h=0.1, scheme="implicit", space_tol=0.2, space_adapt="during", progress=False)
    workbench.write(workbench.run("tp4", T=0.2, **kw), tmp_path / "a.nc")
    workbench.write(workbench.run(restart=tmp_path / "a.nc", T=0.25, progress=False), tmp_path / "b.nc")
    chained = workbench.run(restart=tmp_path / "b.nc", T=0.3, progress=False)
    straight = workbench.run("tp4", T=0.3, **kw)
    assert straight.attrs["space_refinements"] > 0 and "adapted_mesh" in chained
    assert str(chained.adapted_mesh.values) == str(straight.adapted_mesh.values)
    for name in ("u_probe", "u_dofs", "beta", "space_indicator", "space_error_estimate", "ndof", "refinement_time"):
        np.testing.assert_array_equal(chained[name].values, straight[name].values, err_msg=name)
