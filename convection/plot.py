"""Pictures of a finished run: ``python -m convection.plot OUTPUT_DIR [--png FILE]``.

Reads ``statistics.csv`` and the last field file (``fields_NNN.h5`` written by
:mod:`convection.output`) and draws the final temperature with the mesh, and vrms, Nusselt number
and cell count over time.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

__all__ = ["read_statistics", "read_last_field", "plot_run"]


def read_statistics(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a statistics.csv as float arrays."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}
    return {key: np.array([float(r[key]) for r in rows]) for key in rows[0]}


def read_last_field(directory: str | Path, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(points (n, 3), cells (m, k), values, time) of the latest step of field ``name``."""
    import h5py

    files = sorted(Path(directory).glob("fields_*.h5"))
    if not files:
        raise FileNotFoundError(f"no fields_*.h5 in {directory}")
    with h5py.File(files[-1], "r") as h5:
        points = h5["Mesh/mesh/geometry"][...]
        cells = h5["Mesh/mesh/topology"][...]
        steps = h5[f"Function/{name}"]
        key = max(steps.keys(), key=lambda k: float(k.replace("_", ".")))
        values = steps[key][...]
    return points, cells, values, float(key.replace("_", "."))


def plot_run(directory: str | Path, png: str | Path | None = None) -> Path:
    """Draw the run in ``directory`` into a PNG (default ``<directory>/summary.png``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri

    directory = Path(directory)
    png = Path(png) if png else directory / "summary.png"
    stats = read_statistics(directory / "statistics.csv")
    points, cells, values, t = read_last_field(directory, "temperature")
    fig = plt.figure(figsize=(12, 7), constrained_layout=True)
    grid = fig.add_gridspec(2, 3)
    ax = fig.add_subplot(grid[0, :])
    if cells.shape[1] == 3:
        tri = mtri.Triangulation(points[:, 0], points[:, 1], cells)
        image = ax.tripcolor(tri, values.reshape(-1), shading="gouraud", cmap="coolwarm", vmin=0.0, vmax=1.0)
        ax.triplot(tri, color="k", linewidth=0.1, alpha=0.4)
        fig.colorbar(image, ax=ax, label="T")
    ax.set_aspect("equal")
    ax.set_title(f"temperature and mesh at t = {t:.4g}")
    for i, (key, label) in enumerate((("vrms", "vrms"), ("nusselt", "Nusselt (top)"), ("cells", "cells"))):
        axi = fig.add_subplot(grid[1, i])
        if key in stats:
            axi.plot(stats["time"], stats[key])
        axi.set_xlabel("time")
        axi.set_ylabel(label)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m convection.plot", description=__doc__.split("\n")[0])
    parser.add_argument("directory")
    parser.add_argument("--png", default=None)
    args = parser.parse_args(argv)
    print(plot_run(args.directory, args.png))
    return 0


if __name__ == "__main__":
    sys.exit(main())
