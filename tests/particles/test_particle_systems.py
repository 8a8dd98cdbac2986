"""ParticleSystems: several named particle systems called in turn, each as it would be alone."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from fembase.distribute import refine_on_ranks
from fembase.dolfinx_compat import function_space
from particles.manager import ParticleManager, build_generator, build_properties
from particles.population.control import PopulationControl
from particles.properties import PropertyContext
from particles.systems import ParticleSystems, file_stem

from _helpers import gathered


def _mesh(comm=MPI.COMM_WORLD, n=8):
    return dolfinx.mesh.create_unit_square(comm, n, n, ghost_mode=dolfinx.mesh.GhostMode.shared_facet)


def _flow(mesh):
    V = function_space(mesh, "Lagrange", 2, shape=(2,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([np.pi * np.sin(np.pi * x[0]) * np.cos(np.pi * x[1]),
                                      -np.pi * np.cos(np.pi * x[0]) * np.sin(np.pi * x[1])]))
    return u


def _system(mesh, u, generator, *, population=None):
    cells = mesh.topology.index_map(2).size_global
    return ParticleManager(mesh, generator=build_generator(generator, num_cells=cells),
                           properties=build_properties(["initial_position"]), population=population,
                           context=PropertyContext(u_new=u))


def _dense(mesh, u):
    return _system(mesh, u, {"name": "random_uniform", "particles_per_cell": 6, "seed": 3},
                   population=PopulationControl(4, 8, 5))


def _tracers(mesh, u):
    return _system(mesh, u, {"name": "random_uniform", "num_particles": 50, "seed": 11})


def _state(manager):
    """Ids, positions and properties of a manager's particles over all ranks, sorted by id."""
    return gathered(manager.swarm)


def _run(systems, u, steps=6, dt=0.05):
    for step in range(steps):
        systems.advance(u, u, dt, step=step)
        systems.update(PropertyContext(time=(step + 1) * dt, dt=dt, u_new=u), step=step + 1)


def test_a_system_is_the_same_beside_another(world):
    """Each system's particles after advection, population control and a mesh change are those it
    has alone (its own seeds, ids and counters); the counts add up (serial and collective)."""
    mesh = _mesh(world)
    u = _flow(mesh)
    alone = {"dense": ParticleSystems({"dense": _dense(mesh, u)}),
             "tracers": ParticleSystems({"tracers": _tracers(mesh, u)})}
    both = ParticleSystems({"dense": _dense(mesh, u), "tracers": _tracers(mesh, u)}, primary="dense")
    for systems in (*alone.values(), both):
        _run(systems, u)
    fine = refine_on_ranks(mesh)
    for systems in (*alone.values(), both):
        systems.to_mesh(fine, step=7)
    for name in ("dense", "tracers"):
        for x, y in zip(_state(alone[name][name]), _state(both[name])):
            np.testing.assert_array_equal(x, y)
    assert both.num_particles == alone["dense"].num_particles + 50
    assert both.primary is both["dense"] and both.names == ["dense", "tracers"] and len(both) == 2
    assert [s.mesh for s in both.swarms] == [fine, fine]
    assert both["dense"].added > 0 and both.lost == 0
    timings = both.timings
    assert timings["particle_advection"] == pytest.approx(
        both["dense"].timings["particle_advection"] + both["tracers"].timings["particle_advection"])


def test_names_and_primary():
    mesh = _mesh(MPI.COMM_SELF, 2)
    u = _flow(mesh)
    with pytest.raises(ValueError, match="at least one"):
        ParticleSystems({})
    with pytest.raises(ValueError, match="no particle system 'x'"):
        ParticleSystems({"a": _tracers(mesh, u)}, primary="x")
    systems = ParticleSystems({"a": _tracers(mesh, u), "b": _tracers(mesh, u)})
    assert systems.primary_name == "a" and not systems.writes
    assert file_stem("particles") == "particles" and file_stem("tracers") == "particles_tracers"


def test_the_balancer_weighs_every_systems_particles(world):
    """A repartition's cell weights and the load count the particles of all systems (collective)."""
    from convection.adapt.rebalance import RankLoads

    mesh = _mesh(world)
    u = _flow(mesh)
    dense, tracers = _dense(mesh, u), _tracers(mesh, u)
    loads = RankLoads.measure(mesh, [dense.swarm, tracers.swarm], particle_weight=2.0)
    owned = mesh.topology.index_map(2).size_local
    mine = dense.swarm.num_particles + tracers.swarm.num_particles
    assert loads.particles[mesh.comm.rank] == mine
    assert loads.load[mesh.comm.rank] == pytest.approx(owned + 2.0 * mine)
    assert sum(loads.particles) == dense.num_particles + tracers.num_particles


def test_refresh_updates_one_property_where_a_system_has_it():
    """``refresh(column, context)``: that property now, whatever its policy, in the systems that have
    it (the elastic stress of a flow solved again at a step's start); the others untouched."""
    mesh = _mesh(MPI.COMM_SELF)
    u = _flow(mesh)
    cells = mesh.topology.index_map(2).size_global
    sampled = ParticleManager(mesh, generator=build_generator({"name": "random_uniform", "num_particles": 40,
                                                               "seed": 2}, num_cells=cells),
                              properties=build_properties(["initial_position", "velocity"]),
                              context=PropertyContext(u_new=u))
    systems = ParticleSystems({"sampled": sampled, "tracers": _tracers(mesh, u)})
    sampled.properties.values("velocity")[:] = 0.0
    before = systems["tracers"].swarm.properties.copy()
    systems.refresh("velocity", PropertyContext(u_new=u))
    x = sampled.swarm.x
    expected = np.stack([np.pi * np.sin(np.pi * x[:, 0]) * np.cos(np.pi * x[:, 1]),
                         -np.pi * np.cos(np.pi * x[:, 0]) * np.sin(np.pi * x[:, 1])], axis=1)
    np.testing.assert_allclose(sampled.properties.values("velocity"), expected, atol=2e-2)
    np.testing.assert_array_equal(systems["tracers"].swarm.properties, before)
