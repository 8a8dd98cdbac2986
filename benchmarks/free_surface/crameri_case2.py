"""Crameri et al. (2012), case 2 with a true free surface: a light blob rising under a lithosphere,
from ``configs/crameri_case2_free_surface.yaml`` (physical units); the largest topography against
time beside the published free-surface codes.

Published curves: MILAMIN, SULEC and Underworld (the data files of ASPECT's
benchmarks/crameri_et_al/case_2; values interpolated there at the times below). At 3 Myr they
give 398.1, 395.8 and 396.1 m (ASPECT: ~396 m); their peaks are 842.5 m (16.82 Myr), 843.3 m
(16.64 Myr) and 818.0 m (15.78 Myr).

Usage::

    python benchmarks/free_surface/crameri_case2.py [--cells 224x56 112x28+4] [--end 20] [--dt 20] [--cfl 0.1]
                                                     [--composition particles|field] [--keep] [--out DIR]

``NXxNZ`` is a uniform mesh; ``NXxNZ+L`` a base mesh adapted up to ``L`` levels finer (each halves
the cells) where the materials' edges are (the Kelly indicator of the fractions: the blob and
the lid's base), every 4 steps.

Writes ``<out>/crameri_case2.md`` (the largest topography at the published times, each resolution
beside the codes' spread) and ``<out>/crameri_case2.png`` (against time).
"""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np
from mpi4py import MPI

from benchmarks.common import curves_figure
from benchmarks.harness import Benchmark
from convection import load_config, run_config

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=HERE)

TIMES = (0.1, 0.5, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0, 12.5, 15.0, 17.5, 20.0)
"""Myr."""
PUBLISHED = {  # largest topography [m] at TIMES (MILAMIN, SULEC, Underworld)
    "MILAMIN": (200.2, 254.6, 286.2, 341.9, 398.1, 512.4, 638.7, 744.3, 815.9, 838.3, 841.9, 831.5),
    "SULEC": (200.7, 254.3, 286.4, 340.7, 395.8, 506.3, 639.2, 734.9, 798.4, 834.3, 837.9, 823.2),
    "Underworld": (200.1, 255.3, 286.6, 341.8, 396.1, 506.0, 633.7, 730.4, 788.2, 813.6, 815.0, 802.7),
}


ADAPTIVE = ["adaptivity.enabled=true", "adaptivity.every=4", "adaptivity.fields=[composition]",
            "adaptivity.refine_fraction=0.2", "adaptivity.coarsen_fraction=0.5"]
"""The adaptivity of a ``NXxNZ+L`` run (with ``adaptivity.max_level=L``)."""


def parse_mesh(text: str) -> tuple[tuple[int, int], int]:
    """``"224x56"`` -> ((224, 56), 0); ``"112x28+4"`` -> ((112, 28), 4)."""
    base, _, levels = text.partition("+")
    nx, nz = (int(c) for c in base.split("x"))
    return (nx, nz), int(levels or 0)


def label(r: dict[str, Any]) -> str:
    """``224x56 (12.5 km)``, ``112x28 + 4 levels (1.56 km)``, ``... , fields`` (materials as fields)."""
    finest = 2800.0 / r["cells"][0] / 2 ** r.get("levels", 0)
    levels = f" + {r['levels']} levels" if r.get("levels") else ""
    fields = ", fields" if r.get("composition") == "field" else ""
    return f"{r['cells'][0]}x{r['cells'][1]}{levels} ({finest:.3g} km){fields}"


FIELDS = ["composition.source=field", "composition.degree=2", "particles=null",
          "output.statistics=[time,velocity,topography,free_surface,mesh,stokes,wall_time]"]
"""The materials as advected P2 fields instead of particles (``--composition field``)."""


def run(cells: tuple[int, int], dt: float, end: float, out: Path, *, levels: int = 0,
        cfl: float | None = None, composition: str = "particles", overrides: Sequence[str] = ()) -> dict[str, Any]:
    """One run (``levels`` > 0: adapted up to that many levels finer; ``composition``: the
    materials on ``particles`` or as advected ``field``s; ``overrides``: more ``--set`` texts); the
    largest topography [m] against time [Myr] and its cost (collective)."""
    config = load_config(ROOT / "configs" / "crameri_case2_free_surface.yaml", [
        f"mesh.cells=[{cells[0]},{cells[1]}]", f"time.dt_max={dt} kyr", f"time.end={end} Myr",
        "output.fields_every=0", "output.progress=none", f"output.directory={out}",
        *([*ADAPTIVE, f"adaptivity.max_level={levels}"] if levels else []),
        *([f"time.cfl={cfl}"] if cfl is not None else []), *(FIELDS if composition == "field" else []), *overrides])
    start = time.perf_counter()
    run_config(config)
    wall = time.perf_counter() - start
    with open(out / "statistics_physical.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {"cells": list(cells), "levels": levels, "cfl": config["time"]["cfl"], "dt": dt, "composition": composition,
            "t": [float(r["time [Myr]"]) for r in rows], "top": [1e3 * float(r["topography_max [km]"]) for r in rows],
            "lost": int(rows[-1].get("n_lost", 0)), "steps": len(rows) - 1, "wall": wall,
            "cells_max": max(int(r["cells"]) for r in rows)}


