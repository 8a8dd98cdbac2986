"""A 3D box in perspective (pyvista, off-screen), as the cookbooks of ASPECT and G-ADOPT show one:
three orthogonal slices through the centre (x-y: the planform; x-z and y-z: the sections)
coloured by the temperature (the material field where the temperature is constant), an isosurface
of the material field at the middle of its range (0.5 of a composition; without one, of the
temperature), the domain's outline and axes with tick numbers in the output's units."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from convection.io.pictures.labels import Labels, pyvista_format, round_bar_labels
from convection.io.pictures.series import clim, field_values, import_pyvista, is_constant

if TYPE_CHECKING:
    import pyvista as pv

__all__ = ["VolumeView", "volume_picture"]

_SIZE = (1000, 820)
_LABELS = 6  # labels of the colour bar and of each axis: 0, 0.2, ... 1 on a unit cube
_CAMERA = np.array([1.7, -2.4, 1.5])  # view direction: the x-z section faces the viewer, the planform seen from above
_SURFACE_COLOUR = {"coolwarm": "gold", "viridis": "crimson"}
"""The isosurface's colour, one that the slices' colour map does not have."""


class VolumeView(NamedTuple):
    """What a 3D picture drew.

    Attributes:
        path: The PNG written.
        field: The field the slices are coloured by.
        slices: The three slices through the centre (normals x, y, z).
        surface_field: The field of the isosurface (None: no field varies enough for one).
        level: The isosurface's value.
        isosurface: The isosurface (None with ``surface_field``).
    """

    path: Path
    field: str
    slices: pv.MultiBlock
    surface_field: str | None
    level: float | None
    isosurface: pv.PolyData | None


def _has(data: pv.DataSet, name: str | None) -> bool:
    return name is not None and (name in data.point_data.keys() or name in data.cell_data.keys())


def _varies(data: pv.DataSet, name: str | None) -> bool:
    return name is not None and _has(data, name) and not is_constant(field_values(data, name))


def volume_picture(data: pv.DataSet, material: str | None, t: float, path: Path, *,
                   labels: Labels) -> VolumeView | None:
    """Draw the 3D field data set ``data`` (see the module docstring) into ``path``.

    Args:
        data: The fields at one time, a 3D mesh.
        material: The material field (None: the run has none).
        t: The time (for the title).
        path: The PNG to write.
        labels: The output's units.

    Returns:
        What was drawn; None if neither the temperature nor ``material`` varies (nothing to see).
    """
    field = "temperature" if _varies(data, "temperature") else (material if _varies(data, material) else None)
    if field is None:
        return None
    surface_field = material if material is not None and _varies(data, material) else field
    pv = import_pyvista()
    bounds = np.asarray(data.bounds, dtype=np.float64).reshape(3, 2)
    centre = bounds.mean(axis=1)
    slices = data.slice_orthogonal(x=centre[0], y=centre[1], z=centre[2])
    cmap = "coolwarm" if field == "temperature" else "viridis"
    plotter = pv.Plotter(off_screen=True, window_size=_SIZE)
    plotter.set_background("white")
    limits = clim(field_values(data, field))
    title = labels.of(field) + "\n"  # the line below keeps the title off the top label
    bar = {"title": title, "vertical": True, "height": 0.5, "width": 0.06, "position_x": 0.88, "position_y": 0.25,
           "color": "black", "title_font_size": 16, "label_font_size": 14}
    for i, piece in enumerate(slices):
        plotter.add_mesh(piece, scalars=field, cmap=cmap, clim=limits, lighting=False, show_scalar_bar=i == 0,
                         scalar_bar_args=bar)
    round_bar_labels(plotter.scalar_bars[title], limits)
    surface_values = field_values(data, surface_field)
    level = 0.5 * sum(clim(surface_values))
    points = data.cell_data_to_point_data() if surface_field in data.cell_data.keys() else data
    isosurface = points.contour([level], scalars=surface_field)
    if isosurface.n_points:
        plotter.add_mesh(isosurface, color=_SURFACE_COLOUR[cmap], smooth_shading=True, opacity=0.85)
    plotter.add_mesh(data.outline(), color="black", line_width=1.5)
    extent = float(np.max(bounds[:, 1] - bounds[:, 0]))
    plotter.show_bounds(xtitle=labels.axis("x"), ytitle=labels.axis("y"), ztitle=labels.axis("z"), color="black",
                        location="outer", ticks="outside", font_size=14, n_xlabels=_LABELS, n_ylabels=_LABELS,
                        n_zlabels=_LABELS, fmt=pyvista_format(0.0, extent, _LABELS))
    where = ", ".join(f"{name} = {value:.4g}" for name, value in zip("xyz", centre))
    plotter.add_text(f"{field} at t = {labels.time(t)} on slices {where}\n"
                     f"{_SURFACE_COLOUR[cmap]}: isosurface {surface_field} = {level:.4g}",
                     position="upper_edge", font_size=10, color="black")
    direction = _CAMERA / np.linalg.norm(_CAMERA)
    focal = centre - np.array([0.0, 0.0, 0.06 * extent])  # room for the title above
    plotter.camera.focal_point = tuple(focal)
    plotter.camera.position = tuple(focal + 3.9 * extent * direction)
    plotter.camera.up = (0.0, 0.0, 1.0)
    plotter.camera.view_angle = 30.0
    plotter.renderer.reset_camera_clipping_range()
    plotter.screenshot(str(path))
    plotter.close()
    return VolumeView(path, field, slices, surface_field, level, isosurface if isosurface.n_points else None)
