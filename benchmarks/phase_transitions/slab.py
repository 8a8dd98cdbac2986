"""A slab meets the 660: stagnating at a strongly negative Clapeyron slope, sinking through at a weak one.

Usage::

    python -m benchmarks.phase_transitions.slab [--ranks 2] [--quick] [--set KEY=VALUE ...] [--results DIR]

(under ``mpirun -n N`` for N ranks: the runs are in this process). ``configs/annulus_slab_660.yaml``:
a global annulus in physical units, a cold slab hanging 450 km deep from a 60 Myr old lithosphere,
the exothermic 410 (+3 MPa/K, +6 %) and the endothermic 660 (+9 %, 10 times more viscous below),
both with their latent heat. Two runs differ only in the 660's Clapeyron slope: -6 MPa/K and
-1 MPa/K. Every ``--every`` Myr each run measures, from its temperature field:

- ``tip``: the depth [km] of the deepest temperature node colder than the mantle by 300 K (the
  slab's tip; the lithosphere is shallower);
- ``below``: the slab's cold core ``int max(T_m - 300 K - T, 0) dA`` deeper than 760 km (100 km below
  the 660) over the initial slab's (deeper than 150 km, below the lithosphere), ``T_m = 1573 K`` the
  mantle's temperature. The 300 K leave out the mantle the 660's latent heat cools as it goes down
  (``T Delta S / c_p``, 200 K at -6 MPa/K); a sunk core that warms by diffusion leaves it too.

Writes ``<results>/slab.md`` (the two runs side by side) and ``<results>/slab.png`` (the temperature
of both runs at the end, and ``tip`` and ``below`` against time). ``--quick``: the CI size (a 200 km
mesh to 40 Myr; ``tests/configs/test_annulus_slab_660.py``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx.fem

from benchmarks.harness import markdown_table
from convection import build_model, load_config

HERE = Path(__file__).resolve().parent
CONFIG = HERE.parents[1] / "configs" / "annulus_slab_660.yaml"
SLOPES = {"stagnating": "-6 MPa/K", "penetrating": "-1 MPa/K"}
"""The 660's Clapeyron slope of each run."""
LENGTH, T_REF, T_SCALE, T_MANTLE, R_OUTER = 2890.0, 273.0, 1300.0, 1573.0, 6371.0
"""The config's scaling (km, K) and its mantle temperature [K] and outer radius [km]."""
COLD, BELOW, LITHOSPHERE = 300.0, 760.0, 150.0
"""The slab core's temperature deficit [K] (tip and core); the depth [km] below which the core is
counted; the depth [km] below which it is the slab's, not the lithosphere's (at t = 0)."""
QUICK = ["mesh.resolution=200 km", "time.end=40 Myr"]


def measures(model, initial: float | None = None) -> dict[str, float]:
    """``tip`` [km], ``below`` (a share of ``initial``: by default the slab's anomaly now) and ``slab``
    (the slab's anomaly, nondimensional) of the model's temperature (collective; module docstring)."""
    T = model.T
    mesh = T.function_space.mesh
    x = ufl.SpatialCoordinate(mesh)
    depth = (R_OUTER / LENGTH - ufl.sqrt(ufl.dot(x, x))) * LENGTH
    cold = ufl.max_value((T_MANTLE - COLD - T_REF) / T_SCALE - T, 0.0)
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 6})
    forms = [ufl.conditional(ufl.gt(depth, floor), cold, 0.0) * dx for floor in (LITHOSPHERE, BELOW)]
    total, deep = (mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(f)), op=MPI.SUM) for f in forms)
    space = T.function_space
    n = space.dofmap.index_map.size_local
    points = space.tabulate_dof_coordinates()[:n]
    node_depth = R_OUTER - np.hypot(points[:, 0], points[:, 1]) * LENGTH
    colder = T.x.array[:n] * T_SCALE + T_REF < T_MANTLE - COLD
    tip = mesh.comm.allreduce(float(node_depth[colder].max()) if colder.any() else 0.0, op=MPI.MAX)
    return {"tip": tip, "below": deep / (total if initial is None else initial), "slab": total}


def temperature_nodes(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x [km], y [km], T [K]) at the temperature's nodes, gathered on every rank (collective)."""
    space = model.T.function_space
    n = space.dofmap.index_map.size_local
    points = space.tabulate_dof_coordinates()[:n] * LENGTH
    mine = (points[:, 0].copy(), points[:, 1].copy(), model.T.x.array[:n] * T_SCALE + T_REF)
    gathered = model.comm.allgather(mine)
    return tuple(np.concatenate([g[k] for g in gathered]) for k in range(3))  # type: ignore[return-value]


