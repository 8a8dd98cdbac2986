"""Crameri et al. (2012), case 1 with sticky air: the relaxation of a 7 km cosine topography, from
``configs/crameri_case1.yaml`` (physical units).

The surface under the air is measured along vertical lines (:class:`Topography`: h(x) = z_top -
int C_air dz); its cosine mode of the box's width,

    A(t) = (2 / N) sum_j (h(x_j) - mean h) cos(2 pi x_j / 2800 km),

is what the semi-analytical solution describes: A(t) = 7 km exp(-t / tau), rate 1 / tau =
2.139e-12 1/s (tau = 14.8 kyr; the value G-ADOPT's tests/multi_material use for this case). The
particle fractions of the cells along the surface are noisy (a few particles per cell decide a
cell's air fraction), which the largest height picks up but the mode averages out. The rate is the
least-squares slope of ln A over t <= ``--fit`` kyr.

Usage::

    python -m benchmarks.crameri.run [--cells 224x64 448x128] [--air 1e19 1e18 1e17] [--dt 0.25]
                                     [--fit 30] [--mixing geometric] [--out DIR]
    python -m benchmarks.crameri.run --collect DIR [DIR ...]      # the tables of earlier runs, together

Writes ``<out>/results.md`` (fitted rate against the published one per resolution and air
viscosity, with the cost) and ``<out>/results.png`` (A(t) against the analytical curve).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from mpi4py import MPI

from benchmarks.harness import Benchmark
from convection import load_config, run_config
from convection.postprocess import POSTPROCESSORS
from convection.postprocess.base import DiagnosticsSettings, PostprocessorContext
from convection.postprocess.geodynamics import Topography

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=HERE)

RATE = 2.139e-12
"""Crameri et al.'s relaxation rate [1/s]."""
AMPLITUDE = 7.0
"""Initial amplitude [km]."""
KYR = 1e3 * 365.25 * 86400.0


class CosineTopography(Topography):
    """The amplitude of the box-width cosine mode of the surface under the air (module docstring)."""

    name: ClassVar[str] = "cosine_topography"
    description: ClassVar[str] = "amplitude of the cosine mode of the box's width of the surface under the air"
    columns = ("topography_cos1",)
    quantities: ClassVar[dict[str, str]] = {"topography_cos1": "length"}

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> CosineTopography | None:
        names = [f.name for f in context.model.fractions]
        return cls(names.index(settings.topography_material)) if settings.topography_material in names else None

    def __call__(self, model: Any, /) -> dict[str, float]:
        h = self.heights(model)
        x = (np.arange(len(h)) + 0.5) / len(h)  # the lines' positions across the box, as fractions of its width
        return {"topography_cos1": float(2.0 * np.mean((h - h.mean()) * np.cos(2.0 * np.pi * x)))}


def register() -> None:
    """Register :class:`CosineTopography` (once; the runs of this script name it in output.statistics)."""
    if "cosine_topography" not in POSTPROCESSORS:
        POSTPROCESSORS.register(CosineTopography)


