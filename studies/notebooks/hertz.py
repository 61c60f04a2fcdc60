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
# # Hertz: a cylinder pressed on the foundation
#
# The half-disc of radius R = 1 m (scenes `memory_hertz` and `hertz`, plane strain, E = 1000 Pa, ν = 0.3),
# pressed by a total force P per unit thickness on its flat top. Hertz's half-width is a = √(4PR / (πE*)),
# E* = E / (1 − ν²), and the pressure is p(x) = (2P / (πa²)) √(a² − x²) (docs/models.md). Open this file in
# Jupyter with jupytext, or run it as a script; the tests run it at a small size.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np

import workbench
from workbench.references import hertz

SMALL = os.environ.get("WORKBENCH_NOTEBOOK_SMALL") == "1"
LEVELS = [0.005, 0.0025] if SMALL else [0.005, 0.0025, 0.00125]

# %% [markdown]
# ## The elastic contact: the Signorini limit of Model B
#
# No memory, F = c = gap = 0: the body may not penetrate at all. The mesh is graded towards the contact point,
# `h_contact` there; halving it, the pressure approaches Hertz's.

# %%
profiles = {hc: hertz.profile(workbench.run("memory_hertz", h_contact=hc, progress=False)) for hc in LEVELS}
for hc, r in profiles.items():
    print(f"h_contact = {hc:<7g} a = {r['a']:.4f} m, last vertex in contact {r['a_last']:.4f} m, "
          f"pressure L2 error {100 * r['l2']:.2f} %, force / load {r['force']:.6f}")

# %%
fig, ax = plt.subplots(figsize=(7, 3.5))
x = np.linspace(0, 1.5 * profiles[LEVELS[0]]["a"], 300)
a, p = hertz.cylinder(10.0, 1.0, 1000.0, 0.3)
ax.plot(x, p(x), "k", lw=2, label="Hertz")
for hc, r in profiles.items():
    near = r["x"] < 1.5 * a
    ax.plot(r["x"][near], r["p"][near], ".-", ms=4, lw=0.8, label=f"h_contact = {hc:g}")
ax.set_xlabel("x [m]")
ax.set_ylabel("contact pressure [Pa]")
ax.legend()
ax.set_title("elastic cylinder, P = 10 N/m")

# %% [markdown]
# ## A viscoelastic body: the contact grows under a ramp load (Lee–Radok)
#
# Model A with a Kelvin–Voigt body whose viscous tensor is τ times its elastic one, τ = 0.2 s, and a stiff
# normal compliance (c_ν = 1e7), loaded by P = 10 t. The contact half-width lags behind the elastic one; Lee and
# Radok's solution replaces 1/E* by the creep compliance (1 − e^(−t/τ)) / E*.

# %%
hc = 0.0025 if SMALL else 0.00125
ds = workbench.run("hertz", h_contact=hc, c_nu=1e7, tau=0.2, k=0.02, scheme="bdf2", snapshots=(), progress=False)
times = ds.time.values[1:]
measured = np.array([[hertz.profile(ds, t)[key] for key in ("a_last", "a_next")] for t in times])
fig, ax = plt.subplots(figsize=(7, 3.5))
ax.fill_between(times, measured[:, 0], measured[:, 1], color="C0", alpha=0.3,
                label="computed (last vertex in contact .. next)")
ax.plot(times, [hertz.lee_radok(t, 10.0, 1.0, 1000.0, 0.3, 0.2) for t in times], "k", label="Lee–Radok")
ax.plot(times, [hertz.cylinder(10.0 * t, 1.0, 1000.0, 0.3)[0] for t in times], "k--", lw=0.8,
        label="elastic Hertz (no lag)")
ax.set_xlabel("t [s]")
ax.set_ylabel("contact half-width a [m]")
ax.legend()

# %% [markdown]
# The pressure of the viscoelastic body at a few times: not Hertz's ellipse for the current a, since it remembers
# the smaller contacts of the past.

# %%
fig, ax = plt.subplots(figsize=(7, 3.5))
for t in (0.25, 0.5, 1.0):
    r = hertz.profile(ds, t)
    near = r["x"] < 0.15
    ax.plot(r["x"][near], r["p"][near], ".-", ms=3, lw=0.8, label=f"t = {t:g} s")
ax.set_xlabel("x [m]")
ax.set_ylabel("contact pressure [Pa]")
ax.legend()
