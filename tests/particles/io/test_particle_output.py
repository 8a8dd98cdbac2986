"""Particle output: parallel HDF5 per step + one XDMF series, subsets, atomic files."""

import os
import signal
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from fembase.dolfinx_compat import function_space
from fembase.files import H5Sink
from particles import Swarm
from particles.generation import generate
from particles.io.output import ParticleWriter, write_mesh_fields

from _runs import guarded_run

N_PARTICLES = 400


def _swarm(comm):
    mesh = dolfinx.mesh.create_unit_square(comm, 8, 8)
    swarm = Swarm(mesh)
    swarm.add_property("temperature")
    swarm.add_property("velocity", 2)
    generate(swarm, "random_uniform", num_particles=N_PARTICLES, seed=5)
    swarm.property("temperature")[:, 0] = np.sin(swarm.x[:, 0]) + swarm.ids
    swarm.property("velocity")[:] = swarm.x[:, ::-1]
    return swarm


def _gathered(swarm):
    """Global (ids, x, temperature, velocity, rank), sorted by id, on every rank."""
    comm = swarm.comm
    ids = np.concatenate(comm.allgather(swarm.ids))
    x = np.concatenate(comm.allgather(swarm.x))
    temp = np.concatenate(comm.allgather(swarm.property("temperature")[:, 0]))
    vel = np.concatenate(comm.allgather(swarm.property("velocity")))
    rank = np.concatenate(comm.allgather(np.full(swarm.num_particles, comm.rank)))
    order = np.argsort(ids)
    return ids[order], x[order], temp[order], vel[order], rank[order]


def _move(swarm, step):
    """Shift positions (no relocation needed: the writer only reads the arrays)."""
    swarm.x[:] = swarm.x * 0.5 + 0.1 * step


def _grid_points(xdmf: Path):
    """{time: positions (N, 3)} of every step, read with xml.etree + h5py."""
    root = ET.parse(xdmf).getroot()
    out = {}
    for grid in root.iter("Grid"):
        if grid.get("GridType") != "Uniform":
            continue
        t = float(grid.find("Time").get("Value"))
        item = grid.find("Geometry/DataItem")
        fname, dataset = item.text.strip().split(":")
        with h5py.File(xdmf.parent / fname, "r") as f:
            data = f[dataset][...]
        assert data.shape == tuple(int(s) for s in item.get("Dimensions").split())
        out[t] = data
    return out


def _check_series(directory: Path, expected: dict, comm) -> bool:
    """Rank 0 checks the files against the expected gathered data; the verdict is broadcast."""
    ok = True
    if comm.rank == 0:
        names = sorted(os.listdir(directory))
        ok &= names == sorted([f"particles_{s:06d}.h5" for s in expected] + ["particles.xdmf"])
        points = _grid_points(directory / "particles.xdmf")
        with meshio.xdmf.TimeSeriesReader(directory / "particles.xdmf") as reader:
            first, cells = reader.read_points_cells()
            ok &= reader.num_steps == len(expected)
            ok &= cells[0].type == "vertex" and len(cells[0]) == first.shape[0]
            for k, step in enumerate(sorted(expected)):
                ids, x, temp, vel, rank = expected[step]
                t, point_data, _ = reader.read_data(k)
                ok &= t == 0.25 * step
                with h5py.File(directory / f"particles_{step:06d}.h5", "r") as f:
                    h5ids = f["ids"][...]
                    ok &= f["ids"].dtype == np.int64 and f["positions"].shape == (ids.shape[0], 3)
                    ok &= np.array_equal(np.sort(h5ids), ids)  # every id exactly once
                    order = np.argsort(h5ids)
                    pos = f["positions"][...][order]
                    ok &= np.array_equal(pos[:, :2], x) and np.all(pos[:, 2] == 0.0)
                    ok &= np.array_equal(f["properties/temperature"][...][order], temp)
                    ok &= np.array_equal(f["properties/velocity"][...][order], vel)
                    ok &= np.array_equal(f["rank"][...][order], rank)
                    ok &= np.array_equal(point_data["id"], h5ids)
                    ok &= np.array_equal(point_data["velocity"][order], vel)
                    ok &= np.array_equal(points[t], f["positions"][...])
                if k == 0:
                    ok &= np.array_equal(first, points[t])
    return bool(comm.bcast(ok, root=0))


