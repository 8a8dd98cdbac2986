"""Christensen & Yuen (1985) layering: an endothermic transition at mid-depth, whole-mantle or layered convection.

Usage::

    python -m benchmarks.phase_transitions.layering [--case whole layered] [--quick] [--set KEY=VALUE ...]
                                                    [--out DIR] [--results DIR] [--no-run]

``configs/phase_layering.yaml``: isoviscous Boussinesq convection in a unit square at Ra = 1e5 (free
slip, T = 1 below and 0 above), an endothermic phase transition at depth 1/2 at T0 = 1/2, 0.05 wide,
whose deep phase is denser by Rb = 2 Ra (C&Y's Boussinesq series; ASPECT's cookbook
``christensen_yuen_phase_function``), no latent heat. The phase buoyancy parameter is
``P = Rb gamma / Ra`` (``gamma`` the nondimensional Clapeyron slope ``phase_transitions.mid.clapeyron``,
docs/phase_transitions.md), so ``gamma = P / 2``. Two cases: ``whole`` (P = -0.1) and ``layered``
(P = -0.6), on either side of the published boundary (README).

Each case runs in this process (``run_config`` with a model kept for the end) until the steady-state
test stops it or to t = 0.25. The regime (README, "Layering"):

- the criterion, ``dT_mid = <T>(z = 0.3) - <T>(z = 0.7)`` (horizontal means, ``z`` the height): 0 for one
  well-mixed interior, 1/2 for two separate layers with isothermal interiors (3/4 below, 1/4 above);
  from points probed every step, averaged over the last fifth of the run's time. Layered:
  ``dT_mid > 1/4``.
- the mass flux through mid-depth, ``<|w|>(z = 1/2)`` (twice the upward flux per unit width), also
  over vrms and over the whole-mantle case's; and ``E = min over 0.3 <= z <= 0.7 of <|w|>(z) / vrms``
  at the end. Flow crosses the endothermic boundary in the layered regime too (a narrow sheet where
  the layers' cells meet, at a fraction of the whole-mantle case's flux): these measure how much.

Writes ``<results>/layering.md`` (the table) and ``<results>/layering.png`` (each case's final
temperature with the transition's Gamma = 1/2, the profiles of <T> and <|w|> / vrms), and per case
``<out>/<case>/layering.json`` (read back by ``--no-run``). ``--quick`` uses the CI size (24 x 24 cells,
to t = 0.03).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

from benchmarks.harness import OUTPUT, Benchmark, Case, cases, markdown_table
from convection import build_model, load_config, run_config
from convection.io.pictures import read_statistics
from fembase.dolfinx_compat import value_size
from fembase.geometry import locate_owned

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "phase_transitions", results=HERE, results_option=True,
                      quick="CI size: 24 x 24 cells, to t = 0.03", overrides=True,
                      no_run="tabulate the runs already in --out",
                      helps={"set": "a config override for every run (repeatable)"})
CASES = cases(Case("whole", "phase_layering.yaml", ("phase_transitions.mid.clapeyron=-0.05",)),
              Case("layered", "phase_layering.yaml"),
              *(Case(f"P{p:.1f}", "phase_layering.yaml", (f"phase_transitions.mid.clapeyron={p / 2:g}",))
                for p in (-0.2, -0.3, -0.4)))
"""``whole`` (P = -0.1) and ``layered`` (P = -0.6), the two sides; ``P-0.2`` .. ``P-0.4`` (not run by default)
between them, where the published boundary lies."""
QUICK = ("mesh.cells=[24,24]", "time.end=0.03")
"""The CI size's overrides."""
PROBES = (0.3, 0.5, 0.7)
"""Heights of the probed lines (33 points each, every step)."""
NX = 33
"""Points per probed line."""
BAND = (0.3, 0.7)
"""Heights over which E takes its minimum."""
GRID = 65
"""Points per side of the final state's sample grid."""
LAYERED_JUMP = 0.25
"""dT_mid above which a run is layered (half the jump of two separate layers)."""
AVERAGE = 0.2
"""The last fraction of the run's time over which the probes are averaged."""


def probe_points() -> str:
    """The ``diagnostics.points`` override: lines ``l<k>_<i>`` at the heights :data:`PROBES`."""
    return "{" + ", ".join(f"l{k}_{i:02d}: [{i / (NX - 1):g}, {z:g}]" for k, z in enumerate(PROBES)
                           for i in range(NX)) + "}"


def phase_parameter(config: dict) -> float:
    """``P = Rb gamma / Ra`` of a resolved config."""
    transition = config["phase_transitions"]["mid"]
    return float(transition["Rb"]) * float(transition["clapeyron"]) / float(config["physics"]["Ra"])


