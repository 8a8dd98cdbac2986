"""Phase transitions against their closed forms: a boundary deflected by temperature, the latent heat's temperature jump.

Usage::

    python -m benchmarks.phase_transitions.run [--case deflection latent_heat] [--ranks 2] [--quick]
                                               [--set KEY=VALUE ...] [--out DIR] [--results DIR]

``deflection`` (``configs/phase_deflection.yaml``, physical units): the 660 km transition, Clapeyron
slope -2.5 MPa/K, in a mantle at 1900 K + 200 K cos(pi x / 1000 km). The model is built (in this
process, on its ranks) and the depth where its output field ``phase_p660`` crosses 1/2 is found on
columns across the box, beside ``660 km + gamma (T - T0) / (rho g)`` from the physical constants
(3300 kg/m^3, 10 m/s^2): a deflection of 15.15 km at x = 0 and 1000 km.

``latent_heat`` (``configs/phase_latent_heat.yaml``, ASPECT's latent-heat cookbook set-up): mantle at
1600 K flows down a column at 5 cm/yr through an exothermic transition (+4 MPa/K, +5 %, Delta S =
gamma Delta rho / rho^2); run with the CLI to 40 Myr, then the temperature near the bottom against
``T exp(Delta S / c_p)`` (steady state, conduction-free closed form; docs/phase_transitions.md) and
its first-order form ``T (1 + Delta S / c_p)``.

Writes ``<results>/results.md`` (the table, errors relative to the deflection's amplitude and to the
temperature jump) and ``<results>/results.png`` (the phase field with the boundary measured and
predicted; the temperature profile). ``--quick`` uses the CI sizes (50 cells in depth, 30 Myr).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

from benchmarks.harness import OUTPUT, Benchmark, Case, cases, markdown_table
from convection import build_model, load_config
from convection.io.pictures import read_statistics
from convection.launch import run_config

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "phase_transitions", results=HERE, results_option=True, ranks=2,
                      quick="CI sizes: 50 cells in depth, 30 Myr", overrides=True,
                      no_run="tabulate the latent-heat run already in --out",
                      helps={"set": "a config override for every run (repeatable)"})
CASES = cases(Case("deflection", "phase_deflection.yaml"), Case("latent_heat", "phase_latent_heat.yaml"))

CLAPEYRON, DENSITY, GRAVITY = -2.5e6, 3300.0, 10.0
"""The deflection case's slope [Pa/K], rho [kg/m^3], g [m/s^2] (configs/phase_deflection.yaml)."""
ANOMALY, DEPTH, LENGTH = 200.0, 660.0, 1000.0
"""Its temperature anomaly's amplitude [K], the transition's depth and the box's size [km]."""
COLUMNS = (0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0)
"""The columns x / L where the deflection case measures the boundary's depth."""
SLOPE_LH, JUMP_LH, RHO_LH, CP_LH, T_LH = 4.0e6, 0.05, 3300.0, 1250.0, 1600.0
"""The latent-heat case's slope [Pa/K], density jump, rho, c_p [J/kg/K], inflow temperature [K]."""
PROFILE = tuple(range(0, 1001, 25))
"""Depths [km] of the latent-heat case's temperature profile (point probes at x = 25 km)."""


def predicted_depth(x: float) -> float:
    """The boundary's depth [km] at x / L (the closed form, from the physical constants)."""
    return DEPTH + CLAPEYRON * ANOMALY * math.cos(math.pi * x) / (DENSITY * GRAVITY) / 1e3


def crossing_depth(depth: np.ndarray, phase: np.ndarray) -> float:
    """Where ``phase`` (values at the depths ``depth`` of one column; a node may repeat) crosses 1/2: the
    root of the cubic through the two nodes on either side of the crossing."""
    d, index = np.unique(np.round(depth, 9), return_inverse=True)
    g = np.bincount(index, weights=phase) / np.bincount(index) - 0.5
    crossings = np.nonzero((g[:-1] < 0.0) & (g[1:] >= 0.0))[0]
    if not crossings.size:
        raise ValueError("the phase function does not cross 1/2 on this column")
    i = int(crossings[0])
    linear = float(d[i] - g[i] * (d[i + 1] - d[i]) / (g[i + 1] - g[i]))
    if i < 1 or i + 2 >= len(d):
        return linear
    roots = np.roots(np.polyfit(d[i - 1:i + 3] - linear, g[i - 1:i + 3], 3)) + linear
    inside = [r.real for r in roots if abs(r.imag) < 1e-9 and d[i] <= r.real <= d[i + 1]]
    return float(inside[0]) if inside else linear


