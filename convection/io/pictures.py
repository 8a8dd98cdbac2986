"""Pictures of a run: ``python -m convection.plot RUN_DIR [--png FILE] [--times T ...]``.

``summary.png`` (matplotlib): the final temperature (or, without an energy equation, the material
field) with the mesh, read from the last field file (``fields_NNN.h5`` written by
:mod:`convection.io.fields`), and vrms, the Nusselt number and the topography where measured, and
the cell count over time from ``statistics.csv`` (``statistics_physical.csv`` in a model's units).

``snapshots/*.png`` (pyvista, rendered off-screen): at chosen times of ``fields.xdmf`` (default: the
first, middle and last written time; a requested time snaps to the nearest written one),

- the material field (``material``, else ``composition``, else the first other scalar field that is
  not temperature, pressure or velocity; or ``--field NAME``) with the particles of
  ``particles.xdmf`` on top (the written particle time nearest to the field time; coloured by
  ``--particle-property NAME``, else black);
- the viscosity per cell on a logarithmic scale, where the run wrote one that varies;
- the temperature with the mesh edges (skipped, with a message, where it is constant, e.g. Ra = 0).

A run in physical units (``fields_units.json``) gets its times, units and colour-bar titles in
those units.

2D meshes are seen from +z. 3D meshes are cut by the vertical plane y = (centre of the domain): the
picture is that x-z section seen from -y, with the particles within one typical cell size of the
plane.

A spherical shell (3D, hollow around the origin) also gets a perspective ``shell_*.png`` (the seed
paper's picture of section 4.2): the temperature on the equatorial plane z = 0, the core as a grey
sphere, and the particles of the northern hemisphere (within ``--particle-radius``
of the centre if given) as points coloured by ``--particle-property`` (default ``displacement`` when
the particles carry it).

A missing or damaged file of the run folder (the folder itself, ``statistics.csv``, a field or
particle file) stops ``python -m convection.plot`` with one line ``error: ...`` naming it, exit
code 1 (:class:`convection.io.xdmf_check.RunFilesError`; an XDMF series and the HDF5 data of the
times drawn are checked before VTK reads them). A run without field output (statistics only)
gets its curves, and one line saying what was skipped. A ``statistics.csv`` whose last line was
cut off (a run killed while writing it) is read without that line.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from convection.io.statistics import StatisticsFileError, read_table
from convection.io.xdmf_check import RunFilesError, XdmfSeries

if TYPE_CHECKING:
    import pyvista as pv

__all__ = ["RunFilesError", "read_statistics", "read_last_field", "field_units", "plot_run", "import_pyvista",
           "snapshot_times", "plot_snapshots", "particle_series", "field_files", "check_run_folder"]

_FIELD_FILE = re.compile(r"fields_([0-9]+)\.h5")
"""The per-mesh field files :class:`convection.io.fields.FieldOutput` writes."""


def read_statistics(path: str | Path, *, log: Callable[[str], None] | None = None) -> dict[str, np.ndarray]:
    """Columns of a statistics.csv as float arrays, shape=(rows,) each ({} without rows); a last
    line cut off by a kill is left out (and ``log`` told so).

    Raises:
        FileNotFoundError: No such file.
        convection.io.statistics.StatisticsFileError: The file is damaged (one line naming the line).
    """
    table = read_table(path)
    if table.incomplete and log is not None:
        log(f"{path}: its last line was cut off (the run was stopped while writing it); left out")
    if not table.rows:
        return {}
    values = np.array([[float(v) for v in row] for row in table.rows], dtype=np.float64)
    return {name: values[:, i] for i, name in enumerate(table.columns)}


def field_files(directory: str | Path) -> list[Path]:
    """The ``fields_NNN.h5`` files of a run folder in the order they were written (by NNN)."""
    found = [p for p in Path(directory).glob("fields_*.h5") if _FIELD_FILE.fullmatch(p.name)]
    return sorted(found, key=lambda p: int(_FIELD_FILE.fullmatch(p.name).group(1)))


def read_last_field(directory: str | Path, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(points (n, 3), cells (m, k), values, time) of the latest step of field ``name``.

    Raises:
        RunFilesError: No field file, or the last one is damaged or lacks the field.
    """
    import h5py

    files = field_files(directory)
    if not files:
        raise RunFilesError(f"no fields_NNN.h5 in {directory}")
    try:
        with h5py.File(files[-1], "r") as h5:
            if f"Function/{name}" not in h5:
                raise RunFilesError(f"{files[-1]}: no field {name!r} (damaged?)")
            points = h5["Mesh/mesh/geometry"][...]
            cells = h5["Mesh/mesh/topology"][...]
            steps = h5[f"Function/{name}"]
            key = max(steps.keys(), key=lambda k: float(k.replace("_", ".")))
            values = steps[key][...]
    except RunFilesError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as err:
        raise RunFilesError(f"{files[-1]}: damaged HDF5 file ({' '.join(str(err).split())})") from None
    return points, cells, values, float(key.replace("_", "."))


