"""Schmeling et al. (2008), case 1: a slab sinking under its own weight beneath sticky air, from
``configs/subduction.yaml`` (physical units), against the published codes' slab-tip curves.

A 100 km lithosphere (3300 kg/m^3, 1e23 Pa s) from x = 1000 km to the right side of a 3000 x 700 km
mantle (3200 kg/m^3, 1e21 Pa s), its left end hanging 200 km deep, under 50 km of sticky air (0
kg/m^3, 1e19 Pa s); free slip on every side, g = 9.81 m/s^2, geometric viscosity mixing ("geom"
in the paper). The slab tip's depth below the undisturbed surface is the lithosphere's deepest
point (the ``materials`` statistic's ``depth_lithosphere``: the centroid depth of the deepest cell
the lithosphere fills at least half) minus the 50 km of air, in km against time in Myr
(``statistics_physical.csv``).

The published curves (``reference.csv``, made by ``reference_from_xlsx.py`` from the spreadsheet
G-ADOPT ships; MIT licence) are the paper's Fig. 5 data: I2VIS, I2ELVIS, CITCOM, FDCON with
geometric mixing (and, for context, arithmetic/harmonic mixing and LAPEX2D).

Usage::

    python -m benchmarks.schmeling.run [--cells 120x30 ...] [--end 60] [--ranks 2] [--out DIR]
    python -m benchmarks.schmeling.run --collect RUN_DIR [RUN_DIR ...] [--out DIR]

Each run writes ``<out>/run_<cells>/``; ``<out>/results.md`` gets the tip depth every 10 Myr beside
the geometric-mixing codes and the times at which the tip passes 400 and 600 km, and
``<out>/results.png`` the curves. ``--collect`` redoes the table and picture from finished (or
still running) run directories.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.common import read_reference, start_cli_run
from benchmarks.harness import Benchmark

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=HERE, ranks=2)

AIR = 50.0
"""Sticky-air thickness [km]: the undisturbed surface lies this far below the box's top."""
TIMES = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0)
"""Times of the table [Myr]."""
DEPTHS = (400.0, 600.0)
"""Tip depths whose passing times the table gives [km]."""
GEOMETRIC = "geom"


def reference() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The published curves by code name: (time [Myr], tip depth [km]), each shape=(n,)."""
    curves: dict[str, list[tuple[float, float]]] = {}
    for row in read_reference(HERE / "reference.csv"):
        curves.setdefault(row["code"], []).append((float(row["time_Myr"]), float(row["depth_km"])))
    return {name: (np.array([t for t, _ in p]), np.array([z for _, z in p])) for name, p in curves.items()}


def tip_curve(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """This project's (time [Myr], tip depth [km]) of a run directory, each shape=(steps,)."""
    with open(run_dir / "statistics_physical.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["time [Myr]"]) for r in rows])
    z = np.array([float(r["depth_lithosphere [km]"]) for r in rows]) - AIR
    return t, z


def at(curve: tuple[np.ndarray, np.ndarray], time: float) -> float:
    """Tip depth at ``time`` (linear between samples; NaN after the curve's end)."""
    t, z = curve
    return float(np.interp(time, t, z)) if t.size and time <= t[-1] * (1 + 1e-9) else float("nan")


def passing(curve: tuple[np.ndarray, np.ndarray], depth: float) -> float:
    """First time the tip reaches ``depth`` (linear between samples; NaN if it never does)."""
    t, z = curve
    above = np.nonzero(z >= depth)[0]
    if above.size == 0:
        return float("nan")
    i = int(above[0])
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (depth - z[i - 1]) * (t[i] - t[i - 1]) / (z[i] - z[i - 1]))


def _fmt(value: float, digits: int = 0) -> str:
    return "-" if not np.isfinite(value) else f"{value:.{digits}f}"


def _label(run_dir: Path) -> str:
    """``this project NXxNZ``, with ``+L`` for a mesh adapted up to L levels finer."""
    import yaml

    config = run_dir / "config.yaml"
    if not config.exists():
        return f"this project {run_dir.name}"
    data = yaml.safe_load(config.read_text())
    cells = "x".join(str(n) for n in data["mesh"]["cells"])
    adaptivity = data.get("adaptivity") or {}
    levels = f"+{adaptivity['max_level']}" if adaptivity.get("enabled") else ""
    return f"this project {cells}{levels}"


def _cost(run_dir: Path) -> str:
    summary = run_dir / "summary.json"
    if not summary.exists():
        return "running"
    data = json.loads(summary.read_text())
    return f"{data.get('steps', '?')} steps, {data.get('wall_time', float('nan')):.0f} s"


