"""The circular-flow scaling benchmark (benchmarks/scaling/circular.py): annulus mesh, the Couette
flow and its Stokes solve, and short collective runs (annulus, spherical shell) that keep every
particle."""

import math

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from benchmarks.scaling import circular

from fembase.dolfinx_compat import geometry_dofmap
from _helpers import needs_hypre


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
    node_of_vertex[topo.connectivity(2, 0).array] = geometry_dofmap(mesh).reshape(-1)
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


@pytest.mark.parametrize("dim", [2, 3])
def test_couette_flow_rotates_the_surfaces_and_is_tangential(dim):
    flow = circular.CouetteFlow(dim, omega_inner=-1.0, omega_outer=2.0)
    assert np.allclose(flow.angular_velocity(np.array([circular.R_IN, circular.R_OUT])), [-1.0, 2.0])
    x = np.random.default_rng(1).normal(size=(3, 7))
    if dim == 2:
        x[2] = 0.0
    u = flow(x)
    assert u.shape == (dim, 7)
    assert np.allclose(np.sum(u * x[:dim], axis=0), 0.0, atol=1e-14)
    assert set(flow.boundary_conditions()) == {"inner", "outer"}


def test_stokes_solve_reproduces_couette_flow_at_second_order():
    """The Stokes solution with rotations prescribed on both circles is the Couette flow, up to the
    polygonal boundary (second order in h)."""
    errors = []
    for radial in (4, 8):
        flow = circular.StokesFlow(circular.create_annulus(MPI.COMM_SELF, radial), circular.CouetteFlow(2))
        assembly, solve = flow.solve()
        assert assembly > 0.0 and solve > 0.0
        errors.append(flow.max_error())
    assert errors[0] < 2e-2
    assert 1.8 < math.log2(errors[0] / errors[1]) < 2.2



@needs_hypre
def test_spherical_shell_solve_is_iterative_by_default_and_agrees_with_mumps():
    """In 3D the default ('auto') is FGMRES + block Schur preconditioner; with rotations prescribed on
    both spheres it converges in a few tens of iterations to MUMPS's solution."""
    mesh = circular.create_domain(MPI.COMM_SELF, 3, 0.35)
    flows = {name: circular.StokesFlow(mesh, circular.CouetteFlow(3), solver=name) for name in ("auto", "direct")}
    for flow in flows.values():
        flow.solve()
    iterative, direct = flows["auto"], flows["direct"]
    assert iterative.stokes.solver == "iterative" and 5 < iterative.iterations < 100
    difference = np.max(np.abs(iterative.velocity.x.array - direct.velocity.x.array))
    assert difference < 1e-5 * np.max(np.abs(direct.velocity.x.array))
    assert iterative.max_error() == pytest.approx(direct.max_error(), rel=1e-6)

@pytest.mark.mpi
@pytest.mark.parametrize("dim, size", [(2, 6), (3, 0.35)])
def test_short_collective_run_keeps_every_particle(dim, size):
    comm = MPI.COMM_WORLD
    mesh = circular.create_domain(comm, dim, size)
    problem = circular.setup_problem(mesh, particles_per_cell=4, cfl=0.5, integrator="rk2", seed=3)
    ids_before = np.sort(np.concatenate(comm.allgather(problem.swarm.ids)))
    times = circular.advance(problem, 6)
    ids_after = np.sort(np.concatenate(comm.allgather(problem.swarm.ids)))
    swarm = problem.swarm
    in_owned = comm.allreduce(bool(np.all((swarm.cells >= 0) & (swarm.cells < swarm.num_owned_cells))), op=MPI.LAND)
    sent = comm.allreduce(times.sent, op=MPI.SUM)
    moved = comm.allreduce(times.changed_cell, op=MPI.SUM)
    r_min, r_max = circular._radii_range(swarm)
    assert ids_before.shape[0] == problem.num_particles == 4 * mesh.topology.index_map(dim).size_global
    assert np.array_equal(ids_before, np.arange(problem.num_particles))
    assert np.array_equal(ids_before, ids_after)
    assert times.lost == 0
    assert in_owned
    assert moved > 0
    assert (sent > 0) == (comm.size > 1)
    assert times.assemble > 0.0 and times.solve > 0.0
    assert circular.R_IN <= r_min and r_max < circular.R_OUT


def test_weak_plan_keeps_cells_per_rank_and_efficiency_is_relative_to_one_rank():
    runs = circular.plan(["strong", "weak"], [1, 2, 4], 32, 24)
    assert [r.size for r in runs if r.study == "strong"] == [32, 32, 32]
    weak = [r for r in runs if r.study == "weak"]
    cells = [2 * r.size * circular.angular_divisions(r.size) for r in weak]
    assert np.allclose(np.array(cells) / (cells[0] * np.array([1, 2, 4])), 1.0, atol=0.01)
    weak_3d = [r.size for r in circular.plan(["weak"], [1, 2, 4], 0.2, 0.25, dim=3)]
    assert np.allclose(0.25**3 / np.array(weak_3d) ** 3, [1, 2, 4], rtol=1e-3)
    base = {"ranks": 1, "particles": 100, "loop_seconds": 8.0, "particle_seconds": 4.0, "stokes_dofs": 10,
            "stokes_seconds": 3.0}
    strong = [dict(base, study="strong"), dict(base, study="strong", ranks=2, loop_seconds=5.0, particle_seconds=2.0)]
    circular.efficiencies(strong)
    assert strong[1]["efficiency"] == pytest.approx(0.8) and strong[1]["particle_efficiency"] == pytest.approx(1.0)
    weak_recs = [dict(base, study="weak"), dict(base, study="weak", ranks=2, particles=210, loop_seconds=10.0,
                                                  stokes_dofs=20, stokes_seconds=4.0)]
    circular.efficiencies(weak_recs)
    assert weak_recs[1]["efficiency"] == pytest.approx(8.0 * 1.05 / 10.0)
    assert weak_recs[1]["stokes_efficiency"] == pytest.approx(3.0 / 4.0)
    assert strong[1]["stokes_efficiency"] == pytest.approx(0.5)
