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
# # Tutorial: a swelling bilayer from Python
#
# This page is a script (`docs/tutorial.py`, jupytext's percent format) that the documentation build
# runs from top to bottom: every number below was computed when this page was built. Run it yourself
# with `.venv/bin/python docs/tutorial.py` from the checkout, or open it in Jupyter.
#
# The case is the paper's film-substrate bilayer: a thin stiff gel film bonded to a thicker, softer
# gel substrate that is held laterally. Fluid enters through the film's top surface; the film swells,
# is compressed by the lateral constraint, and wrinkles at a critical growth $g_c$ of the total
# thickness. Here it runs on a coarse mesh so that the page builds in well under a minute; the
# [model](model.md) page has the equations and [validation](validation.md) the converged answers.
#
# ## A config
#
# A config is a TOML file; every key has a default. {func}`app.api.load_config` reads one and applies
# overrides, checking every key against its allowed range (the
# [configuration reference](reference/generated/config.md) lists them all).

# %%
from pathlib import Path

import app as hb

REPO = Path(hb.__file__).resolve().parent.parent
cfg = hb.load_config(REPO / "configs" / "bilayer.toml", {
    "mesh.element_size": 0.016,        # coarse: 4x the paper's element size (0.004 mm)
    "mesh.film_layers": 2,             # element layers through the film (the paper's mesh: 8)
    "output.fields": False,            # no ParaView files for this page
})
print(cfg["geometry"])
print("film/substrate modulus ratio:", cfg["material"]["film"]["modulus_ratio"])

# %% [markdown]
# A value out of range stops before anything runs, with one line naming the key; the command line
# prints the same line and exits with code 2:

# %%
try:
    hb.load_config(REPO / "configs" / "bilayer.toml", {"mesh.film_layers": 0})
except hb.ConfigError as err:
    print(err)

# %% [markdown]
# ## A run
#
# {func}`app.api.run` does what `hydrobuckle run` does: it integrates the swelling in time, tests the
# stability of every converged state by the inertia of its Hessian, locates the onset, and then
# estimates the discretization error of $g_c$ with two coarser companion runs and computes the exact 1D
# reduction of the same bilayer beside it. Everything is written into the result directory.

# %%
result = hb.run(cfg, "results/tutorial")
print(result)
print(f"g_c = {result.g_c_um:.3f} um +- {result.g_c_error_um:.3f} um, N_c = {result.N_c:g}, "
      f"at t = {result.critical_time:.4f} s")

# %% [markdown]
# The exact 1D reduction solves the laterally uniform swelling in 1D and tests every Fourier mode: the
# same model, no 2D mesh. On this coarse mesh the 2D answer and the reduction must agree within the 2D
# error bar:

# %%
one_d = result.reduced
print(one_d)
difference = result.g_c_um - one_d.g_c_um
print(f"2D - 1D = {difference:+.3f} um, {abs(difference) / result.g_c_error_um:.2f} of the 2D error bar")

# %% [markdown]
# ## What the run wrote
#
# `result.files` lists the result directory; `result.summary` is `summary.json` and `result.history`
# the columns of `history.csv` (see [outputs](outputs.md)).

# %%
print(sorted(result.files))

# %%
import matplotlib.pyplot as plt

h = result.history
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(h["time"], 1e3 * h["growth_mm"], ".-", label="growth")
ax.axhline(result.g_c_um, color="C3", ls="--", label=f"$g_c$ = {result.g_c_um:.2f} um")
ax.set_xlabel("time [s]")
ax.set_ylabel("growth [um]")
ax.legend()
fig.tight_layout()

# %% [markdown]
# The buckling mode is the eigenvector of the Hessian at the onset (`mode.png`, and `mode.xdmf` for
# ParaView):

# %%
from IPython.display import Image

Image(filename=str(result.files["mode.png"]), width=600)

# %% [markdown]
# ## Next
#
# - The paper's own mesh: `bash scripts/demo.sh` (2 MPI ranks, about 1-2 minutes), or
#   `hb.run(hb.load_config("configs/bilayer.toml"), "results/bilayer")` under `mpirun -n 2`.
# - A parameter study: `hb.study("bilayer-modulus-ratio", "results/ratio", reduced=True)` computes the
#   paper's study by the exact 1D reduction in seconds ([studies](studies.md)).
# - Your own geometry from a gmsh file: [geometries](geometries.md).
