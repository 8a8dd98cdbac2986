"""Flat pictures (pyvista, off-screen): a 2D domain seen from +z, or the x-z section of a 3D domain
through its centre seen from -y; the material field with the particles, the viscosity on a
logarithmic scale, the temperature with the mesh."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from convection.io.pictures.labels import Labels
from convection.io.pictures.series import Series, clim, field_values, import_pyvista, positive, read_particles

if TYPE_CHECKING:
    import pyvista as pv

__all__ = ["Picture", "View", "composition_picture", "mean_cell_size", "picture_plane", "temperature_picture",
           "viscosity_picture"]


_SIDE, _TOP, _BOTTOM = 30, 50, 100  # margins of a snapshot in pixels: sides, title, scalar bars
_MAX_WIDTH, _MAX_HEIGHT, _MIN_WIDTH = 1000, 700, 600  # size of the domain in the picture, pixels
_MIN_EDGE_CELL_PIXELS = 50.0  # mesh edges are drawn if cells cover at least this many pixels on average


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
    """An off-screen plotter framed on one plane of the domain, with room for a title and bars.

    Args:
        data: The field data set (3D: its section).
        view: Which plane is shown and from where.
        bars: Number of scalar bars (side by side below the domain).
    """

    def __init__(self, data: pv.DataSet, view: View, bars: int) -> None:
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
    picture = Picture(data, view, bars=2 if colour_particles else 1)
    # under black particles the field keeps to the lighter part of viridis, so the dots stay visible
    cmap = _light_viridis() if cloud is not None and not colour_particles else "viridis"
    picture.plotter.add_mesh(data, scalars=name, cmap=cmap, clim=clim(field_values(data, name)), lighting=False,
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


def viscosity_picture(data: pv.DataSet, view: View, plane: float | None, t: float, path: Path,
                       labels: Labels) -> Path:
    """The viscosity per cell on a logarithmic colour scale (the runs whose viscosity varies)."""
    picture = Picture(data, view, bars=1)
    shown = data.copy(deep=False)
    shown.cell_data["_log10_viscosity"] = np.log10(positive(field_values(data, "viscosity")))
    picture.plotter.add_mesh(shown, scalars="_log10_viscosity", cmap="magma",
                             clim=clim(shown.cell_data["_log10_viscosity"]), lighting=False,
                             scalar_bar_args=picture.bar(f"log10 {labels.of('viscosity')}", 0))
    return picture.save(f"viscosity at t = {labels.time(t)}{_plane_label(plane)}", path)


def _add_coloured_points(picture: Picture, shown: pv.PolyData, name: str, *, cmap: str, size: float) -> None:
    """The particles ``shown`` coloured by their property ``name`` (vectors: magnitude), with the
    second scalar bar below the picture."""
    values = field_values(shown, name)
    shown.point_data["_colour"] = values
    label = name if np.asarray(shown.point_data[name]).ndim == 1 else f"{name} magnitude"
    picture.plotter.add_points(shown, scalars="_colour", cmap=cmap, clim=clim(values), point_size=size,
                               lighting=False, scalar_bar_args=picture.bar(f"particles: {label}", 1))


def temperature_picture(data: pv.DataSet, view: View, plane: float | None, t: float, path: Path, *,
                         particles: Series | None = None, particle_property: str | None = None,
                         cell_size: float = 0.0, labels: Labels = Labels()) -> Path:
    """The temperature with the mesh; with ``particles`` and ``particle_property`` also the particles
    near the picture plane coloured by that property (viridis, beside the temperature's coolwarm)."""
    picture = Picture(data, view, bars=2 if particles is not None and particle_property is not None else 1)
    # mesh edges only where cells are large enough in the picture not to hide the colours
    edges = bool(picture.domain_pixels[0] * picture.domain_pixels[1] / max(data.n_cells, 1) >= _MIN_EDGE_CELL_PIXELS)
    picture.plotter.add_mesh(data, scalars="temperature", cmap="coolwarm", clim=clim(field_values(data, "temperature")),
                             lighting=False, show_edges=edges, edge_color="black", edge_opacity=0.2, line_width=0.5,
                             scalar_bar_args=picture.bar(labels.of("temperature"), 0))
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
