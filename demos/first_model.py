# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # A first model in a notebook
#
# Thermal convection with particles in a box, set up, run and looked at from Python — the same
# objects `python -m convection run` uses, without a YAML file. This script is a
# [jupytext](https://jupytext.readthedocs.io) "percent" script: run it as it is
# (`python demos/first_model.py`), or open it as a notebook
# (`jupytext --to notebook demos/first_model.py`, then `jupyter lab demos/first_model.ipynb`).
# `tests/docs/test_notebook.py` executes it as a notebook at a tiny size (`PIC_DEMO_SIZE=tiny`).
#
# The problem: Blankenbach et al.'s (1989) case 1a — a unit square heated from below, cooled from
# above, insulating sides, free slip everywhere, Ra = 1e4, constant viscosity. From a small
# perturbation of the conductive profile a single convection cell grows; at steady state the
# published Nusselt number is 4.884 and the root-mean-square velocity 42.865. Particles seeded in
# the lower half show how the cell stirs the box.

# %%
import logging
import os

import matplotlib.pyplot as plt
import numpy as np

from convection.config.loader import load_config
from convection.app.factory import build_model, run_config
from convection.io.pictures import import_pyvista, read_statistics

# The form compiler logs every build at INFO level on the root logger; show warnings only.
logging.getLogger().addFilter(lambda record: record.levelno >= logging.WARNING)

TINY = os.environ.get("PIC_DEMO_SIZE") == "tiny"
CELLS, END = (8, 0.06) if TINY else (24, 0.3)
OUT = os.environ.get("PIC_DEMO_OUTPUT", "output/first_model")

# %% [markdown]
# ## The configuration
#
# A config is a nested dictionary — exactly what a YAML file holds. `load_config` checks it against
# the schema (every key is in the [config reference](../config-reference.md)), fills in every
# default and raises a one-line `ConfigError` naming the key if something is wrong.

# %%
document = {
    "name": "first_model",
    "mesh": {"cells": [CELLS, CELLS]},
    "physics": {"Ra": 1.0e4},
    "boundary": {
        "velocity": {"left": "free_slip", "right": "free_slip", "bottom": "free_slip", "top": "free_slip"},
        "temperature": {"bottom": {"dirichlet": 1.0}, "top": {"dirichlet": 0.0}},
    },
    "initial": {"temperature": "1 - z + 0.01*cos(pi*x)*sin(pi*z)"},
    "particles": {
        "enabled": True,
        "generator": {"name": "random_density", "num_particles": 40 * CELLS * CELLS, "density": "z < 0.5", "seed": 1},
        "properties": ["initial_position", "integrated_strain"],
        "output": {"every_steps": 5},
    },
    "time": {"end": END, "cfl": 2.0},
    "output": {"directory": OUT, "fields_every": 5, "progress": "none"},
}
config = load_config(None, document=document)
print({key: config["stokes"][key] for key in ("degree", "solver")}, config["energy"]["stabilisation"])

# %% [markdown]
# ## Running it
#
# `run_config` builds the model (mesh, Stokes and temperature solvers, particles), runs the time
# loop with the postprocessors and writes the run folder: `statistics.csv`, `fields.xdmf`,
# `particles.xdmf`, `summary.json` (see [Outputs](../outputs.md)). Under `mpirun -n N` the same
# call runs in parallel.

# %%
summary = run_config(config)
print(f"{summary.steps} steps to t = {summary.time:.4f}: {summary.reason}")

# %% [markdown]
# ## The statistics
#
# One row per step; `read_statistics` gives numpy arrays by column. The Nusselt number comes from
# the consistent boundary flux at the top; vrms is the root-mean-square velocity.

# %%
stats = read_statistics(f"{OUT}/statistics.csv")
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.2))
ax1.plot(stats["time"], stats["vrms"])
ax1.axhline(42.864947, color="grey", ls="--", label="steady state (Blankenbach 1989)")
ax1.set_xlabel("t")
ax1.set_ylabel("vrms")
ax1.legend()
ax2.plot(stats["time"], stats["nusselt"])
ax2.axhline(4.884409, color="grey", ls="--")
ax2.set_xlabel("t")
ax2.set_ylabel("Nu (top)")
fig.tight_layout()
plt.show()
print(f"last step: vrms = {stats['vrms'][-1]:.3f}, Nu = {stats['nusselt'][-1]:.3f}")

# %% [markdown]
# ## The fields and the particles, as ParaView reads them
#
# `fields.xdmf` and `particles.xdmf` are XDMF time series; pyvista reads them with VTK's XDMF
# reader, the one ParaView uses. (`import_pyvista` loads VTK so that it renders in a process that
# has imported DOLFINx.) The static backend shows each picture as a PNG in the notebook.

# %%
pv = import_pyvista()
pv.OFF_SCREEN = True
try:
    pv.set_jupyter_backend("static")
except Exception:  # noqa: BLE001 - outside Jupyter (plain python): no backend to set
    pass

fields = pv.get_reader(f"{OUT}/fields.xdmf")
fields.set_active_time_value(fields.time_values[-1])
mesh = fields.read()
mesh = mesh.combine() if isinstance(mesh, pv.MultiBlock) else mesh
particles = pv.get_reader(f"{OUT}/particles.xdmf")
particles.set_active_time_value(particles.time_values[-1])
cloud = particles.read()
cloud = cloud.combine() if isinstance(cloud, pv.MultiBlock) else cloud
cloud.point_data["initial height"] = np.asarray(cloud.point_data["initial_position"])[:, 1]
print(f"t = {fields.time_values[-1]:.4f}: {mesh.n_cells} cells, {cloud.n_points} particles")
left = cloud.points[:, 0] < 0.5
print(f"highest particles: {np.percentile(cloud.points[left, 1], 99):.3f} at the left, "
      f"{np.percentile(cloud.points[~left, 1], 99):.3f} at the right")

plotter = pv.Plotter(shape=(1, 2), window_size=(1000, 460), off_screen=True)
plotter.subplot(0, 0)
plotter.add_mesh(mesh, scalars="temperature", cmap="coolwarm", show_edges=True, edge_color="grey")
plotter.add_text("temperature and mesh", font_size=10)
plotter.view_xy()
plotter.subplot(0, 1)
plotter.add_mesh(mesh.outline(), color="black")
plotter.add_mesh(cloud, scalars="initial height", point_size=4, render_points_as_spheres=True, cmap="viridis")
plotter.add_text("particles by their initial height", font_size=10)
plotter.view_xy()
plotter.show(screenshot=f"{OUT}/first_model.png")

# %% [markdown]
# The cell turns clockwise: the hot limb rises at the left wall (x = 0, where the initial
# perturbation `0.01 cos(pi x) sin(pi z)` is warmest) and the cold limb sinks at the right, so the
# particles, all started below z = 0.5, are lifted at the left first.
#
# ## Stepping a model yourself
#
# `run_config` is a loop around `Model.step`. `build_model` gives the model of a config without
# running it; a loop of your own can change anything between steps (see also
# [the Rayleigh–Taylor demo](rayleigh_taylor.md)).

# %%
from convection.postprocess.postprocessors import Velocity  # noqa: E402

model = build_model(config)
vrms = Velocity()
for _ in range(3):
    model.step(model.cfl_dt(2.0, dt_max=0.01))  # the first step has no velocity yet: dt_max bounds it
    print(f"t = {model.time:.5f}  vrms = {vrms(model)['vrms']:.4f}")
