"""Transport between cells: neighbour search, bounding-box fallback, sorting, counters."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from fembase.evaluation import locate
from particles import Swarm
from particles.relocation.between_cells import relocate


def _mesh(kind, comm=MPI.COMM_SELF):
    if kind == "triangle":
        return dolfinx.mesh.create_unit_square(comm, 12, 10)
    if kind == "tetrahedron":
        return dolfinx.mesh.create_unit_cube(comm, 5, 4, 5)
    return dolfinx.mesh.create_unit_square(comm, 9, 8, cell_type=dolfinx.mesh.CellType.quadrilateral)


def _swarm(mesh, n, rng):
    swarm = Swarm(mesh)
    gdim = mesh.geometry.dim
    pts = rng.random((n, gdim))
    found = locate(mesh, pts, geometry=swarm.geometry)
    ok = (found.cells >= 0) & (found.cells < swarm.num_owned_cells)
    swarm.add(np.flatnonzero(ok), pts[ok], found.xref[ok], found.cells[ok])
    return swarm


@pytest.mark.parametrize("kind", ["triangle", "tetrahedron", "quadrilateral"])
def test_relocated_cells_contain_particles(kind):
    rng = np.random.default_rng(5)
    mesh = _mesh(kind)
    swarm = _swarm(mesh, 4000, rng)
    n = swarm.num_particles
    geom = swarm.geometry
    h = 0.1
    step = 0.4 * h * (rng.random(swarm.x.shape) - 0.5)
    far = rng.random(n) < 0.02
    step[far] = 3 * h * (rng.random((far.sum(), swarm.gdim)) - 0.5)
    new_x = np.clip(swarm.x + step, 1e-9, 1 - 1e-9)
    outside = rng.random(n) < 0.01
    new_x[outside, 0] = 1.5
    swarm.x[:] = new_x
    stats = relocate(swarm)

    assert sum(stats) == n
    assert stats.not_found == np.count_nonzero(outside)
    assert stats.stayed > 0 and stats.neighbour > 0 and stats.fallback > 0
    assert stats.fallback < 0.05 * n

    cells = swarm.cells
    ok = cells >= 0
    assert np.count_nonzero(~ok) == stats.not_found
    # reference positions are in sync and inside the cell
    assert np.allclose(geom.push_forward(cells[ok], swarm.xref[ok]), swarm.x[ok], atol=1e-12)
    assert np.all(geom.inside(swarm.xref[ok]))
    # agrees with a plain bounding-box search (ties on shared facets may pick another cell)
    bb = locate(mesh, swarm.x)
    assert np.array_equal(bb.cells < 0, ~ok)
    differ = ok & (bb.cells != cells)
    assert np.all(geom.inside(geom.pull_back(bb.cells[differ], swarm.x[differ])))
    # sorted by cell with lost particles last, offsets valid
    key = np.where(ok, cells, swarm.num_owned_cells)
    assert np.all(np.diff(key) >= 0)
    for k in rng.integers(0, swarm.num_owned_cells, 20):
        assert np.all(cells[swarm.cell_slice(k)] == k)
    assert swarm.offsets[-1] == np.count_nonzero(ok)
    swarm.remove(~ok)
    swarm.check_invariants()


def test_unmoved_particles_stay():
    rng = np.random.default_rng(9)
    swarm = _swarm(_mesh("triangle"), 500, rng)
    before = swarm.cells.copy()
    stats = relocate(swarm)
    assert stats == (500, 0, 0, 0)
    assert np.array_equal(before, swarm.cells)


@pytest.mark.mpi
def test_relocate_then_migrate_distributed():
    from particles.parallel.migration import migrate

    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 16, 16)
    rng = np.random.default_rng(11 + comm.rank)
    swarm = Swarm(mesh)
    pts = rng.random((2000, 2))
    found = locate(mesh, pts, geometry=swarm.geometry)
    ok = (found.cells >= 0) & (found.cells < swarm.num_owned_cells)
    ids = comm.rank * 10_000 + np.flatnonzero(ok)
    swarm.add(ids, pts[ok], found.xref[ok], found.cells[ok])
    total = swarm.global_num_particles()
    for _ in range(3):
        swarm.x[:] = np.clip(swarm.x + 0.05 * (rng.random(swarm.x.shape) - 0.5), 1e-9, 1 - 1e-9)
        stats = relocate(swarm)
        assert sum(stats) == swarm.num_particles
        migrate(swarm)
    all_ids = np.concatenate(comm.allgather(swarm.ids))
    geom = swarm.geometry
    err = float(np.abs(geom.push_forward(swarm.cells, swarm.xref) - swarm.x).max(initial=0.0))
    sorted_ok = bool(np.all(np.diff(swarm.cells) >= 0)) and bool(np.all(swarm.cells < swarm.num_owned_cells))
    assert comm.allreduce(err, op=MPI.MAX) < 1e-12
    assert comm.allreduce(sorted_ok, op=MPI.LAND)
    assert all_ids.shape[0] == total == np.unique(all_ids).shape[0]


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["triangle", "tetrahedron"])
def test_relocation_hands_over_the_outside_rows(kind):
    """After a relocation without sort, outside_rows() (the rows the relocation listed: ghost cells
    from the kernel, -1 or ghost from the bounding-box fallback) equals a scan of all rows, also
    after some of them were discarded; serially the fallback's -1 rows are the only ones."""
    from particles.storage.row_kernels import rows_outside

    comm = MPI.COMM_WORLD
    mesh = _mesh(kind, comm)
    rng = np.random.default_rng(3 + comm.rank)
    swarm = _swarm(mesh, 3000, rng)
    swarm.x[:] = swarm.x + 0.3 * (rng.random(swarm.x.shape) - 0.5)  # some leave the rank, some the box
    relocate(swarm, sort=False)
    scanned = rows_outside(swarm.cells, swarm.num_owned_cells)
    listed = swarm.outside_rows()
    assert swarm._order.outside is not None  # the listed path, not the scan
    assert np.array_equal(listed, scanned)
    assert comm.allreduce(scanned.size, op=MPI.SUM) > 0
    swarm.discard_rows(scanned[::3])
    assert np.array_equal(swarm.outside_rows(), rows_outside(swarm.cells, swarm.num_owned_cells))
    swarm.discard_rows(swarm.outside_rows())
    swarm.sort()  # with the counts kept up to date through the discards
    swarm.check_invariants()

    # A permutation between the relocation and the migration (take) drops the handed-over rows.
    swarm.x[:] = swarm.x + 0.3 * (rng.random(swarm.x.shape) - 0.5)
    relocate(swarm, sort=False)
    swarm.take(np.arange(swarm.num_particles)[::-1])
    assert np.array_equal(swarm.outside_rows(), rows_outside(swarm.cells, swarm.num_owned_cells))


def test_sort_reuses_buffers_but_never_overwrites_held_arrays():
    rng = np.random.default_rng(4)
    swarm = _swarm(_mesh("triangle"), 600, rng)
    held, held_view = swarm.x, swarm.xref[:, 0]
    expected, expected_view = held.copy(), held_view.copy()
    for _ in range(4):
        swarm.cells[:] = rng.integers(0, swarm.num_owned_cells, swarm.num_particles)
        swarm.sort()
        assert np.array_equal(held, expected) and np.array_equal(held_view, expected_view)
        assert np.all(np.diff(swarm.cells) >= 0)
    del held, held_view
    # the address of the released buffer, not a reference (a reference would block the reuse)
    spare_x = swarm._rows.spare[1].__array_interface__["data"][0]
    swarm.cells[:] = rng.integers(0, swarm.num_owned_cells, swarm.num_particles)
    swarm.sort()
    assert swarm.x.__array_interface__["data"][0] == spare_x  # released buffers are reused
    swarm.check_invariants()