def deflection(overrides: list[str], *, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """The deflection case: the measured and predicted boundary depths [km] by column (collective;
    the result on every rank), and the phase field's nodes (x, depth [km], Gamma) for the picture."""
    config = load_config(CASES["deflection"].path, [*overrides, "output.progress=none",
                                                    "output.directory=/tmp/phase_deflection_unused"])
    model = build_model(config, comm=comm)
    field = model.fields()["phase_p660"]
    space = field.function_space
    n = space.dofmap.index_map.size_local * space.dofmap.index_map_bs
    points = space.tabulate_dof_coordinates()[:n]
    values = field.x.array[:n].copy()
    model.destroy()
    gathered = comm.allgather((points[:, 0].copy(), points[:, 1].copy(), values))
    x = np.concatenate([g[0] for g in gathered])
    depth = (1.0 - np.concatenate([g[1] for g in gathered])) * LENGTH
    phase = np.concatenate([g[2] for g in gathered])
    rows = []
    for column in COLUMNS:
        on = np.abs(x - column) < 1e-9
        rows.append({"x": column * LENGTH, "measured": crossing_depth(depth[on], phase[on]),
                     "predicted": predicted_depth(column)})
    return {"rows": rows, "nodes": (x * LENGTH, depth, phase), "cells": config["mesh"]["cells"]}


def latent_heat_prediction() -> dict[str, float]:
    """The latent-heat case's closed forms: Delta S / c_p, the temperature below [K] (exact, and to first order)."""
    ratio = SLOPE_LH * JUMP_LH / (RHO_LH * CP_LH)  # Delta S / c_p, Delta S = gamma Delta rho / rho^2
    return {"ratio": ratio, "exact": T_LH * math.exp(ratio), "linear": T_LH * (1.0 + ratio)}


def latent_heat(out: Path, *, ranks: int, overrides: list[str], run: bool = True) -> dict:
    """Run the latent-heat case (the CLI, ``ranks`` ranks; ``run=False``: the run already in ``out``)
    and read its probes [K]."""
    probes = ", ".join(f"d{d:04d}: [25 km, {LENGTH - d:g} km]" for d in PROFILE)
    if run:
        run_config(CASES["latent_heat"].path, out, ranks=ranks, cwd=ROOT, overrides=[
            "output.progress=lines", "output.progress_every=100", "output.fields_every=0",
            f"diagnostics.points={{above: [25 km, 800 km], below: [25 km, 50 km], {probes}}}", *overrides])
    statistics = read_statistics(out / "statistics_physical.csv")
    return {"below": float(statistics["T_below [K]"][-1]), "above": float(statistics["T_above [K]"][-1]),
            "time": float(statistics["time [Myr]"][-1]), "steps": int(statistics["step"][-1]),
            "profile": [float(statistics[f"T_d{d:04d} [K]"][-1]) for d in PROFILE]}


def deflection_rows(result: dict) -> list[list[str]]:
    amplitude = abs(CLAPEYRON * ANOMALY / (DENSITY * GRAVITY) / 1e3)
    return [[f"{r['x']:.0f}", f"{r['measured']:.3f}", f"{r['predicted']:.3f}", f"{r['measured'] - DEPTH:+.3f}",
             f"{r['predicted'] - DEPTH:+.3f}", f"{abs(r['measured'] - r['predicted']) / amplitude:.3%}"]
            for r in result["rows"]]


def deflection_error(result: dict) -> float:
    """The largest error of the measured depth over the deflection's amplitude."""
    amplitude = abs(CLAPEYRON * ANOMALY / (DENSITY * GRAVITY) / 1e3)
    return max(abs(r["measured"] - r["predicted"]) for r in result["rows"]) / amplitude


def latent_heat_error(result: dict) -> float:
    """The measured temperature jump's error over the closed form's jump."""
    exact = latent_heat_prediction()["exact"]
    return abs(result["below"] - exact) / (exact - T_LH)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(cases=CASES, default_cases=list(CASES))
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    BENCHMARK.log_load("start")
    text = ["# Phase transitions against their closed forms", ""]
    deflected = heated = None
    if "deflection" in args.case:
        sized = ["mesh.cells=[8,50]"] if args.quick else []
        deflected = deflection([*sized, *args.set], comm=comm)
        text += [f"## Boundary deflection ({deflected['cells'][0]} x {deflected['cells'][1]} cells, P2 temperature)",
                 "", "Depth [km] where phase_p660 crosses 1/2; the error is over the amplitude "
                 f"|gamma| 200 K / (rho g) = {abs(CLAPEYRON * ANOMALY / (DENSITY * GRAVITY) / 1e3):.3f} km.", "",
                 *markdown_table(["x [km]", "measured", "predicted", "deflection measured", "deflection predicted",
                                  "error"], deflection_rows(deflected)),
                 "", f"Largest error: {deflection_error(deflected):.3%}.", ""]
    if "latent_heat" in args.case and comm.rank == 0:
        sized = ["mesh.cells=[2,50]", "time.end=30 Myr", "time.cfl=4"] if args.quick else []
        heated = latent_heat(args.out / "latent_heat", ranks=args.ranks, overrides=[*sized, *args.set],
                             run=not args.no_run)
        closed = latent_heat_prediction()
        text += ["## Latent heat (a column flowing down through an exothermic transition)", "",
                 *markdown_table(["Delta S / c_p", "T above [K]", "T below [K]", "closed form T exp(Delta S / c_p)",
                                  "first order T (1 + Delta S / c_p)", "error over the jump", "steps, time [Myr]"],
                                 [[f"{closed['ratio']:.5f}", f"{heated['above']:.3f}", f"{heated['below']:.3f}",
                                   f"{closed['exact']:.3f}", f"{closed['linear']:.3f}",
                                   f"{latent_heat_error(heated):.3%}", f"{heated['steps']}, {heated['time']:.1f}"]]),
                 ""]
    BENCHMARK.log_load("end")
    if comm.rank == 0:
        BENCHMARK.publish(args.results / "results.md", "\n".join(text))
        _plot(deflected, heated, args.results / "results.png")
        print(f"wrote {args.results / 'results.png'}")
    return 0


def _plot(deflected: dict | None, heated: dict | None, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    if deflected is not None:
        x, depth, phase = deflected["nodes"]
        near = np.abs(depth - DEPTH) < 60.0
        image = axes[0].tricontourf(x[near], depth[near], phase[near], levels=np.linspace(0, 1, 11), cmap="RdBu_r")
        fig.colorbar(image, ax=axes[0], label="phase_p660 (deep phase fraction)")
        xs = np.linspace(0.0, 1.0, 101)
        axes[0].plot(xs * LENGTH, [predicted_depth(c) for c in xs], "k-", label="660 km + gamma dT / (rho g)")
        axes[0].plot([r["x"] for r in deflected["rows"]], [r["measured"] for r in deflected["rows"]], "wo", mec="k",
                     label="measured (phase = 1/2)")
        axes[0].set_ylim(DEPTH + 50.0, DEPTH - 50.0)
        axes[0].set(xlabel="x [km]", ylabel="depth [km]", title="660 deflected by 1900 K + 200 K cos(pi x / L)")
        axes[0].legend(fontsize=7, loc="lower right")
    if heated is not None:
        closed = latent_heat_prediction()
        axes[1].plot(heated["profile"], PROFILE, "o-", color="tab:red", ms=3, label="computed")
        axes[1].axvline(closed["exact"], color="k", ls="--", label="T exp(Delta S / c_p)")
        axes[1].axvline(closed["linear"], color="0.5", ls=":", label="T (1 + Delta S / c_p)")
        axes[1].axhline(500.0, color="0.7", lw=0.6)
        axes[1].invert_yaxis()
        axes[1].set(xlabel="T [K]", ylabel="depth [km]", title="latent heat: downflow through 500 km")
        axes[1].legend(fontsize=7)
    fig.savefig(png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