def check_run_folder(directory: str | Path) -> Path:
    """``directory`` as a Path if it is a run folder with a ``statistics.csv``.

    Raises:
        RunFilesError: It is missing, not a folder, empty, or has no statistics.csv.
    """
    directory = Path(directory)
    if not directory.exists():
        raise RunFilesError(f"run folder '{directory}' not found")
    if not directory.is_dir():
        raise RunFilesError(f"'{directory}' is not a run folder (not a folder)")
    if not (directory / "statistics.csv").is_file():
        what = "is empty" if not any(directory.iterdir()) else "has no statistics.csv"
        raise RunFilesError(f"run folder '{directory}' {what}: nothing to draw")
    return directory


def _field_names(directory: Path) -> list[str]:
    """The fields of the last field file (empty if it cannot be read)."""
    import h5py

    files = field_files(directory)
    try:
        with h5py.File(files[-1], "r") as h5:
            return list(h5["Function"].keys()) if "Function" in h5 else []
    except (OSError, KeyError, ValueError, IndexError):
        return []


def _summary_field(directory: Path) -> tuple[str, tuple[np.ndarray, np.ndarray, np.ndarray, float]] | None:
    """The field the summary shows: the temperature, unless it is constant (no energy equation) and
    the run has materials; then the material index (or the one material's fraction)."""
    if not field_files(directory):
        return None
    names = _field_names(directory)
    temperature = read_last_field(directory, "temperature") if "temperature" in names else None
    if temperature is not None and np.ptp(temperature[2]) > 0.0:
        return "temperature", temperature
    others = [n for n in names if n not in (*NON_MATERIAL_FIELDS, "viscosity")]
    material = "material" if "material" in names else (others[0] if others else None)
    if material is not None:
        return material, read_last_field(directory, material)
    return ("temperature", temperature) if temperature is not None else None