def _run_series(tmp_path, comm):
    directory = Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)) / "out"
    swarm = _swarm(comm)
    writer = ParticleWriter(directory)
    expected = {}
    for step in (0, 1, 2):
        _move(swarm, step)
        record = writer.write(swarm, 0.25 * step, step)
        assert record.num_particles == N_PARTICLES
        expected[step] = _gathered(swarm)
    assert _check_series(directory, expected, comm)


def test_series_serial(tmp_path):
    _run_series(tmp_path, MPI.COMM_WORLD)


@pytest.mark.mpi
def test_series_parallel(tmp_path):
    comm = MPI.COMM_WORLD
    _run_series(tmp_path, comm)
    # the data really were spread over the ranks
    swarm = _swarm(comm)
    assert comm.allreduce(int(swarm.num_particles > 0), op=MPI.SUM) == comm.size


def _subset_case(tmp_path, comm):
    directory = Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0))
    swarm = _swarm(comm)
    chosen = np.array([3, 17, 250, 399, 100000])  # one id does not exist
    ParticleWriter(directory / "nth", every_nth=7, properties=["temperature"]).write(swarm, 0.0, 4)
    ParticleWriter(directory / "ids", ids=chosen).write(swarm, 0.0, 4)
    ParticleWriter(directory / "both", ids=chosen, every_nth=3).write(swarm, 0.0, 4)
    ok = True
    if comm.rank == 0:
        with h5py.File(directory / "nth" / "particles_000004.h5", "r") as f:
            ok &= np.array_equal(np.sort(f["ids"][...]), np.arange(0, N_PARTICLES, 7))
            ok &= list(f["properties"]) == ["temperature"]
            ok &= np.allclose(f["properties/temperature"][...] - np.sin(f["positions"][:, 0]), f["ids"][...])
        with h5py.File(directory / "ids" / "particles_000004.h5", "r") as f:
            ok &= np.array_equal(np.sort(f["ids"][...]), [3, 17, 250, 399])
            ok &= sorted(f["properties"]) == ["temperature", "velocity"]
        with h5py.File(directory / "both" / "particles_000004.h5", "r") as f:
            ok &= np.array_equal(np.sort(f["ids"][...]), [3, 399])
        for sub in ("nth", "ids", "both"):
            ok &= sorted(os.listdir(directory / sub)) == ["particles.xdmf", "particles_000004.h5"]
    assert comm.bcast(ok, root=0)


def test_subsets(tmp_path, world):
    _subset_case(tmp_path, world)


def test_unknown_property_lists_known(tmp_path):
    swarm = _swarm(MPI.COMM_WORLD)
    with pytest.raises(KeyError, match="temperature"):
        ParticleWriter(tmp_path, properties=["pressure"]).write(swarm, 0.0, 0)
    with pytest.raises(ValueError, match="every_nth"):
        ParticleWriter(tmp_path, every_nth=0)


def test_restarted_writer_keeps_earlier_steps(tmp_path):
    swarm = _swarm(MPI.COMM_WORLD)
    first = ParticleWriter(tmp_path)
    for step in range(4):
        first.write(swarm, 0.1 * step, step)
    again = ParticleWriter(tmp_path)  # a restart from step 2
    again.write(swarm, 0.2, 2)
    with meshio.xdmf.TimeSeriesReader(tmp_path / "particles.xdmf") as reader:
        reader.read_points_cells()
        times = [reader.read_data(k)[0] for k in range(reader.num_steps)]
    assert times == [0.0, 0.1, 0.2]
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".")]


