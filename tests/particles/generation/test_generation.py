"""Particle generators: counts, densities, ids, and independence of the number of ranks."""

import dataclasses
import math

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from _helpers import plugin
from fembase.geometry import locate_owned, push_forward
from particles import Swarm
from particles.generation import (
    GENERATORS,
    BoxLattice,
    FromFile,
    GeneratorContext,
    MetropolisHastings,
    RandomDensity,
    RandomUniform,
    ReferencePoints,
    Shell,
    generate,
)
from particles.generation._allocation import exact_global_sum


def _square(comm, n=8, cell_type=dolfinx.mesh.CellType.triangle):
    return dolfinx.mesh.create_unit_square(comm, n, n, cell_type=cell_type)


def _gathered(comm, swarm):
    ids = np.concatenate(comm.allgather(swarm.ids))
    x = np.concatenate(comm.allgather(swarm.x))
    order = np.argsort(ids)
    return ids[order], x[order]


def _placed_correctly(swarm):
    """Sorted, owned cells only, and each particle's own cell maps its xref to its position."""
    swarm.check_invariants()
    if swarm.num_particles == 0:
        return True
    ok = np.allclose(push_forward(swarm.mesh, swarm.cells, swarm.xref), swarm.x, atol=1e-12)
    return bool(ok and np.all(locate_owned(swarm.mesh, swarm.x).cells >= 0))


def _run(comm, generator, mesh_factory):
    swarm = Swarm(mesh_factory(comm))
    result = generate(swarm, generator)
    ok = comm.allreduce(_placed_correctly(swarm), op=MPI.LAND)
    return swarm, result, ok


def _strip_chi2(x, density_1d, bins=8):
    """Chi-square of the counts in x-strips against the strip probabilities of density_1d."""
    edges = np.linspace(0.0, 1.0, bins + 1)
    fine = np.linspace(0.0, 1.0, 20001)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density_1d(fine[1:]) + density_1d(fine[:-1])) * np.diff(fine))])
    p = np.diff(np.interp(edges, fine, cdf / cdf[-1]))
    counts = np.histogram(x, bins=edges)[0]
    expected = p * x.shape[0]
    return float(np.sum((counts - expected) ** 2 / expected)), bins - 1


# ---------------------------------------------------------------------------------------- registry
def test_registry_names_and_errors():
    assert set(GENERATORS) == {"random_uniform", "random_density", "metropolis_hastings", "box_lattice", "shell",
                               "from_file", "reference_points"}
    assert all(name == name.lower() and cls.description for name, cls in GENERATORS.items())
    with pytest.raises(ValueError, match="random_uniform"):
        GENERATORS.lookup("random")
    gen = GENERATORS.build("random_uniform", GENERATORS.settings("random_uniform", num_particles=5, seed=1),
                           GeneratorContext())
    assert gen == plugin(RandomUniform, 5, seed=1)
    assert gen != plugin(RandomUniform, 5, seed=2)
    with pytest.raises(ValueError, match=r"^particle generator 'random_uniform' has no parameter 'density'; its "
                                         r"parameters: \['num_particles', 'seed'\]$"):
        GENERATORS.settings("random_uniform", num_particles=5, density="1")
    with pytest.raises(ValueError, match=r"^particle generator 'box_lattice' needs the parameter 'upper'$"):
        GENERATORS.settings("box_lattice", lower=(0, 0), counts=(2, 2))
    with pytest.raises(TypeError, match="RandomUniform.Settings"):
        RandomUniform(RandomDensity.Settings(5))


def test_every_generator_has_the_plugin_shape():
    """Settings of param fields, build(settings, context) giving the class, dispatched by the registry."""
    for name, cls in GENERATORS.items():
        assert dataclasses.is_dataclass(cls.Settings) and isinstance(cls.affine_cells_only, bool), name
        assert all("schema" in f.metadata for f in dataclasses.fields(cls.Settings)), name


def test_the_context_makes_a_text_density_a_function(tmp_path):
    settings = GENERATORS.settings("metropolis_hastings", num_particles=10, density="x > 0.5")
    seen = []
    gen = GENERATORS.build("metropolis_hastings", settings,
                           GeneratorContext(make_function=lambda text: seen.append(text) or (lambda x: x[:, 0])))
    assert seen == ["x > 0.5"] and callable(gen.settings.density) and settings.density == "x > 0.5"
    with pytest.raises(ValueError, match="^random_density: 'density' is text but no expression parser was given$"):
        GENERATORS.build("random_density", RandomDensity.Settings(10, density="x"), GeneratorContext())
    with pytest.raises(ValueError, match="not found"):
        GENERATORS.build("from_file", FromFile.Settings(tmp_path / "none.txt"), GeneratorContext())
    path = tmp_path / "points.txt"
    path.write_text("0.1 0.2 0.3 0.4\n")
    with pytest.raises(ValueError, match="expected 2 columns, found 4"):
        GENERATORS.build("from_file", FromFile.Settings(path), GeneratorContext(gdim=2))
    assert GENERATORS.build("from_file", FromFile.Settings(path), GeneratorContext()) == plugin(FromFile, path)


