"""The annulus scaling benchmark (benchmarks/scaling/circular.py): mesh, flows, and a short
collective run that keeps every particle."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "scaling"))

import circular  # noqa: E402


def test_annulus_mesh_is_conforming_with_boundary_on_the_circles():
    radial, angular = 3, 20
    mesh = circular.create_annulus(MPI.COMM_SELF, radial, angular=angular)
    topo = mesh.topology
    topo.create_connectivity(1, 2)
    topo.create_connectivity(1, 0)
    num_facets = topo.index_map(1).size_local
    cells_per_facet = np.diff(topo.connectivity(1, 2).offsets)
    assert topo.index_map(0).size_local == (radial + 1) * angular  # the seam column is shared
    assert topo.index_map(2).size_local == 2 * radial * angular
    assert set(np.unique(cells_per_facet)) == {1, 2}
    boundary = np.flatnonzero(cells_per_facet == 1)
    assert boundary.shape[0] == 2 * angular
    assert np.array_equal(np.sort(boundary), np.sort(dolfinx.mesh.exterior_facet_indices(topo)))
    # Euler characteristic of an annulus: V - E + F = 0.
    assert topo.index_map(0).size_local - num_facets + topo.index_map(2).size_local == 0
    x = mesh.geometry.x[:, :2]
    # P1 geometry: the geometry dofmap lists each cell's nodes in the order of its vertices.
    node_of_vertex = np.empty(topo.index_map(0).size_local, dtype=np.int64)
    node_of_vertex[topo.connectivity(2, 0).array] = mesh.geometry.dofmap.array
    r_vertex = np.hypot(*x[node_of_vertex].T)
    facet_vertices = topo.connectivity(1, 0).array.reshape(-1, 2)[boundary]
    r = r_vertex[facet_vertices]
    on_inner = np.isclose(r, circular.R_IN, atol=1e-12).all(axis=1)
    on_outer = np.isclose(r, circular.R_OUT, atol=1e-12).all(axis=1)
    assert np.all(on_inner ^ on_outer)
    assert on_inner.sum() == on_outer.sum() == angular


def test_annulus_area_converges_at_second_order():
    exact = math.pi * (circular.R_OUT**2 - circular.R_IN**2)
    errors, sizes = [], []
    for radial in (2, 4, 8):
        mesh = circular.create_annulus(MPI.COMM_SELF, radial)
        area = dolfinx.fem.assemble_scalar(dolfinx.fem.form(dolfinx.fem.Constant(mesh, 1.0) * ufl.dx))
        errors.append(abs(area - exact))
        sizes.append(1.0 / circular.angular_divisions(radial))
    assert errors[0] > errors[1] > errors[2] > 0.0
    order = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert 1.8 < order < 2.2


def test_wall_flow_vanishes_on_the_circles_and_unknown_flow_lists_names():
    flow = circular.WallFlow()
    theta = np.linspace(0.0, 2.0 * np.pi, 7)
    for r in (circular.R_IN, circular.R_OUT):
        assert np.allclose(flow(np.stack([r * np.cos(theta), r * np.sin(theta)])), 0.0, atol=1e-15)
    inside = flow(np.array([[0.8], [0.0]]))
    assert inside[0, 0] == 0.0 and inside[1, 0] > 0.0
    with pytest.raises(ValueError, match="rigid.*wall|wall.*rigid"):
        circular.create_flow("spiral")


def test_stand_in_solve_converges_to_the_radial_solution():
    solver = circular.PoissonStandIn(circular.create_annulus(MPI.COMM_SELF, 6))
    assert solver.solve() > 0
    assert solver.max_error() < 1e-3


@pytest.mark.mpi
def test_short_collective_run_keeps_every_particle():
    comm = MPI.COMM_WORLD
    mesh = circular.create_annulus(comm, 6)
    problem = circular.setup_problem(mesh, particles_per_cell=4, flow="wall", cfl=0.5, integrator="rk2", seed=3)
    ids_before = np.sort(np.concatenate(comm.allgather(problem.swarm.ids)))
    times = circular.advance(problem, 12)
    ids_after = np.sort(np.concatenate(comm.allgather(problem.swarm.ids)))
    swarm = problem.swarm
    in_owned = comm.allreduce(bool(np.all((swarm.cells >= 0) & (swarm.cells < swarm.num_owned_cells))), op=MPI.LAND)
    sent = comm.allreduce(times.sent, op=MPI.SUM)
    moved = comm.allreduce(times.changed_cell, op=MPI.SUM)
    assert ids_before.shape[0] == problem.num_particles == 4 * mesh.topology.index_map(2).size_global
    assert np.array_equal(ids_before, np.arange(problem.num_particles))
    assert np.array_equal(ids_before, ids_after)
    assert times.lost == 0
    assert in_owned
    assert moved > 0
    assert (sent > 0) == (comm.size > 1)


def test_weak_plan_keeps_cells_per_rank_and_efficiency_is_relative_to_one_rank():
    runs = circular.plan(["strong", "weak"], [1, 2, 4], 32, 24)
    assert [r.radial for r in runs if r.study == "strong"] == [32, 32, 32]
    weak = [r for r in runs if r.study == "weak"]
    cells = [2 * r.radial * circular.angular_divisions(r.radial) for r in weak]
    assert np.allclose(np.array(cells) / (cells[0] * np.array([1, 2, 4])), 1.0, atol=0.01)
    base = {"ranks": 1, "particles": 100, "loop_seconds": 8.0, "particle_seconds": 4.0}
    strong = [dict(base, study="strong"), dict(base, study="strong", ranks=2, loop_seconds=5.0, particle_seconds=2.0)]
    circular.efficiencies(strong)
    assert strong[1]["efficiency"] == pytest.approx(0.8) and strong[1]["particle_efficiency"] == pytest.approx(1.0)
    weak_recs = [dict(base, study="weak"), dict(base, study="weak", ranks=2, particles=210, loop_seconds=10.0)]
    circular.efficiencies(weak_recs)
    assert weak_recs[1]["efficiency"] == pytest.approx(8.0 * 1.05 / 10.0)
