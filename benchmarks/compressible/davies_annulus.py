"""The annulus case 2.1 of Davies et al. (isoviscous, free slip, Ra = 1e4) under the extended
Boussinesq (EBA), truncated anelastic liquid (TALA) and anelastic liquid (ALA) approximations.

Usage::

    python -m benchmarks.compressible.davies_annulus [--case boussinesq eba tala ala] [--resolution 0.1]
                                                     [--ranks 1] [--set KEY=VALUE ...] [--no-run] [--out DIR]

Each case runs ``configs/annulus_davies.yaml`` (radii 1.22 and 2.22, T = 1 inside and 0 outside, free
slip, a degree-4 start, to steady state) with the CLI and the direct Stokes solver; the compressible
cases add ``Di = 0.5``, ``gamma = 1`` and ``T0 = 0.091`` (King et al. 2010's surface temperature).
The reference state is that of ``docs/compressible.md`` with radial gravity: the depth is
``r_outer - |x|``, ``rho_r = exp(Di depth / gamma)``, ``e_up = x / |x|``.

Published values exist for the Boussinesq case only (ASPECT's, in the manual's section on the
benchmark: ``benchmarks.shell.davies.CASES["2.1"]``); the ASPECT manual names the other
approximations but tabulates none, and neither ASPECT's ``benchmarks/davies_et_al`` nor G-ADOPT's
tests and demos hold an EBA, TALA or ALA annulus case of Davies et al. So the table checks what a
steady state must satisfy, whatever the code: the balance of shear heating and work against gravity
(``|Phi - W| / W``: 0 under EBA up to the discretisation, the pressure work under TALA) and the heat
budget of the shell, heat out of the surface minus heat in through the core equal to the heating
inside::

    budget = ((Nu_T - Nu_B) Q_cond - A (Phi - W)) / (Nu_T Q_cond),
    Q_cond = 2 pi / ln(r_o / r_i),   A = pi (r_o^2 - r_i^2)

(``W``, ``Phi`` are the ``heating`` statistics, volume averages). Writes ``<out>/results.md`` and
``<out>/results.png`` (the final temperature of each case and its radial profile).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from benchmarks.harness import OUTPUT, Benchmark, Case, cases, markdown_table
from benchmarks.shell.davies import CASES as BOUSSINESQ_CASES
from convection.geometry.shell import conductive_heat_flow
from convection.io.pictures import read_statistics
from convection.io.pictures.run_files import read_last_field
from convection.launch import run_config

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "davies_annulus", ranks=1, overrides=True,
                      no_run="tabulate the runs already in --out",
                      helps={"set": "a config override for every run (repeatable)"})
DI, SURFACE_TEMPERATURE = 0.5, 0.091
"""The reference state of ``configs/annulus_davies_tala.yaml``."""
RADII = (1.22, 2.22)
CASES = cases(Case("boussinesq", "annulus_davies.yaml"),
              *(Case(form, "annulus_davies_tala.yaml", (f"physics.approximation={form}",)) for form in ("eba", "tala", "ala")))
TALA_OVERRIDES = ("physics.approximation=tala", f"physics.reference.Di={DI}",
                  f"physics.reference.surface_temperature={SURFACE_TEMPERATURE}", "stokes.solver=direct",
                  "output.statistics=[time,velocity,nusselt,temperature,mesh,heating,wall_time]")
"""``configs/annulus_davies.yaml`` with these is ``configs/annulus_davies_tala.yaml`` (the test checks it)."""
PUBLISHED = BOUSSINESQ_CASES["2.1"]["reference"]
"""ASPECT's values of case 2.1 (Boussinesq), 1536 x 128 cells."""
COLUMNS = ("nusselt", "nusselt_bottom", "vrms", "T_mean")


def area(radii: tuple[float, float] = RADII) -> float:
    """The annulus's area ``pi (r_o^2 - r_i^2)``."""
    return math.pi * (radii[1] ** 2 - radii[0] ** 2)


def heat_budget(nu_top: float, nu_bottom: float, W: float, Phi: float, radii: tuple[float, float] = RADII) -> float:
    """``((Nu_T - Nu_B) Q_cond - A (Phi - W)) / (Nu_T Q_cond)``: the steady state's heat budget
    misfit (0: the heat leaving the surface is that entering through the core plus the heating)."""
    q = conductive_heat_flow(radii[0], radii[1], 1.0, 2)
    return ((nu_top - nu_bottom) * q - area(radii) * (Phi - W)) / (nu_top * q)


