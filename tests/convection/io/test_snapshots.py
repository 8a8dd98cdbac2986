"""Snapshot pictures of a run (convection.io.pictures): files, framing and colours of off-screen renders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib import colormaps
from matplotlib.image import imread
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from _picture_runs import TIMES, field_functions, run_directory
from convection.io.fields import FieldOutput
from convection.io.pictures import field_units, main, plot_snapshots, snapshot_times
from convection.io.pictures.labels import Labels
from fembase.dolfinx_compat import function_space
from particles import Swarm
from particles.generation import generate
from particles.io.output import ParticleWriter


def _check_picture(path: Path) -> None:
    """A PNG of material = [z > 1/2] (under black particles) or temperature = z on the unit square."""
    assert path.stat().st_size > 3_000
    image = imread(path)
    assert image.shape[0] > 500 and image.shape[1] > 500
    assert _colours(image) > 50  # not one colour
    # the unit square fills the picture between the title and the bar below it: sampled in the
    # middle at z = 3/4 and z = 1/4
    top, bottom = _patch(image, 0.27, 0.5), _patch(image, 0.67, 0.5)
    if path.name.startswith("material"):
        # black particles on top: the field uses viridis from 0.3 to 1
        assert np.allclose(top, colormaps["viridis"](1.0)[:3], atol=0.03)
        assert np.allclose(bottom, colormaps["viridis"](0.3)[:3], atol=0.03)
    else:
        assert top[0] > top[2] + 0.2 and bottom[2] > bottom[0] + 0.2  # red above, blue below


def _colours(image: np.ndarray) -> int:
    """Number of distinct RGB colours in ``image``."""
    rgb = np.round(image[..., :3] * 255).astype(np.int64).reshape(-1, 3)
    return len(np.unique(rgb @ np.array([1 << 16, 1 << 8, 1])))


def _viridis_position(rgb: np.ndarray) -> float:
    """The value in [0, 1] whose viridis colour is nearest to ``rgb``."""
    values = np.linspace(0.0, 1.0, 256)
    return float(values[np.argmin(np.linalg.norm(colormaps["viridis"](values)[:, :3] - rgb, axis=1))])


def _patch(image: np.ndarray, row: float, col: float) -> np.ndarray:
    """Median RGB (0..1) of a small patch around the relative position (row, col) of ``image``."""
    h, w = image.shape[:2]
    r, c = int(row * h), int(col * w)
    return np.median(image[r - 8 : r + 8, c - 8 : c + 8, :3].reshape(-1, 3), axis=0)


def test_snapshot_times_snap_to_written():
    written = [0.0, 10.0, 20.0, 30.0]
    assert snapshot_times(written) == [0.0, 20.0, 30.0]
    assert snapshot_times(written, [1.0, 9.0, 11.0, 100.0]) == [0.0, 10.0, 30.0]
    assert snapshot_times([5.0]) == [5.0]
    assert snapshot_times([]) == []


def test_snapshots_of_a_2d_run(tmp_path):
    directory = run_directory(tmp_path)
    skipped: list[str] = []
    paths = plot_snapshots(directory, log=skipped.append)
    names = sorted(p.name for p in paths)
    assert names == sorted(f"{kind}_{k:04d}_t{t:g}.png" for kind in ("material", "temperature")
                           for k, t in enumerate(TIMES))
    assert not skipped
    for path in paths:
        assert path.parent == directory / "snapshots"
        _check_picture(path)


def test_particle_colours_and_chosen_times(tmp_path):
    directory = run_directory(tmp_path, temperature="zero")
    skipped: list[str] = []
    paths = plot_snapshots(directory, times=[0.9, 1.2], field="pressure", particle_property="material",
                           log=skipped.append)
    assert [p.name for p in paths] == ["pressure_0001_t1.png"]
    assert skipped == ["t = 1: temperature is constant (0); no temperature picture"]
    image = imread(paths[0])
    # field pressure = x in viridis; particles coloured by material = x + 1, blue (left) to red (right)
    assert _viridis_position(_patch(image, 0.4, 0.12)) < 0.2
    assert _viridis_position(_patch(image, 0.4, 0.88)) > 0.8
    r, g, b = np.moveaxis(image[int(0.1 * image.shape[0]) : int(0.85 * image.shape[0]), :, :3], -1, 0)
    assert ((r > 0.6) & (g < 0.45) & (b < 0.45)).sum() > 50  # red particles (no such viridis colour)
    assert ((b > 0.65) & (r < 0.45)).sum() > 50  # blue particles


def test_temperature_with_particles_coloured_by_a_property(tmp_path):
    """With a particle property the temperature picture shows the particles on top in viridis (the
    seed's figure 5, right: a section coloured by initial radius); the pictures go to out_dir."""
    directory = run_directory(tmp_path)
    out = tmp_path / "pictures"
    paths = plot_snapshots(directory, times=[2.0], particle_property="material", out_dir=out, log=None)
    assert [p.name for p in paths] == ["material_0002_t2.png", "temperature_0002_t2.png"]
    assert all(p.parent == out for p in paths) and not (directory / "snapshots").exists()
    image = imread(paths[1])[..., :3]
    h, w = image.shape[:2]
    body = image[int(0.1 * h): int(0.85 * h)]
    left, right = body[:, : w // 2], body[:, w // 2:]
    # material = x + 2 at t = 2: dark purple particles on the left, yellow ones on the right;
    # neither colour is in coolwarm (the temperature) or white
    def purple(a):
        return ((a[..., 0] < 0.35) & (a[..., 1] < 0.15) & (a[..., 2] > 0.25) & (a[..., 2] < 0.45)).sum()

    def yellow(a):
        return ((a[..., 0] > 0.75) & (a[..., 1] > 0.75) & (a[..., 2] < 0.35)).sum()

    assert purple(left) > 50 and yellow(right) > 50
    assert purple(right) < purple(left) / 5 and yellow(left) < yellow(right) / 5
    plain = plot_snapshots(directory, times=[2.0], log=None)[1]
    assert yellow(imread(plain)[..., :3]) == 0  # without a property: the temperature alone


def test_unknown_names_list_the_known_ones(tmp_path):
    directory = run_directory(tmp_path)
    with pytest.raises(ValueError, match="fields: .*material"):
        plot_snapshots(directory, field="density", log=None)
    with pytest.raises(ValueError, match="properties: id, rank, material"):
        plot_snapshots(directory, particle_property="density", log=None)


def test_snapshots_of_a_3d_run(tmp_path):
    directory = run_directory(tmp_path, dim=3)
    paths = plot_snapshots(directory, times=[2.0], log=None)
    assert [p.name for p in paths] == ["material_0002_t2.png", "volume_0002_t2.png", "temperature_0002_t2.png"]
    for path in (paths[0], paths[2]):
        _check_picture(path)  # the x-z section through the centre, z up


def test_a_3d_box_in_perspective_three_slices_and_an_isosurface(tmp_path):
    """The volume picture: slices x = y = z = 1/2 coloured by the temperature (= z), the isosurface
    material = 1/2 (material = 1 in the cells above z = 1/3: within a cell of z = 1/3), gold on the
    picture."""
    import json

    from convection.io.pictures.labels import Labels
    from convection.io.pictures.series import Series
    from convection.io.pictures.volume import volume_picture

    directory = run_directory(tmp_path, dim=3, particles=False)
    (directory / "fields_units.json").write_text(json.dumps({"time": "Myr", "length": "km", "fields": {}}))
    data, _ = Series(directory / "fields.xdmf").read(2.0)
    data.cell_data["material"][:] = data.cell_centers().points[:, 2] > 1 / 3
    view = volume_picture(data, "material", 2.0, tmp_path / "volume.png", labels=Labels(field_units(directory)))
    assert view.field == "temperature" and view.surface_field == "material" and view.level == pytest.approx(0.5)
    assert view.slices.n_blocks == 3
    for axis, piece in enumerate(view.slices):  # slice_orthogonal: normals x, y, z in this order
        bounds = np.asarray(piece.bounds).reshape(3, 2)
        assert np.allclose(bounds[axis], 0.5) and np.allclose(np.delete(bounds, axis, axis=0), [[0, 1], [0, 1]])
        assert "temperature" in piece.point_data.keys()
    z = np.asarray(view.isosurface.points)[:, 2]
    assert view.isosurface.n_points > 20 and np.all(np.abs(z - 1 / 3) <= 1 / 6 + 1e-9)
    image = imread(view.path)[..., :3]
    gold = (image[..., 0] > 0.8) & (image[..., 1] > 0.6) & (image[..., 1] < 0.9) & (image[..., 2] < 0.3)
    assert gold.sum() > 2_000 and _colours(image) > 200
    data.point_data["temperature"][:] = 0.0  # no temperature: the slices show the material
    view = volume_picture(data, "material", 2.0, tmp_path / "material.png", labels=Labels())
    assert (view.field, view.surface_field) == ("material", "material")
    data.cell_data["material"][:] = 1.0
    assert volume_picture(data, "material", 2.0, tmp_path / "nothing.png", labels=Labels()) is None


def test_cli_draws_summary_and_snapshots(tmp_path, capsys):
    directory = run_directory(tmp_path, particles=False)
    assert main([str(directory), "--times", "2"]) == 0
    printed = capsys.readouterr().out.split()
    assert printed == [str(directory / "summary.png"), str(directory / "snapshots" / "material_0002_t2.png"),
                       str(directory / "snapshots" / "temperature_0002_t2.png")]
    assert all(Path(p).stat().st_size > 3_000 for p in printed)
    assert main([str(directory), "--field", "density"]) == 2


def test_spherical_shell_view_with_particles_coloured_by_displacement(tmp_path):
    """A spherical shell gets a perspective picture: the equatorial temperature slice (hot inside: red
    near the core, blue outside) and the particles near the core in viridis by displacement."""
    pytest.importorskip("gmsh")
    from convection.geometry.shell import ShellSpec, create_shell_mesh

    mesh = create_shell_mesh(MPI.COMM_SELF, ShellSpec(3, 1.22, 2.22, resolution=0.6, geometry_degree=1))
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 1), name="temperature")
    T.interpolate(lambda x: 2.22 - np.linalg.norm(x, axis=0))
    out = FieldOutput(tmp_path)
    out.write({"temperature": T}, 0.0)
    out.close()
    swarm = Swarm(mesh)
    swarm.add_property("displacement")
    generate(swarm, "metropolis_hastings", num_particles=3000, seed=2,
             density=lambda x: (np.linalg.norm(x, axis=1) < 1.5).astype(np.float64))
    swarm.property("displacement")[:, 0] = swarm.x[:, 0]
    ParticleWriter(tmp_path).write(swarm, 0.0, 0)
    paths = plot_snapshots(tmp_path, log=None)
    assert [p.name for p in paths] == ["shell_0000_t0.png", "temperature_0000_t0.png"]
    image = imread(paths[0])
    assert image.shape[:2] == (860, 1000) and _colours(image) > 200
    r, g, b = np.moveaxis(image[int(0.08 * image.shape[0]) : int(0.85 * image.shape[0]), :, :3], -1, 0)
    assert ((r > 0.6) & (g < 0.35) & (b < 0.35)).sum() > 500  # hot slice next to the core
    assert ((b > 0.6) & (r < 0.4) & (g < 0.6)).sum() > 500  # cold slice outside
    viridis = colormaps["viridis"](np.linspace(0.0, 1.0, 16))[:, :3]
    pixels = image[..., :3].reshape(-1, 3)
    near = np.min(np.linalg.norm(pixels[:, None, :] - viridis[None, :, :], axis=2), axis=1) < 0.04
    assert near.sum() > 300  # particles
    with pytest.raises(ValueError, match="properties: id, rank, displacement"):
        plot_snapshots(tmp_path, particle_property="density", log=None)