@pytest.mark.mpi
@pytest.mark.skipif(not h5py.get_config().mpi, reason="h5py without MPI (PyPI's): no parallel write to compare with")
def test_gather_fallback_matches_parallel_write(tmp_path):
    comm = MPI.COMM_WORLD
    directory = Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0))
    local = np.arange(comm.rank * 10, comm.rank * 10 + comm.rank + 2, dtype=np.int64)
    for parallel in (True, False):
        with H5Sink(directory / f"p{parallel}.h5", comm, parallel=parallel) as sink:
            sink.distributed("a", local)
            sink.distributed("b", np.stack([local, -local], axis=1).astype(float))
            sink.replicated("r", np.array([1.5, 2.5]) if comm.rank == 0 else np.zeros(0))
            sink.attrs(answer=42)
    ok = True
    if comm.rank == 0:
        expected = np.concatenate([np.arange(r * 10, r * 10 + r + 2) for r in range(comm.size)])
        for parallel in (True, False):
            with h5py.File(directory / f"p{parallel}.h5", "r") as f:
                ok &= np.array_equal(f["a"][...], expected) and np.array_equal(f["b"][:, 1], -expected)
                ok &= np.array_equal(f["r"][...], [1.5, 2.5]) and f.attrs["answer"] == 42
        ok &= sorted(os.listdir(directory)) == ["pFalse.h5", "pTrue.h5"]
    assert comm.bcast(ok, root=0)


def test_killed_writer_leaves_only_complete_files(tmp_path):
    """A writer SIGKILLed while publishing step 1 leaves step 0 complete and no step-1 file."""
    script = textwrap.dedent(
        f"""
        import os, signal
        from mpi4py import MPI
        import dolfinx.mesh
        from particles import Swarm
        from particles.generation import generate
        from particles.io.output import ParticleWriter
        mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
        swarm = Swarm(mesh)
        generate(swarm, "random_uniform", num_particles=50, seed=1)
        writer = ParticleWriter({str(tmp_path)!r})
        writer.write(swarm, 0.0, 0)
        real_replace = os.replace
        def dying_replace(src, dst):
            if str(dst).endswith("particles_000001.h5"):
                os.kill(os.getpid(), signal.SIGKILL)
            real_replace(src, dst)
        os.replace = dying_replace
        writer.write(swarm, 1.0, 1)
        """
    )
    proc = guarded_run([sys.executable, "-c", script], cwd=Path(__file__).resolve().parents[3], budget=120)
    assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]
    final = sorted(n for n in os.listdir(tmp_path) if not n.startswith("."))
    assert final == ["particles.xdmf", "particles_000000.h5"]
    temporary = [n for n in os.listdir(tmp_path) if n.startswith(".")]
    assert len(temporary) == 1 and temporary[0].startswith(".particles_000001.h5.")  # never a final name
    with h5py.File(tmp_path / "particles_000000.h5", "r") as f:
        assert np.array_equal(np.sort(f["ids"][...]), np.arange(50))
    points = _grid_points(tmp_path / "particles.xdmf")
    assert list(points) == [0.0] and points[0.0].shape == (50, 3)


def test_mesh_fields_dg0_as_cell_data(tmp_path):
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    dg0 = dolfinx.fem.Function(function_space(mesh, "DG", 0), name="density")
    dg0.x.array[:] = 2.0
    p2 = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2), name="temperature")
    p2.interpolate(lambda x: x[0] + x[1])
    tensor = dolfinx.fem.Function(
        function_space(mesh, "DG", 1, shape=(mesh.geometry.dim, mesh.geometry.dim)), name="strain")
    write_mesh_fields(tmp_path / "fields.xdmf", mesh, [dg0, p2, tensor], 0.0)
    write_mesh_fields(tmp_path / "fields.xdmf", mesh, [dg0, p2, tensor], 1.0, append=True)
    root = ET.parse(tmp_path / "fields.xdmf").getroot()
    centers = {(a.get("Name"), a.get("Center")) for a in root.iter("Attribute")}
    assert centers == {("density", "Cell"), ("temperature", "Node"), ("strain", "Node")}
    assert sorted({float(t.get("Value")) for t in root.iter("Time")}) == [0.0, 1.0]
