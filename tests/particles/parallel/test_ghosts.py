"""Vertex ghost layer: halo cells and ghost particles against a brute-force reference."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from particles import Swarm
from particles.generation import generate
from particles.parallel.ghosts import exchange_ghosts, ghost_exchange_for, vertex_complete


def _setup(comm, ghost_mode, n=9):
    mesh = dolfinx.mesh.create_unit_square(comm, n, n, ghost_mode=ghost_mode)
    swarm = Swarm(mesh)
    generate(swarm, "random_uniform", num_particles=700, seed=4)
    swarm.add_property("a")
    swarm.add_property("b", 2)
    swarm.property("a")[:, 0] = 3.0 * swarm.ids
    swarm.property("b")[:] = swarm.x
    return mesh, swarm


def test_serial_has_no_ghosts():
    mesh, swarm = _setup(MPI.COMM_SELF, dolfinx.mesh.GhostMode.shared_facet, 4)
    g = exchange_ghosts(swarm, ["a"])
    ex = ghost_exchange_for(mesh)
    assert g.num_particles == 0 and ex.num_halo_cells == 0 and vertex_complete(mesh)
    assert np.all(np.diff(ex.neighbour_offsets) >= 3)  # vertex neighbours exist in serial too
    with pytest.raises(KeyError, match="a"):
        g.property("b")


@pytest.mark.mpi
@pytest.mark.parametrize("ghost_mode", [dolfinx.mesh.GhostMode.shared_facet, dolfinx.mesh.GhostMode.none])
def test_halo_and_ghost_particles_match_brute_force(ghost_mode):
    comm = MPI.COMM_WORLD
    mesh, swarm = _setup(comm, ghost_mode)
    ex = ghost_exchange_for(mesh)
    g = exchange_ghosts(swarm, ["b", "a"])
    geo = swarm.geometry
    n_owned = swarm.num_owned_cells
    start = mesh.topology.index_map(2).local_range[0]
    verts = geo.coords[geo.nodes[:n_owned, :3]]  # (n_owned, 3, 2)
    all_verts = comm.allgather(verts)
    all_globals = comm.allgather(np.arange(n_owned, dtype=np.int64) + start)
    all_ids = comm.allgather(swarm.ids)
    all_cells = comm.allgather(swarm.cells.astype(np.int64) + start)
    key = np.unique(np.round(np.concatenate([v.reshape(-1, 2) for v in all_verts]), 9), axis=0, return_inverse=True)[1]
    vid, pos = [], 0
    for v in all_verts:
        vid.append(key[pos : pos + v.shape[0] * 3].reshape(-1, 3))
        pos += v.shape[0] * 3
    mine = vid[comm.rank]
    expected_cells, expected_ids = [], []
    for r in range(comm.size):
        if r == comm.rank:
            continue
        touching = np.any(np.isin(vid[r], mine), axis=1)
        expected_cells.append(all_globals[r][touching])
        expected_ids.append(all_ids[r][np.isin(all_cells[r], all_globals[r][touching])])
    exp_cells = np.sort(np.concatenate(expected_cells))
    exp_ids = np.sort(np.concatenate(expected_ids))
    checks = [
        np.array_equal(np.sort(ex.halo_globals), exp_cells),
        np.array_equal(np.sort(g.ids), exp_ids),
        np.allclose(g.property("b"), g.x) and np.array_equal(g.property("a")[:, 0], 3.0 * g.ids),
        np.all(np.diff(g.cells) >= 0),
        # the cell each copy is filed under is the cell its owner keeps it in
        np.array_equal(ex.halo_globals[g.cells - n_owned],
                       np.concatenate(all_cells)[np.argsort(np.concatenate(all_ids))][g.ids]),
        # halo values come from the owners
        np.array_equal(ex.exchange_cell_values((np.arange(n_owned) + start).astype(float)), ex.halo_globals),
    ]
    # local ghost index where the halo cell is a DOLFINx ghost cell: same cell centre
    local = ex.halo_local
    cmap = mesh.topology.index_map(2)
    if ghost_mode == dolfinx.mesh.GhostMode.none:
        checks.append(np.all(local == -1))
    else:
        ghosts = np.asarray(cmap.ghosts)
        present = np.isin(ex.halo_globals, ghosts)
        checks.append(np.array_equal(local >= 0, present))
        checks.append(np.array_equal(ghosts[local[present] - n_owned], ex.halo_globals[present]))
    complete = vertex_complete(mesh)
    checks.append(complete == comm.allreduce(bool(np.all(local >= 0)), op=MPI.LAND))
    ok = comm.allreduce(bool(all(checks)), op=MPI.LAND)
    assert ok, checks
    # with DOLFINx 0.5's facet ghosts a vertex-only neighbour is missing somewhere: the reason for the halo
    assert not complete
