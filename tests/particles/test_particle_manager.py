"""ParticleManager: one object advancing, bounding, interpolating and writing the particles."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl

from fembase.distribute import refine_on_ranks
from fembase.dolfinx_compat import function_space
from particles.generation import RandomUniform
from particles.manager import OutputSchedule, ParticleManager, build_generator, build_properties
from particles.io.output import ParticleWriter
from particles.population.control import PopulationControl
from particles.properties import InitialComposition, PropertyContext

from _helpers import gathered, plugin


def _mesh(comm, n=8):
    return dolfinx.mesh.create_unit_square(comm, n, n, ghost_mode=dolfinx.mesh.GhostMode.shared_facet)


def _psi(x):
    return np.sin(np.pi * x[0]) * np.sin(np.pi * x[1])


def _cell_flow(x):
    """The cellular flow of the stream function sin(pi x) sin(pi y): tangential on the walls."""
    return np.stack([np.pi * np.sin(np.pi * x[0]) * np.cos(np.pi * x[1]),
                     -np.pi * np.cos(np.pi * x[0]) * np.sin(np.pi * x[1])])


def _rotation(mesh):
    """The cellular flow in P2."""
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V, name="velocity")
    u.interpolate(_cell_flow)
    return u


def _manager(mesh, tmp=None, **kwargs):
    dense = plugin(InitialComposition, source=lambda x: (x[:, 1] > 0.5).astype(float), label="dense")
    kwargs.setdefault("properties", ["initial_position", "integrated_strain", "velocity"])
    kwargs["properties"] = [dense, *build_properties(kwargs["properties"])]
    generator = build_generator({"name": "random_uniform", "particles_per_cell": 10, "seed": 3},
                                num_cells=mesh.topology.index_map(2).size_global)
    return ParticleManager(mesh, generator=generator,
                           context=PropertyContext(u_new=_rotation(mesh)), **kwargs)


def _steps(manager, u, n, dt=0.05):
    for step in range(n):
        manager.advance(u, u, dt, step=step)
        manager.update(PropertyContext(time=(step + 1) * dt, dt=dt, u_old=u, u_new=u), step=step + 1)


def test_advance_keeps_particles_and_integrates_properties():
    mesh = _mesh(MPI.COMM_SELF)
    u = _rotation(mesh)
    manager = _manager(mesh)
    field = manager.track("dense")
    n0 = manager.num_particles
    assert n0 == 10 * 128
    mean0 = dolfinx.fem.assemble_scalar(dolfinx.fem.form(field * ufl.dx))
    assert mean0 == pytest.approx(0.5, abs=0.03)
    _steps(manager, u, 10)
    assert manager.num_particles == n0 and manager.lost == 0
    swarm = manager.swarm
    swarm.check_invariants()
    # initial positions never change; each particle stays on its streamline
    x0 = swarm.property("initial_position")
    assert np.abs(_psi(swarm.x.T) - _psi(x0.T)).max() < 3e-2  # RK2, dt = 0.05, P2 on h = 1/8
    assert np.abs(swarm.x - x0).max() > 0.1  # they did move
    # the cellular flow strains everywhere but at the centre: accumulated strain grows
    strain = swarm.property("integrated_strain")[:, 0]
    assert strain.min() >= 0.0 and np.median(strain) > 0.1
    # velocity property refreshed at the update: the flow at the current position
    v = swarm.property("velocity")
    assert np.abs(v - _cell_flow(swarm.x.T).T).max() < 2e-2
    # the tracked field follows the mesh fields of the manager
    assert manager.field("dense") is field
    assert set(np.unique(swarm.property("dense"))) <= {0.0, 1.0}


def test_integrated_strain_in_shear():
    mesh = _mesh(MPI.COMM_SELF)
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([0.1 * (x[1] - 0.5), np.zeros_like(x[0])]))  # simple shear, rate 0.1
    manager = _manager(mesh)
    _steps(manager, u, 4, dt=0.5)
    # simple shear with rate g: eps_xy = g/2, sqrt(eps:eps/2) = g/2 = 0.05, for a time of 2
    assert np.allclose(manager.swarm.property("integrated_strain"), 0.05 * 2.0, rtol=1e-10)


def _bounded_run(comm, tmp: Path | None):
    mesh = _mesh(comm, 6)
    writer = ParticleWriter(tmp, properties=["dense", "integrated_strain"]) if tmp is not None else None
    manager = _manager(mesh, population=PopulationControl(6, 14, seed=2), writer=writer,
                       output=OutputSchedule(every_steps=2) if tmp is not None else OutputSchedule())
    u = _rotation(mesh)
    manager.track("dense")
    manager.update(PropertyContext(time=0.0, u_new=u), step=0)
    _steps_from(manager, u, 0, 3)
    # refine the middle band: new small cells hold few particles, the bounds add some
    marked = dolfinx.mesh.locate_entities(mesh, 2, lambda x: np.abs(x[1] - 0.5) < 0.2)
    fine = refine_on_ranks(mesh, marked)
    u_fine = _rotation(fine)
    manager.to_mesh(fine, context=PropertyContext(time=0.15, u_new=u_fine), step=3)
    after_refine = manager.particles_per_cell()
    _steps_from(manager, u_fine, 3, 2)
    manager.update(PropertyContext(time=0.25, u_new=u_fine), step=5, final=True)
    return manager, after_refine


def _steps_from(manager, u, first, n, dt=0.05):
    for step in range(first, first + n):
        manager.advance(u, u, dt, step=step)
        manager.update(PropertyContext(time=(step + 1) * dt, dt=dt, u_old=u, u_new=u), step=step + 1)


def test_population_bounds_after_refinement_and_output(tmp_path):
    manager, (lo, mean, hi) = _bounded_run(MPI.COMM_SELF, tmp_path)
    assert 6 <= lo and hi <= 14
    assert manager.added > 0 and manager.removed > 0
    assert manager.particles_per_cell()[0] >= 6 and manager.particles_per_cell()[2] <= 14
    written = sorted(p.name for p in tmp_path.glob("particles_*.h5"))
    assert written == ["particles_000000.h5", "particles_000002.h5", "particles_000004.h5", "particles_000005.h5"]
    from convection.io.pictures import import_pyvista

    pv = import_pyvista()  # VTK loaded so that it works beside DOLFINx
    reader = pv.get_reader(str(tmp_path / "particles.xdmf"))
    assert len(reader.time_values) == 4
    reader.set_active_time_value(reader.time_values[-1])
    data = reader.read()
    block = data[0] if isinstance(data, pv.MultiBlock) else data
    assert block.n_points == manager.num_particles
    assert {"dense", "integrated_strain", "id"} <= set(block.point_data.keys())


@pytest.mark.mpi
def test_population_bounds_independent_of_ranks(tmp_path_factory):
    comm = MPI.COMM_WORLD
    parallel, bounds = _bounded_run(comm, None)
    serial, _ = _bounded_run(MPI.COMM_SELF, None)
    ids_p, x_p, props_p = gathered(parallel.swarm)
    ids_s, x_s, props_s = gathered(serial.swarm)
    ok = (bounds[0] >= 6 and bounds[2] <= 14 and np.array_equal(ids_p, ids_s)
          and np.allclose(x_p, x_s, rtol=0, atol=1e-13) and np.allclose(props_p, props_s, rtol=0, atol=1e-12))
    assert comm.allreduce(ok, op=MPI.LAND)


def test_output_every_time(tmp_path):
    mesh = _mesh(MPI.COMM_SELF, 4)
    manager = _manager(mesh, properties=[], writer=ParticleWriter(tmp_path), output=OutputSchedule(every_time=0.1))
    u = _rotation(mesh)
    written = []
    for step in range(12):
        record = manager.update(PropertyContext(time=step * 0.04, u_new=u), step=step)
        if record is not None:
            written.append(step)
        manager.advance(u, u, 0.04, step=step)
    # t = 0, then the first steps at or after 0.1, 0.2, 0.3, 0.4: 0.12, 0.20, 0.32, 0.40
    assert written == [0, 3, 5, 8, 10]


def test_config_errors_name_the_entry():
    with pytest.raises(ValueError, match="particles_per_cell"):
        build_generator({"name": "random_uniform", "particles_per_cell": -5}, num_cells=10)
    with pytest.raises(ValueError, match="not found"):
        build_generator({"name": "from_file", "path": "/nonexistent/points.txt"}, num_cells=10)
    with pytest.raises(ValueError, match="valid: .*random_uniform"):
        build_generator({"name": "magic"}, num_cells=10)
    assert build_generator({"name": "random_uniform", "particles_per_cell": 2.5, "seed": 4}, num_cells=10) \
        == plugin(RandomUniform, 25, seed=4)
    with pytest.raises(ValueError, match=r"^particle generator 'box_lattice' has no parameter 'particles_per_cell'"):
        build_generator({"name": "box_lattice", "particles_per_cell": 2, "lower": [0, 0], "upper": [1, 1]}, num_cells=1)
    with pytest.raises(ValueError, match="item 1: unknown particle property 'strain'; valid: .*integrated_strain"):
        build_properties(["velocity", "strain"])
    with pytest.raises(ValueError, match="item 0: .*bogus"):
        build_properties([{"name": "integrated_strain", "bogus": 1}])
    with pytest.raises(ValueError, match="every_steps"):
        OutputSchedule(every_steps=0)
