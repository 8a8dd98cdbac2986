"""Nested meshes for geometric multigrid (``Domain.create_mesh_levels``): the boxes of n, 2n, 4n cells
per side nest, each fine cell on the rank of its coarse parent, on every rank count; the finest is
the config's mesh (the same cells as ``create_mesh``); a saved partition of the finest is imposed
again with the coarser meshes following it; boxes that do not nest are refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from convection.geometry.box import BoxDomain, BoxSpec
from fembase.distribute import cell_owners_by_input, mesh_fingerprint
from fembase.dolfinx_compat import function_space
from fembase.multigrid import apply, prolongation

_BOXES = {
    "2d_right": BoxSpec((8, 4), (0.0, 0.0), (2.0, 1.0)),
    "2d_left": BoxSpec((8, 8), (0.0, 0.0), (1.0, 1.0), diagonal="left"),
    "2d_crossed": BoxSpec((8, 8), (0.0, 0.0), (1.0, 1.0), diagonal="crossed"),
    "2d_quad": BoxSpec((16, 8), (0.0, 0.0), (2.0, 1.0), cell_type="box"),
    "3d_tet": BoxSpec((4, 4, 8), (0.0, 0.0, 0.0), (1.0, 1.0, 2.0)),
    "3d_hex": BoxSpec((8, 8, 8), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), cell_type="box"),
    "2d_quad_graded": BoxSpec((16, 8), (0.0, 0.0), (2.0, 1.0), cell_type="box", grading=(0.3, 0.6)),
}


def _midpoints(mesh: dolfinx.mesh.Mesh) -> np.ndarray:
    """All owned cell midpoints of every rank, sorted (collective)."""
    tdim = mesh.topology.dim
    n = mesh.topology.index_map(tdim).size_local
    mine = dolfinx.mesh.compute_midpoints(mesh, tdim, np.arange(n, dtype=np.int32))
    every = np.concatenate(mesh.comm.allgather(mine))
    return every[np.lexsort(np.round(every, 12).T[::-1])]


def _quadratic(components: int):
    """A vector quadratic (x has three rows in 2D too, the last zero)."""
    def q(x):
        v = 1.0 + x[0] - 2.0 * x[1] + x[0] * x[1] + 0.5 * x[0] ** 2 - x[2] ** 2
        return np.stack([v * (k + 1.0) for k in range(components)])
    return q


@pytest.mark.parametrize("name", sorted(_BOXES))
def test_box_levels_nest_on_every_rank_count(world, name):
    """Collective: three levels; the finest has the cells of the config's mesh; P2 vector functions
    of each level prolongate exactly to the next (the fine nodes lie in the same rank's coarse cells)."""
    spec = _BOXES[name]
    domain = BoxDomain.from_spec(spec)
    assert domain.mesh_levels(3) == 3
    meshes = domain.create_mesh_levels(world, 3)
    assert len(meshes) == 3
    np.testing.assert_allclose(_midpoints(meshes[-1]), _midpoints(domain.create_mesh(world)), atol=1e-12)
    gdim = spec.gdim
    spaces = [function_space(m, "Lagrange", 2, shape=(gdim,)) for m in meshes]
    for coarse, fine in zip(spaces, spaces[1:]):
        P = prolongation(coarse, fine)
        uc, uf = dolfinx.fem.Function(coarse), dolfinx.fem.Function(fine)
        uc.interpolate(_quadratic(gdim))
        uf.interpolate(_quadratic(gdim))
        y = apply(P, uc.x.array)
        error = world.allreduce(float(np.max(np.abs(y - uf.x.array[:y.size]), initial=0.0)), op=MPI.MAX)
        assert error < 1e-11, (name, error)
        P.destroy()


def test_saved_partition_of_the_finest_is_imposed_again(world):
    """Collective: the finest mesh's owners (as a checkpoint saves them) make the same meshes again,
    fingerprint for fingerprint, the coarse levels included."""
    domain = BoxDomain.from_spec(_BOXES["3d_tet"])
    first = domain.create_mesh_levels(world, 3)
    again = domain.create_mesh_levels(world, 3, owners=cell_owners_by_input(first[-1]))
    for a, b in zip(first, again):
        assert world.allreduce(mesh_fingerprint(a) == mesh_fingerprint(b), op=MPI.LAND)


def test_levels_that_do_not_nest_are_refused():
    domain = BoxDomain.from_spec(BoxSpec((12, 20), (0.0, 0.0), (1.0, 1.0)))
    assert domain.mesh_levels() == 3  # 12 -> 6 -> 3 and 20 -> 10 -> 5
    with pytest.raises(ValueError, match="divisible by 2\\^3"):
        domain.mesh_levels(4)
    alternating = BoxDomain.from_spec(BoxSpec((8, 8), (0.0, 0.0), (1.0, 1.0), diagonal="left/right"))
    assert alternating.mesh_levels() == 1
    with pytest.raises(ValueError, match="alternates"):
        alternating.mesh_levels(2)
    assert BoxDomain.from_spec(BoxSpec((5, 5), (0.0, 0.0), (1.0, 1.0))).mesh_levels() == 1
    graded = BoxDomain.from_spec(BoxSpec((8, 8), (0.0, 0.0), (1.0, 1.0), grading=(0.0, 0.5)))
    assert graded.mesh_levels() == 1
    with pytest.raises(ValueError, match="graded simplex box"):
        graded.mesh_levels(2)


def test_a_coarsest_mesh_without_cells_for_every_rank_is_refused(world):
    """Collective: one hexahedron cannot be shared by several ranks; refused on every rank."""
    domain = BoxDomain.from_spec(BoxSpec((4, 4, 4), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), cell_type="box"))
    if world.size == 1:
        assert len(domain.create_mesh_levels(world, 3)) == 3
        return
    with pytest.raises(RuntimeError, match="leaves 1 of 2 ranks without a cell|leaves 2 of 3 ranks without a cell"):
        domain.create_mesh_levels(world, 3)


def test_a_saved_partition_that_does_not_nest_is_made_to(world):
    """Collective: a partition of the fine cells alone (here round robin, the worst case; e.g. a
    checkpoint written by a run without multigrid) splits coarse cells between ranks; the levels
    made from it keep every fine cell on its coarse parent's rank (the fine cells follow their coarse
    parents, or, on 3 ranks here, where that leaves a rank without a coarsest cell, a fresh
    partition) and every rank has cells."""
    domain = BoxDomain.from_spec(_BOXES["3d_tet"])
    cells = 6 * 4 * 4 * 8
    owners = (np.arange(cells) % world.size).astype(np.int32) if world.rank == 0 else None
    meshes = domain.create_mesh_levels(world, 3, owners=owners)
    spaces = [function_space(m, "Lagrange", 2, shape=(3,)) for m in meshes]
    for coarse, fine in zip(spaces, spaces[1:]):
        prolongation(coarse, fine).destroy()
    for mesh in meshes:
        assert mesh.topology.index_map(3).size_local > 0
