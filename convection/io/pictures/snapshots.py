"""``snapshots/*.png``: the pictures of chosen times of ``fields.xdmf`` (see :mod:`convection.io.pictures`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple
from collections.abc import Callable, Sequence

import numpy as np

from convection.io.pictures.labels import Labels, time_label
from convection.io.pictures.run_files import field_units, particle_series
from convection.io.pictures.sections import (composition_picture, mean_cell_size, picture_plane, temperature_picture,
                                             viscosity_picture)
from convection.io.pictures.series import (Series, field_values, is_constant, material_field, positive, scalar_names,
                                           snapshot_times)
from convection.io.pictures.shell import shell_picture, shell_radii
from convection.io.pictures.volume import volume_picture

if TYPE_CHECKING:
    import pyvista as pv

__all__ = ["plot_snapshots"]


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
        The written PNG files, in time order (at each time: composition, viscosity, shell or
        volume, temperature).

    Raises:
        RunFilesError: ``fields.xdmf`` is missing, or it, ``particles.xdmf`` or an HDF5 file of a
            drawn time is damaged.
        ValueError: ``field``, ``particle_property`` or ``particle_system`` does not exist.
    """
    say = log if log is not None else (lambda line: None)
    directory = Path(directory)
    fields = Series(directory / "fields.xdmf")
    particles = Series(series) if (series := particle_series(directory, particle_system)) is not None else None
    out_dir = directory / "snapshots" if out_dir is None else Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    labels = Labels(field_units(directory) or {})
    written: list[Path] = []
    for t in snapshot_times(fields.times, times):
        index = int(np.argmin(np.abs(fields.times - t))) if fields.times.size else 0
        data, _ = fields.read(t)
        wanted = _Wanted(field, particle_property, particle_radius)
        written += _pictures_at(data, t, out_dir, f"{index:04d}_t{time_label(t)}", particles, wanted, labels, say)
    return written


class _Wanted(NamedTuple):
    """What :func:`plot_snapshots` was asked to draw (see its arguments)."""

    field: str | None
    particle_property: str | None
    particle_radius: float | None


def _pictures_at(data: pv.DataSet, t: float, out_dir: Path, stem: str, particles: Series | None, wanted: _Wanted,
                 labels: Labels, say: Callable[[str], None]) -> list[Path]:
    """The pictures of the fields ``data`` at time ``t`` (file names ``<kind>_<stem>.png``)."""
    written = []
    section, view, plane = picture_plane(data)
    cell_size = mean_cell_size(data) if plane is not None else 0.0
    name = material_field(data, wanted.field)
    if name is None:
        say(f"t = {time_label(t)}: no material field (fields: {', '.join(scalar_names(data))}); "
            "no composition picture")
    else:
        written.append(composition_picture(section, view, plane, name, t, particles, wanted.particle_property,
                                           cell_size, out_dir / f"{name}_{stem}.png", labels=labels))
    if "viscosity" in data.cell_data.keys() and np.ptp(np.log10(positive(field_values(data, "viscosity")))) > 1e-12:
        written.append(viscosity_picture(section, view, plane, t, out_dir / f"viscosity_{stem}.png", labels))
    radii = shell_radii(data)
    if radii is not None and "temperature" in data.point_data.keys():
        written.append(shell_picture(data, radii, t, particles, wanted.particle_property, out_dir / f"shell_{stem}.png",
                                     max_radius=wanted.particle_radius, labels=labels))
    elif plane is not None:  # a 3D box: slices and an isosurface in perspective
        volume = volume_picture(data, name, t, out_dir / f"volume_{stem}.png", labels=labels)
        written += [volume.path] if volume is not None else []
    if "temperature" not in data.point_data.keys() and "temperature" not in data.cell_data.keys():
        say(f"t = {time_label(t)}: no temperature field; no temperature picture")
    elif is_constant(field_values(data, "temperature")):
        value = float(field_values(data, "temperature")[0])
        say(f"t = {time_label(t)}: temperature is constant ({value:.6g}); no temperature picture")
    else:
        # with a particle property asked for, the particles near the section show it on top
        # (for a shell: the seed paper's figure 5, right, with initial_position)
        shown = particles if wanted.particle_property is not None else None
        written.append(temperature_picture(section, view, plane, t, out_dir / f"temperature_{stem}.png",
                                           particles=shown, particle_property=wanted.particle_property,
                                           cell_size=cell_size, labels=labels))
    return written