def write(out: Path, results: list[dict[str, Any]]) -> None:
    lines = ["# Crameri et al. (2012) case 2: a blob rising under a lithosphere, with a free surface", "",
             "Generated by `benchmarks/free_surface/crameri_case2.py` (configs/crameri_case2_free_surface.yaml; "
             "particles, 16 per cell). The largest topography [m] at the published times, beside MILAMIN, SULEC and "
             "Underworld (ASPECT's benchmarks/crameri_et_al/case_2 data).", "",
             "| t [Myr] | " + " | ".join(PUBLISHED) + " | spread | "
             + " | ".join(f"{label(r)}, CFL {r.get('cfl', 0.1):g}" for r in results) + " |",
             "|---|" + "---|" * (len(PUBLISHED) + 1 + len(results))]
    for i, t in enumerate(TIMES):
        codes = [v[i] for v in PUBLISHED.values()]
        ours = [f"{np.interp(t, r['t'], r['top']):.1f}" if r["t"][-1] >= t - 1e-9 else "-" for r in results]
        lines.append(f"| {t:g} | " + " | ".join(f"{c:.1f}" for c in codes) + f" | {min(codes):.1f}-{max(codes):.1f} | "
                     + " | ".join(ours) + " |")
    lines += ["", "| run | largest dt [kyr] | steps | most cells | wall [s] | lost | peak [m] | at [Myr] |",
              "|---|---|---|---|---|---|---|---|"]
    for r in results:
        k = int(np.argmax(r["top"]))
        lines.append(f"| {label(r)}, CFL {r.get('cfl', 0.1):g} | {r['dt']:g} | {r['steps']} | {r.get('cells_max', '-')} | "
                     f"{r['wall']:.0f} | {r['lost']} | {r['top'][k]:.1f} | {r['t'][k]:.2f} |")
    (out / "crameri_case2.md").write_text("\n".join(lines) + "\n")
    (out / "crameri_case2.json").write_text(json.dumps(results, indent=1))
    _picture(out / "crameri_case2.png", results)


def _picture(path: Path, results: list[dict[str, Any]]) -> None:
    """The codes' curves over the time the runs cover, and the runs (each its own gray and dashes)."""
    end = max(r["t"][-1] for r in results)
    shown = np.asarray([t for t in TIMES if t <= end * (1 + 1e-9)])
    curves = [(shown, np.asarray(values[: shown.size]), name, {"marker": "o", "markersize": 3, "linewidth": 0.8})
              for name, values in PUBLISHED.items()]
    styles = [(":", "0.55"), ("-.", "0.35"), ("--", "0.0"), ("-", "tab:purple"), ("-", "tab:red"), ("--", "tab:brown")]
    curves += [(np.asarray(r["t"]), np.asarray(r["top"]), f"this code, {label(r)}",
                {"color": styles[i % len(styles)][1], "linestyle": styles[i % len(styles)][0], "linewidth": 1.2})
               for i, r in enumerate(results)]
    curves_figure(path, curves, xlabel="time [Myr]", ylabel="largest topography [m]",
                  title="Crameri case 2: a blob under a lithosphere, free surface")


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", nargs="+", default=["224x56"])
    parser.add_argument("--end", type=float, default=20.0, help="end time [Myr]")
    parser.add_argument("--dt", type=float, default=20.0, help="largest step [kyr]")
    parser.add_argument("--cfl", type=float, default=None, help="Courant number (default: the config's, 0.1)")
    parser.add_argument("--composition", choices=("particles", "field"), default="particles",
                        help="the materials on particles (the config's) or as advected P2 fields")
    parser.add_argument("--keep", action="store_true",
                        help="keep the other runs of <out>/crameri_case2.json in the table (runs made one at a time)")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out = Path(args.out)
    results = []
    if args.keep and (out / "crameri_case2.json").exists():
        wanted = {label({"cells": c, "levels": lv, "composition": args.composition})
                  for c, lv in map(parse_mesh, args.cells)}
        results = [r for r in json.loads((out / "crameri_case2.json").read_text()) if label(r) not in wanted]
    for text in args.cells:
        cells, levels = parse_mesh(text)
        r = run(cells, args.dt, args.end, out / "runs" / f"case2_{text}_{args.composition}", levels=levels,
                cfl=args.cfl, composition=args.composition)
        results.append(r)
        results.sort(key=lambda r: 2800.0 / r["cells"][0] / 2 ** r.get("levels", 0), reverse=True)  # coarse first
        if MPI.COMM_WORLD.rank == 0:
            print(f"{text}: topography at 3 Myr {np.interp(3.0, r['t'], r['top']):.1f} m, peak {max(r['top']):.1f} m, "
                  f"{r['wall']:.0f} s, lost {r['lost']}", flush=True)
    if MPI.COMM_WORLD.rank == 0:
        write(out, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
