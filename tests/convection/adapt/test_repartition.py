"""Distributed repartitioning (issue 12): every rank hands ``create_mesh`` only its own cells, and the
result is the mesh the gathered path (everything through rank 0) made before."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl

from convection.adapt.hierarchy import MeshHierarchy
from fembase.distribute import (
    create_partitioned_mesh, gather_cell_layout, mesh_piece, owner_partitioner, pull, redistribute,
)
from fembase.dolfinx_compat import create_mesh as compat_create_mesh
from fembase.dolfinx_compat import geometry_dofmap


class _Recorder:
    """Wraps ``dolfinx.mesh.create_mesh``: the shapes of the cells and nodes each call got here
    (the nodes are the array among the next two arguments: DOLFINx 0.10 puts the element first)."""

    def __init__(self, monkeypatch):
        self.calls = []
        original = dolfinx.mesh.create_mesh

        def create_mesh(comm, cells, *args, **kwargs):
            x = next(a for a in args[:2] if isinstance(a, np.ndarray))
            self.calls.append((np.asarray(cells).shape[0], x.shape[0]))
            return original(comm, cells, *args, **kwargs)

        monkeypatch.setattr(dolfinx.mesh, "create_mesh", create_mesh)


def _own(mesh):
    """(owned cells, owned geometry nodes) of this rank."""
    return mesh.topology.index_map(mesh.topology.dim).size_local, mesh.geometry.index_map().size_local


def _cells_by_midpoint(mesh):
    """Sorted midpoints of the owned cells and of the ghost cells (rounded, to compare meshes)."""
    tdim = mesh.topology.dim
    imap = mesh.topology.index_map(tdim)
    mid = dolfinx.mesh.compute_midpoints(mesh, tdim, np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    mid = np.round(mid, 12)

    def rows(a):
        return a[np.lexsort(a.T[::-1])]

    return rows(mid[: imap.size_local]), rows(mid[imap.size_local:])


def _all(comm, flag):
    return bool(comm.allreduce(bool(flag), op=MPI.LAND))


def _band(hierarchy, mesh, z0):
    num_owned = mesh.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(mesh, 2, np.arange(num_owned, dtype=np.int32))
    wanted = np.clip(hierarchy.levels(mesh) + (np.abs(mid[:, 1] - z0) < 0.08), 0, 2).astype(np.int32)
    return hierarchy.rebuild(mesh, wanted)


def test_pull_fetches_rows_of_other_ranks(world):
    comm = world
    n = 3 + comm.rank  # uneven blocks
    starts = np.concatenate([[0], np.cumsum(comm.allgather(n))]).astype(np.int64)
    values = np.column_stack([np.arange(starts[comm.rank], starts[comm.rank + 1])] * 2) * np.array([1, -1])
    wanted = np.random.default_rng(comm.rank).integers(0, starts[-1], size=17)
    got = pull(comm, wanted, values, starts)
    assert _all(comm, np.array_equal(got, np.column_stack([wanted, -wanted])))


@pytest.mark.mpi
def test_repartition_hands_create_mesh_only_own_cells_and_makes_the_same_mesh(monkeypatch):
    comm = MPI.COMM_WORLD
    base = dolfinx.mesh.create_rectangle(comm, [np.zeros(2), np.array([0.9142, 1.0])], [12, 12],
                                         dolfinx.mesh.CellType.triangle, ghost_mode=dolfinx.mesh.GhostMode.shared_facet)
    hierarchy = MeshHierarchy(base)
    mesh = _band(hierarchy, _band(hierarchy, base, 0.3), 0.3)
    num_owned = mesh.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(mesh, 2, np.arange(num_owned, dtype=np.int32))
    particles = 40.0 * (mid[:, 1] > 0.5)
    old_base, old_canonical = hierarchy.base, hierarchy.base_canonical
    own_base, own_mesh = _own(old_base), _own(mesh)
    base_of = hierarchy.base_cells(mesh)

    recorder = _Recorder(monkeypatch)
    new = hierarchy.repartition(mesh, particles, particle_weight=0.01, method="rcb")
    monkeypatch.undo()
    # Every rank passed exactly its own owned cells and owned nodes: base first, then the mesh.
    assert _all(comm, recorder.calls == [own_base, own_mesh]), recorder.calls
    assert comm.allreduce(recorder.calls[1][0]) == mesh.topology.index_map(2).size_global

    # The owners the partitioner chose, read off the new base: every base cell on one rank ...
    n_base = hierarchy.base.topology.index_map(2).size_local
    owners = np.full(hierarchy.num_base_cells, -1, dtype=np.int32)
    owners[hierarchy.base_canonical[:n_base]] = comm.rank
    chosen = np.empty_like(owners)
    comm.Allreduce(owners, chosen, op=MPI.MAX)
    assert np.all(chosen >= 0) and comm.allreduce(n_base) == hierarchy.num_base_cells
    assert len(set(chosen.tolist())) == comm.size  # the partition uses every rank
    # ... and every cell of the new mesh on the rank of its base cell.
    assert _all(comm, np.all(chosen[hierarchy.base_cells(new)] == comm.rank))

    # The gathered path of before, with the same owners, makes the same meshes: the same owned and
    # ghost cells on every rank (by canonical index for the base, by midpoint for the mesh).
    domain = ufl.Mesh(base.ufl_domain().ufl_coordinate_element())
    n_old = old_base.topology.index_map(2).size_local
    gathered = create_partitioned_mesh(comm, gather_cell_layout(old_base, old_canonical[:n_old]), chosen, domain)
    ref_imap = gathered.mesh.topology.index_map(2)
    ref = (np.sort(gathered.canonical[: ref_imap.size_local]), np.sort(gathered.canonical[ref_imap.size_local:]))
    got = (np.sort(hierarchy.base_canonical[:n_base]), np.sort(hierarchy.base_canonical[n_base:]))
    assert _all(comm, all(np.array_equal(a, b) for a, b in zip(ref, got)))
    offset = comm.exscan(num_owned) or 0
    layout = gather_cell_layout(mesh, np.arange(offset, offset + num_owned, dtype=np.int64))
    all_owners = comm.gather(chosen[base_of], root=0)
    reference = create_partitioned_mesh(comm, layout, np.concatenate(all_owners) if comm.rank == 0 else None,
                                        ufl.Mesh(domain.ufl_coordinate_element())).mesh
    same = all(np.array_equal(a, b) for a, b in zip(_cells_by_midpoint(reference), _cells_by_midpoint(new)))
    assert _all(comm, same)
    assert comm.allreduce(new.topology.index_map(2).num_ghosts) > 0

    # The recipe (each rank's own pieces) makes both meshes again, bit for bit.
    before = (hierarchy.base.geometry.x.copy(), geometry_dofmap(hierarchy.base).reshape(-1).copy(),
              hierarchy.base_canonical.copy(), new.geometry.x.copy(), geometry_dofmap(new).reshape(-1).copy())
    recipe = hierarchy.recipe
    assert _all(comm, recipe.base.cells.shape[0] == own_base[0] and recipe.mesh.cells.shape[0] == own_mesh[0])
    again = hierarchy.replay(recipe)
    after = (hierarchy.base.geometry.x, geometry_dofmap(hierarchy.base).reshape(-1), hierarchy.base_canonical,
             again.geometry.x, geometry_dofmap(again).reshape(-1))
    assert _all(comm, all(np.array_equal(a, b) for a, b in zip(before, after)))


@pytest.mark.mpi
def test_redistribute_hands_create_mesh_only_own_cells(monkeypatch):
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 14, 14)
    num_owned = mesh.topology.index_map(2).size_local
    mid = dolfinx.mesh.compute_midpoints(mesh, 2, np.arange(num_owned, dtype=np.int32))
    owners = np.minimum((mid[:, 0] + mid[:, 1]) / 2.0 * comm.size, comm.size - 1).astype(np.int32)  # diagonal bands
    recorder = _Recorder(monkeypatch)
    new = redistribute(mesh, owners)
    monkeypatch.undo()
    assert _all(comm, recorder.calls == [_own(mesh)]), recorder.calls
    n_new = new.topology.index_map(2).size_local
    new_mid = dolfinx.mesh.compute_midpoints(new, 2, np.arange(n_new, dtype=np.int32))
    band = np.minimum((new_mid[:, 0] + new_mid[:, 1]) / 2.0 * comm.size, comm.size - 1).astype(np.int32)
    assert _all(comm, np.all(band == comm.rank))
    # the same cells as the gathered path gives, owned and ghost
    offset = comm.exscan(num_owned) or 0
    layout = gather_cell_layout(mesh, np.arange(offset, offset + num_owned, dtype=np.int64))
    gathered = comm.gather(owners, root=0)
    reference = create_partitioned_mesh(comm, layout, np.concatenate(gathered) if comm.rank == 0 else None,
                                        ufl.Mesh(mesh.ufl_domain().ufl_coordinate_element())).mesh
    same = all(np.array_equal(a, b) for a, b in zip(_cells_by_midpoint(reference), _cells_by_midpoint(new)))
    assert _all(comm, same)


@pytest.mark.mpi
def test_owner_partitioner_ghosts_neighbours_passed_by_other_ranks():
    """Cells passed by every rank; a cell's facet neighbours passed elsewhere still make it a ghost
    on their owners (the exchange in the partitioner)."""
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 9, 7)
    num_owned = mesh.topology.index_map(2).size_local
    owners = np.full(num_owned, (comm.rank + 1) % comm.size, dtype=np.int32)  # every cell moves on
    piece = mesh_piece(mesh, owners)
    new = compat_create_mesh(comm, piece.cells, piece.x, ufl.Mesh(mesh.ufl_domain().ufl_coordinate_element()),
                             owner_partitioner(piece.owners))
    imap = new.topology.index_map(2)
    counts = comm.allgather(num_owned)
    assert imap.size_local == counts[(comm.rank - 1) % comm.size]
    # every interior facet is seen from both sides on every rank that owns one of its cells
    new.topology.create_entities(1)
    new.topology.create_connectivity(1, 2)
    f2c = new.topology.connectivity(1, 2)
    n_facets = new.topology.index_map(1).size_local + new.topology.index_map(1).num_ghosts
    facet_mid = dolfinx.mesh.compute_midpoints(new, 1, np.arange(n_facets, dtype=np.int32))
    on_boundary = np.any(np.isclose(facet_mid[:, :2], 0.0) | np.isclose(facet_mid[:, :2], 1.0), axis=1)
    touching_owned = [f for f in range(n_facets) if len(f2c.links(f)) == 1 and not on_boundary[f]
                      and f2c.links(f)[0] < imap.size_local]
    assert _all(comm, len(touching_owned) == 0)
    area = dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * ufl.dx(domain=new)))
    assert comm.allreduce(area) == pytest.approx(1.0)
