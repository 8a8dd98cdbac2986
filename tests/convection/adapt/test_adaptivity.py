"""Rebuild-from-base adaptivity and field transfer between meshes (serial and collective)."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from convection.adapt.adaptivity import AdaptivitySettings, kelly_indicator, wanted_levels

from convection.adapt.hierarchy import MeshHierarchy
from convection.geometry.box import BoxSpec, create_box_mesh
from convection.geometry.mesh import cell_volumes
from convection.adapt.transfer import PointEvaluator, transfer_function
from fembase.dolfinx_compat import function_space, refine_keeping_partition
from fembase.geometry import CellGeometry


def _front(x):
    return np.tanh((x[1] - 0.5 - 0.1 * np.cos(np.pi * x[0])) / 0.03)


def _quadratic(x):
    return x[0] ** 2 - 3.0 * x[0] * x[1] + 0.5 * x[1]


def _adapt_cycle(comm, rounds, params):
    base = create_box_mesh(comm, BoxSpec((8, 8), (0.0, 0.0), (2.0, 1.0)))
    hierarchy = MeshHierarchy(base)
    mesh = base
    history = []
    for _ in range(rounds):
        V = function_space(mesh, "Lagrange", 2)
        T = dolfinx.fem.Function(V)
        T.interpolate(_front)
        wanted = wanted_levels(kelly_indicator([T]), hierarchy.levels(mesh), params, comm)
        mesh = hierarchy.rebuild(mesh, wanted)
        levels = hierarchy.levels(mesh)
        history.append((mesh.topology.index_map(2).size_global,
                        comm.allreduce(int(levels.max(initial=0)), op=MPI.MAX),
                        comm.allreduce(int(levels.min(initial=99)), op=MPI.MIN)))
    return base, mesh, history


def _check_adaptation(comm):
    params = AdaptivitySettings(min_level=0, max_level=3, refine_fraction=0.2, coarsen_fraction=0.3)
    base, mesh, history = _adapt_cycle(comm, 5, params)
    cells = [h[0] for h in history]
    assert cells[0] > base.topology.index_map(2).size_global  # refined near the front
    assert max(h[1] for h in history) == 3 and min(h[2] for h in history) >= 0
    # fewer cells than uniform refinement to the finest level
    assert cells[-1] < base.topology.index_map(2).size_global * 4 ** 3 / 4
    # the domain is still covered exactly
    num_owned = mesh.topology.index_map(2).size_local
    area = comm.allreduce(float(cell_volumes(mesh)[:num_owned].sum()), op=MPI.SUM)
    assert area == pytest.approx(2.0, rel=1e-12)
    # the fine cells sit at the front, the coarse ones away from it
    tdim = 2
    midpoints = dolfinx.mesh.compute_midpoints(mesh, tdim, np.arange(num_owned, dtype=np.int32))
    distance = np.abs(_front(midpoints.T))
    levels = MeshHierarchy(base).levels(mesh)
    near = comm.allreduce(int(np.count_nonzero(levels[distance < 0.5] == 3)), op=MPI.SUM)
    far_fine = comm.allreduce(int(np.count_nonzero(levels[distance > 0.99999] == 3)), op=MPI.SUM)
    assert near > 0 and far_fine == 0

    # coarsening: a flat field takes the mesh back to the minimum level
    hierarchy = MeshHierarchy(base)
    flat = AdaptivitySettings(min_level=1, max_level=3, refine_fraction=0.2, coarsen_fraction=1.0)
    for _ in range(4):
        wanted = wanted_levels(np.zeros(mesh.topology.index_map(2).size_local), hierarchy.levels(mesh), flat, comm)
        mesh = hierarchy.rebuild(mesh, wanted)
    assert mesh.topology.index_map(2).size_global == base.topology.index_map(2).size_global * 4


def _check_transfer(comm):
    base = create_box_mesh(comm, BoxSpec((6, 6), (0.0, 0.0), (1.0, 1.0)))
    base.topology.create_entities(1)
    edges = dolfinx.mesh.locate_entities(base, 1, lambda x: x[0] < 0.45)
    fine = refine_keeping_partition(base, edges)
    other = create_box_mesh(comm, BoxSpec((7, 5), (0.0, 0.0), (1.0, 1.0)))  # unrelated partition
    for target_mesh in (fine, other):
        src = dolfinx.fem.Function(function_space(base, "Lagrange", 2))
        src.interpolate(_quadratic)
        dst = dolfinx.fem.Function(function_space(target_mesh, "Lagrange", 2))
        transfer_function(src, dst)
        exact = dolfinx.fem.Function(dst.function_space)
        exact.interpolate(_quadratic)
        err = comm.allreduce(float(np.abs(dst.x.array - exact.x.array).max(initial=0.0)), op=MPI.MAX)
        assert err < 1e-12
        vsrc = dolfinx.fem.Function(function_space(base, "Lagrange", 2, shape=(base.geometry.dim,)))
        vsrc.interpolate(lambda x: np.vstack([_quadratic(x), -x[1] ** 2]))
        vdst = dolfinx.fem.Function(function_space(target_mesh, "Lagrange", 2, shape=(target_mesh.geometry.dim,)))
        transfer_function(vsrc, vdst)
        vexact = dolfinx.fem.Function(vdst.function_space)
        vexact.interpolate(lambda x: np.vstack([_quadratic(x), -x[1] ** 2]))
        verr = comm.allreduce(float(np.abs(vdst.x.array - vexact.x.array).max(initial=0.0)), op=MPI.MAX)
        assert verr < 1e-12
        # A target whose dofs are not point values (Nedelec): the interpolation of the source's
        # values, which are exact for this quadratic field.
        cdst = dolfinx.fem.Function(function_space(target_mesh, "N1curl", 2))
        transfer_function(vsrc, cdst)
        cexact = dolfinx.fem.Function(cdst.function_space)
        cexact.interpolate(lambda x: np.vstack([_quadratic(x), -x[1] ** 2]))
        cerr = comm.allreduce(float(np.abs(cdst.x.array - cexact.x.array).max(initial=0.0)), op=MPI.MAX)
        assert cerr < 1e-11


def _check_nested_transfer(comm, monkeypatch):
    """Between two meshes rebuilt from one base, each node is found among the old cells of its base
    cell (no bounding-box search) and the transfer equals the one by bounding-box search."""
    base = create_box_mesh(comm, BoxSpec((6, 6), (0.0, 0.0), (1.0, 1.0)))
    hierarchy = MeshHierarchy(base)
    levels = np.zeros(base.topology.index_map(2).size_local, dtype=np.int32)
    midpoints = dolfinx.mesh.compute_midpoints(base, 2, np.arange(levels.size, dtype=np.int32))
    old = hierarchy.rebuild(base, np.where(midpoints[:, 0] < 0.5, 2, 0).astype(np.int32))
    midpoints = dolfinx.mesh.compute_midpoints(old, 2, np.arange(old.topology.index_map(2).size_local, dtype=np.int32))
    new = hierarchy.rebuild(old, np.where(midpoints[:, 1] < 0.4, 2, 0).astype(np.int32))
    evaluator = PointEvaluator(old)
    for element in (("Lagrange", 2), ("DG", 0)):
        src = dolfinx.fem.Function(function_space(old, element))
        src.interpolate(_front)
        searched = dolfinx.fem.Function(function_space(new, element))
        transfer_function(src, searched, evaluator=PointEvaluator(old))
        nested = dolfinx.fem.Function(searched.function_space)
        with monkeypatch.context() as patch:
            patch.setattr(CellGeometry, "_tree_candidates", lambda *args: pytest.fail("tree search"))
            transfer_function(src, nested, evaluator=evaluator,
                              candidates=lambda cells: hierarchy.candidates(old, new, cells))
        err = comm.allreduce(float(np.abs(nested.x.array - searched.x.array).max(initial=0.0)), op=MPI.MAX)
        assert err < 1e-14
    assert comm.allreduce(new.topology.index_map(2).size_local, op=MPI.SUM) > 4 * 72


def test_adaptation_refines_front_and_coarsens_back():
    _check_adaptation(MPI.COMM_WORLD)


def test_transfer_reproduces_quadratic():
    _check_transfer(MPI.COMM_WORLD)


@pytest.mark.mpi
def test_adaptation_parallel():
    _check_adaptation(MPI.COMM_WORLD)


@pytest.mark.mpi
def test_transfer_parallel():
    _check_transfer(MPI.COMM_WORLD)


def test_nested_transfer(world, monkeypatch):
    _check_nested_transfer(world, monkeypatch)