def test_exact_sum_is_order_independent():
    rng = np.random.default_rng(0)
    values = rng.random(10000) * 10.0 ** rng.integers(-8, 8, 10000)
    s1 = exact_global_sum(MPI.COMM_SELF, values)
    s2 = exact_global_sum(MPI.COMM_SELF, values[::-1].copy())
    assert s1 == s2 == math.fsum(values)


# ---------------------------------------------------------------------------------------- serial
def test_random_uniform_counts_ids_per_cell():
    swarm, result, ok = _run(MPI.COMM_SELF, plugin(RandomUniform, 1000, seed=2), lambda c: _square(c, 6))
    assert ok and result.num_global == result.num_local == swarm.num_particles == 1000
    np.testing.assert_array_equal(np.sort(swarm.ids), np.arange(1000))
    # Uniform density: every cell (area 1/72) gets floor or ceil of 1000/72 particles.
    counts = swarm.particles_per_cell()
    assert counts.min() >= np.floor(1000 / 72) and counts.max() <= np.ceil(1000 / 72)
    assert len(np.unique(swarm.x, axis=0)) == 1000


def test_random_density_follows_density():
    def rho(x):
        return 1.0 + 10.0 * x[:, 0] ** 2

    swarm, result, ok = _run(MPI.COMM_SELF, plugin(RandomDensity, 4000, seed=7, density=rho), lambda c: _square(c, 16))
    assert ok and swarm.num_particles == 4000
    chi2, dof = _strip_chi2(swarm.x[:, 0], lambda s: 1.0 + 10.0 * s**2)
    assert chi2 < dof + 5.0 * np.sqrt(2.0 * dof)
    # A density concentrated in the left half puts (almost) nothing right of 0.5.
    swarm2, _, _ = _run(MPI.COMM_SELF, plugin(RandomDensity, 500, seed=1, density=lambda x: (x[:, 0] < 0.5) * 1.0),
                        lambda c: _square(c, 8))
    assert np.all(swarm2.x[:, 0] <= 0.5 + 1e-12)


def test_random_uniform_seed_changes_positions_not_ids():
    a, _, _ = _run(MPI.COMM_SELF, plugin(RandomUniform, 200, seed=1), _square)
    b, _, _ = _run(MPI.COMM_SELF, plugin(RandomUniform, 200, seed=2), _square)
    assert not np.allclose(np.sort(a.x[:, 0]), np.sort(b.x[:, 0]))
    np.testing.assert_array_equal(np.sort(a.ids), np.sort(b.ids))


def test_generate_appends_after_existing_ids():
    swarm = Swarm(_square(MPI.COMM_SELF, 4))
    generate(swarm, "random_uniform", num_particles=10, seed=0)
    result = generate(swarm, "reference_points", kind="quadrature", degree=1)
    assert result.first_id == 10 and swarm.num_particles == 10 + 32
    np.testing.assert_array_equal(np.sort(swarm.ids), np.arange(42))


@pytest.mark.parametrize("cell_type", [dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.quadrilateral])
def test_metropolis_hastings_follows_density_inside_cells(cell_type):
    """A coarse 3x3 mesh, density varying strongly inside cells: strip counts still match."""
    def rho(x):
        return np.exp(3.0 * x[:, 0])

    swarm, result, ok = _run(MPI.COMM_SELF, plugin(MetropolisHastings, 3000, density=rho, seed=4, thinning=5),
                             lambda c: _square(c, 3, cell_type))
    assert ok and swarm.num_particles == 3000
    chi2, dof = _strip_chi2(swarm.x[:, 0], lambda s: np.exp(3.0 * s), bins=12)
    assert chi2 < dof + 6.0 * np.sqrt(2.0 * dof)
    # Piecewise-constant sampling (random_density) misses the in-cell variation on this mesh.
    flat, _, _ = _run(MPI.COMM_SELF, plugin(RandomDensity, 3000, density=rho, seed=4), lambda c: _square(c, 3))
    chi2_flat, _ = _strip_chi2(flat.x[:, 0], lambda s: np.exp(3.0 * s), bins=12)
    assert chi2_flat > 3.0 * chi2


