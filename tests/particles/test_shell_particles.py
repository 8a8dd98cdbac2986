"""Particles on a curved (second-order) annulus mesh: location near curved boundaries, generation,
rigid-rotation advection across ranks with no particle lost."""


import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem

pytest.importorskip("gmsh")

from _helpers import gathered, plugin, swarm_at  # noqa: E402
from convection.geometry.shell import ShellSpec, create_shell_mesh  # noqa: E402
from fembase.dolfinx_compat import function_space
from fembase.geometry import locate_owned  # noqa: E402
from fembase.geometry import CellGeometry  # noqa: E402
from particles import Swarm  # noqa: E402
from particles.advection import Advector  # noqa: E402
from particles.generation import generate  # noqa: E402
from particles.generation.metropolis_hastings import MetropolisHastings  # noqa: E402

RI, RO = 1.22, 2.22


def _annulus(comm, resolution=0.4):
    return create_shell_mesh(comm, ShellSpec(2, RI, RO, resolution=resolution))


def _count(comm, mask):
    return comm.allreduce(int(np.count_nonzero(mask)), op=MPI.SUM)


def _found_anywhere(comm, mask):
    """Points found on at least one rank (a point on a facet between two ranks' cells is owned by
    both within the pull-back tolerance; generators and migration give it to the lowest rank)."""
    anywhere = np.empty(mask.shape[0], dtype=np.int32)
    comm.Allreduce(mask.astype(np.int32), anywhere, op=MPI.MAX)
    return int(np.count_nonzero(anywhere))


def test_curved_cells_located_by_pull_back(world):
    """Points just inside the outer circle (in the part of a cell bulging beyond its straight edge)
    are found; points just inside the hole (between a straight edge and the inner circle) are not."""
    mesh = _annulus(world)
    geometry = CellGeometry(mesh)
    assert geometry.curvature_padding > 1e-3  # the cells are curved
    angles = np.linspace(0.0, 2.0 * np.pi, 1001)[:-1]
    for radius, expected in ((RO - 1e-4, angles.size), (RI + 1e-6, angles.size), (1.7, angles.size),
                             (RI - 1e-4, 0), (RO + 1e-4, 0)):
        points = radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        found = geometry.locate(points, owned_only=True)
        assert _found_anywhere(world, found.cells >= 0) == expected, radius
        hit = found.cells >= 0
        assert np.allclose(geometry.push_forward(found.cells[hit], found.xref[hit]), points[hit], atol=1e-12)
        owned = locate_owned(mesh, points)
        assert np.array_equal(owned.cells, found.cells)


def test_generated_particles_inside_the_shell(world):
    mesh = _annulus(world)
    swarm = Swarm(mesh)
    generate(swarm, plugin(MetropolisHastings, 2000, seed=3))  # random_uniform needs affine cells
    r = np.linalg.norm(swarm.x, axis=1)
    assert _count(world, (r < RI - 1e-12) | (r > RO + 1e-12)) == 0
    assert world.allreduce(swarm.num_particles) == 2000
    assert np.allclose(swarm.geometry.push_forward(swarm.cells, swarm.xref), swarm.x, atol=1e-12)


def test_rigid_rotation_in_curved_annulus(world):
    """One revolution of u = 2 pi (-y, x) with RK2: every particle is kept, stays in the shell, and
    its error is RK2's closed-form amplification error |A^n - 1| r (the field is exact in P2)."""
    mesh = _annulus(world)
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([-2.0 * np.pi * x[1], 2.0 * np.pi * x[0]]))
    radii = np.array([RI + 1e-3, 1.5, 1.9, RO - 2e-3])
    phi = 2.0 * np.pi * (np.arange(24) + 0.3) / 24
    points = np.concatenate([r * np.stack([np.cos(phi), np.sin(phi)], axis=1) for r in radii])
    swarm = swarm_at(mesh, points)
    assert world.allreduce(swarm.num_particles) == points.shape[0]
    steps = 100
    advector = Advector(swarm, integrator="rk2")
    lost = 0
    for _ in range(steps):
        lost += advector.step(u, u, 1.0 / steps).global_lost
    swarm.check_invariants()
    ids, x, _ = gathered(swarm)
    assert lost == 0 and np.array_equal(ids, np.arange(points.shape[0]))
    z = 1j * 2.0 * np.pi / steps
    amplification = (1.0 + z + z * z / 2.0) ** steps
    expected = abs(amplification - 1.0) * np.linalg.norm(points, axis=1)
    assert np.allclose(np.linalg.norm(x - points, axis=1), expected, rtol=1e-6)
    assert np.allclose(swarm.geometry.push_forward(swarm.cells, swarm.xref), swarm.x, atol=1e-12)


