"""Flat pictures: a 2D domain seen from +z, or the x-z section of a 3D domain through its centre
seen from -y; the material field with the particles, the viscosity (on a logarithmic scale where
it spans a decade or more), the temperature with the mesh. pyvista renders the plane off-screen,
exactly the domain's pixels; matplotlib frames that image with axes x and z in the output's units,
the title and the colour bars (plain tick numbers, :mod:`convection.io.pictures.labels`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from convection.io.pictures.labels import Labels, plain_ticks
from convection.io.pictures.series import Series, clim, field_values, import_pyvista, positive, read_particles

if TYPE_CHECKING:
    import pyvista as pv
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["ColourBar", "Picture", "View", "composition_picture", "mean_cell_size",
           "picture_plane", "temperature_picture", "viscosity_picture"]


_MAX_WIDTH, _MAX_HEIGHT = 1000, 700  # largest size of the domain in the picture, pixels
_MIN_WIDTH = 600  # smallest width of the picture, pixels (room for the colour bars)
_LEFT, _RIGHT, _TOP, _BELOW, _BARS = 85, 35, 45, 55, 80  # margins, pixels: axes, title, tick labels, colour bars
_DPI = 100
_MIN_EDGE_CELL_PIXELS = 50.0  # mesh edges are drawn if cells cover at least this many pixels on average


class ColourBar(NamedTuple):
    """A colour bar below a picture: what it is titled, its colour map and range; ``log``: a
    logarithmic scale (the range in the values' units)."""

    title: str
    cmap: Any
    limits: tuple[float, float]
    log: bool = False


class View(NamedTuple):
    """How a picture looks at the domain.

    Attributes:
        axes: World axes shown (horizontal, vertical).
        normal: World axis pointing out of the picture plane.
        toward: +1 or -1: the side of the ``normal`` axis the camera is on.
    """

    axes: tuple[int, int]
    normal: int
    toward: float


VIEW_2D = View((0, 1), 2, 1.0)  # from +z: x right, y up
VIEW_3D = View((0, 2), 1, -1.0)  # from -y: x right, z up


class Picture:
    """One plane of the domain rendered off-screen by pyvista, framed by matplotlib: axes in the
    output's units, the title above, the colour bars below (plain tick numbers).

    Args:
        data: The field data set (3D: its section).
        view: Which plane is shown and from where.
        labels: The output's units.
    """

    def __init__(self, data: pv.DataSet, view: View, labels: Labels) -> None:
        pv = import_pyvista()
        bounds = np.asarray(data.bounds, dtype=np.float64).reshape(3, 2)
        (x0, x1), (y0, y1) = bounds[view.axes[0]], bounds[view.axes[1]]
        extent = max(x1 - x0, y1 - y0)
        width, height = max(x1 - x0, 1e-9 * extent), max(y1 - y0, 1e-9 * extent)
        self.scale = min(_MAX_WIDTH / width, _MAX_HEIGHT / height)  # pixels per length unit
        self.domain_pixels = (width * self.scale, height * self.scale)
        self.extent = (x0, x0 + width, y0, y0 + height)
        self.view, self.labels = view, labels
        self.bars: list[ColourBar] = []
        size = (max(1, int(round(width * self.scale))), max(1, int(round(height * self.scale))))
        self.plotter = pv.Plotter(off_screen=True, window_size=size)
        self.plotter.set_background("white")
        focal = bounds.mean(axis=1)
        focal[view.axes[0]], focal[view.axes[1]] = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        self.front = bounds[view.normal, 1 if view.toward > 0 else 0]
        self.eps = 1e-3 * extent * view.toward  # lifts particles just above the field
        position = focal.copy()
        position[view.normal] = self.front + view.toward * 10.0 * extent
        self._camera = (focal, position, 0.5 * height)

    def add(self, shown: pv.DataSet, scalars: str, bar: ColourBar, *, points: bool = False, **kwargs: Any) -> None:
        """Draw ``shown`` coloured by ``scalars`` (points: as dots), with ``bar`` below the picture.
        A logarithmic bar colours by the values' log10 (which ``scalars`` must hold)."""
        limits = tuple(np.log10(bar.limits)) if bar.log else bar.limits
        add = self.plotter.add_points if points else self.plotter.add_mesh
        add(shown, scalars=scalars, cmap=bar.cmap, clim=limits, lighting=False, show_scalar_bar=False, **kwargs)
        self.bars.append(bar)

    def save(self, title: str, path: Path) -> Path:
        """Render the plane and write the PNG with its axes, title and colour bars."""
        self.figure(title).savefig(path, dpi=_DPI)
        return path

    def figure(self, title: str) -> Figure:
        """Render the plane (this closes the plotter) into a matplotlib figure with its axes, title
        and colour bars."""
        plotter = self.plotter
        plotter.enable_parallel_projection()
        focal, position, half_height = self._camera
        up = np.zeros(3)
        up[self.view.axes[1]] = 1.0
        plotter.camera.focal_point = tuple(focal)
        plotter.camera.position = tuple(position)
        plotter.camera.up = tuple(up)
        plotter.camera.parallel_scale = half_height
        plotter.renderer.reset_camera_clipping_range()
        image = plotter.screenshot(return_img=True)
        plotter.close()
        return _framed(image, self.extent, title, self.bars, self.labels)


def _framed(image: np.ndarray, extent: tuple[float, float, float, float], title: str, bars: list[ColourBar],
            labels: Labels) -> Figure:
    """The rendered ``image`` of the plane ``extent`` (left, right, bottom, top) as a matplotlib figure
    of the same pixels: axes x and z in the output's units, the title, the colour bars side by side below."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    height, width = image.shape[:2]
    fig_w, fig_h = max(width + _LEFT + _RIGHT, _MIN_WIDTH), _TOP + height + _BELOW + _BARS
    fig = Figure(figsize=(fig_w / _DPI, fig_h / _DPI), dpi=_DPI)
    FigureCanvasAgg(fig)  # draws without pyplot, as every matplotlib release does
    left = _LEFT + 0.5 * (fig_w - _LEFT - _RIGHT - width)
    ax = fig.add_axes((left / fig_w, (_BELOW + _BARS) / fig_h, width / fig_w, height / fig_h))
    ax.imshow(image, extent=extent, aspect="auto", interpolation="nearest")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel(plain_ticks(ax.xaxis, extent[0], extent[1], labels.axis("x")))
    ax.set_ylabel(plain_ticks(ax.yaxis, extent[2], extent[3], labels.axis("z")))
    ax.set_title(title, fontsize=11)
    room = (fig_w - _LEFT - _RIGHT) / max(len(bars), 1)
    for slot, bar in enumerate(bars):
        cax = fig.add_axes(((_LEFT + slot * room + 20) / fig_w, 46 / fig_h, (room - 40) / fig_w, 14 / fig_h))
        _colour_bar(fig, cax, bar)
    return fig


def _colour_bar(fig: Figure, cax: Axes, bar: ColourBar) -> None:
    """A horizontal colour bar in ``cax``: plain tick numbers (decades on a logarithmic scale)."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LogNorm, Normalize

    lo, hi = bar.limits
    norm = LogNorm(lo, hi) if bar.log else Normalize(lo, hi)
    colours = fig.colorbar(ScalarMappable(norm=norm, cmap=bar.cmap), cax=cax, orientation="horizontal")
    label = bar.title if bar.log else plain_ticks(colours.ax.xaxis, lo, hi, bar.title)
    colours.set_label(label, fontsize=10)
    colours.ax.tick_params(labelsize=9)


def picture_plane(data: pv.DataSet) -> tuple[pv.DataSet, View, float | None]:
    """2D: the data itself, seen from +z. 3D: the x-z section through the centre, seen from -y."""
    bounds = np.asarray(data.bounds, dtype=np.float64).reshape(3, 2)
    extent = float(np.max(bounds[:, 1] - bounds[:, 0]))
    if bounds[2, 1] - bounds[2, 0] <= 1e-12 * extent:
        return data, VIEW_2D, None
    centre = bounds.mean(axis=1)
    return data.slice(normal="y", origin=tuple(centre)), VIEW_3D, float(centre[1])


def mean_cell_size(data: pv.DataSet) -> float:
    """Cube root of the mean cell volume (cells of either orientation count positive)."""
    volumes = data.compute_cell_sizes(length=False, area=False, volume=True).cell_data["Volume"]
    return float(np.abs(volumes).sum() / max(data.n_cells, 1)) ** (1.0 / 3.0)


def _particles_near(cloud: pv.DataSet, picture: Picture, section: float | None, cell_size: float) -> pv.PolyData:
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


def _plane_label(plane: float | None) -> str:
    return "" if plane is None else f", section y = {plane:.4g}"


def composition_picture(data: pv.DataSet, view: View, plane: float | None, name: str, t: float,
                         particles: Series | None, particle_property: str | None, cell_size: float,
                         path: Path, *, labels: Labels = Labels()) -> Path:
    cloud = None
    title = f"{name} at t = {labels.time(t)}{_plane_label(plane)}"
    if particles is not None:
        cloud, tp = read_particles(particles, t, particle_property)
        if abs(tp - t) > 1e-9 * max(1.0, abs(t)):
            title += f"; particles at t = {labels.time(tp)}"
    colour_particles = cloud is not None and particle_property is not None
    picture = Picture(data, view, labels)
    # under black particles the field keeps to the lighter part of viridis, so the dots stay visible
    cmap = _light_viridis() if cloud is not None and not colour_particles else "viridis"
    picture.add(data, name, ColourBar(labels.of(name), cmap, clim(field_values(data, name))))
    if cloud is not None:
        shown = _particles_near(cloud, picture, plane, cell_size)
        if shown.n_points:
            area = picture.domain_pixels[0] * picture.domain_pixels[1]
            size = float(np.clip(0.3 * np.sqrt(area / shown.n_points), 1.0, 4.0))
            if colour_particles and particle_property is not None:
                _add_coloured_points(picture, shown, particle_property, cmap="coolwarm", size=size)
            else:
                picture.plotter.add_points(shown, color="black", point_size=size, lighting=False)
    return picture.save(title, path)


def viscosity_picture(data: pv.DataSet, view: View, plane: float | None, t: float, path: Path,
                       labels: Labels) -> Path:
    """The viscosity per cell on a logarithmic colour scale (the runs whose viscosity varies)."""
    picture = Picture(data, view, labels)
    shown = data.copy(deep=False)
    values = positive(field_values(data, "viscosity"))
    lo, hi = clim(values)
    if hi >= 10.0 * lo > 0.0:  # spans a decade or more: a logarithmic scale
        shown.cell_data["_log10_viscosity"] = np.log10(values)
        picture.add(shown, "_log10_viscosity", ColourBar(labels.of("viscosity"), "magma", (lo, hi), log=True))
    else:
        picture.add(shown, "viscosity", ColourBar(labels.of("viscosity"), "magma", (lo, hi)))
    return picture.save(f"viscosity at t = {labels.time(t)}{_plane_label(plane)}", path)


def _add_coloured_points(picture: Picture, shown: pv.PolyData, name: str, *, cmap: str, size: float) -> None:
    """The particles ``shown`` coloured by their property ``name`` (vectors: magnitude), with the
    second scalar bar below the picture."""
    values = field_values(shown, name)
    shown.point_data["_colour"] = values
    label = name if np.asarray(shown.point_data[name]).ndim == 1 else f"{name} magnitude"
    picture.add(shown, "_colour", ColourBar(f"particles: {label}", cmap, clim(values)), points=True, point_size=size)


def temperature_picture(data: pv.DataSet, view: View, plane: float | None, t: float, path: Path, *,
                         particles: Series | None = None, particle_property: str | None = None,
                         cell_size: float = 0.0, labels: Labels = Labels()) -> Path:
    """The temperature with the mesh; with ``particles`` and ``particle_property`` also the particles
    near the picture plane coloured by that property (viridis, beside the temperature's coolwarm)."""
    picture = Picture(data, view, labels)
    # mesh edges only where cells are large enough in the picture not to hide the colours
    edges = bool(picture.domain_pixels[0] * picture.domain_pixels[1] / max(data.n_cells, 1) >= _MIN_EDGE_CELL_PIXELS)
    bar = ColourBar(labels.of("temperature"), "coolwarm", clim(field_values(data, "temperature")))
    picture.add(data, "temperature", bar,
                show_edges=edges, edge_color="black", edge_opacity=0.2, line_width=0.5)
    title = f"temperature at t = {labels.time(t)}{_plane_label(plane)}"
    if particles is not None and particle_property is not None and particles.times.size:
        cloud, tp = read_particles(particles, t, particle_property)
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