def run(cells: tuple[int, int], air: float, dt: float, end: float, out: Path, *, cfl: float = 1.0,
        theta: float = 0.0, mixing: str = "geometric") -> dict[str, Any]:
    """One run (``dt`` [kyr] caps the CFL step ``cfl``; 0: no cap; ``theta``: stokes.buoyancy_theta);
    its statistics in physical units and the wall time (collective)."""
    register()
    config = load_config(ROOT / "configs" / "crameri_case1.yaml", [
        f"mesh.cells=[{cells[0]},{cells[1]}]", f"materials.air.viscosity={air:.6e} Pa s",
        f"time.dt_max={dt} kyr" if dt > 0 else "time.dt_max=null", f"time.cfl={cfl}", f"stokes.buoyancy_theta={theta}",
        f"physics.viscosity.mixing={mixing}",
        f"time.end={end} kyr", "output.fields_every=0", "output.progress=none", f"output.directory={out}",
        "output.statistics=[time, velocity, topography, cosine_topography, mesh, stokes, particles, wall_time]"])
    start = time.perf_counter()
    run_config(config)
    wall = time.perf_counter() - start
    with open(out / "statistics_physical.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["time [kyr]"]) for r in rows])
    amplitude = np.array([float(r["topography_cos1 [km]"]) for r in rows])
    return {"cells": cells, "air": air, "t": t, "A": amplitude, "wall": wall, "steps": len(rows) - 1,
            "max": np.array([float(r["topography_max [km]"]) for r in rows])}


def criterion(air: float) -> float:
    """Crameri et al.'s C = 3/(16 pi^3) (L / h_air)^3 eta_air / eta_mantle of this setup."""
    return 3.0 / (16.0 * np.pi**3) * (2800.0 / 100.0) ** 3 * air / 1e21


def _read(path: Path) -> list[dict[str, Any]]:
    """The runs a results.json holds (arrays as numpy arrays)."""
    runs = json.loads(path.read_text())
    return [{k: np.asarray(v) if isinstance(v, list) and k != "cells" else v for k, v in r.items()} for r in runs]


def fitted_rate(t: np.ndarray, amplitude: np.ndarray, fit: float) -> float:
    """Least-squares slope of -ln A over t <= fit [1/s]."""
    keep = (t <= fit) & (amplitude > 0)
    slope = np.polyfit(t[keep], np.log(amplitude[keep]), 1)[0]
    return -slope / KYR


def write(out: Path, results: list[dict[str, Any]], fit: float, dt: float) -> None:
    lines = ["# Crameri et al. (2012) case 1 with sticky air", "",
             "Generated by `benchmarks/crameri/run.py` from `configs/crameri_case1.yaml` (100 km of sticky air, density 0;",
             f"particles, 16 per cell, cell averages; time step {dt} kyr). A: the amplitude of the surface's box-width cosine",
             f"mode; the rate is the slope of -ln A over t <= {fit:g} kyr, against Crameri et al.'s 2.139e-12 1/s.", "",
             "C = 3/(16 pi^3) (L/h_air)^3 eta_air/eta_mantle is Crameri et al.'s criterion (L = 2800 km, h_air = 100 km):",
             "sticky air stands in for a free surface when C << 1.", "",
             "| cells | cell size | air viscosity [Pa s] | C | fitted rate [1/s] | error | A(0) [km] | steps | wall [s] |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        rate = fitted_rate(r["t"], r["A"], fit)
        lines.append(f"| {r['cells'][0]} x {r['cells'][1]} | {2800 / r['cells'][0]:g} km | {r['air']:.0e} | "
                     f"{criterion(r['air']):.3g} | {rate:.4e} | "
                     f"{100 * (rate - RATE) / RATE:+.2f} % | {r['A'][0]:.3f} | {r['steps']} | {r['wall']:.0f} |")
    (out / "results.md").write_text("\n".join(lines) + "\n")
    (out / "results.json").write_text(json.dumps([{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                                   for k, v in r.items()} for r in results], indent=1))
    _picture(out / "results.png", results)


def _picture(path: Path, results: list[dict[str, Any]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    end = max(r["t"][-1] for r in results)
    t = np.linspace(0.0, end, 200)
    ax.plot(t, AMPLITUDE * np.exp(-RATE * t * KYR), "k-", linewidth=2, label="semi-analytical (Crameri et al. 2012)")
    for r in results:
        ax.plot(r["t"], r["A"], "--", linewidth=1,
                label=f"{r['cells'][0]}x{r['cells'][1]}, air {r['air']:.0e} Pa s")
    ax.set_xlabel("time [kyr]")
    ax.set_ylabel("cosine amplitude of the surface [km]")
    ax.set_title("Crameri case 1: relaxation under sticky air")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)


def theta_study(args: argparse.Namespace, out: Path) -> int:
    """The fitted rate at CFL 0.1, 0.5 and 1 with the explicit buoyancy (theta 0) and the predicted
    one (theta 0.5 and 1; convection.physics.buoyancy), the steps limited by the CFL number alone."""
    cells = tuple(int(c) for c in args.cells[0].split("x"))
    lines = ["# Sticky air and the time step: stokes.buoyancy_theta", "",
             f"Generated by `benchmarks/crameri/run.py --theta-study` ({cells[0]} x {cells[1]} cells, air "
             f"{args.air[0]:.0e} Pa s, {args.mixing} mixing, no step cap: dt = CFL h / max|u|). The rate is fitted over "
             f"t <= {args.fit:g} kyr; published 2.139e-12 1/s.", "",
             "| CFL | buoyancy_theta | steps | mean dt [kyr] | fitted rate [1/s] | error | A at the end [km] |",
             "|---|---|---|---|---|---|---|"]
    for cfl in (0.1, 0.5, 1.0):
        for theta in (0.0, 0.5, 1.0):
            folder = out / "runs" / f"theta_cfl{cfl}_theta{theta}"
            r = run(cells, args.air[0], 0.0, args.fit, folder, cfl=cfl, theta=theta, mixing=args.mixing)
            if MPI.COMM_WORLD.rank == 0:
                rate = fitted_rate(r["t"], r["A"], args.fit) if r["steps"] > 1 and np.all(r["A"] > 0) else np.nan
                lines.append(f"| {cfl:g} | {theta:g} | {r['steps']} | {r['t'][-1] / max(r['steps'], 1):.3g} | "
                             f"{rate:.4e} | {100 * (rate - RATE) / RATE:+.1f} % | {r['A'][-1]:.3f} |")
                print(lines[-1], flush=True)
    if MPI.COMM_WORLD.rank == 0:
        (out / "theta.md").write_text("\n".join(lines) + "\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", nargs="+", default=["224x64", "448x128"])
    parser.add_argument("--air", type=float, nargs="+", default=[1e19, 1e18, 1e17])
    parser.add_argument("--dt", type=float, default=0.25, help="time step [kyr]")
    parser.add_argument("--fit", type=float, default=30.0, help="fit the rate over t <= this [kyr]")
    parser.add_argument("--mixing", default="geometric", help="physics.viscosity.mixing")
    parser.add_argument("--theta-study", action="store_true",
                        help="instead: the first --cells and --air at CFL 0.1, 0.5, 1 (no step cap) with "
                             "stokes.buoyancy_theta 0, 0.5 and 1; writes theta.md")
    parser.add_argument("--collect", nargs="+", metavar="DIR",
                        help="no runs: write the results of earlier --out folders (their results.json) together")
    args = parser.parse_args(argv)
    out = args.out
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        BENCHMARK.log_load("start")
    if args.collect:
        collected = [r for folder in args.collect for r in _read(Path(folder) / "results.json")]
        if comm.rank == 0:
            out.mkdir(parents=True, exist_ok=True)
            write(out, sorted(collected, key=lambda r: (r["cells"][0], -r["air"])), args.fit, args.dt)
        return 0
    if args.theta_study:
        return theta_study(args, out)
    results = []
    for text in args.cells:
        cells = tuple(int(c) for c in text.split("x"))
        for air in args.air:
            folder = out / "runs" / f"{text}_air{air:.0e}"
            r = run(cells, air, args.dt, args.fit, folder, mixing=args.mixing)
            if comm.rank == 0:
                print(f"{text} air {air:.0e}: rate {fitted_rate(r['t'], r['A'], args.fit):.4e} 1/s "
                      f"(published {RATE:.4e}), A(0) = {r['A'][0]:.3f} km, {r['wall']:.0f} s", flush=True)
            results.append(r)
    if comm.rank == 0:
        write(out, results, args.fit, args.dt)
    return 0


if __name__ == "__main__":
    sys.exit(main())
