"""gmsh annulus and spherical-shell meshes: curved cells with boundary nodes on the circles/spheres,
no inverted cells, areas/volumes to the accuracy of second-order geometry, radius-based boundaries."""

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx.fem

pytest.importorskip("gmsh")

from convection.geometry.registry import DOMAINS, domain_from_settings  # noqa: E402
from convection.geometry.domain import LevelsByRefinement, MeshSection  # noqa: E402
from convection.geometry.radial import RadialMeshSettings  # noqa: E402
from convection.geometry.shell import (  # noqa: E402
    SHELL_BOUNDARIES, ShellSpec, SphericalShell, create_shell_mesh, shell_domain, shell_radii,
)
from fembase.dolfinx_compat import (  # noqa: E402
    coordinate_map, evaluate_expression, geometry_dofmap, refine_keeping_partition,
)


def _integral(mesh, form):
    return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(form)), op=MPI.SUM)


def _min_jacobian(mesh):
    tdim = mesh.topology.dim
    points = np.array([[0.25] * tdim, [0.02] * tdim, [0.96] + [0.02] * (tdim - 1), [0.02] * (tdim - 1) + [0.96]])
    expr = dolfinx.fem.Expression(ufl.JacobianDeterminant(mesh), points)
    cells = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)
    local = float(evaluate_expression(expr, mesh, cells).min()) if cells.size else np.inf
    return mesh.comm.allreduce(local, op=MPI.MIN)


@pytest.mark.parametrize("gdim, resolution, tolerance", [(2, 0.3, 1e-4), (3, 0.5, 1e-3)])
def test_curved_shell_mesh(world, gdim, resolution, tolerance):
    spec = ShellSpec(gdim, 1.22, 2.22, resolution=resolution)
    mesh = create_shell_mesh(world, spec)
    assert coordinate_map(mesh).degree == 2
    assert _min_jacobian(mesh) > 0.0  # the coarse 3D mesh needs gmsh's high-order untangling
    assert shell_radii(mesh) == pytest.approx((1.22, 2.22), abs=1e-12)
    domain = shell_domain(spec)
    volume = _integral(mesh, dolfinx.fem.Constant(mesh, 1.0) * ufl.dx)
    assert abs(volume - spec.volume) < tolerance * spec.volume
    for name, radius in zip(SHELL_BOUNDARIES, (1.22, 2.22)):
        area = _integral(mesh, dolfinx.fem.Constant(mesh, 1.0) * domain.measure(mesh, name))
        exact = 2 * np.pi * radius if gdim == 2 else 4 * np.pi * radius**2
        assert abs(area - exact) < tolerance * exact
        assert world.allreduce(domain.locate_facets(mesh, name).size) > 0


def test_straight_cells_and_interfaces():
    spec = ShellSpec(2, resolution=0.3, geometry_degree=1, interfaces=(1.72,))
    mesh = create_shell_mesh(MPI.COMM_WORLD, spec)
    assert coordinate_map(mesh).degree == 1
    r = np.linalg.norm(mesh.geometry.x[:, :2], axis=1)
    assert np.any(np.abs(r - 1.72) < 1e-12)  # vertices on the interface circle
    volume = _integral(mesh, dolfinx.fem.Constant(mesh, 1.0) * ufl.dx)
    assert volume < spec.volume  # chords cut the outer circle


def test_spec_from_config_and_checks():
    keys = RadialMeshSettings(radii=(1.0, 2.0), resolution=0.4, geometry_degree=2)
    domain = domain_from_settings(MeshSection("spherical_shell", keys, 2_000_000))
    assert isinstance(domain, SphericalShell) and domain.spec.gdim == 3 and domain.spec.name == "spherical_shell"
    assert domain.gravity.name == "radial" and domain.gravity.outer_radius == 2.0
    with pytest.raises(ValueError, match="inner_radius"):
        ShellSpec(2, 2.0, 1.0)
    with pytest.raises(ValueError, match="unknown geometry 'torus'"):
        DOMAINS.lookup("torus")


def test_shell_mesh_written_and_read_again(tmp_path):
    """``msh_file``: the first call meshes and writes the file, the second reads it: the same cells
    and nodes (to the file's 17 significant digits), the boundary still found by radius."""
    spec = ShellSpec(2, 1.22, 2.22, resolution=0.4, geometry_degree=2, interfaces=(1.72,))
    msh = tmp_path / "annulus.msh"
    made = create_shell_mesh(MPI.COMM_SELF, spec, msh_file=msh)
    assert msh.exists()
    read = create_shell_mesh(MPI.COMM_SELF, spec, msh_file=msh)
    tdim = made.topology.dim
    assert read.topology.index_map(tdim).size_local == made.topology.index_map(tdim).size_local
    assert np.allclose(read.geometry.x, made.geometry.x, rtol=0.0, atol=1e-14)
    facets = shell_domain(spec).locate_facets(read, "outer")
    assert facets.size > 0


