"""The seed's global model (section 4.2): ``configs/shell_adaptive.yaml`` — an adaptive, load-balanced
3D spherical shell with plates and particles at the core-mantle boundary — with and without the
weighted repartition, and its pictures.

Usage::

    python -m benchmarks.shell.shell_adaptive [--ranks 2] [--steps 40] [--reuse]   # the comparison
    python -m benchmarks.shell.shell_adaptive --picture RUN_DIR              # the seed's figure 5

The comparison runs the config on ``--ranks`` ranks for ``--steps`` steps in five ways:

- ``rcb``: as shipped, repartitioned every 5 steps by recursive coordinate bisection, each cut
  placed so that cells, particles and the load ``1 + W n_particles(K)`` (``W =
  balance.particle_weight = 0.05``) all split evenly (the particles are balanced by construction,
  whatever ``W``: with ``W = 0`` the runs are identical);
- ``morton_weighted``: repartitioned as often into blocks of equal load ``1 + W n_particles(K)``
  along a Morton (Z-order) curve, ``W = 0.05``;
- ``morton_cells``: the same blocks by the cell count alone (``W = 0``): the repartition without
  the particle weights;
- ``morton_w1``: the Morton blocks with ``W = 1`` (a particle costs as much as a cell): what the
  weights do when the particles are a large part of the load;
- ``static``: never repartitioned (``balance.strategy: none``): the base mesh's partition, refined
  where the temperature asks;

and writes ``imbalance.png`` and ``imbalance.md`` (particle and cell imbalance, max/mean over the
ranks, per step; mean and worst over the run; wall time) and prints one JSON line. The particles
sit in a layer around the core, a few percent of the volume, so balancing cells alone leaves them
on whichever ranks own the core's cells. The particle counts per rank are deterministic; the wall
times depend on the machine's load (stated in the benchmark README when measured).

``--picture`` draws a finished run (``python -m convection.plot``): in
``RUN_DIR/snapshots/displacement/``, ``shell_*.png``, the particles within r < 1.45 coloured by
displacement over the temperature on the equatorial plane (the seed's figure 5, left); in
``RUN_DIR/snapshots/initial_radius/``, ``temperature_*.png``, the vertical section y = 0 of the
temperature with the particles near it coloured by the magnitude of ``initial_position`` — their
initial radius (right).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks.common import ROOT, start_cli_run
from benchmarks.harness import OUTPUT, Benchmark
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "shell_adaptive", ranks=2, overrides=True,
                      helps={"set": "extra config override key=value"})

CONFIG = ROOT / "configs" / "shell_adaptive.yaml"
VARIANTS = {
    "rcb": [],
    "morton_weighted": ["balance.method=morton"],
    "morton_cells": ["balance.method=morton", "balance.particle_weight=0.0"],
    "morton_w1": ["balance.method=morton", "balance.particle_weight=1.0"],
    "static": ["balance.strategy=none"],
}
STATISTICS = "[time,velocity,nusselt,mesh,particles,load,wall_time]"


def _finished(folder: Path, steps: int) -> bool:
    """Whether ``folder`` holds a finished run of ``steps`` steps (its statistics end at that step)."""
    try:
        return int(read_statistics(folder / "statistics.csv")["step"][-1]) == steps
    except Exception:  # noqa: BLE001 - missing or damaged: not finished
        return False


def compare(out: Path, *, ranks: int, steps: int, extra: list[str], reuse: bool = False) -> dict:
    """Run every variant (with ``reuse``: only those without a finished run in ``out``) and write
    imbalance.md / imbalance.png next to this script."""
    results = {}
    for name, overrides in VARIANTS.items():
        folder = out / name
        if not (reuse and _finished(folder, steps)):
            if folder.exists():
                shutil.rmtree(folder)
            run = start_cli_run(CONFIG, folder, ranks=ranks, nice=0, log=out / f"{name}.log",
                                overrides=[f"time.max_steps={steps}", "time.end=1e9", f"output.statistics={STATISTICS}",
                                           "particles.output.every_steps=1000000", *overrides, *extra])
            run.wait()
        stats = read_statistics(folder / "statistics.csv")
        results[name] = {key: np.asarray(stats[key], dtype=float) for key in
                         ("step", "cells", "n_particles", "particle_imbalance", "cell_imbalance", "wall_time")}
    summary = {name: {"particle_imbalance_mean": float(r["particle_imbalance"][1:].mean()),
                      "particle_imbalance_max": float(r["particle_imbalance"][1:].max()),
                      "cell_imbalance_mean": float(r["cell_imbalance"][1:].mean()),
                      "cells_final": int(r["cells"][-1]), "particles_final": int(r["n_particles"][-1]),
                      "wall_seconds": float(r["wall_time"][-1])} for name, r in results.items()}
    lines = [f"configs/shell_adaptive.yaml on {ranks} ranks, {steps} steps (adapted every 5, repartitioned every 5 "
             "unless static). Imbalance = max/mean over the ranks, per step, averaged over steps 1..end.", "",
             "| partition | particle imbalance, mean | worst | cell imbalance, mean | cells at the end | particles "
             "| wall [s] |", "|---|---|---|---|---|---|---|"]
    for name, s in summary.items():
        lines.append(f"| {name} | {s['particle_imbalance_mean']:.3f} | {s['particle_imbalance_max']:.3f} | "
                     f"{s['cell_imbalance_mean']:.3f} | {s['cells_final']} | {s['particles_final']} | "
                     f"{s['wall_seconds']:.0f} |")
    (HERE / "imbalance.md").write_text("\n".join(lines) + "\n")
    _plot(results, HERE / "imbalance.png", ranks)
    return summary


def _plot(results: dict, png: Path, ranks: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, r in results.items():
        axes[0].plot(r["step"][1:], r["particle_imbalance"][1:], "o-", ms=3, label=name)
        axes[1].plot(r["step"][1:], r["cell_imbalance"][1:], "o-", ms=3, label=name)
    axes[0].set_ylabel("particle imbalance (max/mean)")
    axes[1].set_ylabel("cell imbalance (max/mean)")
    for ax in axes:
        ax.axhline(1.0, color="grey", lw=0.8)
        ax.set_xlabel("time step")
        ax.legend()
    fig.suptitle(f"shell_adaptive.yaml on {ranks} ranks: repartitioned by bisection (cells and particles), "
                 "Morton blocks (weighted / cells only), or never", fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def picture(run_dir: Path) -> None:
    """The seed's figure 5 from a finished run (python -m convection.plot, twice): into
    ``RUN_DIR/snapshots/displacement/`` the particles within r < 1.45 coloured by displacement
    (``shell_*.png``), into ``RUN_DIR/snapshots/initial_radius/`` the vertical section y = 0 of the
    temperature with the particles near it coloured by their initial radius (``temperature_*.png``)."""
    run_dir = run_dir.resolve()  # the drawing runs in the project folder
    base = [sys.executable, "-m", "convection.io.pictures", str(run_dir)]
    subprocess.run([*base, "--particle-property", "displacement", "--particle-radius", "1.45",
                    "--snapshots", str(run_dir / "snapshots" / "displacement")], cwd=ROOT, check=True)
    subprocess.run([*base, "--particle-property", "initial_position",
                    "--snapshots", str(run_dir / "snapshots" / "initial_radius")], cwd=ROOT, check=True)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--reuse", action="store_true",
                        help="keep the variants that already have a finished run in --out (run only the others)")
    parser.add_argument("--picture", type=Path, default=None, metavar="RUN_DIR", help="draw a finished run")
    args = parser.parse_args(argv)
    if args.picture is not None:
        picture(args.picture)
        return 0
    BENCHMARK.log_load("start")
    args.out.mkdir(parents=True, exist_ok=True)
    summary = compare(args.out, ranks=args.ranks, steps=args.steps, extra=args.set, reuse=args.reuse)
    print((HERE / "imbalance.md").read_text())
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