def final(statistics: dict) -> dict[str, float]:
    """The last row: :data:`COLUMNS`, ``W`` and ``Phi`` (0 without the heating statistic), steps, time, cells."""
    values = {k: float(statistics[k][-1]) for k in COLUMNS}
    values["W"] = float(statistics["heating_W"][-1]) if "heating_W" in statistics else 0.0
    values["Phi"] = float(statistics["heating_Phi"][-1]) if "heating_Phi" in statistics else 0.0
    window = max(1, len(statistics["step"]) // 10)
    values["drift"] = max(abs(statistics[k][-1] / statistics[k][-window] - 1.0) for k in COLUMNS)
    values.update(steps=int(statistics["step"][-1]), time=float(statistics["time"][-1]),
                  cells=int(statistics["cells"][-1]))
    return values


def row(name: str, ours: dict[str, float], wall: float) -> list[str]:
    cells = [name, str(ours["cells"]), str(ours["steps"]), f"{ours['time']:.3g}"]
    for key in COLUMNS:
        text = f"{ours[key]:.5g}"
        if name == "boussinesq":
            text += f" ({PUBLISHED[key]}; {ours[key] / PUBLISHED[key] - 1.0:+.2%})"
        cells.append(text)
    if ours["W"]:
        cells += [f"{ours['W']:.5g}", f"{ours['Phi']:.5g}", f"{abs(ours['Phi'] - ours['W']) / ours['W']:.2%}"]
    else:
        cells += ["-", "-", "-"]
    budget = heat_budget(ours["nusselt"], ours["nusselt_bottom"], ours["W"], ours["Phi"])
    cells += [f"{budget:+.2%}", f"{ours['drift']:.1e}", f"{wall:.0f}"]
    return cells


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(cases=CASES, default_cases=list(CASES))
    parser.add_argument("--resolution", type=float, default=0.1, help="gmsh cell size of the annulus")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    rows, runs = [], {}
    for name in args.case:
        case = CASES[name]
        out = args.out / f"{name}_h{args.resolution:g}"
        if not args.no_run:
            run_config(case.path, out, ranks=args.ranks, cwd=ROOT, overrides=[
                "output.progress=lines", "output.progress_every=200", "stokes.solver=direct",
                f"mesh.resolution={args.resolution}", *case.overrides, *args.set])
        summary = json.loads((out / "summary.json").read_text())
        rows.append(row(name, final(read_statistics(out / "statistics.csv")), summary["wall_time"]))
        runs[name] = out
    header = ["case", "cells", "steps", "end time", "Nu_T (outer)", "Nu_B (inner)", "vrms", "<T>", "W", "Phi",
              "abs(Phi-W)/W", "heat budget", "largest change over the last tenth", "wall time [s]"]
    BENCHMARK.log_load("end")
    BENCHMARK.publish(args.out / "results.md", "\n".join(markdown_table(header, rows)) + "\n")
    picture(runs, args.out / "results.png")
    print(f"wrote {args.out / 'results.png'}")
    return 0


def radial_profile(points: np.ndarray, values: np.ndarray, bins: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """``(r, <T>(r))``: the nodal values averaged in ``bins`` radial bins between the radii."""
    r = np.hypot(points[:, 0], points[:, 1])
    edges = np.linspace(RADII[0], RADII[1], bins + 1)
    which = np.clip(np.digitize(r, edges) - 1, 0, bins - 1)
    sums = np.bincount(which, weights=values, minlength=bins)
    counts = np.bincount(which, minlength=bins)
    return 0.5 * (edges[1:] + edges[:-1]), sums / np.maximum(counts, 1)


def picture(runs: dict[str, Path], png: Path) -> None:
    """The final temperature of each run (a panel each) and their radial profiles (the last panel)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    fig, axes = plt.subplots(1, len(runs) + 1, figsize=(3.6 * (len(runs) + 1), 3.8), constrained_layout=True)
    for ax, (name, run) in zip(axes, runs.items()):
        points, cells, values, _ = read_last_field(run, "temperature")
        shown = ax.tripcolor(Triangulation(points[:, 0], points[:, 1], cells[:, :3]), values[:, 0],
                             shading="gouraud", cmap="coolwarm", vmin=0.0, vmax=1.0)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(name.upper() if name != "boussinesq" else "Boussinesq")
        r, mean = radial_profile(points, values[:, 0])
        axes[-1].plot(mean, r, label=ax.get_title())
    fig.colorbar(shown, ax=axes[:-1], shrink=0.7, label="T")
    axes[-1].set_xlabel("mean T at radius r")
    axes[-1].set_ylabel("r")
    axes[-1].legend(fontsize=8)
    fig.suptitle(f"Davies et al. case 2.1 (Ra = 1e4, free slip) at steady state; EBA, TALA, ALA: Di = {DI}, "
                 f"T0 = {SURFACE_TEMPERATURE}")
    fig.savefig(png, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
