"""Busse et al. (1994) case 1a: steady 3D bimodal convection, against the published Nu and vrms.

Usage::

    python -m benchmarks.busse.run [--ranks 1] [--coarse 12x8x12] [--fine 20x12x20] [--cfl 16]
                                   [--out DIR] [--no-run] [--quick]

Runs ``configs/busse_1a.yaml`` twice: on the ``--coarse`` mesh, uniform, from the config's initial
temperature to its steady state; then on the config's graded ``--fine`` mesh from that steady state
(``initial.from_run``) at ``--cfl`` to its own. Writes ``<out>/results.md`` (each run's Nu at the
top and the bottom and vrms against the published values, steps, model time and wall time) and
``<out>/results.png`` (the fine run's temperature on the mid-depth plane z = 1/2, where the bimodal
planform shows: the upwelling at x = y = 0, the downwelling at the opposite corner, and on the
front side y = 0; its Nu and vrms against time). ``--no-run`` tabulates the run folders
already in ``--out``; ``--quick`` makes tiny meshes and a few steps (the test's smoke run).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.harness import OUTPUT, Benchmark, markdown_table
from convection.io.pictures import read_statistics
from convection.io.pictures.run_files import read_last_field
from convection.launch import run_config

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CONFIG = ROOT / "configs" / "busse_1a.yaml"
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "busse", ranks=1, quick="tiny meshes, a few steps (smoke test)",
                      no_run="tabulate the runs already in --out")
PUBLISHED = {"nusselt": 3.5374, "vrms": 40.999}
"""Busse et al. (1994), case 1a: the extrapolated values of their comparison."""
SIZE = (1.0079, 0.6283, 1.0)


def _cells(text: str) -> str:
    return "[" + ",".join(str(int(n)) for n in text.lower().split("x")) + "]"


def _run(out: Path, ranks: int, overrides: list[str]) -> None:
    progress = ["output.progress=lines", "output.progress_every=10"]
    run_config(CONFIG, out, ranks=ranks, overrides=[*progress, *overrides], cwd=ROOT)


def _row(name: str, folder: Path) -> tuple[list[str], dict]:
    summary = json.loads((folder / "summary.json").read_text())
    stats = read_statistics(folder / "statistics.csv")
    nu, nu_bottom, vrms = stats["nusselt"][-1], stats["nusselt_bottom"][-1], stats["vrms"][-1]
    err = lambda value, key: f"{(value - PUBLISHED[key]) / PUBLISHED[key]:+.2%}"  # noqa: E731
    cells = "x".join(str(n) for n in _mesh_cells(folder))
    row = [name, cells, str(summary["steps"]), f"{stats['time'][-1]:.4f}", f"{nu:.4f}", err(nu, "nusselt"),
           f"{nu_bottom:.4f}", err(nu_bottom, "nusselt"), f"{vrms:.3f}", err(vrms, "vrms"),
           f"{summary['wall_time']:.0f}", summary.get("reason", "")]
    return row, stats


def _mesh_cells(folder: Path) -> list[int]:
    import yaml

    return list(yaml.safe_load((folder / "config.yaml").read_text())["mesh"]["cells"])


def _picture(fine: Path, stats: dict, png: Path) -> None:
    """Mid-depth plane and the front side of the fine run's last temperature, and its Nu and vrms."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    points, _, values, t = read_last_field(fine, "temperature")
    T = np.asarray(values).reshape(-1)
    mid = np.abs(points[:, 2] - 0.5) < 1e-9
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4), constrained_layout=True,
                             gridspec_kw={"width_ratios": [1.1, 1.0, 1.0]})
    tri = Triangulation(points[mid, 0], points[mid, 1])
    shown = axes[0].tricontourf(tri, T[mid], levels=np.linspace(0.0, 1.0, 21), cmap="coolwarm")
    axes[0].set_aspect("equal")
    axes[0].set(xlabel="x", ylabel="y", title=f"temperature on z = 1/2, t = {t:.3g}")
    fig.colorbar(shown, ax=axes[0], label="temperature", shrink=0.8)
    # the front face y = 0, through the upwelling at x = 0
    face = np.abs(points[:, 1]) < 1e-9
    axes[1].tricontourf(Triangulation(points[face, 0], points[face, 2]), T[face], levels=np.linspace(0.0, 1.0, 21),
                        cmap="coolwarm")
    axes[1].set_aspect("equal")
    axes[1].set(xlabel="x", ylabel="z", title="the front side y = 0")
    for key, colour in (("nusselt", "C0"), ("vrms", "C1")):
        axes[2].plot(stats["time"], stats[key] / PUBLISHED[key], color=colour, label=f"{key} / published")
    axes[2].axhline(1.0, color="k", lw=0.8)
    axes[2].axhspan(0.99, 1.01, color="0.9")
    axes[2].set(xlabel="time of the continued run", ylim=(0.95, 1.05), title="fine run against Busse et al.")
    axes[2].legend()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--coarse", default="12x8x12", help="the uniform mesh of the first run")
    parser.add_argument("--fine", default="20x12x20", help="the graded mesh continued from it")
    parser.add_argument("--cfl", type=float, default=16.0, help="cfl of the continued run")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out: Path = args.out
    coarse, fine = out / f"coarse_{args.coarse}", out / f"fine_{args.fine}"
    quick = ["time.max_steps=3", "output.fields_every=1"] if args.quick else []
    if not args.no_run:
        _run(coarse, args.ranks, [f"mesh.cells={_cells(args.coarse)}", "mesh.grading=null", *quick])
        _run(fine, args.ranks, [f"mesh.cells={_cells(args.fine)}", f"time.cfl={args.cfl}",
                                f"initial.from_run={coarse}", *quick])
    rows, stats = [], {}
    for name, folder in (("cold, uniform", coarse), (f"from the coarse run, graded, cfl {args.cfl:g}", fine)):
        row, stats = _row(name, folder)
        rows.append(row)
    header = ["run", "cells", "steps", "model time", "Nu top", "error", "Nu bottom", "error", "vrms", "error",
              "wall [s]", "stop"]
    table = "\n".join([*markdown_table(header, rows), "",
                       f"Published (Busse et al. 1994, case 1a): Nu {PUBLISHED['nusselt']}, vrms {PUBLISHED['vrms']}.",
                       f"{BENCHMARK.log_load('end')}"]) + "\n"
    BENCHMARK.publish(out / "results.md", table)
    _picture(fine, stats, out / "results.png")
    print(f"wrote {out / 'results.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
