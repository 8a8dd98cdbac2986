"""``summary.png`` (matplotlib): the last field with the mesh and the run's curves over time.

The field is the final temperature (or, without an energy equation, the material field), read from
the last field file (``fields_NNN.h5`` written by :mod:`convection.io.fields`); the curves are vrms,
the Nusselt number and the topography where measured, and the cell count, from ``statistics.csv``
(``statistics_physical.csv`` in a model's units).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from convection.io.pictures.labels import Labels
from convection.io.pictures.run_files import (NON_MATERIAL_FIELDS, RunFilesError, check_run_folder, field_files,
                                              field_names, field_units, read_last_field, read_statistics)
from convection.io.statistics import StatisticsFileError

__all__ = ["curve_panels", "plot_run", "summary_field"]


def summary_field(directory: Path) -> tuple[str, tuple[np.ndarray, np.ndarray, np.ndarray, float]] | None:
    """The field the summary shows: the temperature, unless it is constant (no energy equation) and
    the run has materials; then the material index (or the one material's fraction)."""
    if not field_files(directory):
        return None
    names = field_names(directory)
    temperature = read_last_field(directory, "temperature") if "temperature" in names else None
    if temperature is not None and np.ptp(temperature[2]) > 0.0:
        return "temperature", temperature
    others = [n for n in names if n not in (*NON_MATERIAL_FIELDS, "viscosity")]
    material = "material" if "material" in names else (others[0] if others else None)
    if material is not None:
        return material, read_last_field(directory, material)
    return ("temperature", temperature) if temperature is not None else None


def curve_panels(directory: Path, stats: dict[str, np.ndarray], log: Callable[[str], None] | None
            ) -> tuple[np.ndarray, str, list[tuple[np.ndarray, str]]]:
    """(time, its label, [(values, label)] of the lower panels): vrms, the Nusselt number where the run
    measured one, topography and cells; from statistics_physical.csv (with units) where the run wrote it."""
    physical = directory / "statistics_physical.csv"
    table, time_label = stats, "time"
    if physical.is_file():
        try:
            table = read_statistics(physical, log=log)
        except (OSError, StatisticsFileError):
            table = stats
    labelled = {name.split(" [")[0]: (values, name) for name, values in table.items()}
    time, time_label = labelled.get("time", (stats.get("time", np.zeros(0)), "time"))
    panels = []
    for key, label in (("vrms", "vrms"), ("nusselt", "Nusselt (top)"), ("topography_max", "topography (max)"),
                       ("cells", "cells")):
        if key not in labelled or not np.isfinite(labelled[key][0]).any():
            continue
        values, name = labelled[key]
        panels.append((values, label + name[len(key):] if name != key else label))
    return time, time_label, panels[:3]


def plot_run(directory: str | Path, png: str | Path | None = None, *, log: Callable[[str], None] | None = None) -> Path:
    """Draw the run in ``directory`` into a PNG (default ``<directory>/summary.png``): the last
    temperature with the mesh (for a model without an energy equation its materials; a note instead
    if the run wrote no fields), then up to three of vrms, the Nusselt number, the topography and
    the cells over time -- only what the run measured, in its units where it has them
    (``statistics_physical.csv``). ``log`` hears about a cut-off last line of statistics.csv.

    Raises:
        RunFilesError: ``statistics.csv`` or the last field file is missing or damaged.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri

    directory = check_run_folder(directory)
    png = Path(png) if png else directory / "summary.png"
    try:
        stats = read_statistics(directory / "statistics.csv", log=log)
    except StatisticsFileError as err:
        raise RunFilesError(str(err)) from None
    shown = summary_field(directory)
    units = field_units(directory)
    labels = Labels(units or {})
    time, time_label, panels = curve_panels(directory, stats, log)
    fig = plt.figure(figsize=(12, 7), constrained_layout=True)
    grid = fig.add_gridspec(2, max(1, len(panels)))
    ax = fig.add_subplot(grid[0, :])
    if shown is None:
        ax.text(0.5, 0.5, "no field output", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
    else:
        name, (points, cells, values, t) = shown
        if cells.shape[1] == 3:
            tri = mtri.Triangulation(points[:, 0], points[:, 1], cells)
            values = values.reshape(-1)
            if name == "temperature":
                limits = (0.0, 1.0) if units is None else (float(values.min()), float(values.max()))
                image = ax.tripcolor(tri, values, shading="gouraud", cmap="coolwarm", vmin=limits[0], vmax=limits[1])
            else:
                image = ax.tripcolor(tri, values if values.size == len(points) else values[: len(cells)],
                                     shading="gouraud" if values.size == len(points) else "flat", cmap="viridis")
            ax.triplot(tri, color="k", linewidth=0.1, alpha=0.4)
            label = labels.of(name)
            fig.colorbar(image, ax=ax, label="T" if label == "temperature" else label)
        ax.set_aspect("equal")
        where = f"({units['length']})" if units is not None and units.get("length") else "(solver's units)"
        ax.set_title(f"{name} and mesh at t = {labels.time(t)} {where}")
    for i, (values, label) in enumerate(panels):
        axi = fig.add_subplot(grid[1, i])
        axi.plot(time[: len(values)], values)
        axi.set_xlabel(time_label)
        axi.set_ylabel(label)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png