def test_metropolis_hastings_uniform_on_distorted_quads():
    """Uniform density on a non-affine quadrilateral mesh: the |det J| weighting keeps it uniform."""
    mesh = _square(MPI.COMM_SELF, 4, dolfinx.mesh.CellType.quadrilateral)
    x = mesh.geometry.x
    x[:, 0] = x[:, 0] ** 2  # stretch: cells narrow on the left, wide on the right
    swarm = Swarm(mesh)
    generate(swarm, plugin(MetropolisHastings, 4000, seed=3))
    assert _placed_correctly(swarm)
    chi2, dof = _strip_chi2(swarm.x[:, 0], lambda s: np.ones_like(s), bins=10)
    assert chi2 < dof + 6.0 * np.sqrt(2.0 * dof)


def test_random_density_rejects_non_affine_cells():
    swarm = Swarm(_square(MPI.COMM_SELF, 2, dolfinx.mesh.CellType.quadrilateral))
    with pytest.raises(ValueError, match="metropolis_hastings"):
        generate(swarm, plugin(RandomUniform, 10))


def test_box_lattice_inside_and_outside():
    swarm, result, ok = _run(MPI.COMM_SELF, plugin(BoxLattice, (0.0, 0.0), (1.0, 1.0), (5, 4)), _square)
    assert ok and result.num_global == 20 and result.num_outside == 0
    order = np.argsort(swarm.ids)
    np.testing.assert_allclose(swarm.x[order][:4], [[0, 0], [0, 1 / 3], [0, 2 / 3], [0, 1]], atol=1e-15)
    swarm, result, ok = _run(MPI.COMM_SELF, plugin(BoxLattice, (-1.0, 0.25), (2.0, 0.75), (7, 3)), _square)
    # x in {-1, -.5, 0, .5, 1, 1.5, 2}: 3 columns inside the unit square.
    assert ok and result.num_global == 9 and result.num_outside == 12
    np.testing.assert_array_equal(np.sort(swarm.ids), np.sort(np.ravel_multi_index((np.repeat([2, 3, 4], 3),
                                                                                    np.tile([0, 1, 2], 3)), (7, 3))))


def test_shell_counts_points_outside():
    gen = plugin(Shell, (0.5, 0.5), (0.2, 0.45, 0.8), (8, 16, 32))
    swarm, result, ok = _run(MPI.COMM_SELF, gen, _square)
    pts = gen.points()
    inside = np.all((pts >= -1e-12) & (pts <= 1 + 1e-12), axis=1)
    assert ok and result.num_global == inside.sum() and result.num_outside == (~inside).sum() > 0
    np.testing.assert_array_equal(np.sort(swarm.ids), np.flatnonzero(inside))
    np.testing.assert_allclose(np.linalg.norm(swarm.x - 0.5, axis=1)[swarm.ids < 8], 0.2)
    pts3 = plugin(Shell, (0.0, 0.0, 0.0), (1.0,), (100,)).points()
    np.testing.assert_allclose(np.linalg.norm(pts3, axis=1), 1.0)
    assert abs(pts3.mean(axis=0)).max() < 0.02


def test_from_file_reports_outside(tmp_path):
    path = tmp_path / "points.txt"
    rows = np.array([[0.1, 0.2], [2.0, 0.5], [0.5, 0.5], [-0.1, 0.3], [1.0, 1.0]])
    np.savetxt(path, rows, header="x y")
    swarm, result, ok = _run(MPI.COMM_SELF, plugin(FromFile, path), _square)
    assert ok and result.num_global == 3 and result.num_outside == 2
    order = np.argsort(swarm.ids)
    np.testing.assert_array_equal(swarm.ids[order], [0, 2, 4])
    np.testing.assert_array_equal(swarm.x[order], rows[[0, 2, 4]])


@pytest.mark.parametrize("kind,degree,per_cell", [("quadrature", 2, 3), ("quadrature", 4, 6), ("lattice", 4, 3)])
def test_reference_points(kind, degree, per_cell):
    swarm, result, ok = _run(MPI.COMM_SELF, plugin(ReferencePoints, kind, degree), lambda c: _square(c, 4))
    assert ok and result.num_global == 32 * per_cell
    assert np.all(swarm.particles_per_cell() == per_cell)
    with pytest.raises(ValueError, match="quadrature"):
        plugin(ReferencePoints, "gauss", 2).reference_points(None)


def test_random_uniform_3d_tetrahedra():
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 3)
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, 810, seed=9))
    assert _placed_correctly(swarm) and swarm.num_particles == 810
    assert swarm.particles_per_cell().min() == 5 and swarm.particles_per_cell().max() == 5


