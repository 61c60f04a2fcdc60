# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Exploring a scene
#
# Pick a scene, change its parameters, run it and look at the fields. Open this file in Jupyter with
# `jupytext` (`pip install -e ".[notebooks]"`, then *Open as notebook*), or run it as a script.
# The test suite runs it at a small size (`WORKBENCH_NOTEBOOK_SMALL=1`), so it cannot rot.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np

import workbench
from workbench import plotting

SMALL = os.environ.get("WORKBENCH_NOTEBOOK_SMALL") == "1"

# %% [markdown]
# Every parameter, with its unit and allowed range (the same table as `workbench show tp5`):

# %%
scene = workbench.scene("tp5", h=0.05 if SMALL else 0.0125, k=0.01, T=0.3 if SMALL else 1.0)
for name, value, unit, allowed, meaning in scene.table()[:8]:
    print(f"{name:10s} {str(value):12s} {unit:6s} {meaning}")

# %% [markdown]
# Change the physics: a stronger glue, a tension-only bonding law (already the tp5 default), and run.

# %%
ds = workbench.run(scene.with_(gamma_nu=1.0), progress=False)
ds

# %%
plotting.overview(ds)

# %% [markdown]
# The deformed slab at T coloured by the von Mises norm of the stress (magnification 1).

# %%
last = ds.isel(snapshot=-1)
xy = np.stack([ds.vertex_x.values, ds.vertex_y.values], axis=1) + last.u_nodes.values
fig, ax = plt.subplots(figsize=(8, 2.2))
tpc = ax.tripcolor(xy[:, 0], xy[:, 1], ds.cell_vertices.values, facecolors=last.von_mises.values, shading="flat")
fig.colorbar(tpc, ax=ax, label="von Mises [Pa]")
ax.set_aspect("equal")
ax.set_title(f"t = {float(last.snapshot_time):g} s")

# %% [markdown]
# The bonding field along the contact side at a few times:

# %%
fig, ax = plt.subplots()
for t in np.quantile(ds.time.values, [0.25, 0.5, 1.0], method="nearest"):
    ax.plot(ds.facet_x, ds.beta.sel(time=t), label=f"t = {t:.2f}")
ax.set(xlabel="x [m]", ylabel="beta")
ax.legend()

# %% [markdown]
# In Jupyter, NGSolve's web viewer shows the mesh and fields in 3D (it needs `anywidget`;
# the browser loads its JavaScript from a CDN). Outside a notebook this cell does nothing.

# %%
try:
    get_ipython  # noqa: F821 - defined only inside IPython
    from ngsolve.webgui import Draw

    from workbench.discrete import discretisation

    d = discretisation.build(scene)
    d.u.vec.FV().NumPy()[:] = last.u_dofs.values
    Draw(d.u, d.mesh, deformation=True)
except (NameError, ImportError):
    print("not in a notebook with anywidget: web viewer skipped")