def _cap_cells(mesh, radii) -> int:
    """Owned cells with all vertices on one of the spheres ``radii``."""
    tdim = mesh.topology.dim
    n = mesh.topology.index_map(tdim).size_local
    nodes = geometry_dofmap(mesh)[:n, : tdim + 1]
    r = np.linalg.norm(mesh.geometry.x[nodes], axis=2)
    return sum(int(np.all(np.abs(r - radius) < 1e-9 * radius, axis=1).sum()) for radius in radii)


def test_a_base_the_manifold_curves_has_no_cell_on_one_sphere():
    """gmsh's Delaunay shell has, at some sizes, tetrahedra with all four vertices on a sphere (which
    the manifold cannot curve): at 0.4 and 0.5 with Debian 12's gmsh 4.8, at 0.5 with Debian 13's.
    The straight base of a hierarchy (``curvable``) is meshed again a little finer until it has
    none, the same mesh at every call."""
    radii = (1.22, 2.22)
    plain = [create_shell_mesh(MPI.COMM_SELF, ShellSpec(3, *radii, resolution=size, geometry_degree=1))
             for size in (0.4, 0.5)]
    assert max(_cap_cells(mesh, radii) for mesh in plain) > 0
    for size in (0.4, 0.5):
        spec = ShellSpec(3, *radii, resolution=size, geometry_degree=1, curvable=True)
        meshes = [create_shell_mesh(MPI.COMM_SELF, spec) for _ in range(2)]
        assert _cap_cells(meshes[0], radii) == 0
        assert np.array_equal(meshes[0].geometry.x, meshes[1].geometry.x)
        domain = shell_domain(ShellSpec(3, *radii, resolution=size))
        assert _cap_cells(domain.create_mesh(MPI.COMM_SELF, straight=True), radii) == 0


def _shortest_edge(mesh) -> float:
    tdim = mesh.topology.dim
    nodes = geometry_dofmap(mesh)[:, : tdim + 1]
    x = mesh.geometry.x[nodes]
    local = min(float(np.linalg.norm(x[:, i] - x[:, j], axis=1).min()) for i in range(4) for j in range(i))
    return mesh.comm.allreduce(local, op=MPI.MIN)


def test_a_uniformly_refined_base_has_no_short_edges():
    """Uniform refinement cuts a sliver's inner octahedron along a diagonal far shorter than half the
    cell (:data:`convection.geometry.shell.UNIFORM_BASE_QUALITY`): the base of a fixed shell's two
    levels (gmsh at 0.5) refined once has no edge below a fifth of 0.5; the curvable base gmsh's
    own optimiser threshold leaves (an adaptive shell's) has one of 0.083."""
    domain = shell_domain(ShellSpec(3, 1.22, 2.22, resolution=0.25))

    def refined_shortest_edge(base):
        return _shortest_edge(refine_keeping_partition(base))

    assert refined_shortest_edge(domain.coarsened(1).create_mesh(MPI.COMM_SELF, straight=True)) > 0.1
    assert refined_shortest_edge(shell_domain(ShellSpec(3, 1.22, 2.22, resolution=0.5)).create_mesh(
        MPI.COMM_SELF, straight=True)) < 0.09


@pytest.mark.parametrize("resolution, degree, levels", [
    (0.25, 2, 2), (0.125, 2, 3), (0.1, 2, 3), (0.3, 2, 1), (0.25, 1, 1),
])
def test_shell_levels_by_refinement(resolution, degree, levels):
    """A fixed shell's multigrid levels refine gmsh's shell at ``resolution * 2^(L-1)``, whose cells
    may be at most half the shell's thickness (1 here)."""
    domain = shell_domain(ShellSpec(3, 1.22, 2.22, resolution=resolution, geometry_degree=degree))
    assert isinstance(domain, LevelsByRefinement)
    assert domain.mesh_levels() == levels
    assert domain.coarsened(2).spec.resolution == pytest.approx(4 * resolution)


def test_shell_levels_refused_beyond_the_thickness():
    domain = shell_domain(ShellSpec(3, 1.22, 2.22, resolution=0.25))
    assert domain.mesh_levels(2) == 2
    with pytest.raises(ValueError, match="3 levels need a coarsest mesh of cell size resolution \\* 2\\^2 = 1"):
        domain.mesh_levels(3)
    with pytest.raises(ValueError, match="need mesh.geometry_degree 2"):
        shell_domain(ShellSpec(3, 1.22, 2.22, resolution=0.25, geometry_degree=1)).mesh_levels(2)
