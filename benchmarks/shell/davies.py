"""Isoviscous convection in a 2D annulus against the cylindrical-shell benchmark of Davies et al.
(reference values: ASPECT's runs of the benchmark, ASPECT manual, "The 2D cylindrical shell
benchmarks by Davies et al.").

Runs ``configs/annulus_davies.yaml`` to steady state for each case and mesh size and tabulates the
final volume-mean temperature, Nusselt numbers of the outer (top) and inner (bottom) surface and
vrms against the reference:

======  =============================  =====================  ======  ======  ======  ========
case    name                           settings               <T>     Nu_T    Nu_B    vrms
======  =============================  =====================  ======  ======  ======  ========
1.1     BA_Ra104_Iso_ZS                zero slip, Ra = 1e4    0.403   2.464   2.468   19.053
2.1     BA_Ra104_Iso_FS                free slip, Ra = 1e4    0.382   4.7000  4.706   46.244
2.2     BA_Ra105_Iso_FS                free slip, Ra = 1e5    0.382   9.548   9.584   193.371
======  =============================  =====================  ======  ======  ======  ========

The Nusselt numbers are the heat flow through a surface over the conductive heat flow of the shell
(Davies et al.'s definition; conduction gives 1 on both surfaces).

Usage::

    python -m benchmarks.shell.davies --cases 2.1 1.1 --resolutions 0.1 0.07 0.05
    python -m benchmarks.shell.davies --cases 2.1 --resolutions 0.14 --adaptive 1   # adaptive mesh
    python -m benchmarks.shell.davies --table          # the table from measured/davies.json only

Writes ``measured/davies.json`` (merged with earlier runs: one record per case and resolution) and
prints the markdown table of ``README.md``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import start_cli_run
from benchmarks.harness import Benchmark
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, ranks=1, overrides=True)

CONFIG = HERE.parents[1] / "configs" / "annulus_davies.yaml"
MEASURED = HERE / "measured" / "davies.json"
SOURCE = ("ASPECT manual, 'The 2D cylindrical shell benchmarks by Davies et al.' (W. Durkin, W. Bangerth), "
          "results table; ASPECT at 1536 x 128 cells (geodynamics/aspect, benchmarks/davies_et_al)")

CASES: dict[str, dict] = {
    "1.1": {"name": "BA_Ra104_Iso_ZS", "overrides": ["boundary.velocity.inner=no_slip",
                                                     "boundary.velocity.outer=no_slip"],
            "reference": {"T_mean": 0.403, "nusselt": 2.464, "nusselt_bottom": 2.468, "vrms": 19.053}},
    "2.1": {"name": "BA_Ra104_Iso_FS", "overrides": [],
            "reference": {"T_mean": 0.382, "nusselt": 4.7000, "nusselt_bottom": 4.706, "vrms": 46.244}},
    "2.2": {"name": "BA_Ra105_Iso_FS", "overrides": ["physics.Ra=1e5"],
            "reference": {"T_mean": 0.382, "nusselt": 9.548, "nusselt_bottom": 9.584, "vrms": 193.371}},
}
"""The benchmark cases: config overrides and the reference values."""

COLUMNS = ("T_mean", "nusselt", "nusselt_bottom", "vrms")


ADAPTIVE_END = 0.8


def adaptive_overrides(levels: int) -> list[str]:
    """Config overrides of an adaptive run: the base mesh refined up to ``levels`` times where the
    temperature's Kelly indicator is largest (30 % of the cells up, 50 % down, every 10 steps), so
    the fine cells follow the boundary layers and plumes.

    An adapting mesh keeps the statistics moving by about 1e-5 (cells go up and down a level at the
    edges of the refined region every 10 steps), so the config's steady-state test (relative change
    below 1e-5 over 100 steps) never fires: adaptive runs end at ``t = 0.8`` instead, later than any
    uniform run took to become steady (t = 0.51 to 0.65), and the table's drift column shows how
    still they are."""
    return ["adaptivity.enabled=true", "adaptivity.min_level=0", f"adaptivity.max_level={levels}",
            "adaptivity.every=10", "adaptivity.refine_fraction=0.3", "adaptivity.coarsen_fraction=0.5",
            "adaptivity.fields=[temperature]", f"time.end={ADAPTIVE_END}", "time.steady_state_tolerance=null"]


def _key(record: dict) -> tuple:
    return record["case"], record["resolution"], record.get("adaptive_levels", 0)


def run_case(case: str, resolution: float, *, output: Path, ranks: int, extra: list[str], adaptive: int = 0) -> dict:
    """Run one case at one mesh size to steady state; the final statistics row and the run's facts.
    ``adaptive`` > 0: that many adaptive levels above the base mesh of this size."""
    label = f"case_{case}_h{resolution:g}" + (f"_adaptive{adaptive}" if adaptive else "")
    out = output / label
    overrides = [f"mesh.resolution={resolution}", *CASES[case]["overrides"],
                 *(adaptive_overrides(adaptive) if adaptive else []), *extra]
    start = time.time()
    start_cli_run(CONFIG, out, ranks=ranks, overrides=overrides, log=output / f"{label}.log").wait()
    stats = read_statistics(out / "statistics.csv")
    window = max(1, len(stats["time"]) // 10)
    # An adaptive run's values: the mean over the last tenth of the steps (the outer Nusselt number
    # jumps by up to 2e-3 for a few steps after each adaptation, while the boundary layer's
    # temperature settles on the new cells).
    final = {k: float(np.mean(stats[k][-window:]) if adaptive else stats[k][-1]) for k in COLUMNS}
    drift = {k: float((np.ptp(stats[k][-window:]) if adaptive else abs(stats[k][-1] - stats[k][-window]))
                      / max(abs(final[k]), 1e-300)) for k in COLUMNS}
    return {"case": case, "resolution": resolution, "adaptive_levels": adaptive, "ranks": ranks,
            "cells": int(stats["cells"][-1]), "cells_max": int(max(stats["cells"])), "steps": int(stats["step"][-1]),
            "time": float(stats["time"][-1]), "final": final, "drift_last_tenth": drift,
            "wall_seconds": time.time() - start, "overrides": overrides}


def load_measured() -> list[dict]:
    return json.loads(MEASURED.read_text()) if MEASURED.is_file() else []


def table(records: list[dict]) -> str:
    """Markdown table: every measured case and size, with the reference row of each case."""
    head = ("| case | mesh size | cells | steps | end time | <T> | Nu_T (outer) | Nu_B (inner) | vrms | "
            "largest deviation from the reference | largest change over the last tenth of the steps (adaptive: max - min) |")
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for case in sorted({r["case"] for r in records}):
        ref = CASES[case]["reference"]
        rows.append(f"| {case} {CASES[case]['name']} | reference (ASPECT) | | | | {ref['T_mean']} | {ref['nusselt']} "
                    f"| {ref['nusselt_bottom']} | {ref['vrms']} | | |")
        for r in sorted((r for r in records if r["case"] == case),
                        key=lambda r: (r.get("adaptive_levels", 0), -r["resolution"])):
            f = r["final"]
            worst = max(COLUMNS, key=lambda k: abs(f[k] / ref[k] - 1.0))
            size = f"{r['resolution']:g}" + (f", adaptive +{r['adaptive_levels']}" if r.get("adaptive_levels") else "")
            cells = f"{r.get('cells', '')}" + (f" (at most {r['cells_max']})" if r.get("adaptive_levels") else "")
            drift = max(r["drift_last_tenth"].values())
            rows.append(f"| {case} | {size} | {cells} | {r['steps']} | {r['time']:.3g} "
                        f"| {f['T_mean']:.4f} "
                        f"| {f['nusselt']:.4f} | {f['nusselt_bottom']:.4f} | {f['vrms']:.3f} "
                        f"| {100 * (f[worst] / ref[worst] - 1.0):+.2f} % ({worst}) | {drift:.1e} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=["2.1"], choices=sorted(CASES))
    parser.add_argument("--resolutions", type=float, nargs="+", default=[0.1, 0.07])
    parser.add_argument("--output", type=Path, default=Path("output/shell_davies"))
    parser.add_argument("--adaptive", type=int, default=0, metavar="LEVELS",
                        help="adapt the mesh by the temperature, up to LEVELS refinements of the base")
    parser.add_argument("--table", action="store_true", help="only print the table of measured/davies.json")
    args = parser.parse_args(argv)
    records = load_measured()
    if not args.table:
        BENCHMARK.log_load("start")
        for case in args.cases:
            for resolution in args.resolutions:
                record = run_case(case, resolution, output=args.output, ranks=args.ranks, extra=args.set,
                                  adaptive=args.adaptive)
                print(json.dumps(record), flush=True)
                # measured again: another run of this script may have added a record meanwhile
                records = [r for r in load_measured() if _key(r) != _key(record)] + [record]
                MEASURED.write_text(json.dumps(records, indent=1) + "\n")
    print(f"Reference: {SOURCE}.\n")
    print(table(records))
    return 0


if __name__ == "__main__":
    sys.exit(main())
