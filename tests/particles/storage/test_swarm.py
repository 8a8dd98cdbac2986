"""Cell-sorted storage invariants of particles.Swarm."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from particles import Swarm


@pytest.fixture
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)


def _random_batch(rng, swarm, m, start_id):
    cells = rng.integers(0, swarm.num_owned_cells, m).astype(np.int32)
    return np.arange(start_id, start_id + m), rng.random((m, 2)), rng.random((m, 2)), cells


def test_add_keeps_cells_sorted_and_offsets(mesh):
    rng = np.random.default_rng(1)
    swarm = Swarm(mesh)
    swarm.add_property("c", 1, value=0.0)
    for batch in range(3):
        ids, x, xref, cells = _random_batch(rng, swarm, 50, 50 * batch)
        swarm.add(ids, x, xref, cells, properties=ids[:, None].astype(float))
    swarm.check_invariants()
    assert swarm.num_particles == 150
    for k in range(swarm.num_owned_cells):
        rows = swarm.cell_slice(k)
        assert np.all(swarm.cells[rows] == k)
    # properties travel with their particle through the sort
    assert np.array_equal(swarm.property("c")[:, 0], swarm.ids.astype(float))


def test_remove_and_property_columns(mesh):
    rng = np.random.default_rng(2)
    swarm = Swarm(mesh)
    ids, x, xref, cells = _random_batch(rng, swarm, 40, 0)
    swarm.add(ids, x, xref, cells)
    swarm.add_property("v", 2, value=1.0)
    swarm.add_property("w", 1, value=3.0)
    assert swarm.property("w").shape == (40, 1) and np.all(swarm.property("w") == 3.0)
    swarm.remove_property("v")
    assert swarm.layout("w").start == 0 and swarm.num_property_columns == 1
    removed = swarm.remove(swarm.ids % 2 == 0)
    assert removed == 20 and swarm.num_particles == 20
    swarm.check_invariants()
    with pytest.raises(KeyError, match="known"):
        swarm.property("nope")


def test_appended_rows_are_placed_by_the_next_sort_stably(mesh):
    rng = np.random.default_rng(3)
    swarm = Swarm(mesh)
    swarm.add_property("c", 1)
    ids, x, xref, cells = _random_batch(rng, swarm, 60, 0)
    swarm.add(ids, x, xref, cells, properties=ids[:, None].astype(float))
    before = swarm.ids.copy()
    ids2, x2, xref2, cells2 = _random_batch(rng, swarm, 30, 100)
    swarm.append_rows(ids2, x2, xref2, cells2, ids2[:, None].astype(float))
    assert swarm.num_particles == 90 and np.array_equal(swarm.ids[60:], ids2)  # appended, unsorted
    swarm.sort()
    swarm.check_invariants()
    assert np.array_equal(swarm.property("c")[:, 0], swarm.ids.astype(float))
    for k in range(swarm.num_owned_cells):
        # within a cell: the old rows in their order, then the appended ones in theirs
        got = swarm.ids[swarm.cell_slice(k)]
        old = before[np.isin(before, got)]
        new = ids2[cells2 == k]
        assert np.array_equal(got, np.concatenate([old, new]))


def test_discarded_rows_are_dropped_by_the_next_sort(mesh):
    rng = np.random.default_rng(4)
    swarm = Swarm(mesh)
    ids, x, xref, cells = _random_batch(rng, swarm, 80, 0)
    swarm.add(ids, x, xref, cells)
    leaving = np.arange(0, 80, 7)
    left = swarm.ids[leaving].copy()
    swarm.cells[leaving] = -1  # e.g. left the rank's cells
    swarm.discard_rows(leaving)
    ids2, x2, xref2, cells2 = _random_batch(rng, swarm, 5, 500)
    swarm.append_rows(ids2, x2, xref2, cells2)
    swarm.sort()
    swarm.check_invariants()
    assert swarm.num_particles == 80 - leaving.size + 5
    assert set(swarm.ids) == (set(range(80)) - set(left)) | set(ids2)


def test_stale_pending_counts_are_detected(mesh):
    rng = np.random.default_rng(5)
    swarm = Swarm(mesh)
    ids, x, xref, cells = _random_batch(rng, swarm, 100, 0)
    swarm.add(ids, x, xref, cells)
    counts = np.zeros(swarm.num_owned_cells + 2, dtype=np.int64)
    counts[: swarm.num_owned_cells] = swarm.particles_per_cell()
    swarm.set_pending_counts(counts, False)
    swarm.cells[:] = rng.integers(0, swarm.num_owned_cells, 100)  # changed behind the counts' back
    swarm.sort()
    swarm.check_invariants()
    assert sorted(swarm.ids) == list(range(100))
    with pytest.raises(ValueError, match="shape"):
        swarm.set_pending_counts(np.zeros(3, dtype=np.int64), False)


def test_stage_table_travels_and_is_kept_allocated(mesh):
    rng = np.random.default_rng(6)
    swarm = Swarm(mesh)
    ids, x, xref, cells = _random_batch(rng, swarm, 200, 0)
    swarm.add(ids, x, xref, cells)
    addresses = set()
    for step in range(4):
        table = swarm.stage_table(3)
        table[:] = swarm.ids[:, None] * np.array([1.0, 2.0, 3.0])
        addresses.add(table.__array_interface__["data"][0])
        del table  # a view held across the sort would (rightly) keep its buffer from being reused
        swarm.cells[:] = rng.integers(0, swarm.num_owned_cells, swarm.num_particles)
        swarm.sort()
        assert np.array_equal(swarm.stage, swarm.ids[:, None] * np.array([1.0, 2.0, 3.0]))
        swarm.take(np.arange(0, swarm.num_particles, 2) if step == 2 else np.arange(swarm.num_particles))
        assert np.array_equal(swarm.stage, swarm.ids[:, None] * np.array([1.0, 2.0, 3.0]))
        swarm.release_stage_table()
        assert swarm.stage.shape == (swarm.num_particles, 0) and swarm.property_names == []
    swarm.check_invariants()
    assert len(addresses) <= 2  # the current and the spare buffer, not a new one per step


def test_column_assignment_checks_the_length(mesh):
    swarm = Swarm(mesh)
    rng = np.random.default_rng(7)
    swarm.add(*_random_batch(rng, swarm, 10, 0))
    swarm.x = swarm.x + 0.0
    with pytest.raises(ValueError, match="shape"):
        swarm.x = np.zeros((11, 2))


def test_append_nothing_with_a_stage_table(mesh):
    swarm = Swarm(mesh)
    rng = np.random.default_rng(8)
    swarm.add(*_random_batch(rng, swarm, 10, 0))
    swarm.stage_table(2)[:] = 1.0
    swarm.append_rows(np.empty(0), np.empty((0, 2)), np.empty((0, 2)), np.empty(0), np.empty((0, 0)),
                      np.empty((0, 2)))
    assert swarm.num_particles == 10 and np.all(swarm.stage == 1.0)


@pytest.mark.parametrize("stage_width", [0, 2])
def test_packed_rows_round_trip(mesh, stage_width):
    """pack_by_slot groups rows by destination (stable within one) with every column; append_packed
    writes them back as appended rows, keeping the pending counts of the next sort right."""
    from particles.storage.row_kernels import pack_by_slot

    rng = np.random.default_rng(8)
    source = Swarm(mesh)
    source.add_property("c", 3)
    ids, x, xref, cells = _random_batch(rng, source, 50, 0)
    source.add(ids, x, xref, cells, properties=rng.random((50, 3)))
    stage = source.stage_table(stage_width) if stage_width else np.empty((50, 0))
    stage[:] = rng.random(stage.shape)
    rows = np.array([3, 17, 5, 40, 22, 9], dtype=np.int64)
    slots = np.array([1, 0, 1, 2, 0, 1], dtype=np.int64)
    hints = np.arange(6, dtype=np.int64).view(np.float64)
    table, offsets = pack_by_slot(rows, slots, 3, source.ids.view(np.float64), hints, source.x, source.xref,
                                  source.properties, stage)
    assert list(offsets) == [0, 2, 5, 6]
    order = np.array([1, 4, 0, 2, 5, 3])  # slot 0, then 1, then 2, each in row order
    assert np.array_equal(table[:, 0].view(np.int64), source.ids[rows[order]])
    assert np.array_equal(table[:, 1].view(np.int64), order)

    target = Swarm(mesh)
    target.add_property("c", 3)
    if stage_width:
        target.stage_table(stage_width)
    ids2, x2, xref2, cells2 = _random_batch(rng, target, 20, 100)
    target.add(ids2, x2, xref2, cells2)
    counts = np.zeros(target.num_owned_cells + 2, dtype=np.int64)
    counts[: target.num_owned_cells] = target.particles_per_cell()
    target.set_pending_counts(counts, True)
    new_cells = rng.integers(0, target.num_owned_cells, 6).astype(np.int32)
    target.append_packed(table, new_cells)
    assert target.num_particles == 26
    assert np.array_equal(target.ids[20:], source.ids[rows[order]])
    assert np.array_equal(target.x[20:], source.x[rows[order]])
    assert np.array_equal(target.xref[20:], source.xref[rows[order]])
    assert np.array_equal(target.properties[20:], source.properties[rows[order]])
    assert np.array_equal(target.stage[20:], stage[rows[order]])
    assert np.array_equal(target.cells[20:], new_cells)
    pending = target._order.counts.copy()
    target.sort()  # with the pending counts: they must describe the appended rows
    target.check_invariants()
    assert np.array_equal(pending[: target.num_owned_cells], target.particles_per_cell())
    with pytest.raises(ValueError, match="packed table"):
        target.append_packed(table[:, :-1], new_cells)
