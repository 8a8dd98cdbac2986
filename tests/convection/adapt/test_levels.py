"""The multigrid levels of fixed and adaptive meshes (convection/adapt/levels.py): which meshes, that
they nest (the prolongations build on every rank), which rounds are skipped, and the mesh a
repartition made refused."""

from __future__ import annotations

import numpy as np
import pytest
import dolfinx

from convection.adapt.hierarchy import MeshHierarchy
from convection.adapt.levels import MAX_RATIO, MeshLevels, coarsening_levels
from convection.geometry.box import BoxDomain, BoxSpec
from convection.solvers.stokes.multigrid import VelocityMultigrid
from fembase.dolfinx_compat import function_space


def _cells(mesh) -> int:
    return mesh.topology.index_map(mesh.topology.dim).size_global


def _setup(comm):
    """A 2D box of 8 x 8 squares over 4 x 4 and 2 x 2, and the hierarchy refined from it."""
    meshes = BoxDomain.from_spec(BoxSpec((8, 8), (0.0, 0.0), (1.0, 1.0))).create_mesh_levels(comm, 3)
    return meshes, MeshHierarchy(meshes[-1])


def _wanted(mesh, where) -> np.ndarray:
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    midpoints = dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim, np.arange(num_owned, dtype=np.int32))
    return np.where(where(midpoints), 2, 0).astype(np.int32)


def test_fixed_mesh_levels_are_the_boxes(world):
    """Collective: the base's levels are the boxes below it (each a quarter of the next)."""
    meshes, _ = _setup(world)
    levels = MeshLevels(meshes[:-1], meshes[-1])
    assert levels(meshes[-1]) == tuple(meshes[:-1])
    with pytest.raises(ValueError, match="not refined from the base"):
        levels(BoxDomain.from_spec(BoxSpec((8, 8), (0.0, 0.0), (1.0, 1.0))).create_mesh(world))


@pytest.mark.parametrize("region, skipped", [(0.5, 0), (0.1, 1)])
def test_adaptive_levels_nest_and_coarsen(world, region, skipped):
    """Collective: the base refined twice where x < region. Refining half the box (128, 344, 1176
    cells serially), every mesh coarsens enough to be a level; refining a tenth (128, 200, 456),
    the base has more than MAX_RATIO of the first round's cells and is skipped. The prolongations between the levels build (every
    fine node in a coarse cell of its rank: they nest on this partition)."""
    meshes, hierarchy = _setup(world)
    mesh = hierarchy.rebuild(meshes[-1], _wanted(meshes[-1], lambda x: x[:, 0] < region))
    rounds = hierarchy.chain.meshes
    assert len(rounds) == 3 and rounds[0] is meshes[-1] and rounds[-1] is mesh
    below = MeshLevels(meshes[:-1], meshes[-1], hierarchy)(mesh)
    assert below[:2] == tuple(meshes[:2]) and below[-1] is rounds[-2]
    assert len(below) == 2 + len(rounds) - 1 - skipped
    counts = [_cells(m) for m in (*below, mesh)]
    assert all(coarse <= MAX_RATIO * fine for coarse, fine in zip(counts, counts[1:])), counts
    V = function_space(mesh, "Lagrange", 2, shape=(2,))
    multigrid = VelocityMultigrid(V, below)
    assert multigrid.levels == len(below) + 1
    multigrid.destroy()


def test_a_mesh_the_last_rebuild_did_not_make_has_the_base_as_next_level(world):
    """Collective: after a second rebuild the first adapted mesh is no longer one the chain made
    (as a checkpoint's mesh made again on another rank count is not): its levels are the boxes and
    the base, which it is nested in (the prolongation builds); the base's own levels stay."""
    meshes, hierarchy = _setup(world)
    levels = MeshLevels(meshes[:-1], meshes[-1], hierarchy)
    first = hierarchy.rebuild(meshes[-1], _wanted(meshes[-1], lambda x: x[:, 0] < 0.5))
    second = hierarchy.rebuild(first, _wanted(first, lambda x: x[:, 1] < 0.5))
    assert levels(second)[-1] is not first and len(levels(second)) > 3
    assert levels(first) == tuple(meshes)
    VelocityMultigrid(function_space(first, "Lagrange", 2, shape=(2,)), levels(first)).destroy()
    assert levels(meshes[-1]) == tuple(meshes[:-1])


def test_coarsening_levels_keeps_both_ends():
    class Fake:
        def __init__(self, n):
            self.n = n

    import convection.adapt.levels as module

    sizes = [10, 30, 40, 100]
    fakes = [Fake(n) for n in sizes]
    original = module._cells
    module._cells = lambda m: m.n
    try:
        kept = coarsening_levels(fakes)
    finally:
        module._cells = original
    # 100 -> 40 (<= 50) -> 30 is > 20: skipped -> 10 (<= 20)
    assert [k.n for k in kept] == [10, 40, 100]