def slab_run(slope: str, overrides: list[str], *, every: float, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """Run the config with the 660's Clapeyron slope ``slope`` (in this process, collective) and measure
    every ``every`` Myr: ``{"rows": [(time [Myr], tip, below), ...], "nodes": ..., "steps": n}``."""
    config = load_config(CONFIG, [*overrides, f"phase_transitions.p660.clapeyron={slope}", "output.progress=none",
                                  "output.directory=/tmp/annulus_slab_660_unused"])
    myr = float(load_config(CONFIG, ["time.end=1 Myr"])["time"]["end"])
    end, cfl = float(config["time"]["end"]), float(config["time"]["cfl"])
    model = build_model(config, comm=comm)
    model.start()
    start = measures(model)
    rows = [(0.0, start["tip"], start["below"])]
    while model.time < end * (1.0 - 1e-12):
        target = min(end, (len(rows)) * every * myr)
        model.step(min(model.cfl_dt(cfl), target - model.time))
        if model.time >= target * (1.0 - 1e-12):
            now = measures(model, start["slab"])
            rows.append((model.time / myr, now["tip"], now["below"]))
    result = {"rows": rows, "nodes": temperature_nodes(model), "steps": model.timestep,
              "cells": model.num_cells}
    model.destroy()
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the CI size: " + ", ".join(QUICK))
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a config override")
    parser.add_argument("--every", type=float, default=10.0, help="Myr between measures")
    parser.add_argument("--results", type=Path, default=HERE, help="where slab.md and slab.png go")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    overrides = [*(QUICK if args.quick else []), *args.set]
    runs = {name: slab_run(slope, overrides, every=args.every, comm=comm) for name, slope in SLOPES.items()}
    if comm.rank == 0:
        first = next(iter(runs.values()))
        header = ["time [Myr]", *(f"{k} {name} ({SLOPES[name]})" for name in runs for k in ("tip [km]", "below"))]
        table = [[f"{row[0]:.0f}", *(v for r in runs.values() for v in (f"{r['rows'][i][1]:.0f}",
                                                                        f"{r['rows'][i][2]:.3f}"))]
                 for i, row in enumerate(first["rows"])]
        text = ["# A slab at the 660", "",
                f"configs/annulus_slab_660.yaml, {first['cells']} cells, {comm.size} rank(s); overrides "
                f"{overrides or 'none'}; steps: " + ", ".join(f"{n} {r['steps']}" for n, r in runs.items()) + ".",
                f"tip: the deepest node {COLD:.0f} K colder than the mantle; below: the cold core "
                f"int max(T_m - {COLD:.0f} K - T, 0) dA deeper than {BELOW:.0f} km over the initial slab's "
                f"(deeper than {LITHOSPHERE:.0f} km).", "", *markdown_table(header, table), ""]
        (args.results / "slab.md").write_text("\n".join(text))
        print("\n".join(text))
        _plot(runs, args.results / "slab.png")
        print(f"wrote {args.results / 'slab.md'} and {args.results / 'slab.png'}")
    return 0


def _plot(runs: dict[str, dict], png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri

    fig = plt.figure(figsize=(12, 4.6), constrained_layout=True)
    grid = fig.add_gridspec(2, 3)
    for k, (name, run) in enumerate(runs.items()):
        ax = fig.add_subplot(grid[:, k])
        x, y, T = run["nodes"]
        triangles = mtri.Triangulation(x, y)
        cx, cy = x[triangles.triangles].mean(axis=1), y[triangles.triangles].mean(axis=1)
        triangles.set_mask(np.hypot(cx, cy) < 3480.0 + 1.0)
        image = ax.tricontourf(triangles, T, levels=np.linspace(273.0, 1800.0, 18), cmap="RdBu_r")
        phi = np.linspace(0.0, np.pi, 200)
        for depth in (410.0, 660.0):
            ax.plot((R_OUTER - depth) * np.cos(phi), (R_OUTER - depth) * np.sin(phi), "k:", lw=0.6)
        ax.set(xlim=(-2200, 2200), ylim=(4200, 6500), aspect="equal", xlabel="x [km]",
               title=f"{name}: 660 at {SLOPES[name]}, {run['rows'][-1][0]:.0f} Myr")
        ax.set_ylabel("y [km]")
    fig.colorbar(image, ax=fig.axes, label="T [K]", shrink=0.8, location="left")
    labels = (("tip", "slab tip depth [km]"), ("below", f"slab core below {BELOW:.0f} km / initial"))
    for k, (key, label) in enumerate(labels):
        ax = fig.add_subplot(grid[k, 2])
        for name, run in runs.items():
            rows = np.array(run["rows"])
            ax.plot(rows[:, 0], rows[:, 1 + k], "o-", ms=3, label=f"{SLOPES[name]}")
        if key == "tip":
            ax.axhline(660.0, color="0.6", lw=0.6)
            ax.invert_yaxis()
        ax.set(xlabel="time [Myr]", ylabel=label)
        ax.legend(fontsize=7)
    fig.savefig(png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
