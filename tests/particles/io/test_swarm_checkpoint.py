"""Checkpoint/restart: bit-for-bit continuation, restore on another rank count, one-line errors."""

import os
import shutil
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from convection.launch import mpirun
from fembase.dolfinx_compat import function_space
from particles import Swarm
from particles.advection import Advector
from particles.io.swarm_checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from particles.generation import generate

from _runs import guarded_run

ROOT = Path(__file__).resolve().parents[3]
N_CELLS = 10
N_PARTICLES = 300
DT = 0.5 / N_CELLS  # CFL 0.5 for max |u| = 1


def _vortex(x):
    """u = curl of sin^2(pi x) sin^2(pi y) / pi: one closed vortex, zero on the walls of the unit square."""
    sx, cx = np.sin(np.pi * x[0]), np.cos(np.pi * x[0])
    sy, cy = np.sin(np.pi * x[1]), np.cos(np.pi * x[1])
    return np.stack([2.0 * sx * sx * sy * cy, -2.0 * sx * cx * sy * sy])


def _mesh_and_velocity(comm, n=N_CELLS):
    mesh = dolfinx.mesh.create_unit_square(comm, n, n)
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(_vortex)
    return mesh, u


def _new_swarm(mesh):
    swarm = Swarm(mesh)
    swarm.add_property("distance")
    swarm.add_property("x_prev", 2)
    generate(swarm, "random_uniform", num_particles=N_PARTICLES, seed=11)
    return swarm


def _run(swarm, u, steps):
    """RK2 steps; 'distance' accumulates the length of each step's chord."""
    advector = Advector(swarm, integrator="rk2")
    for _ in range(steps):
        swarm.property("x_prev")[:] = swarm.x
        advector.step(u, u, DT)
        swarm.property("distance")[:, 0] += np.linalg.norm(swarm.x - swarm.property("x_prev"), axis=1)


def _gathered(swarm, comm=None):
    """(ids, x, properties) over all ranks of ``comm`` (default: the swarm's), sorted by id."""
    comm = comm or swarm.comm
    ids = np.concatenate(comm.allgather(swarm.ids))
    x = np.concatenate(comm.allgather(swarm.x))
    props = np.concatenate(comm.allgather(swarm.properties))
    order = np.argsort(ids)
    return ids[order], x[order], props[order]


def _local_state(swarm):
    return (swarm.ids, swarm.x, swarm.xref, swarm.cells, swarm.properties)


def _shared_dir(tmp_path, comm):
    return Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0))


def _all(comm, flag):
    return bool(comm.allreduce(bool(flag), op=MPI.LAND))


def _invariants_ok(swarm):
    try:
        swarm.check_invariants()
    except AssertionError:
        return False
    return True


def _restart_bitwise(tmp_path, comm):
    path = _shared_dir(tmp_path, comm) / "ck.h5"
    mesh, u = _mesh_and_velocity(comm)
    reference = _new_swarm(mesh)
    _run(reference, u, 20)

    first = _new_swarm(mesh)
    _run(first, u, 10)
    rng = np.random.default_rng(7)
    rng.random(3)
    save_checkpoint(path, first, step=10, time=10 * DT, rng_state=rng.bit_generator.state,
                    extra={"dt_history": np.full(10, DT)})
    # The same mesh: a freshly built mesh may be partitioned differently on 3 ranks (then the
    # restore is correct but not exact, see test_restore_on_another_mesh).
    restored = load_checkpoint(path, mesh)
    swarm = restored.swarm
    assert restored.exact
    assert restored.step == 10 and restored.time == 10 * DT
    np.testing.assert_array_equal(restored.extra["dt_history"], np.full(10, DT))
    again = np.random.default_rng(0)
    again.bit_generator.state = restored.rng_state
    assert np.array_equal(again.random(5), rng.random(5))
    assert swarm.property_names == ["distance", "x_prev"]
    same = all(np.array_equal(a, b) for a, b in zip(_local_state(first), _local_state(swarm)))
    assert _all(comm, same and np.array_equal(first.offsets, swarm.offsets))  # same ranks, same order

    _run(swarm, u, 10)
    ids, x, props = _gathered(swarm)
    ref_ids, ref_x, ref_props = _gathered(reference)
    np.testing.assert_array_equal(ids, np.arange(N_PARTICLES))
    np.testing.assert_array_equal(ids, ref_ids)
    assert np.array_equal(x, ref_x)  # bit for bit
    assert np.array_equal(props, ref_props)
    assert props[:, 0].min() > 0.0  # the particles moved
    assert _all(comm, all(np.array_equal(a, b) for a, b in zip(_local_state(reference), _local_state(swarm))))


def test_restart_bitwise(tmp_path, world):
    _restart_bitwise(tmp_path, world)


def test_restore_on_another_mesh(tmp_path):
    """A different mesh (other cells, other global indices) goes through locate + migrate."""
    mesh, u = _mesh_and_velocity(MPI.COMM_WORLD)
    swarm = _new_swarm(mesh)
    _run(swarm, u, 3)
    save_checkpoint(tmp_path / "ck.h5", swarm, step=3, time=3 * DT)
    other = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 7, 5, dolfinx.mesh.CellType.quadrilateral)
    restored = load_checkpoint(tmp_path / "ck.h5", other)
    assert not restored.exact and restored.rng_state is None and restored.extra == {}
    assert _invariants_ok(restored.swarm)
    for a, b in zip(_gathered(swarm), _gathered(restored.swarm)):
        assert np.array_equal(a, b)
    geom = restored.swarm.geometry
    assert np.allclose(geom.push_forward(restored.swarm.cells, restored.swarm.xref), restored.swarm.x, atol=1e-12)


