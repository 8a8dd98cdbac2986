"""Weighted space-filling-curve partitioning (the mechanism for particle-weighted load balancing)."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl

from convection.balance import block_owners, morton_order, weighted_partitioner


def test_block_owners_balance_weights():
    w = np.r_[np.full(50, 10.0), np.ones(150)]
    owners = block_owners(w, 4)
    assert np.all(np.diff(owners) >= 0) and set(owners) == {0, 1, 2, 3}
    sums = np.bincount(owners, weights=w)
    assert sums.max() / sums.mean() < 1.05
    with pytest.raises(ValueError, match="positive"):
        block_owners(np.array([1.0, 0.0]), 2)


def test_morton_order_is_a_permutation_with_locality():
    rng = np.random.default_rng(0)
    p = rng.random((400, 2))
    order = morton_order(p)
    assert np.array_equal(np.sort(order), np.arange(400))
    steps = np.linalg.norm(np.diff(p[order], axis=0), axis=1)
    assert np.median(steps) < 0.2 * np.median(np.linalg.norm(np.diff(p, axis=0), axis=1))


def _structured(n):
    xs = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(xs, xs)
    x = np.column_stack([X.ravel(), Y.ravel()])
    cells = []
    for j in range(n):
        for i in range(n):
            v0 = j * (n + 1) + i
            cells += [[v0, v0 + 1, v0 + n + 2], [v0, v0 + n + 1, v0 + n + 2]]
    return x, np.array(cells, dtype=np.int64)


@pytest.mark.mpi
def test_weighted_mesh_partition():
    comm = MPI.COMM_WORLD
    def weight(mid):
        return 1.0 + 10.0 * (mid[:, 1] < 0.3)  # heavy cells at the bottom, as particles near an interface

    if comm.rank == 0:
        x, cells = _structured(12)
        order = morton_order(x[cells].mean(axis=1))
        cells = cells[order]
        weights = weight(x[cells].mean(axis=1))
    else:
        x, cells, weights = np.zeros((0, 2)), np.zeros((0, 3), dtype=np.int64), np.zeros(0)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.triangle, 1))
    mesh = dolfinx.mesh.create_mesh(comm, cells, x, domain, ghost_mode=dolfinx.mesh.GhostMode.shared_facet,
                                    partitioner=weighted_partitioner(weights))
    num_owned = mesh.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(mesh, 2, np.arange(num_owned, dtype=np.int32))
    sums = np.array(comm.allgather(float(weight(mid[:, :2]).sum())))
    counts = np.array(comm.allgather(num_owned))
    assert counts.sum() == 2 * 12 * 12
    assert sums.max() / sums.mean() < 1.1  # balanced by weight ...
    assert counts.max() / counts.mean() > 1.2  # ... not by cell count
    area = comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * ufl.dx(domain=mesh))))
    assert area == pytest.approx(1.0)
    assert comm.allreduce(mesh.topology.index_map(2).num_ghosts) > 0
