"""Lab-note helper: tip depth at 10/20/30/40 Myr, volume drift and cost of diagnostic run folders.

    python -m benchmarks.schmeling.log.tabulate RUN_DIR [RUN_DIR ...]

Tip = depth_lithosphere - 50 km (linear between steps); drift = volume at the last step over the
first, minus 1; wall = the last step's wall_time column summed (per-step seconds) or the log's.
"""

import csv
import sys
from pathlib import Path

import numpy as np

TIMES = (0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 40.0)


def row(run: Path) -> str:
    with open(run / "statistics_physical.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["time [Myr]"]) for r in rows])
    tip = np.array([float(r["depth_lithosphere [km]"]) for r in rows]) - 50.0
    tips = [f"{np.interp(s, t, tip):.0f}" if s <= t[-1] + 1e-9 else "-" for s in TIMES]
    drift = []
    for m in ("air", "lithosphere"):
        v = np.array([float(r[f"volume_{m} [km^2]"]) for r in rows])
        drift.append(f"{100 * (v[-1] / v[0] - 1):+.2f}%")
    wall = "?"
    log = run.with_suffix(".log")
    if log.exists():
        tail = [line for line in log.read_text().splitlines() if line.startswith("rc=")]
        wall = tail[-1] if tail else "running"
    return f"| {run.name} | {t[-1]:.1f} | {len(rows) - 1} | " + " | ".join(tips) + " | " + " | ".join(drift) + f" | {wall} |"


if __name__ == "__main__":
    print("| run | t_end [Myr] | steps | " + " | ".join(f"tip {s:g}" for s in TIMES) + " | dV air | dV lith | cost |")
    print("|---" * (5 + len(TIMES) + 2) + "|")
    for arg in sys.argv[1:]:
        print(row(Path(arg)))