@pytest.mark.mpi
def test_restore_on_another_rank_count(tmp_path):
    """COMM_WORLD -> COMM_SELF on every rank, and COMM_SELF on rank 0 -> COMM_WORLD."""
    world = MPI.COMM_WORLD
    directory = _shared_dir(tmp_path, world)
    mesh, u = _mesh_and_velocity(world)
    swarm = _new_swarm(mesh)
    _run(swarm, u, 5)
    save_checkpoint(directory / "world.h5", swarm, step=5, time=5 * DT)
    expected = _gathered(swarm)
    assert world.allreduce(int(swarm.num_particles > 0), op=MPI.SUM) == world.size

    self_mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, N_CELLS, N_CELLS)
    alone = load_checkpoint(directory / "world.h5", self_mesh)
    ok = (not alone.exact) and _invariants_ok(alone.swarm)
    ok &= all(np.array_equal(a, b) for a, b in zip(_gathered(alone.swarm), expected))
    assert _all(world, ok)

    if world.rank == 0:
        self_mesh2, self_u = _mesh_and_velocity(MPI.COMM_SELF)
        lone = _new_swarm(self_mesh2)
        _run(lone, self_u, 4)
        save_checkpoint(directory / "self.h5", lone, step=4, time=4 * DT)
        lone_data = _gathered(lone)
    else:
        lone_data = None
    lone_data = world.bcast(lone_data, root=0)
    spread = load_checkpoint(directory / "self.h5", mesh)
    ok = (not spread.exact) and spread.step == 4 and _invariants_ok(spread.swarm)
    ok &= all(np.array_equal(a, b) for a, b in zip(_gathered(spread.swarm), lone_data))
    assert _all(world, ok)
    assert world.allreduce(int(spread.swarm.num_particles > 0), op=MPI.SUM) == world.size


# ---------------------------------------------------------------------- damaged files
def _make_cases(directory: Path, swarm) -> dict[str, tuple[Path, str]]:
    """Collective: one valid checkpoint, then rank 0 derives damaged copies. {case: (path, expected words)}."""
    good = directory / "good.h5"
    save_checkpoint(good, swarm, step=1, time=0.5)
    cases = {
        "missing": (directory / "nope.h5", "missing"),
        "garbage": (directory / "garbage.h5", "not an HDF5 file"),
        "truncated": (directory / "truncated.h5", "damaged HDF5 file"),
        "no xref": (directory / "noxref.h5", "missing dataset 'xref'"),
        "version": (directory / "version.h5", "version mismatch"),
        "size": (directory / "size.h5", "size mismatch"),
    }
    if swarm.comm.rank == 0:
        (directory / "garbage.h5").write_bytes(np.random.default_rng(1).bytes(4096))
        data = good.read_bytes()
        (directory / "truncated.h5").write_bytes(data[: len(data) // 2])
        for name in ("noxref", "version", "size"):
            shutil.copy(good, directory / f"{name}.h5")
        with h5py.File(directory / "noxref.h5", "a") as f:
            del f["xref"]
        with h5py.File(directory / "version.h5", "a") as f:
            f.attrs["version"] = 99
        with h5py.File(directory / "size.h5", "a") as f:
            x = f["x"][...]
            del f["x"]
            f["x"] = x[:-1]
    swarm.comm.Barrier()
    return cases


def _check_errors(tmp_path, comm):
    directory = _shared_dir(tmp_path, comm)
    mesh = dolfinx.mesh.create_unit_square(comm, 4, 4)
    swarm = Swarm(mesh)
    swarm.add_property("tag")
    generate(swarm, "random_uniform", num_particles=40, seed=2)
    ok = True
    for case, (path, words) in _make_cases(directory, swarm).items():
        try:
            load_checkpoint(path, mesh)
            message = None
        except CheckpointError as err:
            message = str(err)
        good = message is not None and "\n" not in message and str(path) in message and words in message
        ok &= good
        assert _all(comm, good), f"{case}: {message}"
    assert _all(comm, ok)
    assert issubclass(CheckpointError, RuntimeError)
    assert load_checkpoint(directory / "good.h5", mesh).swarm.global_num_particles() == 40


def test_damaged_checkpoints(tmp_path, world):
    _check_errors(tmp_path, world)


def test_damaged_checkpoint_under_mpirun_does_not_hang(tmp_path):
    """Every rank of a 2-rank run raises the same one-line error (a subprocess with a timeout)."""
    (tmp_path / "garbage.h5").write_bytes(b"\x00garbage" * 100)
    script = textwrap.dedent(
        f"""
        from mpi4py import MPI
        import dolfinx.mesh
        from particles.io.swarm_checkpoint import CheckpointError, load_checkpoint
        mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
        lines = []
        for name in ("missing.h5", "garbage.h5"):
            try:
                load_checkpoint({str(tmp_path)!r} + "/" + name, mesh)
            except CheckpointError as err:
                lines.append(str(err))
        with open({str(tmp_path)!r} + f"/rank{{MPI.COMM_WORLD.rank}}.txt", "w") as fh:
            fh.write("\\n".join(lines) + "\\n")
        """
    )
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [*mpirun(2), sys.executable, "-c", script]
    proc = guarded_run(cmd, cwd=ROOT, env=env, budget=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for rank in (0, 1):
        lines = (tmp_path / f"rank{rank}.txt").read_text().splitlines()
        assert lines == [f"checkpoint {tmp_path}/missing.h5: missing (no such file)",
                         f"checkpoint {tmp_path}/garbage.h5: not an HDF5 file"]
