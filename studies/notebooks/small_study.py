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
# # A small refinement study
#
# Confirm the O(h + k) convergence of the paper's scheme on a rod problem with an exact solution,
# then on the slab against the finest case, and look at the speed/accuracy trade.
# The test suite runs this file with `WORKBENCH_NOTEBOOK_SMALL=1`.

# %%
import os

from workbench import plotting
from workbench.study import Study

SMALL = os.environ.get("WORKBENCH_NOTEBOOK_SMALL") == "1"

# %% [markdown]
# Test problem 1 against its exact solution (docs/models.md): a k-sweep, in this process (`workers=0`).

# %%
rod = Study("tp1", k=[0.04, 0.02, 0.01] if SMALL else [0.04, 0.02, 0.01, 0.005, 0.0025], reference="ode", workers=0)
ds = rod.run(progress=False)
rod.assert_order(1.0, tol=0.1, along="k")
ds.observed_order.sel(along="k").squeeze().to_series()

# %%
plotting.convergence(ds)

# %% [markdown]
# The slab (tp5), coupled k = 0.2 h, P1 and P2, in two worker processes.

# %%
slab = Study("tp5", h=[0.05, 0.025] if SMALL else [0.05, 0.025, 0.0125, 0.00625], k_over_h=0.2,
             order=[1, 2], T=0.2 if SMALL else 1.0, n_compare=4)
sds = slab.run(progress=False)
plotting.convergence(sds)

# %%
plotting.pareto(sds)

# %%
slab.cheapest(float(sds.error.max()))
