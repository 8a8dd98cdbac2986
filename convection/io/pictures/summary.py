"""``summary.png`` (matplotlib): the last field with the mesh and the run's curves over time.

The field is the final temperature (or, without an energy equation, the material field), read from
the last field file (``fields_NNN.h5`` written by :mod:`convection.io.fields`); the curves are vrms,
the Nusselt number and the topography where measured, and the cell count, from ``statistics.csv``
(``statistics_physical.csv`` in a model's units).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple
from collections.abc import Callable

import numpy as np

from convection.io.pictures.labels import Labels, plain_ticks
from convection.io.pictures.run_files import (NON_MATERIAL_FIELDS, RunFilesError, check_run_folder, field_files,
                                              field_names, field_units, read_last_field, read_statistics)
from convection.io.statistics import StatisticsFileError

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["FlatMesh", "curve_panels", "flat_mesh", "plot_run", "summary_field", "summary_figure"]


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
    return time, time_label, panels


class FlatMesh(NamedTuple):
    """The triangles a 2D picture of a field draws.

    Attributes:
        points: Picture coordinates (horizontal, vertical), shape=(num_points, 2).
        triangles: Vertex indices, shape=(num_triangles, 3), int64.
        cell_of: The mesh cell of each triangle, shape=(num_triangles,), int64 (for cell values).
        outlines: The cells (or faces) as the mesh has them, for its edges, shape=(num, 3 or 4).
        axes: The coordinates shown, e.g. ``(0, 1)`` in 2D, ``(0, 2)`` for an x-z plane in 3D.
        where: Which part of a 3D mesh is shown ("" in 2D).
    """

    points: np.ndarray
    triangles: np.ndarray
    cell_of: np.ndarray
    outlines: np.ndarray
    axes: tuple[int, int]
    where: str


_TET_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])


def flat_mesh(points: np.ndarray, cells: np.ndarray) -> FlatMesh | None:
    """What of a mesh a matplotlib picture can draw: triangles as they are, quadrilaterals cut in two;
    of tetrahedra, the faces on the plane y = (smallest y), the x-z side of a box nearest to a viewer
    at -y; None for hexahedra or a 3D mesh without such a side (e.g. a spherical shell)."""
    points = np.asarray(points, dtype=np.float64)
    flat = points.shape[1] < 3 or np.ptp(points[:, 2]) == 0.0
    if cells.shape[1] == 3:
        return FlatMesh(points[:, :2], cells.astype(np.int64), np.arange(len(cells)), cells, (0, 1), "")
    if cells.shape[1] == 4 and flat:  # quadrilaterals, their vertices in cyclic order (XDMF's)
        halves = np.concatenate([cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]]).astype(np.int64)
        return FlatMesh(points[:, :2], halves, np.tile(np.arange(len(cells)), 2), cells, (0, 1), "")
    if cells.shape[1] != 4:
        return None
    y0, extent = float(points[:, 1].min()), float(np.ptp(points))
    on_side = np.abs(points[:, 1] - y0) <= 1e-9 * extent
    faces = cells[:, _TET_FACES]  # (cells, 4, 3)
    keep = on_side[faces].all(axis=2)
    if not keep.any():
        return None
    cell_of, face = np.nonzero(keep)
    triangles = faces[cell_of, face].astype(np.int64)
    return FlatMesh(points[:, [0, 2]], triangles, cell_of.astype(np.int64), triangles, (0, 2), f"side y = {y0:.4g}")


def _draw_field(fig: Figure, ax: Axes, shown: tuple[str, tuple[np.ndarray, np.ndarray, np.ndarray, float]],
                mesh: FlatMesh, labels: Labels) -> None:
    """The field with the mesh, axes in the output's units, a colour bar with plain numbers."""
    import matplotlib.tri as mtri
    from matplotlib.collections import PolyCollection

    name, (points, cells, values, t) = shown
    tri = mtri.Triangulation(mesh.points[:, 0], mesh.points[:, 1], mesh.triangles)
    values = values.reshape(-1)
    at_points = values.size == len(points)
    shown_values = values if at_points else values[: len(cells)][mesh.cell_of]
    lo, hi = float(shown_values.min()), float(shown_values.max())
    if name == "temperature" and labels.length is None:
        lo, hi = 0.0, 1.0
    cmap = "coolwarm" if name == "temperature" else "viridis"
    image = ax.tripcolor(tri, shown_values, shading="gouraud" if at_points else "flat", cmap=cmap, vmin=lo, vmax=hi)
    ax.add_collection(PolyCollection(mesh.points[mesh.outlines], facecolors="none", edgecolors="k", linewidths=0.1,
                                     alpha=0.4))
    bar = fig.colorbar(image, ax=ax, fraction=0.04, pad=0.02)
    bar.set_label(plain_ticks(bar.ax.yaxis, lo, hi, labels.of(name)))
    for axis, coordinate, label in ((ax.xaxis, 0, ax.set_xlabel), (ax.yaxis, 1, ax.set_ylabel)):
        column = mesh.points[:, coordinate]
        label(plain_ticks(axis, float(column.min()), float(column.max()), labels.axis("xz"[coordinate])))
    ax.set_aspect("equal")
    where = f", {mesh.where}" if mesh.where else ""
    ax.set_title(f"{name} and mesh at t = {labels.time(t)}{where}")


