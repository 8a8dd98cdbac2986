"""Lab-note helper: where the materials' volume drift lives -- in the particles or in the fit.

    python -m benchmarks.schmeling.log.volume_sources RUN_DIR [EVERY]

For every EVERY-th particle file of RUN_DIR: the air's and the lithosphere's area by the nearest
particle (each point of a 1 km grid takes the material of its nearest particle: no cell, no fit),
beside the ``materials`` statistic of the same step (the fitted fractions' integral), both against
the areas at t = 0 (150 000 and 210 000 km^2); and how many lithosphere particles the population
control has added (ids above the first file's largest id) against the first file's count.
"""

import csv
import sys
from pathlib import Path

import h5py
import numpy as np
from scipy.spatial import cKDTree

AREA = {"air": 3000.0 * 50.0, "lithosphere": 2000.0 * 100.0 + 100.0 * 100.0}


def main(run: Path, every: int) -> None:
    with open(run / "statistics_physical.csv", newline="") as f:
        stats = {int(r["step"]): r for r in csv.DictReader(f)}
    gx, gz = np.meshgrid(np.arange(0.5, 3000.0, 1.0), np.arange(0.5, 750.0, 1.0))
    grid = np.c_[gx.ravel(), gz.ravel()]
    files = sorted(run.glob("particles_*.h5"))
    with h5py.File(files[0], "r") as f:
        first_id = int(f["ids"][:].max())
        first_lith = int((f["properties/lithosphere"][:] > 0.5).sum())
    for name in files[::every]:
        with h5py.File(name, "r") as f:
            x, ids, step = f["positions"][:, :2], f["ids"][:], int(f.attrs["step"])
            prop = {m: f[f"properties/{m}"][:] for m in AREA}
            t = float(f.attrs["time"])
        _, nearest = cKDTree(x).query(grid)
        row = stats.get(step, {})
        parts = []
        for m, area in AREA.items():
            mine = 100.0 * (prop[m][nearest].sum() / area - 1.0)
            fitted = 100.0 * (float(row.get(f"volume_{m} [km^2]", "nan")) / area - 1.0)
            parts.append(f"{m} nearest {mine:+.2f} % fit {fitted:+.2f} %")
        new_lith = int(((ids > first_id) & (prop["lithosphere"] > 0.5)).sum())
        print(f"t={t:5.1f}: " + " | ".join(parts) + f" | new lithosphere particles {new_lith} "
              f"({100.0 * new_lith / first_lith:+.2f} % of {first_lith})")


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 1)
