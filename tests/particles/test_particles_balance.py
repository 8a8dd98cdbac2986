"""particles.balance.rebalance: repartition a swarm's mesh for its particles and move them along."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from fembase.distribute import cell_owners
from fembase.dolfinx_compat import SCATTER_ADD, function_space
from fembase.evaluation import locate
from fembase.partition import rcb_owners
from particles import Swarm
from particles.balance import rebalance


def _corner_swarm(mesh, n=6000, seed=3):
    """Particles in the disc of radius 0.2 around (0.3, 0.7), ids 0..n-1, a 2-column property;
    each point goes to the lowest rank that owns it (so the default partition is unbalanced)."""
    comm = mesh.comm
    rng = np.random.default_rng(seed)
    r, phi = 0.2 * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    pts = np.column_stack([0.3 + r * np.cos(phi), 0.7 + r * np.sin(phi)])
    swarm = Swarm(mesh)
    swarm.add_property("tag", 2)
    found = locate(mesh, pts, geometry=swarm.geometry)
    mine = (found.cells >= 0) & (found.cells < swarm.num_owned_cells)
    owner = np.where(mine, comm.rank, comm.size).astype(np.int32)
    lowest = np.empty_like(owner)
    comm.Allreduce(owner, lowest, op=MPI.MIN)
    mine &= lowest == comm.rank
    ids = np.flatnonzero(mine)
    swarm.add(ids, pts[mine], found.xref[mine], found.cells[mine], np.column_stack([2.0 * ids, -ids]))
    return swarm


def _gathered(swarm):
    comm = swarm.comm
    ids = np.concatenate(comm.allgather(swarm.ids))
    order = np.argsort(ids)
    x = np.concatenate(comm.allgather(swarm.x))[order]
    tag = np.concatenate(comm.allgather(swarm.property("tag")))[order]
    return ids[order], x, tag


def _imbalance(comm, value):
    counts = np.array(comm.allgather(value), dtype=float)
    return counts.max() / counts.mean()


def test_rcb_options_load_only_and_axes():
    rng = np.random.default_rng(1)
    points = rng.random((2000, 2))
    particles = np.where(points[:, 1] > 0.6, 50.0, 0.0)  # all particles in the top band
    cells = np.ones(2000)
    owners = rcb_owners(points, cells, particles, 2, particle_weight=1.0, balance=("load",), axes=(0,))
    load = np.bincount(owners, cells + particles)
    assert load.max() / load.mean() < 1.02
    # Cuts perpendicular to x only: both parts reach across the whole height.
    for part in (0, 1):
        y = points[owners == part, 1]
        assert y.min() < 0.05 and y.max() > 0.95
    # The default (cells, particles and load together) cannot balance particles with one x cut
    # any better, but it must still balance the cells.
    default = rcb_owners(points, cells, particles, 2, particle_weight=1.0)
    assert np.bincount(default).max() / 1000 < 1.05
    with pytest.raises(ValueError, match="balance"):
        rcb_owners(points, cells, particles, 2, particle_weight=1.0, balance=("area",))
    with pytest.raises(ValueError, match="axes"):
        rcb_owners(points, cells, particles, 2, particle_weight=1.0, axes=(2,))


def test_rebalance_serial_returns_the_swarm():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 8, 8)
    swarm = _corner_swarm(mesh, n=500)
    assert rebalance(swarm) is swarm
    with pytest.raises(ValueError, match="valid names"):
        rebalance(swarm, method="metis")


@pytest.mark.mpi
@pytest.mark.parametrize("kwargs, limit", [({}, 1.05), ({"axes": (1,)}, 1.05), ({"method": "morton"}, 1.15),
                                           ({"balance": ("cells", "particles", "load")}, 1.5)])
def test_rebalance_keeps_particles_and_evens_them_out(kwargs, limit):
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 24, 24)
    swarm = _corner_swarm(mesh)
    before = _gathered(swarm)
    new = rebalance(swarm, particle_weight=1.0, **kwargs)
    after = _gathered(new)
    ok = True
    try:
        new.check_invariants()
    except AssertionError:
        ok = False
    assert comm.allreduce(ok, op=MPI.LAND)
    for a, b in zip(before, after):
        np.testing.assert_array_equal(a, b)
    assert new.mesh is not mesh
    assert new.mesh.topology.index_map(2).size_global == mesh.topology.index_map(2).size_global
    # the particles now sit in the cells of the new mesh that contain them
    err = np.abs(new.geometry.push_forward(new.cells, new.xref) - new.x).max(initial=0.0)
    assert comm.allreduce(err, op=MPI.MAX) < 1e-12
    if comm.size > 1:
        assert _imbalance(comm, swarm.num_particles) > 1.3  # the starting point is unbalanced
        if "balance" in kwargs:  # cells, particles and load together: the worst of them as low as the cuts allow
            assert max(_imbalance(comm, new.num_owned_cells), _imbalance(comm, new.num_particles)) < limit
        else:  # the load 1 + W n per rank
            assert _imbalance(comm, new.num_owned_cells + new.num_particles) < limit


@pytest.mark.mpi
def test_cell_owners_are_collective_and_complete():
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 10, 10)
    num_owned = mesh.topology.index_map(2).size_local
    owners = cell_owners(mesh, np.ones(num_owned), particle_weight=0.0)
    assert owners.shape == (num_owned,) and owners.dtype == np.int32
    total = np.bincount(np.concatenate(comm.allgather(owners)), minlength=comm.size)
    assert total.sum() == 200 and total.max() / total.mean() < 1.05


def _touching_cells_missing(mesh) -> int:
    """Cells of other ranks that share a vertex with an owned cell but are not local here: the
    number of cells around each vertex of an owned cell, counted over all ranks (owned cells, summed
    into a P1 vector) minus the local (owned and ghost) cells around it."""
    import dolfinx.fem
    import dolfinx.la

    V = function_space(mesh, "Lagrange", 1)
    tdim = mesh.topology.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    num_local = num_owned + mesh.topology.index_map(tdim).num_ghosts
    dofs = np.array([V.dofmap.cell_dofs(c) for c in range(num_local)])
    total = dolfinx.fem.Function(V)
    np.add.at(total.x.array, dofs[:num_owned].reshape(-1), 1.0)
    total.x.scatter_reverse(SCATTER_ADD)
    total.x.scatter_forward()
    local = np.zeros_like(total.x.array)
    np.add.at(local, dofs.reshape(-1), 1.0)
    touched = np.unique(dofs[:num_owned])
    return int(np.sum(total.x.array[touched] - local[touched]))


@pytest.mark.mpi
@pytest.mark.parametrize("ghost_layer", ["vertex", "facet"])
def test_vertex_ghost_layer_holds_every_touching_cell(ghost_layer):
    """With the vertex layer every cell that touches an owned cell is local (so a particle that
    crosses a partition corner lands in a ghost cell); the facet layer misses the cells that touch
    only at a corner, which this check must see."""
    comm = MPI.COMM_WORLD
    if comm.size == 1:
        pytest.skip("needs several ranks")
    mesh = dolfinx.mesh.create_unit_square(comm, 16, 16)
    new = rebalance(_corner_swarm(mesh), ghost_layer=ghost_layer)
    missing = comm.allreduce(_touching_cells_missing(new.mesh), op=MPI.SUM)
    if ghost_layer == "vertex":
        assert missing == 0
    else:
        assert missing > 0
    with pytest.raises(ValueError, match="ghost layer"):
        rebalance(new, ghost_layer="edge")