def test_viscosity_on_a_log_scale_and_titles_in_units(tmp_path):
    """A run that wrote a varying viscosity (1e19 above z = 1/2, 1e23 below) gets a viscosity picture
    on a logarithmic scale (magma: the low viscosity dark, the high light); a run in physical units
    (fields_units.json) has its units in the titles and colour bars."""
    import json

    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 6, 6)
    functions = field_functions(mesh, "z")
    viscosity = dolfinx.fem.Function(function_space(mesh, "DG", 0))
    viscosity.interpolate(lambda x: np.where(x[1] > 0.5, 1e19, 1e23))
    out = FieldOutput(tmp_path)
    out.write({**functions, "viscosity": viscosity}, 2.5)
    out.close()
    (tmp_path / "fields_units.json").write_text(json.dumps({"time": "Myr", "length": "km", "fields": {}}))
    written = plot_snapshots(tmp_path, log=None)
    names = sorted(p.name for p in written)
    assert names == ["material_0000_t2.5.png", "temperature_0000_t2.5.png", "viscosity_0000_t2.5.png"]
    image = imread(tmp_path / "snapshots" / "viscosity_0000_t2.5.png")
    top, bottom = _patch(image, 0.27, 0.5), _patch(image, 0.67, 0.5)
    assert np.allclose(top, colormaps["magma"](0.0)[:3], atol=0.03)  # 1e19: the low end
    assert np.allclose(bottom, colormaps["magma"](1.0)[:3], atol=0.03)  # 1e23: the high end
    (tmp_path / "fields_units.json").write_text(json.dumps({"time": "Myr", "length": "km",
                                                             "fields": {"viscosity": "Pa*s", "material": "1"}}))
    labels = Labels(field_units(tmp_path))
    assert (labels.time(2.5), labels.of("viscosity"), labels.of("material")) == ("2.5 Myr", "viscosity [Pa*s]",
                                                                              "material")
    assert Labels().time(2.5) == "2.5" and field_units(tmp_path / "nowhere") is None


