"""A spherical shell in perspective (the seed paper's picture of section 4.2): the temperature on the
equatorial plane, the core as a grey sphere, the particles of the northern hemisphere."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from convection.io.pictures.labels import Labels, round_bar_labels
from convection.io.pictures.series import Series, clim, field_values, import_pyvista

if TYPE_CHECKING:
    import pyvista as pv

__all__ = ["shell_picture", "shell_radii"]


def shell_radii(data: pv.DataSet) -> tuple[float, float] | None:
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


def shell_picture(data: pv.DataSet, radii: tuple[float, float], t: float, particles: Series | None,
                   particle_property: str | None, path: Path, max_radius: float | None = None,
                   labels: Labels = Labels()) -> Path:
    """Perspective view of a spherical shell: equatorial temperature slice, the core, the
    particles of the northern hemisphere (within ``max_radius`` of the centre if given)."""
    pv = import_pyvista()
    inner, outer = radii
    plotter = pv.Plotter(off_screen=True, window_size=_SHELL_SIZE)
    plotter.set_background("white")
    bar = {"vertical": False, "height": 0.06, "width": 0.38, "position_y": 0.03, "color": "black",
           "title_font_size": 14, "label_font_size": 12}
    section = data.slice(normal="z", origin=(0.0, 0.0, 0.0))
    values = field_values(section, "temperature")
    title = f"{labels.of('temperature')} (equatorial plane)"
    plotter.add_mesh(section, scalars="temperature", cmap="coolwarm", clim=clim(values), lighting=False,
                     scalar_bar_args=dict(bar, title=title, position_x=0.06))
    round_bar_labels(plotter.scalar_bars[title], clim(values))
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
            colour = field_values(cloud, name)[keep]
            shown.point_data["_colour"] = colour
            label = name if np.asarray(cloud.point_data[name]).ndim == 1 else f"{name} magnitude"
            plotter.add_points(shown, scalars="_colour", cmap="viridis", clim=clim(colour), point_size=size,
                               render_points_as_spheres=True,
                               scalar_bar_args=dict(bar, title=f"particles: {label}", position_x=0.56))
            round_bar_labels(plotter.scalar_bars[f"particles: {label}"], clim(colour))
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