def _panels(directory: Path, stats: dict[str, np.ndarray], log: Callable[[str], None] | None
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
    shown = _summary_field(directory)
    units = field_units(directory)
    labels = _Labels(units or {})
    time, time_label, panels = _panels(directory, stats, log)
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


# --------------------------------------------------------------------------- snapshots (pyvista)
NON_MATERIAL_FIELDS = ("temperature", "pressure", "velocity", "strain_rate_II", "stress_II")
MATERIAL_FIELDS = ("material", "composition")
_SIDE, _TOP, _BOTTOM = 30, 50, 100  # margins of a snapshot in pixels: sides, title, scalar bars
_MAX_WIDTH, _MAX_HEIGHT, _MIN_WIDTH = 1000, 700, 600  # size of the domain in the picture, pixels
_MIN_EDGE_CELL_PIXELS = 50.0  # mesh edges are drawn if cells cover at least this many pixels on average


def import_pyvista() -> ModuleType:
    """pyvista, with VTK's libraries loaded so that they render also in a process that uses DOLFINx.

    ``import dolfinx`` leaves the dlopen flags at ``RTLD_NOW | RTLD_GLOBAL``, which puts libdolfinx's
    C++ template instantiations (e.g. ``std::regex`` internals, new ``std::string`` ABI) in the
    global symbol scope. VTK's wheels are built with the old ``std::string`` ABI; loaded after
    DOLFINx, their calls bind to DOLFINx's copies and the first scalar bar aborts the process
    (``std::bad_alloc`` in ``vtkScalarBarActor``). Loaded with ``RTLD_DEEPBIND``, each VTK library
    finds its own symbols first. All VTK modules are loaded at once, so no module that pyvista
    loads later on demand binds the wrong way. Use this instead of ``import pyvista`` wherever
    DOLFINx may have been imported first.
    """
    if "pyvista" in sys.modules:
        return sys.modules["pyvista"]
    flags = sys.getdlopenflags()
    sys.setdlopenflags(os.RTLD_NOW | os.RTLD_DEEPBIND)
    try:
        import vtkmodules.all  # noqa: F401 - loads every VTK library under these flags

        import pyvista
        import pyvista.plotting  # noqa: F401
    finally:
        sys.setdlopenflags(flags)
    return pyvista


class _Series:
    """A Temporal XDMF collection read with VTK's XdmfReader, as ParaView reads it.

    Args:
        path: The ``.xdmf`` file.
    """

    def __init__(self, path: Path) -> None:
        self.series = XdmfSeries(path)  # checks the XML before VTK's parser sees it
        pv = import_pyvista()
        self.path = path
        self.reader = pv.get_reader(str(path))
        self.times = np.sort(np.asarray(self.reader.time_values, dtype=np.float64))

    def nearest(self, t: float) -> float:
        """The written time nearest to ``t``."""
        return float(self.times[np.argmin(np.abs(self.times - t))]) if self.times.size else float(t)

    def read(self, t: float) -> tuple[pv.DataSet, list[str]]:
        """The data set at written time ``t``, and the names of arrays VTK read with a wrong length.

        Arrays whose length matches neither the points nor the cells are dropped (VTK's reader
        reads e.g. an XDMF ``Matrix`` attribute as a single tuple).

        Raises:
            RunFilesError: An HDF5 file of that time is missing or damaged, or VTK read nothing.
        """
        pv = import_pyvista()
        self.series.check(t)
        if self.times.size:
            self.reader.set_active_time_value(t)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pyvista's InvalidMeshWarning: handled below
            data = self.reader.read()
            if isinstance(data, pv.MultiBlock):
                data = data.combine()
        if data.n_points == 0:
            raise RunFilesError(f"{self.path}: nothing could be read at t = {t:.6g} (damaged?)")
        dropped = []
        for arrays, size in ((data.point_data, data.n_points), (data.cell_data, data.n_cells)):
            for name in list(arrays.keys()):
                if arrays[name].shape[0] != size:
                    arrays.remove(name)
                    dropped.append(name)
        return data, dropped


class _View(NamedTuple):
    """How a picture looks at the domain.

    Attributes:
        axes: World axes shown (horizontal, vertical).
        normal: World axis pointing out of the picture plane.
        toward: +1 or -1: the side of the ``normal`` axis the camera is on.
    """

    axes: tuple[int, int]
    normal: int
    toward: float


_VIEW_2D = _View((0, 1), 2, 1.0)  # from +z: x right, y up
_VIEW_3D = _View((0, 2), 1, -1.0)  # from -y: x right, z up


def snapshot_times(available: Sequence[float], requested: Sequence[float] | None = None) -> list[float]:
    """The written times to draw: for each requested time the nearest available one.

    Args:
        available: Written times, shape=(n,).
        requested: Wanted times; default the first, middle and last available time.

    Returns:
        Sorted distinct times, each one of ``available``.
    """
    times = np.sort(np.asarray(available, dtype=np.float64))
    if times.size == 0:
        return []
    if requested is None:
        requested = [times[0], times[times.size // 2], times[-1]]
    return sorted({float(times[np.argmin(np.abs(times - t))]) for t in requested})


def _scalar_names(data: pv.DataSet) -> list[str]:
    """Scalar (one-component) point and cell arrays of ``data``, in file order."""
    names = []
    for arrays in (data.cell_data, data.point_data):
        names += [n for n in arrays.keys() if arrays[n].ndim == 1 or arrays[n].shape[1] == 1]
    return names


def _material_field(data: pv.DataSet, field: str | None) -> str | None:
    """The field of the composition picture (see the module docstring); None if there is none."""
    names = list(data.cell_data.keys()) + list(data.point_data.keys())
    if field is not None:
        if field not in names:
            raise ValueError(f"no field '{field}' in fields.xdmf; fields: {', '.join(names)}")
        return field
    scalars = _scalar_names(data)
    for name in (*MATERIAL_FIELDS, *(n for n in scalars if n not in NON_MATERIAL_FIELDS)):
        if name in scalars:
            return name
    return None


def _values(data: pv.DataSet, name: str) -> np.ndarray:
    values = data.cell_data[name] if name in data.cell_data.keys() else data.point_data[name]
    return np.linalg.norm(values, axis=1) if values.ndim > 1 and values.shape[1] > 1 else values.reshape(-1)


def _clim(values: np.ndarray) -> tuple[float, float]:
    """Colour range of ``values``; an end within round-off of zero becomes zero (no "-5.55e-17")."""
    lo, hi = float(np.min(values)), float(np.max(values))
    if hi <= lo:
        return lo - 0.5, hi + 0.5
    lo, hi = (0.0 if abs(v) <= 1e-9 * (hi - lo) else v for v in (lo, hi))
    return lo, hi


def _is_constant(values: np.ndarray) -> bool:
    lo, hi = float(np.min(values)), float(np.max(values))
    return hi - lo <= 1e-12 * max(1.0, abs(lo), abs(hi))


class _Picture:
    """An off-screen plotter framed on one plane of the domain, with room for a title and bars.

    Args:
        data: The field data set (3D: its section).
        view: Which plane is shown and from where.
        bars: Number of scalar bars (side by side below the domain).
    """

    def __init__(self, data: pv.DataSet, view: _View, bars: int) -> None:
        pv = import_pyvista()
        bounds = np.asarray(data.bounds, dtype=np.float64).reshape(3, 2)
        (x0, x1), (y0, y1) = bounds[view.axes[0]], bounds[view.axes[1]]
        extent = max(x1 - x0, y1 - y0)
        width, height = max(x1 - x0, 1e-9 * extent), max(y1 - y0, 1e-9 * extent)
        self.scale = min(_MAX_WIDTH / width, _MAX_HEIGHT / height)  # pixels per length unit
        self.domain_pixels = (width * self.scale, height * self.scale)
        size = (int(round(max(width * self.scale + 2 * _SIDE, _MIN_WIDTH))),
                int(round(height * self.scale + _TOP + _BOTTOM)))
        self.size = size
        self.view, self.bars = view, bars
        self.plotter = pv.Plotter(off_screen=True, window_size=size)
        self.plotter.set_background("white")
        focal = bounds.mean(axis=1)
        focal[view.axes[0]] = 0.5 * (x0 + x1)
        focal[view.axes[1]] = y0 + (0.5 * size[1] - _BOTTOM) / self.scale
        self.front = bounds[view.normal, 1 if view.toward > 0 else 0]
        self.eps = 1e-3 * extent * view.toward  # lifts particles just above the field
        position = focal.copy()
        position[view.normal] = self.front + view.toward * 10.0 * extent
        self._camera = (focal, position, 0.5 * size[1] / self.scale)

    def bar(self, title: str, slot: int) -> dict[str, object]:
        """scalar_bar_args of bar number ``slot`` (of ``self.bars``) below the domain."""
        width = 0.84 / self.bars
        return {"title": title, "vertical": False, "position_x": 0.08 + slot * width + 0.02,
                "position_y": 8 / self.size[1], "width": width - 0.04, "height": 84 / self.size[1],
                "color": "black", "title_font_size": 14, "label_font_size": 12, "fmt": "%.3g", "n_labels": 5,
                "unconstrained_font_size": True}

    def save(self, title: str, path: Path) -> Path:
        """Add the title, frame the camera and write the PNG."""
        plotter = self.plotter
        plotter.add_text(title, position="upper_edge", font_size=9, color="black")
        for bar in plotter.scalar_bars.values():
            bar.SetTextPositionToPrecedeScalarBar()  # labels and title below the bar: no overlap
        plotter.enable_parallel_projection()
        focal, position, half_height = self._camera
        up = np.zeros(3)
        up[self.view.axes[1]] = 1.0
        plotter.camera.focal_point = tuple(focal)
        plotter.camera.position = tuple(position)
        plotter.camera.up = tuple(up)
        plotter.camera.parallel_scale = half_height
        plotter.renderer.reset_camera_clipping_range()
        plotter.screenshot(str(path))
        plotter.close()
        return path


def _section(data: pv.DataSet) -> tuple[pv.DataSet, _View, float | None]:
    """2D: the data itself, seen from +z. 3D: the x-z section through the centre, seen from -y."""
    bounds = np.asarray(data.bounds, dtype=np.float64).reshape(3, 2)
    extent = float(np.max(bounds[:, 1] - bounds[:, 0]))
    if bounds[2, 1] - bounds[2, 0] <= 1e-12 * extent:
        return data, _VIEW_2D, None
    centre = bounds.mean(axis=1)
    return data.slice(normal="y", origin=tuple(centre)), _VIEW_3D, float(centre[1])


def _mean_cell_size(data: pv.DataSet) -> float:
    """Cube root of the mean cell volume (cells of either orientation count positive)."""
    volumes = data.compute_cell_sizes(length=False, area=False, volume=True).cell_data["Volume"]
    return float(np.abs(volumes).sum() / max(data.n_cells, 1)) ** (1.0 / 3.0)


def _particles_near(cloud: pv.DataSet, picture: _Picture, section: float | None, cell_size: float) -> pv.PolyData:
    """The particles to draw, moved just in front of the picture plane (3D: those near the section)."""
    pv = import_pyvista()
    keep = np.ones(cloud.n_points, dtype=bool)
    if section is not None:
        keep = np.abs(cloud.points[:, picture.view.normal] - section) <= cell_size
    points = np.array(cloud.points[keep], dtype=np.float64)
    points[:, picture.view.normal] = picture.front + picture.eps
    out = pv.PolyData(points)
    for name in cloud.point_data.keys():
        out.point_data[name] = np.asarray(cloud.point_data[name])[keep]
    return out


def _light_viridis() -> object:
    """viridis without its darkest 30 % (a matplotlib colormap)."""
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    return ListedColormap(colormaps["viridis"](np.linspace(0.3, 1.0, 256)), name="viridis_light")


def _time_label(t: float) -> str:
    return f"{t:.6g}"


def field_units(directory: str | Path) -> dict[str, Any] | None:
    """The units of a run's field output (``fields_units.json``: ``{"time", "length", "fields"}``,
    written by a model in physical units), or None (nondimensional output)."""
    path = Path(directory) / "fields_units.json"
    try:
        units = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return units if isinstance(units, dict) else None


@dataclass(frozen=True)
class _Labels:
    """Titles in the output's units (:func:`field_units`; none: the solver's numbers)."""

    units: Mapping[str, Any] = field(default_factory=dict)

    def time(self, t: float) -> str:
        unit = self.units.get("time")
        return f"{t:.6g} {unit}" if unit else f"{t:.6g}"

    def of(self, name: str) -> str:
        unit = (self.units.get("fields") or {}).get(name)
        return f"{name} [{unit}]" if unit and unit != "1" else name


def particle_series(directory: Path, system: str | None = None, /) -> Path | None:
    """The particle output (XDMF series) a picture draws: system ``system``'s
    (``particles_<name>.xdmf``), or by default ``particles.xdmf``, else the first system's by name;
    None if the run wrote no particles.

    Raises:
        ValueError: ``system`` wrote no output here (naming those that did).
    """
    written = sorted(directory.glob("particles*.xdmf"))
    if system is None:
        default = directory / "particles.xdmf"
        return default if default.is_file() else (written[0] if written else None)
    path = directory / ("particles.xdmf" if system == "particles" else f"particles_{system}.xdmf")
    if not path.is_file():
        names = [p.stem.removeprefix("particles_") for p in written]
        raise ValueError(f"no output of the particle system {system!r} in {directory} (written: {names or 'none'})")
    return path


def plot_snapshots(
    directory: str | Path,
    times: Sequence[float] | None = None,
    field: str | None = None,
    particle_property: str | None = None,
    *,
    particle_radius: float | None = None,
    particle_system: str | None = None,
    out_dir: str | Path | None = None,
    log: Callable[[str], None] | None = print,
) -> list[Path]:
    """Draw composition (with particles) and temperature pictures into ``directory/snapshots``.

    Reads ``fields.xdmf`` (and ``particles.xdmf`` if present) with VTK's XdmfReader and renders
    off-screen with pyvista; see the module docstring for what each picture shows.

    Args:
        directory: The run directory.
        times: Wanted times, each snapped to the nearest written one; default the first, middle
            and last written time.
        field: Field of the composition picture (default: ``material``, ``composition``, or the
            first other scalar field that is not temperature, pressure or velocity).
        particle_property: Particle property that colours the particles (vectors: magnitude);
            default black particles (spherical shells: ``displacement`` if the particles carry it).
        particle_radius: Spherical shells: draw only the particles within this distance of the
            centre (default all of the northern hemisphere).
        particle_system: The particle system drawn, of a run with several (its output
            ``particles_<name>.xdmf``); default the run's ``particles.xdmf``, else the first
            system's output by name.
        out_dir: Folder of the pictures (default ``directory/snapshots``).
        log: Receives one line per skipped picture (default ``print``; None: silent).

    Returns:
        The written PNG files, in time order (composition before temperature).

    Raises:
        RunFilesError: ``fields.xdmf`` is missing, or it, ``particles.xdmf`` or an HDF5 file of a
            drawn time is damaged.
        ValueError: ``field``, ``particle_property`` or ``particle_system`` does not exist.
    """
    say = log if log is not None else (lambda line: None)
    directory = Path(directory)
    fields = _Series(directory / "fields.xdmf")
    particles = _Series(series) if (series := particle_series(directory, particle_system)) is not None else None
    out_dir = directory / "snapshots" if out_dir is None else Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    labels = _Labels(field_units(directory) or {})
    written: list[Path] = []
    for t in snapshot_times(fields.times, times):
        index = int(np.argmin(np.abs(fields.times - t))) if fields.times.size else 0
        stem = f"{index:04d}_t{_time_label(t)}"
        data, _ = fields.read(t)
        section, view, plane = _section(data)
        cell_size = _mean_cell_size(data) if plane is not None else 0.0
        name = _material_field(data, field)
        if name is None:
            say(f"t = {_time_label(t)}: no material field (fields: {', '.join(_scalar_names(data))}); "
                "no composition picture")
        else:
            written.append(_composition_picture(section, view, plane, name, t, particles, particle_property,
                                                cell_size, out_dir / f"{name}_{stem}.png", labels=labels))
        if "viscosity" in data.cell_data.keys() and np.ptp(np.log10(_positive(_values(data, "viscosity")))) > 1e-12:
            written.append(_viscosity_picture(section, view, plane, t, out_dir / f"viscosity_{stem}.png", labels))
        radii = _shell_radii(data)
        if radii is not None and "temperature" in data.point_data.keys():
            written.append(_shell_picture(data, radii, t, particles, particle_property, out_dir / f"shell_{stem}.png",
                                          max_radius=particle_radius, labels=labels))
        if "temperature" not in data.point_data.keys() and "temperature" not in data.cell_data.keys():
            say(f"t = {_time_label(t)}: no temperature field; no temperature picture")
        elif _is_constant(_values(data, "temperature")):
            value = float(_values(data, "temperature")[0])
            say(f"t = {_time_label(t)}: temperature is constant ({value:.6g}); no temperature picture")
        else:
            # with a particle property asked for, the particles near the section show it on top
            # (for a shell: the seed paper's figure 5, right, with initial_position)
            shown = particles if particle_property is not None else None
            written.append(_temperature_picture(section, view, plane, t, out_dir / f"temperature_{stem}.png",
                                                particles=shown, particle_property=particle_property,
                                                cell_size=cell_size, labels=labels))
    return written


def _plane_label(plane: float | None) -> str:
    return "" if plane is None else f", section y = {plane:.4g}"


def _composition_picture(data: pv.DataSet, view: _View, plane: float | None, name: str, t: float,
                         particles: _Series | None, particle_property: str | None, cell_size: float,
                         path: Path, *, labels: _Labels = _Labels()) -> Path:
    cloud = None
    title = f"{name} at t = {labels.time(t)}{_plane_label(plane)}"
    if particles is not None:
        cloud, tp = _read_particles(particles, t, particle_property)
        if abs(tp - t) > 1e-9 * max(1.0, abs(t)):
            title += f"; particles at t = {labels.time(tp)}"
    colour_particles = cloud is not None and particle_property is not None
    picture = _Picture(data, view, bars=2 if colour_particles else 1)
    # under black particles the field keeps to the lighter part of viridis, so the dots stay visible
    cmap = _light_viridis() if cloud is not None and not colour_particles else "viridis"
    picture.plotter.add_mesh(data, scalars=name, cmap=cmap, clim=_clim(_values(data, name)), lighting=False,
                             scalar_bar_args=picture.bar(labels.of(name), 0))
    if cloud is not None:
        shown = _particles_near(cloud, picture, plane, cell_size)
        if shown.n_points:
            area = picture.domain_pixels[0] * picture.domain_pixels[1]
            size = float(np.clip(0.3 * np.sqrt(area / shown.n_points), 1.0, 4.0))
            if colour_particles:
                _add_coloured_points(picture, shown, particle_property, cmap="coolwarm", size=size)
            else:
                picture.plotter.add_points(shown, color="black", point_size=size, lighting=False)
    return picture.save(title, path)


def _positive(values: np.ndarray) -> np.ndarray:
    """The values, with non-positive or non-finite ones raised to the smallest positive one (a
    logarithmic colour scale)."""
    good = np.isfinite(values) & (values > 0.0)
    floor = float(values[good].min()) if good.any() else 1.0
    return np.where(good, values, floor)


def _viscosity_picture(data: pv.DataSet, view: _View, plane: float | None, t: float, path: Path,
                       labels: _Labels) -> Path:
    """The viscosity per cell on a logarithmic colour scale (the runs whose viscosity varies)."""
    picture = _Picture(data, view, bars=1)
    shown = data.copy(deep=False)
    shown.cell_data["_log10_viscosity"] = np.log10(_positive(_values(data, "viscosity")))
    picture.plotter.add_mesh(shown, scalars="_log10_viscosity", cmap="magma",
                             clim=_clim(shown.cell_data["_log10_viscosity"]), lighting=False,
                             scalar_bar_args=picture.bar(f"log10 {labels.of('viscosity')}", 0))
    return picture.save(f"viscosity at t = {labels.time(t)}{_plane_label(plane)}", path)


def _add_coloured_points(picture: _Picture, shown: pv.PolyData, name: str, *, cmap: str, size: float) -> None:
    """The particles ``shown`` coloured by their property ``name`` (vectors: magnitude), with the
    second scalar bar below the picture."""
    values = _values(shown, name)
    shown.point_data["_colour"] = values
    label = name if np.asarray(shown.point_data[name]).ndim == 1 else f"{name} magnitude"
    picture.plotter.add_points(shown, scalars="_colour", cmap=cmap, clim=_clim(values), point_size=size,
                               lighting=False, scalar_bar_args=picture.bar(f"particles: {label}", 1))


def _read_particles(particles: _Series, t: float, particle_property: str | None) -> tuple[pv.DataSet, float]:
    """The particles written nearest to ``t`` and their time; ``particle_property`` must exist.

    Raises:
        ValueError: No such particle property (the message lists those there are).
    """
    tp = particles.nearest(t)
    cloud, dropped = particles.read(tp)
    if particle_property is not None and particle_property not in cloud.point_data.keys():
        known = [n for n in cloud.point_data.keys()]
        unread = f" (VTK could not read: {', '.join(dropped)})" if dropped else ""
        raise ValueError(f"no particle property '{particle_property}' in {particles.path.name}; "
                         f"properties: {', '.join(known)}{unread}")
    return cloud, tp


def _temperature_picture(data: pv.DataSet, view: _View, plane: float | None, t: float, path: Path, *,
                         particles: _Series | None = None, particle_property: str | None = None,
                         cell_size: float = 0.0, labels: _Labels = _Labels()) -> Path:
    """The temperature with the mesh; with ``particles`` and ``particle_property`` also the particles
    near the picture plane coloured by that property (viridis, beside the temperature's coolwarm)."""
    picture = _Picture(data, view, bars=2 if particles is not None and particle_property is not None else 1)
    # mesh edges only where cells are large enough in the picture not to hide the colours
    edges = bool(picture.domain_pixels[0] * picture.domain_pixels[1] / max(data.n_cells, 1) >= _MIN_EDGE_CELL_PIXELS)
    picture.plotter.add_mesh(data, scalars="temperature", cmap="coolwarm", clim=_clim(_values(data, "temperature")),
                             lighting=False, show_edges=edges, edge_color="black", edge_opacity=0.2, line_width=0.5,
                             scalar_bar_args=picture.bar(labels.of("temperature"), 0))
    title = f"temperature at t = {labels.time(t)}{_plane_label(plane)}"
    if particles is not None and particle_property is not None and particles.times.size:
        cloud, tp = _read_particles(particles, t, particle_property)
        shown = _particles_near(cloud, picture, plane, cell_size)
        if shown.n_points:
            area = picture.domain_pixels[0] * picture.domain_pixels[1]
            size = float(np.clip(0.3 * np.sqrt(area / shown.n_points), 2.0, 5.0))
            _add_coloured_points(picture, shown, particle_property, cmap="viridis", size=size)
        where = f" within {cell_size:.2g}" if plane is not None else ""
        title += f"; {shown.n_points} particles{where}"
        if abs(tp - t) > 1e-9 * max(1.0, abs(t)):
            title += f" at t = {labels.time(tp)}"
    return picture.save(title, path)

def _shell_radii(data: pv.DataSet) -> tuple[float, float] | None:
    """(inner, outer) radius if ``data`` is a 3D shell around the origin (its points keep away from
    the origin by more than a fifth of their largest radius), else None."""
    points = np.asarray(data.points, dtype=np.float64)
    if points.size == 0 or np.ptp(points[:, 2]) <= 1e-12 * np.ptp(points):
        return None
    r = np.linalg.norm(points, axis=1)
    inner, outer = float(r.min()), float(r.max())
    return (inner, outer) if inner > 0.2 * outer else None


_SHELL_SIZE = (1000, 860)
_SHELL_CAMERA = np.array([1.6, -2.2, 1.5])  # view direction, from above the equator


def _shell_picture(data: pv.DataSet, radii: tuple[float, float], t: float, particles: _Series | None,
                   particle_property: str | None, path: Path, max_radius: float | None = None,
                   labels: _Labels = _Labels()) -> Path:
    """Perspective view of a spherical shell: equatorial temperature slice, the core, the
    particles of the northern hemisphere (within ``max_radius`` of the centre if given)."""
    pv = import_pyvista()
    inner, outer = radii
    plotter = pv.Plotter(off_screen=True, window_size=_SHELL_SIZE)
    plotter.set_background("white")
    bar = {"vertical": False, "height": 0.06, "width": 0.38, "position_y": 0.03, "color": "black",
           "title_font_size": 14, "label_font_size": 12, "fmt": "%.3g", "n_labels": 5}
    section = data.slice(normal="z", origin=(0.0, 0.0, 0.0))
    values = _values(section, "temperature")
    plotter.add_mesh(section, scalars="temperature", cmap="coolwarm", clim=_clim(values), lighting=False,
                     scalar_bar_args=dict(bar, title=f"{labels.of('temperature')} (equatorial plane)", position_x=0.06))
    plotter.add_mesh(pv.Sphere(radius=inner, theta_resolution=96, phi_resolution=48), color="lightgrey",
                     smooth_shading=True)
    title = f"spherical shell at t = {labels.time(t)}"
    if particles is not None and particles.times.size:
        tp = particles.nearest(t)
        cloud, dropped = particles.read(tp)
        names = list(cloud.point_data.keys())
        name = particle_property if particle_property is not None else ("displacement" if "displacement" in names
                                                                         else None)
        if name is not None and name not in names:
            unread = f" (VTK could not read: {', '.join(dropped)})" if dropped else ""
            raise ValueError(f"no particle property '{name}' in {particles.path.name}; properties: "
                             f"{', '.join(names)}{unread}")
        points = np.asarray(cloud.points, dtype=np.float64)
        keep = points[:, 2] >= 0.0
        if max_radius is not None:
            keep &= np.linalg.norm(points, axis=1) <= max_radius
        shown = pv.PolyData(points[keep])
        size = float(np.clip(7.5 - np.log10(max(int(keep.sum()), 1)), 2.5, 5.0))
        if name is None:
            plotter.add_points(shown, color="black", point_size=size, render_points_as_spheres=True)
        else:
            colour = _values(cloud, name)[keep]
            shown.point_data["_colour"] = colour
            label = name if np.asarray(cloud.point_data[name]).ndim == 1 else f"{name} magnitude"
            plotter.add_points(shown, scalars="_colour", cmap="viridis", clim=_clim(colour), point_size=size,
                               render_points_as_spheres=True,
                               scalar_bar_args=dict(bar, title=f"particles: {label}", position_x=0.56))
        where = "z >= 0" + (f", r <= {max_radius:.4g}" if max_radius is not None else "")
        title += f"; {int(keep.sum())} particles ({where})"
        if abs(tp - t) > 1e-9 * max(1.0, abs(t)):
            title += f" at t = {labels.time(tp)}"
    plotter.add_text(title, position="upper_edge", font_size=10, color="black")
    for scalar_bar in plotter.scalar_bars.values():
        scalar_bar.SetTextPositionToPrecedeScalarBar()
    direction = _SHELL_CAMERA / np.linalg.norm(_SHELL_CAMERA)
    plotter.camera.focal_point = (0.0, 0.0, -0.12 * outer)
    plotter.camera.position = tuple(3.4 * outer * direction)
    plotter.camera.up = (0.0, 0.0, 1.0)
    plotter.camera.view_angle = 30.0
    plotter.renderer.reset_camera_clipping_range()
    plotter.screenshot(str(path))
    plotter.close()
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m convection.plot", description=__doc__.split("\n")[0])
    parser.add_argument("directory", help="run directory")
    parser.add_argument("--png", default=None, help="summary picture (default RUN_DIR/summary.png)")
    parser.add_argument("--times", type=float, nargs="+", default=None, metavar="T",
                        help="snapshot times, each snapped to the nearest written time "
                             "(default: first, middle and last)")
    parser.add_argument("--field", default=None,
                        help="field of the composition snapshots (default: material, else composition, else "
                             "the first other scalar field)")
    parser.add_argument("--particle-property", default=None, metavar="NAME",
                        help="particle property that colours the particles (default: black particles)")
    parser.add_argument("--particle-radius", type=float, default=None, metavar="R",
                        help="spherical shells: draw only particles within R of the centre (default: all of the "
                             "northern hemisphere)")
    parser.add_argument("--particle-system", default=None, metavar="NAME",
                        help="of a run with several particle systems: the one drawn (default: the first that "
                             "wrote output, by name)")
    parser.add_argument("--snapshots", default=None, metavar="DIR",
                        help="folder of the snapshot pictures (default RUN_DIR/snapshots)")
    args = parser.parse_args(argv)
    try:
        _draw(args)
    except (StatisticsFileError, OSError) as exc:  # RunFilesError, and e.g. a picture that cannot be written
        return _error(exc, 1)
    except ValueError as exc:  # an unknown --field or --particle-property
        return _error(exc, 2)
    return 0


def _draw(args: argparse.Namespace) -> None:
    """What ``main`` draws: the summary, then the snapshots (or one line saying why none)."""
    directory = check_run_folder(args.directory)
    print(plot_run(directory, args.png, log=print))
    if not (directory / "fields.xdmf").exists() and not field_files(directory):
        print(f"{directory}: no field output (fields.xdmf, fields_NNN.h5): summary without the temperature, "
              "no snapshots")
        return
    paths = plot_snapshots(directory, args.times, args.field, args.particle_property,
                           particle_radius=args.particle_radius, particle_system=args.particle_system,
                           out_dir=args.snapshots)
    for path in paths:
        print(path)


def _error(exc: BaseException, code: int) -> int:
    print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