# ---------------------------------------------------------------------------------------- MPI
def _generators(path):
    return [
        plugin(RandomUniform, 1500, seed=11),
        plugin(RandomDensity, 1200, seed=3, density=lambda x: 1.0 + np.sin(3.0 * x[:, 0]) ** 2 + x[:, 1]),
        plugin(MetropolisHastings, 800, density=lambda x: np.exp(-8.0 * ((x[:, 0] - 0.4) ** 2 + (x[:, 1] - 0.6) ** 2)),
                           seed=5),
        plugin(BoxLattice, (0.0, 0.0), (1.0, 1.0), (13, 13)),
        plugin(Shell, (0.5, 0.5), (0.25, 0.6), (24, 40)),
        plugin(FromFile, path),
        plugin(ReferencePoints, "quadrature", 3),
        plugin(ReferencePoints, "lattice", 3),
    ]


@pytest.mark.mpi
@pytest.mark.parametrize("which", range(8))
@pytest.mark.parametrize("cell_type", [dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.quadrilateral])
def test_same_particles_on_any_number_of_ranks(which, cell_type, tmp_path):
    comm = MPI.COMM_WORLD
    path = tmp_path / "points.txt"
    np.savetxt(path, np.random.default_rng(0).uniform(-0.2, 1.2, size=(300, 2)))
    gen = _generators(path)[which]
    if cell_type == dolfinx.mesh.CellType.quadrilateral and isinstance(gen, (RandomUniform, RandomDensity)):
        pytest.skip("random_density needs affine simplices")

    def factory(c):
        return _square(c, 12, cell_type)

    swarm, result, ok = _run(comm, gen, factory)
    ids, x = _gathered(comm, swarm)
    serial, serial_result, serial_ok = _run(MPI.COMM_SELF, gen, factory)
    sorder = np.argsort(serial.ids)
    assert ok and serial_ok
    assert result.num_global == serial_result.num_global == ids.shape[0]
    assert result.num_outside == serial_result.num_outside
    np.testing.assert_array_equal(ids, serial.ids[sorder])
    np.testing.assert_array_equal(x, serial.x[sorder])
    if not isinstance(gen, (BoxLattice, Shell, FromFile)):
        np.testing.assert_array_equal(ids, np.arange(ids.shape[0]))


@pytest.mark.mpi
def test_parallel_density_statistics():
    comm = MPI.COMM_WORLD
    swarm, result, ok = _run(comm, plugin(RandomDensity, 4000, seed=21, density=lambda x: 1.0 + 10.0 * x[:, 0] ** 2),
                             lambda c: _square(c, 16))
    _, x = _gathered(comm, swarm)
    chi2, dof = _strip_chi2(x[:, 0], lambda s: 1.0 + 10.0 * s**2)
    assert ok and x.shape[0] == 4000 and comm.allreduce(swarm.num_particles) == 4000
    assert chi2 < dof + 5.0 * np.sqrt(2.0 * dof)
    assert comm.allreduce(result.num_local) == result.num_global == 4000


@pytest.mark.mpi
@pytest.mark.parametrize("gen", [plugin(RandomUniform, 700, seed=1), plugin(ReferencePoints, "quadrature", 2),
                                 plugin(MetropolisHastings, 300, density=lambda x: 1.0 + x[:, 2], seed=2, thinning=3),
                                 plugin(BoxLattice, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (5, 4, 5))])
def test_same_particles_on_any_number_of_ranks_3d(gen):
    comm = MPI.COMM_WORLD

    def factory(c):
        return dolfinx.mesh.create_unit_cube(c, 4, 4, 4)

    swarm, result, ok = _run(comm, gen, factory)
    ids, x = _gathered(comm, swarm)
    serial, _, serial_ok = _run(MPI.COMM_SELF, gen, factory)
    sorder = np.argsort(serial.ids)
    assert ok and serial_ok and result.num_outside == 0
    np.testing.assert_array_equal(ids, np.arange(result.num_global))
    np.testing.assert_array_equal(ids, serial.ids[sorder])
    np.testing.assert_array_equal(x, serial.x[sorder])


def test_metropolis_hastings_keeps_to_the_support_of_the_density():
    """A density that is 1 in a thin strip x < 0.05 and 0 elsewhere covers the first column of cells
    only in part (cells 1/3 wide): every particle lies in the strip, none in the rest of those cells."""
    def rho(x):
        return (x[:, 0] < 0.05).astype(np.float64)

    swarm, _, ok = _run(MPI.COMM_SELF, plugin(MetropolisHastings, 600, density=rho, seed=5, quadrature_degree=8),
                        lambda c: _square(c, 3))
    assert ok and swarm.num_particles == 600
    assert np.all(swarm.x[:, 0] < 0.05)
