"""fields.xdmf (one series over changing meshes) and particles.xdmf, opened as ParaView does.

``pyvista.get_reader`` gives VTK's XdmfReader, the reader ParaView uses for ``.xdmf``. Rank 0 reads;
the list of failures is broadcast so every rank passes or fails together.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from convection.io.fields import FieldOutput
from convection.io.output_units import Conversion, OutputUnits
from convection.io.pictures import import_pyvista
from fembase.dolfinx_compat import function_space, refine_keeping_partition
from particles import Swarm
from particles.generation import generate
from particles.io.output import ParticleWriter

if TYPE_CHECKING:
    import pyvista as pv


def _shared_dir(tmp_path: Path, comm: MPI.Intracomm) -> Path:
    return Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0))


def _fields(mesh: dolfinx.mesh.Mesh, t: float) -> dict[str, dolfinx.fem.Function]:
    """P2 temperature (1 + t)(x + 2y), DG0 material [y > 1/2], P2 velocity (y, -x)."""
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(lambda x: (1.0 + t) * (x[0] + 2.0 * x[1]))
    material = dolfinx.fem.Function(function_space(mesh, "DG", 0))
    material.interpolate(lambda x: (x[1] > 0.5).astype(np.float64))
    u = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,)))
    u.interpolate(lambda x: np.stack([x[1], -x[0]]))
    return {"temperature": T, "material": material, "velocity": u}


def _check_time(grid: pv.DataSet, t: float, cells: int, points: int) -> list[str]:
    """Failures of the grid read at time ``t`` against the closed-form fields."""
    errors = []
    if grid.n_cells != cells or grid.n_points != points:
        errors.append(f"t={t}: {grid.n_cells} cells, {grid.n_points} points; expected {cells}, {points}")
        return errors
    if sorted(grid.point_data.keys()) != ["temperature", "velocity"] or list(grid.cell_data.keys()) != ["material"]:
        errors.append(f"t={t}: point data {list(grid.point_data)}, cell data {list(grid.cell_data)}")
        return errors
    x = grid.points
    if not np.allclose(grid.point_data["temperature"], (1.0 + t) * (x[:, 0] + 2.0 * x[:, 1]), atol=1e-12):
        errors.append(f"t={t}: temperature differs from (1 + t)(x + 2y)")
    if not np.allclose(grid.point_data["velocity"], np.stack([x[:, 1], -x[:, 0], 0 * x[:, 0]], axis=1), atol=1e-12):
        errors.append(f"t={t}: velocity differs from (y, -x, 0)")
    centres = grid.cell_centers().points
    if not np.array_equal(grid.cell_data["material"], (centres[:, 1] > 0.5).astype(float)):
        errors.append(f"t={t}: material differs from [y > 1/2] at the cell centres")
    return errors


def _read_series(path: Path, expected: dict[float, tuple[int, int]]) -> list[str]:
    """Failures of the series at ``path`` against {time: (global cells, global points)}."""
    reader = import_pyvista().get_reader(str(path))  # not `import pyvista`: see import_pyvista
    times = list(reader.time_values)
    if not np.allclose(times, sorted(expected)):
        return [f"time values {times}, expected {sorted(expected)}"]
    errors = []
    for t in times:
        reader.set_active_time_value(t)
        grid = reader.read()
        errors += _check_time(grid, t, *expected[min(expected, key=lambda s: abs(s - t))])
    return errors


def _field_series(tmp_path: Path, comm: MPI.Intracomm) -> None:
    directory = _shared_dir(tmp_path, comm)
    coarse = dolfinx.mesh.create_unit_square(comm, 4, 4)
    coarse.topology.create_entities(1)
    fine = refine_keeping_partition(coarse)
    out = FieldOutput(directory)
    expected: dict[float, tuple[int, int]] = {}
    errors: list[str] = []
    for mesh, times in ((coarse, (0.0, 0.5)), (fine, (1.0, 1.5))):
        size = (mesh.topology.index_map(2).size_global, mesh.topology.index_map(0).size_global)
        for t in times:
            out.write(_fields(mesh, t), t)
            expected[t] = size
            if comm.rank == 0 and t == 0.0:
                # readable at once (the epoch file is closed), as by ParaView while a run goes on
                errors += _read_series(directory / "fields.xdmf", {0.0: size})
    out.close()
    if comm.rank == 0:
        errors += _read_series(directory / "fields.xdmf", expected)
        names = sorted(os.listdir(directory))
        wanted = ["fields.xdmf", "fields_000.h5", "fields_000.xdmf", "fields_001.h5", "fields_001.xdmf"]
        if names != wanted:
            errors.append(f"files {names}, expected {wanted}")
    if out.files != [directory / "fields_000.xdmf", directory / "fields_001.xdmf"]:
        errors.append(f"FieldOutput.files = {out.files}")
    errors = comm.bcast(errors, root=0)
    assert not errors, "\n".join(errors)
    assert expected[0.0] == (32, 25) and expected[1.0] == (128, 81)


def test_field_series_serial(tmp_path):
    _field_series(tmp_path, MPI.COMM_WORLD)


@pytest.mark.mpi
def test_field_series_parallel(tmp_path):
    comm = MPI.COMM_WORLD
    assert comm.size > 1
    _field_series(tmp_path, comm)


def test_rewritten_time_replaces_its_grid(tmp_path):
    """Writing a time again (e.g. after adapting the mesh at that time) keeps only the later grid."""
    coarse = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    coarse.topology.create_entities(1)
    out = FieldOutput(tmp_path, prefix="state")
    out.write(_fields(coarse, 0.0), 0.0)
    out.write(_fields(refine_keeping_partition(coarse), 0.0), 0.0)
    out.close()
    assert out.series_path == tmp_path / "state.xdmf"
    assert not _read_series(out.series_path, {0.0: (128, 81)})


def _particle_series(tmp_path: Path, comm: MPI.Intracomm, vector_size: int = 3) -> None:
    directory = _shared_dir(tmp_path, comm)
    mesh = dolfinx.mesh.create_unit_square(comm, 6, 6)
    swarm = Swarm(mesh)
    swarm.add_property("material")
    swarm.add_property("vector", vector_size)
    swarm.add_property("_stage", 2)
    generate(swarm, "random_uniform", num_particles=300, seed=3)
    writer = ParticleWriter(directory, properties=["material", "vector"])
    times = (0.0, 2.5, 5.0)
    for step, t in enumerate(times):
        swarm.property("material")[:, 0] = swarm.x[:, 0] + t
        swarm.property("vector")[:] = 0.0
        swarm.property("vector")[:, :2] = swarm.x[:, ::-1]
        writer.write(swarm, t, step)
    errors: list[str] = []
    if comm.rank == 0:
        reader = import_pyvista().get_reader(str(directory / "particles.xdmf"))
        if list(reader.time_values) != list(times):
            errors.append(f"time values {reader.time_values}")
        for t in times:
            reader.set_active_time_value(t)
            cloud = reader.read()
            if cloud.n_points != 300 or sorted(cloud.point_data.keys()) != ["id", "material", "rank", "vector"]:
                errors.append(f"t={t}: {cloud.n_points} particles with {list(cloud.point_data)}")
                continue
            x = cloud.points
            if not np.allclose(cloud.point_data["material"], x[:, 0] + t, atol=1e-12):
                errors.append(f"t={t}: material differs from x + t")
            vector = cloud.point_data["vector"]
            if vector.shape != (300, 3) or not np.allclose(vector[:, :2], x[:, 1::-1], atol=1e-12):
                errors.append(f"t={t}: vector property {vector.shape} differs from (y, x, 0)")
            if sorted(np.unique(cloud.point_data["rank"])) != list(range(comm.size)):
                errors.append(f"t={t}: ranks {np.unique(cloud.point_data['rank'])}")
    errors = comm.bcast(errors, root=0)
    assert not errors, "\n".join(errors)


def test_particle_series_serial(tmp_path):
    _particle_series(tmp_path, MPI.COMM_WORLD)


@pytest.mark.mpi
def test_particle_series_parallel(tmp_path):
    _particle_series(tmp_path, MPI.COMM_WORLD)


@pytest.mark.filterwarnings("ignore:UnstructuredGrid mesh is not valid")
def test_particle_series_two_component_property(tmp_path):
    _particle_series(tmp_path, MPI.COMM_WORLD, vector_size=2)


def _units() -> OutputUnits:
    """Coordinates x 10 (km), times x 2 (Myr), temperature 3 T + 1 (K), velocity x 5 (cm/yr)."""
    return OutputUnits(length=Conversion(10.0, 0.0, "km"), time=Conversion(2.0, 0.0, "Myr"),
                       fields={"temperature": Conversion(3.0, 1.0, "K"), "velocity": Conversion(5.0, 0.0, "cm/yr")})


def _series_in_units(tmp_path: Path, comm: MPI.Intracomm) -> None:
    """Fields and particles written with units: ParaView reads the converted coordinates, times and
    values (the material, dimensionless, as it is); the mesh and swarm keep the solver's numbers."""
    directory = _shared_dir(tmp_path, comm)
    mesh = dolfinx.mesh.create_unit_square(comm, 4, 4)
    before = mesh.geometry.x.copy()
    out = FieldOutput(directory, units=_units())
    for t in (0.0, 0.5):
        out.write(_fields(mesh, t), t)
    out.close()
    swarm = Swarm(mesh)
    swarm.add_property("velocity", 2)
    generate(swarm, "random_uniform", num_particles=100, seed=3)
    swarm.property("velocity")[:] = swarm.x[:, ::-1]
    x_before = swarm.x.copy()
    ParticleWriter(directory, units=_units()).write(swarm, 0.5, 0)
    errors: list[str] = []
    if not np.array_equal(mesh.geometry.x, before) or not np.array_equal(swarm.x, x_before):
        errors.append("writing changed the mesh's or the particles' coordinates")
    if comm.rank == 0:
        reader = import_pyvista().get_reader(str(directory / "fields.xdmf"))
        if list(reader.time_values) != [0.0, 1.0]:
            errors.append(f"field times {reader.time_values}, expected [0, 1] Myr")
        reader.set_active_time_value(1.0)
        grid = reader.read()
        x = grid.points / 10.0  # the solver's coordinates
        if not np.allclose(grid.bounds, (0.0, 10.0, 0.0, 10.0, 0.0, 0.0)):
            errors.append(f"field bounds {grid.bounds}, expected a 10 km square")
        if not np.allclose(grid.point_data["temperature"], 3.0 * 1.5 * (x[:, 0] + 2.0 * x[:, 1]) + 1.0, atol=1e-11):
            errors.append("temperature is not 3 T + 1")
        if not np.allclose(grid.point_data["velocity"][:, :2], 5.0 * np.stack([x[:, 1], -x[:, 0]], axis=1), atol=1e-11):
            errors.append("velocity is not 5 u")
        centres = grid.cell_centers().points / 10.0
        if not np.array_equal(grid.cell_data["material"], (centres[:, 1] > 0.5).astype(float)):
            errors.append("the dimensionless material changed")
        cloud = import_pyvista().get_reader(str(directory / "particles.xdmf")).read()
        p = cloud.points / 10.0
        if list(import_pyvista().get_reader(str(directory / "particles.xdmf")).time_values) != [1.0]:
            errors.append("particle time not in Myr")
        if not (p.min() >= 0.0 and p.max() <= 1.0 and p[:, :2].max() > 0.8):
            errors.append(f"particle positions not in km: {cloud.bounds}")
        if not np.allclose(cloud.point_data["velocity"][:, :2], 5.0 * p[:, 1::-1], atol=1e-11):
            errors.append("particle velocity is not 5 v")
        for name, fields in (("fields", {"temperature": "K", "velocity": "cm/yr", "material": "1"}),
                             ("particles", {"velocity": "cm/yr"})):
            units = json.loads((directory / f"{name}_units.json").read_text())
            if units != {"time": "Myr", "length": "km", "fields": fields}:
                errors.append(f"{name}_units.json: {units}")
    errors = comm.bcast(errors, root=0)
    assert not errors, "\n".join(errors)


def test_series_in_units_serial(tmp_path):
    _series_in_units(tmp_path, MPI.COMM_WORLD)


@pytest.mark.mpi
def test_series_in_units_parallel(tmp_path):
    _series_in_units(tmp_path, MPI.COMM_WORLD)