def _mean(values: np.ndarray, axis: int = 0) -> np.ndarray:
    """The trapezoidal mean over equally spaced points spanning [0, 1] along ``axis``."""
    v = np.moveaxis(np.asarray(values), axis, 0)
    return (v[1:] + v[:-1]).sum(axis=0) / (2.0 * (v.shape[0] - 1))


def sample(model, functions: dict, points: np.ndarray) -> dict[str, np.ndarray]:
    """``functions`` (name -> Function) at ``points`` (n, 2), each point evaluated by the lowest rank
    owning a cell that holds it (collective; the values on every rank)."""
    comm = model.comm
    cells = locate_owned(model.mesh, points).cells
    owner = np.where(cells >= 0, comm.rank, comm.size)
    lowest = np.empty_like(owner)
    comm.Allreduce(owner, lowest, op=MPI.MIN)
    mine = np.flatnonzero(lowest == comm.rank)
    x = np.zeros((len(mine), 3))
    x[:, :2] = points[mine]
    out = {}
    for name, f in functions.items():
        size = value_size(f.function_space)
        local = np.zeros((len(points), size))
        if len(mine):
            local[mine] = np.asarray(f.eval(x, cells[mine])).reshape(len(mine), -1)[:, :size]
        total = np.zeros_like(local)
        comm.Allreduce(local, total, op=MPI.SUM)
        out[name] = total
    return out


def final_state(model) -> dict:
    """The final state on a GRID x GRID grid: T, w, Gamma; the profiles <T>(z), <|w|>(z) / vrms; E."""
    z = np.linspace(0.0, 1.0, GRID)
    X, Z = np.meshgrid(z, z)
    points = np.column_stack([X.ravel(), Z.ravel()])
    fields = model.fields()
    values = sample(model, {"T": fields["temperature"], "u": fields["velocity"], "phase": fields["phase_mid"]}, points)
    T = values["T"][:, 0].reshape(GRID, GRID)
    u = values["u"][:, 0].reshape(GRID, GRID)
    w = values["u"][:, 1].reshape(GRID, GRID)
    phase = values["phase"][:, 0].reshape(GRID, GRID)
    speed = np.sqrt((values["u"][:, :2] ** 2).sum(axis=1)).reshape(GRID, GRID)
    vrms = float(np.sqrt(_mean(_mean(speed ** 2, axis=1))))
    crossing = _mean(np.abs(w), axis=1) / vrms
    band = (z >= BAND[0] - 1e-12) & (z <= BAND[1] + 1e-12)
    return {"z": z.tolist(), "T": T.tolist(), "u": u.tolist(), "w": w.tolist(), "phase": phase.tolist(),
            "T_profile": _mean(T, axis=1).tolist(),
            "crossing": crossing.tolist(), "E": float(crossing[band].min()), "vrms_grid": vrms}


def probe_series(statistics: dict) -> dict:
    """From the probes: dT_mid and <|w|>(z = 1/2) / vrms over time, their means over the last AVERAGE of the time."""
    t = statistics["time"]
    lines = [np.array([statistics[f"T_l{k}_{i:02d}"] for i in range(NX)]) for k in range(len(PROBES))]
    jump = _mean(lines[0]) - _mean(lines[2])
    w = np.array([statistics[f"vy_l1_{i:02d}"] for i in range(NX)])
    mid = _mean(np.abs(w)) / np.maximum(statistics["vrms"], 1e-300)
    late = t >= (1.0 - AVERAGE) * t[-1]
    return {"time": t.tolist(), "jump": jump.tolist(), "mid": mid.tolist(),
            "jump_mean": float(jump[late].mean()), "jump_std": float(jump[late].std()),
            "mid_mean": float(mid[late].mean()), "flux": float(_mean(np.abs(w))[late].mean()), "vrms": float(statistics["vrms"][late].mean()),
            "nusselt": float(statistics["nusselt"][late].mean()), "steps": int(statistics["step"][-1]),
            "end_time": float(t[-1])}