def test_the_particle_system_drawn(tmp_path):
    """particles.xdmf by default; of a run with several systems the one asked for, else the first
    by name; an unknown one is named with those written."""
    from convection.io.pictures import particle_series

    assert particle_series(tmp_path) is None
    for name in ("particles_tracers.xdmf", "particles_dense.xdmf"):
        (tmp_path / name).write_text("<Xdmf/>")
    assert particle_series(tmp_path) == tmp_path / "particles_dense.xdmf"
    assert particle_series(tmp_path, "tracers") == tmp_path / "particles_tracers.xdmf"
    with pytest.raises(ValueError, match=r"'slab'.*written: \['dense', 'tracers'\]"):
        particle_series(tmp_path, "slab")
    (tmp_path / "particles.xdmf").write_text("<Xdmf/>")
    assert particle_series(tmp_path) == tmp_path / "particles.xdmf"


def _bar_texts(fig, bar_axes):
    fig.canvas.draw()
    axis = bar_axes.xaxis
    return [t.get_text() for t in axis.get_ticklabels() if t.get_text()], axis.get_offset_text().get_text()


def test_snapshot_axes_in_the_runs_units_and_plain_colour_bars(tmp_path):
    """A run in km: the picture's axes are x [km] and z [km] over the domain; a temperature bar in
    K is ticked 400, 600, ... (no 1e+03, no offset); a viscosity over four decades is on a
    logarithmic bar; a nondimensional run's axes are x and z."""
    import json

    from convection.io.pictures.sections import ColourBar, Picture, picture_plane
    from convection.io.pictures.series import Series

    directory = run_directory(tmp_path, particles=False)
    (directory / "fields_units.json").write_text(json.dumps({"time": "Myr", "length": "km", "fields": {}}))
    data, _ = Series(directory / "fields.xdmf").read(2.0)
    plane, view, _ = picture_plane(data)
    picture = Picture(plane, view, Labels(field_units(directory)))
    picture.add(plane, "temperature", ColourBar("temperature [K]", "coolwarm", (273.0, 1573.0)))
    picture.add(plane, "pressure", ColourBar("viscosity [Pa s]", "magma", (1e19, 1e23), log=True))
    fig = picture.figure("title")
    field, temperature, viscosity = fig.axes
    assert (field.get_xlabel(), field.get_ylabel(), field.get_title()) == ("x [km]", "z [km]", "title")
    assert field.get_xlim() == (0.0, 1.0) and field.get_ylim() == (0.0, 1.0)
    ticks, offset = _bar_texts(fig, temperature)
    assert offset == "" and {"400", "800", "1200"} <= set(ticks) and all(t.isdigit() for t in ticks)
    assert temperature.get_xlabel() == "temperature [K]"
    assert viscosity.get_xscale() == "log" and viscosity.get_xlabel() == "viscosity [Pa s]"
    assert len(fig.axes) == 3
    plain = Picture(plane, view, Labels())
    plain.add(plane, "temperature", ColourBar("temperature", "coolwarm", (0.0, 1.0)))
    fig = plain.figure("title")
    assert (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()) == ("x", "z")
    ticks, offset = _bar_texts(fig, fig.axes[1])
    assert offset == "" and {"0.0", "0.4", "1.0"} <= set(ticks)
