"""The free surface's mesh motion (convection/deform/motion.py) and its config checks: the cell
quality measure; a uniform rise moves every node in proportion to its height (the harmonic mesh
velocity of a linear profile is exact), with the velocity relative to the mesh; the initial
topography raises the top by the given height; the configs a free surface refuses."""

from __future__ import annotations

import numpy as np
import pytest
import dolfinx
import dolfinx.fem
import dolfinx.mesh
from mpi4py import MPI

from convection.config.loader import load_config
from convection.deform.motion import FreeSurface, cell_quality
from convection.deform.surface import SurfaceTerms
from convection.geometry.box import BoxDomain, BoxSpec
from convection.schema import ConfigError
from fembase.dolfinx_compat import function_space

from _runs import CONFIGS


def test_cell_quality_is_one_for_the_regular_simplex():
    comm = MPI.COMM_SELF
    triangle = dolfinx.mesh.create_mesh(comm, np.array([[0, 1, 2]], dtype=np.int64),
                                        np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2.0]]),
                                        dolfinx.mesh.create_unit_square(comm, 1, 1).ufl_domain())
    assert abs(cell_quality(triangle)[0]) == pytest.approx(1.0, rel=1e-12)
    right = dolfinx.mesh.create_unit_square(comm, 1, 1)  # two right isosceles triangles
    assert np.abs(cell_quality(right)) == pytest.approx(np.sqrt(3.0) / 2.0, rel=1e-12)
    cube = dolfinx.mesh.create_unit_cube(comm, 1, 1, 1)
    assert np.all((np.abs(cell_quality(cube)) > 0.3) & (np.abs(cell_quality(cube)) < 1.0))


def _box(comm):
    domain = BoxDomain.from_spec(BoxSpec((8, 4), (0.0, 0.0), (2.0, 1.0)))
    mesh = domain.create_mesh(comm)
    return mesh, domain, FreeSurface(mesh, domain, SurfaceTerms(("top",), 1.0, 0.5))


def test_uniform_rise_moves_every_node_in_proportion_to_its_height(world):
    mesh, domain, surface = _box(world)
    V = function_space(mesh, "Lagrange", 2, shape=(2,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([np.zeros(x.shape[1]), np.full(x.shape[1], 0.3)]))
    z = mesh.geometry.x[:, 1].copy()
    w = surface.velocity(u)
    W = w.function_space.tabulate_dof_coordinates()
    assert world.allreduce(float(np.abs(w.x.array - 0.3 * W[:, 1]).max(initial=0.0)), op=MPI.MAX) < 1e-9
    relative = surface.relative(u)
    X = V.tabulate_dof_coordinates()
    expected = np.stack([np.zeros(X.shape[0]), 0.3 * (1.0 - X[:, 1])], axis=1).reshape(-1)
    assert world.allreduce(float(np.abs(relative.x.array - expected).max(initial=0.0)), op=MPI.MAX) < 1e-9
    surface.move(0.1)
    assert world.allreduce(float(np.abs(mesh.geometry.x[:, 1] - z * 1.03).max(initial=0.0)), op=MPI.MAX) < 1e-9
    assert surface.quality_min > 0.8 and surface.moves == 1
    # the boundaries are those of the undeformed mesh (kept): the top's facets are still found
    top = domain.locate_facets(mesh, "top")
    assert world.allreduce(int(top.size), op=MPI.SUM) >= 8


def test_initial_topography_raises_the_top(world):
    mesh, domain, surface = _box(world)
    z = mesh.geometry.x[:, 1].copy()
    x = mesh.geometry.x[:, 0].copy()
    surface.raise_surface(lambda p: 0.1 * np.cos(np.pi * p[0]))
    assert np.allclose(mesh.geometry.x[:, 1], z + z * 0.1 * np.cos(np.pi * x), atol=1e-14)
    positions, heights = surface.heights()
    assert np.allclose(heights, 0.1 * np.cos(np.pi * positions[:, 0]), atol=1e-14)


@pytest.mark.parametrize("overrides, key", [
    (["free_surface.theta=0.3"], "free_surface"),  # a section without a free-surface boundary
    (["boundary.velocity.top=free_surface"], "free_surface.buoyancy"),  # no units: B must be given
    (["boundary.velocity.top=free_surface", "free_surface.buoyancy=1e3", "stokes.solver=multigrid"],
     "stokes.solver"),
    (["boundary.velocity.bottom=free_surface", "free_surface.buoyancy=1e3"], "boundary.velocity.bottom"),
    (["boundary.velocity.top=free_surface", "free_surface.buoyancy=1e3", "free_surface.initial_topography=x +"],
     "free_surface.initial_topography"),
])
def test_configs_a_free_surface_refuses(overrides, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        load_config(CONFIGS / "blankenbach_1a.yaml", overrides)


def test_an_annulus_topography_below_the_inner_circle_is_refused():
    with pytest.raises(ConfigError, match="free_surface.initial_topography"):
        load_config(CONFIGS / "annulus_free_surface.yaml", ["free_surface.initial_topography=1.5*cos(4*phi)"])


def test_free_surface_on_a_spherical_shell_is_refused():
    with pytest.raises(ConfigError, match="a free surface is the top of a box or the outer circle of an annulus"):
        load_config(CONFIGS / "shell_adaptive.yaml", ["boundary.velocity.outer=free_surface",
                                                      "free_surface.buoyancy=1e3"])


def test_units_give_the_surface_load():
    config = load_config(CONFIGS / "crameri_case1_free_surface.yaml")
    # B = rho0 g L^3 / (eta0 kappa): 3300 kg/m^3, 10 m/s^2, 700 km, 1e21 Pa s, kappa 1e-6 m^2/s
    assert config["free_surface"]["buoyancy"] == pytest.approx(3300 * 10 * 700e3**3 / (1e21 * 1e-6), rel=1e-12)


def test_an_initial_topography_below_the_bottom_is_refused_by_the_check():
    """The config check refuses it (so `python -m convection check` does, as the run would)."""
    with pytest.raises(ConfigError, match="free_surface.initial_topography': '-800\\*km' is .* must stay above"):
        load_config(CONFIGS / "crameri_case1_free_surface.yaml",
                    ["mesh.cells=[28,7]", "free_surface.initial_topography=-800*km"])