def write(out: Path, runs: list[Path]) -> str:
    """Write ``results.md`` and ``results.png`` for the run directories; returns the table."""
    published = reference()
    geometric = {n: c for n, c in published.items() if n.endswith(GEOMETRIC)}
    ours = {_label(r): tip_curve(r) for r in runs}
    head = "| curve | " + " | ".join(f"{t:g} Myr" for t in TIMES) + " | " + " | ".join(
        f"reaches {d:g} km [Myr]" for d in DEPTHS) + " |"
    lines = ["# Schmeling et al. (2008), case 1: slab-tip depth [km] below the surface", "",
             "Generated by `benchmarks/schmeling/run.py` from `configs/subduction.yaml` (geometric viscosity "
             "mixing, sticky air 50 km / 1e19 Pa s). Published curves: the paper's codes with geometric mixing "
             "(reference.csv). A dash: the curve does not reach that time or depth.", "",
             head, "|" + "---|" * (1 + len(TIMES) + len(DEPTHS))]
    for name, curve in [*ours.items(), *geometric.items()]:
        lines.append(f"| {name} | " + " | ".join(_fmt(at(curve, t)) for t in TIMES) + " | "
                     + " | ".join(_fmt(passing(curve, d), 1) for d in DEPTHS) + " |")
    lines += ["", "| run | cost |", "|---|---|"] + [f"| {_label(r)} | {_cost(r)} |" for r in runs]
    for name, curve in ours.items():
        lines += ["", _placement(name, curve, geometric)]
    text = "\n".join(lines) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.md").write_text(text)
    _picture(out / "results.png", ours, published)
    return text


def _placement(name: str, curve: tuple[np.ndarray, np.ndarray], geometric: dict[str, tuple]) -> str:
    """Where a curve falls among the published ones, by the time it reaches each depth."""
    parts = []
    for depth in DEPTHS:
        mine = passing(curve, depth)
        theirs = sorted((passing(c, depth), n) for n, c in geometric.items() if np.isfinite(passing(c, depth)))
        if not np.isfinite(mine) or not theirs:
            continue
        earlier, n = sum(1 for t, _ in theirs if t < mine), len(theirs)
        rank = ("earlier than all" if earlier == 0 else "later than all" if earlier == n else
                f"after {earlier} of the")
        parts.append(f"{depth:g} km at {mine:.1f} Myr, {rank} {n} geometric-mixing codes that reach it "
                     f"({theirs[0][0]:.1f}-{theirs[-1][0]:.1f} Myr)")
    return f"{name}: " + ("; ".join(parts) if parts else "has not reached 400 km yet") + "."


def _picture(png: Path, ours: dict[str, tuple], published: dict[str, tuple]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.0, 5.5), constrained_layout=True)
    for name, (t, z) in published.items():
        style = dict(lw=1.2, ls="--") if name.endswith(GEOMETRIC) else dict(lw=0.7, ls=":", color="0.6")
        ax.plot(t, z, label=name if name.endswith(GEOMETRIC) else None, **style)
    ax.plot([], [], ls=":", color="0.6", label="other mixing (arith/harm), LAPEX2D")
    for i, (name, (t, z)) in enumerate(ours.items()):
        ax.plot(t, z, lw=2.0, color=("k", "0.45", "0.7")[i % 3], ls=("-", "-", "--")[i % 3], label=name)
    ax.set_xlim(0, 65)
    ax.set_ylim(720, 150)
    ax.set_xlabel("time [Myr]")
    ax.set_ylabel("slab-tip depth [km]")
    ax.set_title("Schmeling et al. (2008) case 1, geometric viscosity mixing")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cells", nargs="+", default=["120x30"], help="meshes, NXxNY (default 120x30: 25 km cells)")
    parser.add_argument("--end", type=float, default=60.0, help="end time [Myr]")
    parser.add_argument("--collect", nargs="+", type=Path, help="only tabulate these run directories")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    if args.collect:
        runs = args.collect
    else:
        runs = []
        for cells in args.cells:
            nx, ny = (int(n) for n in cells.split("x"))
            run_dir = args.out / f"run_{cells}"
            run = start_cli_run(ROOT / "configs" / "subduction.yaml", run_dir, ranks=args.ranks,
                                overrides=[f"mesh.cells=[{nx},{ny}]", f"time.end={args.end} Myr"],
                                log=run_dir.with_suffix(".log"))
            run.wait()
            runs.append(run_dir)
    print(write(args.out, runs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
