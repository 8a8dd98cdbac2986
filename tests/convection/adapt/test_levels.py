"""The multigrid levels of fixed and adaptive meshes (convection/adapt/levels.py): which meshes, that
they nest (the prolongations build on every rank), which rounds are skipped, the levels a
repartition moves with the base, and a mesh not refined from the base refused."""

from __future__ import annotations

import numpy as np
import pytest
import dolfinx
import dolfinx.fem
from mpi4py import MPI

from convection.adapt.hierarchy import MeshHierarchy
from convection.adapt.levels import MAX_RATIO, MeshLevels, coarsening_levels
from convection.geometry.box import BoxDomain, BoxSpec
from convection.solvers.stokes.multigrid import VelocityMultigrid
from fembase.dolfinx_compat import coordinate_map, function_space


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
    the base has more than MAX_RATIO of the first round's cells and is skipped. The prolongations between the levels
    build (every fine node in a coarse cell of its rank: they nest on this partition)."""
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


def _repartitioned(comm, hierarchy, mesh):
    """``mesh`` repartitioned with particles crowded into x < 0.3 (a partition other than the
    refinement's on more than one rank)."""
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    midpoints = dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim, np.arange(num_owned, dtype=np.int32))
    return hierarchy.repartition(mesh, np.where(midpoints[:, 0] < 0.3, 400.0, 1.0), particle_weight=1.0)


def test_a_repartition_moves_the_refinement_rounds_with_the_base(world):
    """Collective: with keep_levels a repartition of a mesh refined in two rounds moves the round's
    mesh too, every cell with its base cell: the levels are the new base and the round (the boxes
    below the old base are dropped), with the cells they had, and the prolongations build on the
    new partition. The recipe makes the same meshes again (same rank count)."""
    meshes, hierarchy = _setup(world)
    hierarchy.keep_levels = True
    levels = MeshLevels(meshes[:-1], meshes[-1], hierarchy)
    mesh = hierarchy.rebuild(meshes[-1], _wanted(meshes[-1], lambda x: x[:, 0] < 0.5))
    counts = [_cells(m) for m in hierarchy.chain.meshes]
    moved = _repartitioned(world, hierarchy, mesh)
    below = levels(moved)
    assert len(below) == 2 and below[0] is hierarchy.base and below[0] is not meshes[-1]
    assert [_cells(m) for m in (*below, moved)] == counts
    if world.size > 1:  # the partition changed
        owned = world.allgather(moved.topology.index_map(2).size_local)
        assert owned != world.allgather(mesh.topology.index_map(2).size_local)
    VelocityMultigrid(function_space(moved, "Lagrange", 2, shape=(2,)), below).destroy()
    again = MeshHierarchy(BoxDomain.from_spec(BoxSpec((8, 8), (0.0, 0.0), (1.0, 1.0))).create_mesh(world))
    made = again.replay(hierarchy.recipe)
    assert [_cells(m) for m in again.chain.meshes] == counts and again.chain.meshes[-1] is made
    np.testing.assert_array_equal(made.geometry.x, moved.geometry.x)


def test_a_repartitioned_unrefined_mesh_has_no_levels(world):
    """Collective: a repartition of the unrefined base leaves a mesh with the base's cells: no
    coarser mesh is nested in it rank by rank, so it has no levels (the Stokes solver then takes
    the AMG until an adaptation refines it)."""
    meshes, hierarchy = _setup(world)
    hierarchy.keep_levels = True
    levels = MeshLevels(meshes[:-1], meshes[-1], hierarchy)
    moved = _repartitioned(world, hierarchy, meshes[-1])
    assert levels(moved) == ()


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
    # a coarsest mesh with as many cells as the finest is no level
    module._cells = lambda m: m.n
    try:
        assert [k.n for k in coarsening_levels([Fake(100), Fake(100)])] == [100]
    finally:
        module._cells = original


def test_curved_levels_nest_through_their_straight_cells(world):
    """Collective: the annulus (gmsh's straight base, the shell manifold curving every mesh)
    refined to level 2 near the outer circle and a ray (three rounds): the levels are the curved
    base and the curved first round (the third round refined little: skipped); every node of a finer level is found
    through the straight cells (the prolongations build) and the prolongation of a smooth field's interpolant agrees
    with the fine interpolant to the curved cells' geometric error (quadratic maps of the circles), while a
    prolongation found in the curved cells themselves misses nodes outside the coarse boundary."""
    pytest.importorskip("gmsh")
    from convection.geometry.shell import ShellSpec, create_shell_mesh
    from fembase.manifold import ShellManifold
    from fembase.multigrid import apply, prolongation

    hierarchy = MeshHierarchy(create_shell_mesh(world, ShellSpec(2, 1.22, 2.22, resolution=0.3, geometry_degree=1)),
                              manifold=ShellManifold(1.22, 2.22, 2))
    base = hierarchy.base
    near = lambda x: (np.abs(np.arctan2(x[:, 1], x[:, 0])) < 0.6) | (np.linalg.norm(x[:, :2], axis=1) > 1.9)  # noqa: E731
    mesh = hierarchy.curve(base)
    for _ in range(2):
        mesh = hierarchy.rebuild(mesh, _wanted(mesh, near))
    levels = MeshLevels((), base, hierarchy)
    below = levels(mesh)
    assert len(below) == 2 and all(coordinate_map(m).degree == 2 for m in below)
    # the rounds' straight meshes (the last round refined little: skipped), curved
    counts = [_cells(m) for m in hierarchy.chain.meshes]
    assert [_cells(m) for m in (*below, mesh)] == [counts[0], counts[1], counts[-1]] and len(counts) == 4
    V = function_space(mesh, "Lagrange", 2, shape=(2,))
    multigrid = VelocityMultigrid(V, below, locate=levels.locate)
    assert multigrid.levels == 3
    coarse = function_space(below[-1], "Lagrange", 2, shape=(2,))
    field = lambda x: np.stack([np.sin(x[0]) * x[1], np.cos(x[1]) + x[0] ** 2])  # noqa: E731
    u_coarse, u_fine = dolfinx.fem.Function(coarse), dolfinx.fem.Function(V)
    u_coarse.interpolate(field)
    u_fine.interpolate(field)
    n = V.dofmap.index_map.size_local * 2
    error = np.abs(apply(multigrid.interpolations[-1], u_coarse.x.array) - u_fine.x.array[:n]).max(initial=0.0)
    assert world.allreduce(error, op=MPI.MAX) < 2e-3
    multigrid.destroy()
    with pytest.raises(ValueError, match="not nested"):
        prolongation(coarse, V)