_WIDE = 1.8
"""A field wider than this (width / height) goes above the curves, a narrower one beside them."""


class _Layout(NamedTuple):
    """The axes of a summary: the field's (None without a field), one per curve, and for each curve
    whether the time is written below it."""

    field: Axes | None
    curves: list[Axes]
    time_labelled: list[bool]


def _layout(fig: Figure, mesh: FlatMesh | None, curves: int) -> _Layout:
    """Axes for the field and the curves, nothing left empty: a wide field above a row of curves, a
    narrower one beside a column of them (sharing the time axis, written below the last only)."""
    if mesh is None or curves == 0:
        grid = fig.add_gridspec(1, max(1, curves))
        field_ax = fig.add_subplot(grid[0, 0]) if mesh is not None else None
        return _Layout(field_ax, [fig.add_subplot(grid[0, i]) for i in range(curves)], [True] * curves)
    width, height = np.ptp(mesh.points, axis=0)
    if width >= _WIDE * height:
        grid = fig.add_gridspec(2, curves)
        return _Layout(fig.add_subplot(grid[0, :]), [fig.add_subplot(grid[1, i]) for i in range(curves)],
                       [True] * curves)
    grid = fig.add_gridspec(curves, 2, width_ratios=[1.3, 1.0])
    first = fig.add_subplot(grid[0, 1])
    column = [first, *(fig.add_subplot(grid[i, 1], sharex=first) for i in range(1, curves))]
    for ax in column[:-1]:
        ax.tick_params(labelbottom=False)
    return _Layout(fig.add_subplot(grid[:, 0]), column, [False] * (curves - 1) + [True])


def plot_run(directory: str | Path, png: str | Path | None = None, *, log: Callable[[str], None] | None = None) -> Path:
    """Draw the run in ``directory`` (:func:`summary_figure`) into a PNG (default
    ``<directory>/summary.png``).

    Raises:
        RunFilesError: ``statistics.csv`` or the last field file is missing or damaged.
    """
    import matplotlib.pyplot as plt

    directory = check_run_folder(directory)
    png = Path(png) if png else directory / "summary.png"
    fig = summary_figure(directory, log=log)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png


def summary_figure(directory: str | Path, *, log: Callable[[str], None] | None = None) -> Figure:
    """The summary of the run in ``directory``: the last temperature with the mesh (for a model
    without an energy equation its materials; of a 3D box its side y = (smallest y); left out if
    the run wrote no fields or its mesh has no such side), then one panel for each of vrms, the
    Nusselt number, the topography and the cells over time that the run measured -- in its units
    where it has them (``statistics_physical.csv``), axes and colour bar with plain numbers. No
    panel is left empty. ``log`` hears about a cut-off last line of statistics.csv.

    Raises:
        RunFilesError: ``statistics.csv`` or the last field file is missing or damaged.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory = check_run_folder(directory)
    try:
        stats = read_statistics(directory / "statistics.csv", log=log)
    except StatisticsFileError as err:
        raise RunFilesError(str(err)) from None
    shown = summary_field(directory)
    mesh = None if shown is None else flat_mesh(shown[1][0], shown[1][1])
    labels = Labels(field_units(directory) or {})
    time, time_label, panels = curve_panels(directory, stats, log)
    fig = plt.figure(figsize=(12, 7 if mesh is not None and panels else 4), constrained_layout=True)
    layout = _layout(fig, mesh, len(panels))
    if shown is not None and mesh is not None:
        _draw_field(fig, layout.field, shown, mesh, labels)
    for axi, labelled, (values, label) in zip(layout.curves, layout.time_labelled, panels):
        _draw_curve(axi, time[: len(values)], values, time_label if labelled else None, label)
    if mesh is None and not panels:
        fig.text(0.5, 0.5, "nothing to draw: no field output and no vrms, Nusselt number, topography or cells",
                 ha="center", va="center")
    elif mesh is None:
        fig.suptitle("no field output" if shown is None
                     else f"{shown[0]}: not drawn (hexahedra, or no flat side y = min)")
    return fig


def _draw_curve(ax: Axes, time: np.ndarray, values: np.ndarray, time_label: str | None, label: str) -> None:
    """One statistics column over time, with plain tick numbers."""
    ax.plot(time, values)
    xlabel = plain_ticks(ax.xaxis, float(np.min(time, initial=0.0)), float(np.max(time, initial=0.0)),
                         time_label or "")
    if time_label is not None:
        ax.set_xlabel(xlabel)
    finite = values[np.isfinite(values)]
    ax.set_ylabel(plain_ticks(ax.yaxis, float(np.min(finite, initial=0.0)), float(np.max(finite, initial=0.0)), label))