def run_case(case: Case, out: Path, overrides: list[str], *, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """Run ``case`` in this process (collective) and measure it; the result (also written to
    ``<out>/<case>/layering.json`` by rank 0)."""
    folder = out / case.name
    config = load_config(case.path, [*case.overrides, *overrides, f"diagnostics.points={probe_points()}",
                                     "output.statistics=[time,velocity,nusselt,temperature,points,wall_time]",
                                     "output.progress=lines", "output.progress_every=200", "output.fields_every=0",
                                     f"output.directory={folder}"])
    model = build_model(config, comm=comm)
    summary = run_config(config, comm=comm, model=model)
    result = {"case": case.name, "P": phase_parameter(config), "Ra": float(config["physics"]["Ra"]),
              "cells": list(config["mesh"]["cells"]), "reason": summary.reason, **final_state(model)}
    model.destroy()
    if comm.rank == 0:
        result.update(probe_series(read_statistics(folder / "statistics.csv")))
        (folder / "layering.json").write_text(json.dumps(result))
    return comm.bcast(result if comm.rank == 0 else None, root=0)


def regime(result: dict) -> str:
    """``layered`` or ``whole mantle`` by the temperature jump (module docstring)."""
    return "layered" if result["jump_mean"] > LAYERED_JUMP else "whole mantle"


def table(results: list[dict]) -> list[str]:
    whole = next((r["flux"] for r in results if r["case"] == "whole"), None)
    rows = [[r["case"], f"{r['P']:+.2f}", f"{r['Ra']:.0e}", f"{r['cells'][0]} x {r['cells'][1]}",
             f"{r['steps']}, {r['end_time']:.3f}", f"{r['nusselt']:.3f}", f"{r['vrms']:.2f}",
             f"{r['jump_mean']:.3f} +- {r['jump_std']:.3f}", f"{r['flux']:.2f}", f"{r['mid_mean']:.3f}",
             f"{r['flux'] / whole:.3f}" if whole else "", f"{r['E']:.3f}", regime(r)] for r in results]
    flux = "<\\|w\\|>(1/2)"  # escaped: a bar would end the table's cell
    return markdown_table(["case", "P", "Ra", "cells", "steps, time", "Nu", "vrms", "dT_mid", flux, f"{flux} / vrms",
                           f"{flux} / whole's", "E", "regime"], rows)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(cases=CASES, default_cases=["whole", "layered"])
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    BENCHMARK.log_load("start")
    overrides = [*(QUICK if args.quick else ()), *args.set]
    results = []
    for name in args.case:
        if args.no_run:
            results.append(json.loads((args.out / name / "layering.json").read_text()))
        else:
            results.append(run_case(CASES[name], args.out, overrides, comm=comm))
    BENCHMARK.log_load("end")
    if comm.rank == 0:
        text = ["# Christensen & Yuen (1985) layering", "",
                "Isoviscous Boussinesq convection, unit square, endothermic transition at mid-depth, Rb = 2 Ra, "
                "no latent heat. dT_mid = <T>(z=0.3) - <T>(z=0.7) and <|w|>(1/2) / vrms averaged over the last "
                f"{AVERAGE:.0%} of the run's time; E = min over {BAND[0]} <= z <= {BAND[1]} of <|w|>(z) / vrms "
                f"at the end; layered when dT_mid > {LAYERED_JUMP}.", "", *table(results), ""]
        BENCHMARK.publish(args.results / "layering.md", "\n".join(text))
        _plot(results, args.results / "layering.png")
        print(f"wrote {args.results / 'layering.png'}")
    return 0


def _plot(results: list[dict], png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    fig = plt.figure(figsize=(max(3.2 * n, 8.0), 7.0), constrained_layout=True)
    top, bottom = fig.subfigures(2, 1, height_ratios=[1.0, 1.0])
    fields = np.atleast_1d(top.subplots(1, n))
    for ax, r in zip(fields, results):
        z = np.asarray(r["z"])
        image = ax.contourf(z, z, np.asarray(r["T"]), levels=np.linspace(0.0, 1.0, 21), cmap="coolwarm")
        ax.streamplot(z, z, np.asarray(r["u"]), np.asarray(r["w"]), color="0.25", density=0.7, linewidth=0.5, minlength=0.3,
                      arrowsize=0.5)
        ax.contour(z, z, np.asarray(r["phase"]), levels=[0.5], colors="k", linewidths=1.5)
        ax.set(xlabel="x", ylabel="z", title=f"P = {r['P']:+.2f}: {regime(r)}", xlim=(0, 1), ylim=(0, 1))
    top.colorbar(image, ax=list(fields), label="T (black: Gamma = 1/2)", shrink=0.8)
    profile_T, profile_w = bottom.subplots(1, 2)
    for r in results:
        z = np.asarray(r["z"])
        profile_T.plot(r["T_profile"], z, label=f"P = {r['P']:+.2f}: dT_mid = {r['jump_mean']:.3f}")
        profile_w.plot(r["crossing"], z, label=f"P = {r['P']:+.2f}")
    for ax in (profile_T, profile_w):
        ax.axhline(0.5, color="0.7", lw=0.6)
        ax.legend(fontsize=7)
    profile_T.plot([0.75, 0.25], [0.3, 0.7], "k+", ms=10, label="two separate layers")
    profile_T.set(xlabel="<T>(z)", ylabel="z", title="horizontal mean temperature (+: two ideal layers)")
    profile_w.set(xlabel="<|w|>(z) / vrms", ylabel="z", title="mean vertical speed over vrms")
    fig.savefig(png, dpi=90)
    plt.close(fig)
    from PIL import Image  # a 256-colour PNG: a quarter of the size, the same picture

    Image.open(png).convert("RGB").quantize(colors=256).save(png, optimize=True)


if __name__ == "__main__":
    sys.exit(main())