def test_confinement_keeps_particles_crossing_a_curved_boundary(world):
    """Large RK2 steps of a rotation carry particles near the outer circle across it (straight steps
    along a curved boundary): without confinement they are lost, with
    :func:`convection.geometry.mesh.shell_confinement` every particle stays, inside the shell."""
    from convection.geometry.shell import shell_confinement

    spec = ShellSpec(2, RI, RO, resolution=0.4)
    mesh = create_shell_mesh(world, spec)
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([-2.0 * np.pi * x[1], 2.0 * np.pi * x[0]]))
    phi = 2.0 * np.pi * np.arange(40) / 40
    points = (RO - 1e-3) * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    lost = {}
    for confine in (None, shell_confinement(mesh, spec)):
        swarm = swarm_at(mesh, points)
        advector = Advector(swarm, integrator="rk2", confine=confine)
        lost[confine is None] = sum(advector.step(u, u, 0.02).global_lost for _ in range(5))
        if confine is not None:
            ids, x, _ = gathered(swarm)
            r = np.linalg.norm(x, axis=1)
            assert ids.size == points.shape[0] and np.all((r >= RI) & (r <= RO))
    assert lost[True] > 0 and lost[False] == 0


@pytest.mark.parametrize("gdim, resolution", [(2, 0.3), (3, 0.5)])
def test_confinement_on_straight_cells_puts_points_in_cells(world, gdim, resolution):
    """Straight-sided shells: confined points lie in the mesh (none in the inscribed hole, none outside
    the outer polygon/polyhedron), points already inside stay where they are, and the outer bound
    is within a sagitta of the circle/sphere."""
    from fembase.evaluation import locate
    from convection.geometry.shell import shell_confinement

    spec = ShellSpec(gdim, RI, RO, resolution=resolution, geometry_degree=1)
    mesh = create_shell_mesh(world, spec)
    confine = shell_confinement(mesh, spec)
    rng = np.random.default_rng(4)
    direction = rng.normal(size=(4000, gdim))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    r = rng.uniform(0.95 * RI, 1.05 * RO, size=4000)
    points = r[:, None] * direction
    confined = points.copy()
    confine(confined)
    radius = np.linalg.norm(confined, axis=1)
    moved = np.any(confined != points, axis=1)
    assert np.all(radius >= RI * (1 - 1e-12)) and np.all(radius < RO)
    assert not np.any(moved & (r > RI * 1.001) & (r < RO - resolution**2))
    assert radius.max() > RO - 2.0 * resolution**2 / RO  # the bound is not more than a sagitta or so inside
    found = locate(mesh, confined, geometry=Swarm(mesh).geometry).cells >= 0
    owners = np.zeros(found.shape, dtype=np.int32)
    world.Allreduce(found.astype(np.int32), owners, op=MPI.SUM)
    assert np.all(owners >= 1)


def test_generated_particles_are_confined_on_straight_cells(world):
    """Straight-sided cells cover part of the inscribed hole (r < r_inner): a ParticleManager with
    ``confine`` moves generated particles there to the inner circle before the properties start
    (so initial_position is inside the shell and displacement starts at 0); none is lost."""
    from convection.geometry.shell import shell_confinement
    from particles.generation import RandomUniform
    from particles.manager import ParticleManager

    spec = ShellSpec(2, RI, RO, resolution=0.3, geometry_degree=1)
    mesh = create_shell_mesh(world, spec)
    unconfined = ParticleManager(mesh, generator=plugin(RandomUniform, 8000, seed=5))
    r = np.linalg.norm(unconfined.swarm.x, axis=1)
    below = _count(world, r < RI * (1 - 1e-9))
    assert below > 0  # the gap is real without confinement
    manager = ParticleManager(mesh, generator=plugin(RandomUniform, 8000, seed=5),
                              properties=["initial_position", "displacement"],
                              confine=shell_confinement(mesh, spec))
    ids, x, _ = gathered(manager.swarm)
    r = np.linalg.norm(x, axis=1)
    assert ids.size == 8000 and np.array_equal(np.sort(ids), np.arange(8000)) and manager.lost == 0
    assert np.all(r >= RI * (1 - 1e-12)) and np.all(r <= RO)
    assert _count(world, np.linalg.norm(manager.swarm.x, axis=1) < RI * (1 - 1e-9)) == 0
    assert np.array_equal(manager.swarm.property("initial_position"), manager.swarm.x)
    assert np.all(manager.swarm.property("displacement") == 0.0)
    located = manager.swarm.geometry.push_forward(manager.swarm.cells, manager.swarm.xref)
    assert np.allclose(located, manager.swarm.x, atol=1e-12)
