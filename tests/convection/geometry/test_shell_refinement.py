"""Issue 22: refinement and coarsening of the curved annulus (fembase/manifold.py and
MeshHierarchy(manifold=)): boundary geometry nodes on the circles to round-off, no inverted cell
after three refinement rounds and after coarsening back, the area converging to the exact one, and
the same mesh on any number of ranks (to the last bit)."""

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx.fem

pytest.importorskip("gmsh")

from convection.adapt.hierarchy import MeshHierarchy  # noqa: E402
from convection.geometry.shell import ShellSpec, create_shell_mesh  # noqa: E402
from fembase.dolfinx_compat import coordinate_map, evaluate_expression, geometry_dofmap  # noqa: E402
from fembase.manifold import ShellManifold, boundary_radius_error  # noqa: E402

RI, RO = 1.22, 2.22
SPEC = ShellSpec(2, RI, RO, resolution=0.3, geometry_degree=1)
POINTS = np.array([[1 / 3, 1 / 3], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 0.5], [0.5, 0.0], [0.0, 0.5]])


def _hierarchy(comm):
    return MeshHierarchy(create_shell_mesh(comm, SPEC), manifold=ShellManifold(RI, RO, 2))


def _area(mesh):
    form = dolfinx.fem.form(dolfinx.fem.Constant(mesh, 1.0) * ufl.dx(domain=mesh))
    return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)


def _min_jacobian_ratio(mesh):
    """Smallest det J of the curved cells at the vertices, edge midpoints and centroid, over det J of
    the straight cell of the same vertices (> 0: no cell inverted, whatever the orientation)."""
    n = mesh.topology.index_map(2).size_local
    detj = evaluate_expression(dolfinx.fem.Expression(ufl.JacobianDeterminant(mesh), POINTS), mesh,
                               np.arange(n, dtype=np.int32)).reshape(n, -1)
    x = mesh.geometry.x[geometry_dofmap(mesh)[:n, :3]][:, :, :2]
    straight = np.linalg.det(x[:, 1:] - x[:, :1])
    local = float((detj / straight[:, None]).min()) if n else np.inf
    return mesh.comm.allreduce(local, op=MPI.MIN)


def _adaptive_wanted(hierarchy, mesh, round_):
    """Refine the cells near the ray theta = 0 and near both circles (rounds 1..3), by the
    straight midpoints (rank independent)."""
    n = mesh.topology.index_map(2).size_local
    x = mesh.geometry.x[geometry_dofmap(mesh)[:n, :3]][:, :, :2].mean(axis=1)
    r, theta = np.linalg.norm(x, axis=1), np.arctan2(x[:, 1], x[:, 0])
    near = (np.abs(theta) < 0.6) | (r > RO - 0.25) | (r < RI + 0.2)
    return np.where(near, round_, 0).astype(np.int32)


def test_manifold_maps_base_and_boundary():
    comm = MPI.COMM_SELF
    base = create_shell_mesh(comm, SPEC)
    manifold = ShellManifold(RI, RO, 2)
    manifold.fit(base)
    x = base.geometry.x[:, :2]
    r = np.linalg.norm(x, axis=1)
    boundary = (np.abs(r - RI) < 1e-12) | (np.abs(r - RO) < 1e-12)
    assert np.abs(manifold.curved_points(x[boundary]) - x[boundary]).max() < 1e-13  # boundary vertices stay
    dofs = geometry_dofmap(base)
    inside = np.concatenate([x[dofs].mean(axis=1), 0.5 * (x[dofs[:, 0]] + x[dofs[:, 1]])])
    y = manifold.curved_points(inside)
    assert np.abs(y - inside).max() > 1e-4  # cells at the boundary bend
    assert np.abs(manifold.straight_points(y) - inside).max() < 1e-13  # the inverse, inside the base
    with pytest.raises(ValueError, match="2D .* or 3D"):
        ShellManifold(RI, RO, 4)


def test_refined_annulus_rounds(world):
    hierarchy = _hierarchy(world)
    errors = []
    for level in range(4):
        mesh = hierarchy.uniform(level)
        assert coordinate_map(mesh).degree == 2
        assert boundary_radius_error(mesh, RI, RO) < 1e-12
        assert _min_jacobian_ratio(mesh) > 0.8  # measured 0.84, 0.91, 0.95, 0.98
        assert np.all(hierarchy.levels(mesh) == level)
        errors.append(abs(_area(mesh) - SPEC.volume) / SPEC.volume)
    # Measured 2.1e-6, 1.4e-7, 8.5e-9, 5.3e-10: fourth order in h (P2 boundary, h^4 per chord).
    assert errors[1] < 1e-6 and errors[3] < 1e-9
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 3.7), orders


def test_adaptive_rounds_and_coarsening(world):
    hierarchy = _hierarchy(world)
    mesh = hierarchy.uniform(0)
    for round_ in (1, 2, 3):
        mesh = hierarchy.rebuild(mesh, _adaptive_wanted(hierarchy, mesh, round_))
        assert boundary_radius_error(mesh, RI, RO) < 1e-12
        assert _min_jacobian_ratio(mesh) > 0.5
    assert world.allreduce(int(hierarchy.levels(mesh).max()), op=MPI.MAX) >= 3
    cells = mesh.topology.index_map(2).size_global
    assert abs(_area(mesh) - SPEC.volume) < 1e-6 * SPEC.volume
    n = mesh.topology.index_map(2).size_local
    coarse = hierarchy.rebuild(mesh, np.zeros(n, dtype=np.int32))
    assert coarse.topology.index_map(2).size_global == hierarchy.base.topology.index_map(2).size_global < cells
    assert boundary_radius_error(coarse, RI, RO) < 1e-12
    assert _min_jacobian_ratio(coarse) > 0.5


def _sorted_nodes(mesh):
    """All owned geometry nodes of the mesh, gathered on every rank, sorted (rows)."""
    n = mesh.geometry.index_map().size_local
    x = np.concatenate(mesh.comm.allgather(np.array(mesh.geometry.x[:n, :2])))
    return x[np.lexsort(x.T[::-1])]


@pytest.mark.mpi
def test_refined_annulus_is_partition_independent():
    world = MPI.COMM_WORLD
    assert world.size > 1
    hierarchy = _hierarchy(world)
    mesh = hierarchy.uniform(1)
    for round_ in (2, 3):
        mesh = hierarchy.rebuild(mesh, _adaptive_wanted(hierarchy, mesh, round_))
    nodes = _sorted_nodes(mesh)
    serial_hierarchy = _hierarchy(MPI.COMM_SELF)
    serial = serial_hierarchy.uniform(1)
    for round_ in (2, 3):
        serial = serial_hierarchy.rebuild(serial, _adaptive_wanted(serial_hierarchy, serial, round_))
    expected = _sorted_nodes(serial)
    assert nodes.shape == expected.shape
    # The same nodes to round-off: measured 2.2e-16 (one unit in the last place at |x| ~ 2) on 2 and 3
    # ranks; the cause of that last bit is not pinned down (the radial rule tried first gave 0).
    assert np.abs(nodes - expected).max() <= 4 * np.finfo(float).eps * RO
