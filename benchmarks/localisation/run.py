"""Strain localisation in an extending visco-plastic layer (configs/localisation.yaml).

Usage::

    python -m benchmarks.localisation.run                 # with and without weakening, picture
    python -m benchmarks.localisation.run --methods       # Picard against Newton, per step
    python -m benchmarks.localisation.run --cells 32x8    # smaller

The default runs the model twice, with the strain weakening of the config (yield stress
``sigma_y w(e)``, ``w`` linear from 1 at plastic strain ``e = 0.05`` to 0.25 at ``e = 0.5``) and
without it, and measures from the particles at the end time how localised the deformation is:

- ``yielded``: the fraction of the particles that ever yielded (``e > 0.01``): the width of the
  deforming zone;
- ``e_max``, ``e_p99``: the largest and the 99th percentile plastic strain;
- ``band``: the fraction of the particles holding half of the total plastic strain (the smaller,
  the more localised).

It writes ``results.md`` and ``localisation.png`` (the viscosity field with the particles coloured
by plastic strain, both runs) into ``--results`` (default: this folder) and prints one JSON line
last.

``--methods`` runs the first ``--steps`` steps with Picard and with Newton to the relative residual
1e-8 every step and writes ``methods.md`` and ``methods.png`` (iterations per step).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import h5py
import numpy as np

from benchmarks.common import iterations_figure
from benchmarks.harness import OUTPUT, Benchmark
from convection.launch import run_config
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "localisation", results=HERE, results_option=True, ranks=1,
                      overrides=True, helps={"set": "extra config override key=value", "out": "run folders",
                                             "results": "where the tables and pictures go"})

CONFIG = ROOT / "configs" / "localisation.yaml"


def run(out: Path, *, cells: str, ranks: int, extra: list[str]) -> float:
    """Run the config with the CLI into ``out``; returns the wall time."""
    nx, ny = (int(n) for n in cells.split("x"))
    start = time.perf_counter()
    run_config(CONFIG, out, ranks=ranks, cwd=ROOT,
               overrides=[f"mesh.cells=[{nx},{ny}]", "output.progress=lines", "output.progress_every=50", *extra])
    return time.perf_counter() - start


def last_particles(out: Path) -> tuple[np.ndarray, np.ndarray]:
    """Positions shape=(n, 3) and plastic strain shape=(n,) of the last particle output."""
    path = sorted(out.glob("particles_*.h5"))[-1]
    with h5py.File(path, "r") as f:
        return f["positions"][...], f["properties/plastic_strain"][...]


def localisation(e: np.ndarray) -> dict[str, float]:
    """Measures of how localised the plastic strain ``e`` of the particles is (module docstring)."""
    order = np.sort(e)[::-1]
    total = float(order.sum())
    half = int(np.searchsorted(np.cumsum(order), 0.5 * total)) + 1 if total > 0 else 0
    return {"yielded": float(np.mean(e > 0.01)), "e_max": float(e.max()), "e_p99": float(np.percentile(e, 99)),
            "band": half / e.size}


def picture(runs: dict[str, Path], path: Path) -> None:
    """The viscosity (log scale) with the particles coloured by plastic strain, one panel per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from convection.io.pictures import import_pyvista

    pv = import_pyvista()  # not `import pyvista` after DOLFINx: see import_pyvista

    fig, axes = plt.subplots(len(runs), 1, figsize=(10, 3.1 * len(runs)), squeeze=False)
    for ax, (label, out) in zip(axes[:, 0], runs.items()):
        reader = pv.get_reader(str(out / "fields.xdmf"))
        reader.set_active_time_point(len(reader.time_values) - 1)
        data = reader.read()
        data = data[0] if isinstance(data, pv.MultiBlock) else data
        tri = data.cells_dict if hasattr(data, "cells_dict") else None
        cells = np.asarray(next(iter(tri.values()))) if tri else None
        eta = np.asarray(data.cell_data["viscosity"]) if "viscosity" in data.cell_data else None
        pts = np.asarray(data.points)
        if cells is not None and eta is not None:
            pc = ax.tripcolor(pts[:, 0], pts[:, 1], cells[:, :3], facecolors=np.log10(eta), cmap="Greys_r",
                              vmin=-3, vmax=0)
            fig.colorbar(pc, ax=ax, label="log10 viscosity", location="left", pad=0.06, fraction=0.03)
        x, e = last_particles(out)
        shown = np.flatnonzero(e > 0.01)  # the particles that yielded
        shown = shown[np.argsort(e[shown])]
        sc = ax.scatter(x[shown, 0], x[shown, 1], c=e[shown], s=1.0, cmap="viridis", vmin=0,
                        vmax=max(float(np.percentile(e, 99.5)), 1e-12))
        fig.colorbar(sc, ax=ax, label="plastic strain (e > 0.01)", pad=0.01, fraction=0.03)
        ax.set_aspect("equal")
        ax.set_xlim(float(pts[:, 0].min()), float(pts[:, 0].max()))
        ax.set_ylim(0, 1)
        t = float(read_statistics(out / "statistics.csv")["time"][-1])
        ax.set_title(f"{label}, t = {t:.3g}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    from PIL import Image  # a 256-colour PNG: a third of the size, the same picture

    Image.open(path).convert("RGB").quantize(colors=256).save(path, optimize=True)


def _load_line() -> str:
    """The machine's load when the table was written (the wall times are not timings otherwise)."""
    import os

    return (f"Load average at the end: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; the wall times are "
            "what these runs took, not a timing measurement.")


def compare(out: Path, results: Path, *, cells: str, ranks: int, extra: list[str]) -> dict:
    runs = {"with strain weakening": out / "weakening", "without strain weakening": out / "no_weakening"}
    walls = {}
    walls["with strain weakening"] = run(runs["with strain weakening"], cells=cells, ranks=ranks, extra=extra)
    walls["without strain weakening"] = run(runs["without strain weakening"], cells=cells, ranks=ranks,
                                            extra=["physics.viscosity.law.plastic.weakening=null", *extra])
    result: dict = {"cells": cells, "ranks": ranks}
    lines = [f"configs/localisation.yaml, {cells} cells (P2-P1), {ranks} rank(s); measures of the particles' plastic "
             "strain e at the end time (benchmarks/localisation/run.py docstring).", "",
             "| run | yielded (e > 0.01) | band (half of the strain) | e_max | e_p99 | nonlinear its/step | wall [s] |",
             "|---|---|---|---|---|---|---|"]
    for label, folder in runs.items():
        _, e = last_particles(folder)
        m = localisation(e)
        stats = read_statistics(folder / "statistics.csv")
        its = float(np.mean(stats["nonlinear_iterations"]))
        key = "weakening" if label.startswith("with ") else "no_weakening"
        result[key] = {**m, "nonlinear_per_step": its, "wall_seconds": walls[label]}
        lines.append(f"| {label} | {m['yielded']:.3f} | {m['band']:.4f} | {m['e_max']:.3g} | {m['e_p99']:.3g} | "
                     f"{its:.2f} | {walls[label]:.0f} |")
    lines += ["", _load_line()]
    (results / "results.md").write_text("\n".join(lines) + "\n")
    picture(runs, results / "localisation.png")
    return result


def methods(out: Path, results: Path, *, cells: str, steps: int, ranks: int) -> dict:
    """Picard against Newton: iterations per step to the relative residual 1e-8."""
    counts: dict[str, list[int]] = {}
    walls = {}
    for method in ("picard", "newton"):
        walls[method] = run(out / f"methods_{method}", cells=cells, ranks=ranks,
                            extra=[f"time.max_steps={steps}", f"stokes.nonlinear.method={method}",
                                   "stokes.nonlinear.rtol=1e-8", "stokes.nonlinear.max_iterations=5000",
                                   "output.fields_every=0"])
        counts[method] = [int(c) for c in read_statistics(out / f"methods_{method}" / "statistics.csv")["nonlinear_iterations"]]
    lines = [f"configs/localisation.yaml, {cells} cells, first {steps} steps, relative residual 1e-8 every step "
             f"(MUMPS), {ranks} rank(s).", "",
             "| method | iterations, total | per step (mean) | max | wall [s] |", "|---|---|---|---|---|"]
    for method in ("picard", "newton"):
        c = counts[method]
        lines.append(f"| {method} | {sum(c)} | {sum(c) / len(c):.2f} | {max(c)} | {walls[method]:.0f} |")
    lines += ["", _load_line()]
    (results / "methods.md").write_text("\n".join(lines) + "\n")
    iterations_figure(results / "methods.png", counts, title=f"localisation model, {cells}")
    return {"cells": cells, **{m: sum(counts[m]) for m in counts}, **{f"{m}_max": max(counts[m]) for m in counts}}


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", default="64x16", help="NXxNY")
    parser.add_argument("--methods", action="store_true", help="Picard against Newton, per step")
    parser.add_argument("--steps", type=int, default=40)
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = Path(args.results)
    results.mkdir(parents=True, exist_ok=True)
    if args.methods:
        result = methods(out, results, cells=args.cells, steps=args.steps, ranks=args.ranks)
    else:
        result = compare(out, results, cells=args.cells, ranks=args.ranks, extra=list(args.set))
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
