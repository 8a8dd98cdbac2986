"""Population control by particle density (particles/population/density.py), the equal-volume sub-cells
(particles/population/subcells.py) and the distribution score (particles/population/distribution.py)."""

import basix
import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from fembase.geometry import locate_owned
from particles import Swarm
from particles.population.density import Neighbourhood, particle_density, removal_mask
from particles.population.distribution import cell_scores, distribution_score, scores_of_counts
from particles.generation import generate
from particles.generation.maps import CellMaps
from particles.generation.sampling import uniform_reference_points
from particles.population.control import PopulationControl, control_population
from particles.population.subcells import SubCells


def _placed(mesh, x, first_id=0):
    """A swarm with particles at the points ``x`` (shape=(m, 2)) that this rank's owned cells hold."""
    swarm = Swarm(mesh)
    found = locate_owned(mesh, x)
    keep = found.cells >= 0
    swarm.add(first_id + np.flatnonzero(keep), x[keep], found.xref[keep], found.cells[keep])
    return swarm


def _varying(comm, n=8, num=900, seed=2):
    mesh = dolfinx.mesh.create_unit_square(comm, n, n)
    swarm = Swarm(mesh)
    generate(swarm, "random_density", num_particles=num, seed=seed, density=lambda x: np.exp(-6.0 * x[:, 0]))
    swarm.add_property("tag")
    swarm.property("tag")[:, 0] = swarm.ids
    return swarm


@pytest.mark.parametrize("cell", [basix.CellType.triangle, basix.CellType.tetrahedron, basix.CellType.quadrilateral,
                                  basix.CellType.hexahedron])
@pytest.mark.parametrize("g", [1, 2, 3])
def test_subcells_have_equal_volume_and_sample_inside(cell, g):
    sub = SubCells(cell, g)
    assert sub.num == g ** sub.tdim
    assert np.array_equal(sub.index(sub.centroids), np.arange(sub.num))
    rng = np.random.default_rng(4)
    x = uniform_reference_points(cell, rng.random((40000 * sub.num, sub.tdim)))
    counts = np.bincount(sub.index(x), minlength=sub.num)
    assert np.all(np.abs(counts / 40000 - 1.0) < 0.03)  # ~5 standard deviations
    which = rng.integers(0, sub.num, 2000)
    inside = sub.sample(which, uniform_reference_points(cell, rng.random((2000, sub.tdim))))
    assert np.array_equal(sub.index(inside), which)


def _brute_density(swarm, bandwidth):
    """rho at each particle from every particle of its cell and the cells sharing a vertex with it."""
    mesh = swarm.mesh
    c2v = mesh.topology.connectivity(2, 0)
    verts = [set(c2v.links(c)) for c in range(swarm.num_owned_cells)]
    nodes = mesh.geometry.x[:, :2]
    out = np.empty(swarm.num_particles)
    for p in range(swarm.num_particles):
        c = swarm.cells[p]
        corners = nodes[list(verts[c])]
        diam = max(np.linalg.norm(a - b) for a in corners for b in corners)
        h = bandwidth * diam / np.sqrt(2)
        near = np.array([bool(verts[c] & verts[k]) for k in swarm.cells])
        d2 = ((swarm.x[near] - swarm.x[p]) ** 2).sum(axis=1)
        out[p] = np.clip(1 - d2 / h ** 2, 0, None).sum()
    return out


def test_density_estimate_is_the_kernel_sum_over_the_cell_and_its_neighbours():
    swarm = _varying(MPI.COMM_SELF, n=4, num=300)
    rho = particle_density(swarm, 0.3)
    assert np.allclose(rho, _brute_density(swarm, 0.3), rtol=1e-13, atol=1e-13)
    assert np.all(rho >= 1.0)  # the particle's own kernel
    wide = particle_density(swarm, 0.6)
    assert np.all(wide >= rho) and wide.sum() > rho.sum()


def _cluster_and_spread(mesh):
    """In the lower-left triangle of a 1x1 mesh: 8 particles within 0.01 of (0.3, 0.1), 10 spread."""
    rng = np.random.default_rng(1)
    cluster = np.array([0.3, 0.1]) + 0.01 * (rng.random((8, 2)) - 0.5)
    spread = np.array([[0.15, 0.05], [0.45, 0.05], [0.6, 0.05], [0.75, 0.05], [0.9, 0.05], [0.5, 0.3],
                       [0.6, 0.3], [0.1, 0.4], [0.2, 0.6], [0.1, 0.8]])
    return np.concatenate([cluster, spread])


def test_the_most_clustered_particles_are_removed_first():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 1, 1, diagonal=dolfinx.mesh.DiagonalType.left)
    x = _cluster_and_spread(mesh)
    swarm = _placed(mesh, x)
    assert swarm.num_particles == 18 and swarm.particles_per_cell().max() == 18
    mask = removal_mask(swarm, Neighbourhood.of(swarm, 0.3), 11)
    assert np.count_nonzero(mask) == 7 and set(swarm.ids[mask]) <= set(range(8))  # 7 of the 8 in the cluster
    kept = set(range(8)) - set(swarm.ids[mask].tolist())
    stats = control_population(swarm, max_per_cell=11, method="density")
    assert stats.removed == 7 and set(swarm.ids.tolist()) == kept | set(range(8, 18))
    count = _placed(mesh, x)
    control_population(count, max_per_cell=11, seed=0, method="count")
    assert np.count_nonzero(count.ids < 8) > 1  # random removal leaves more than one of the cluster


def test_new_particles_fill_the_emptiest_region():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 1, 1, diagonal=dolfinx.mesh.DiagonalType.left)
    rng = np.random.default_rng(3)
    pts = rng.random((4000, 2)) * [0.3, 1.0]  # only the left 30 % of the square
    old = _placed(mesh, pts[pts[:, 1] < 1 - pts[:, 0]][:40])  # 40 in the lower-left triangle
    assert sorted(old.particles_per_cell().tolist()) == [0, 40]
    swarm = _placed(mesh, old.x.copy())
    stats = control_population(swarm, min_per_cell=52, method="density", seed=5)
    assert stats.added == 12 + 52
    cell = int(old.cells[0])
    new = (swarm.ids >= 40) & (swarm.cells == cell)
    # all in the empty part (a sub-cell reaching 0.05 into the strip at most)
    assert np.count_nonzero(new) == 12 and np.all(swarm.x[new, 0] > 0.25)
    random = _placed(mesh, old.x.copy())
    control_population(random, min_per_cell=52, method="count", seed=5)
    new_random = (random.ids >= 40) & (random.cells == cell)
    assert np.count_nonzero(random.x[new_random, 0] < 0.25) >= 2  # random addition also fills the full strip
    assert cell_scores(swarm, 2)[cell] < cell_scores(random, 2)[cell]


def test_score_of_known_spreads():
    # one cell, 4 buckets: even, all in one, half and half, none
    bucket = np.array([0, 1, 2, 3] * 2 + [2] * 8 + [0] * 4 + [1] * 4)
    cells = np.repeat([0, 1, 2], 8)
    s = scores_of_counts(bucket, cells, 4, 4)
    assert s[0] == 0.0 and s[1] == 1.0 and s[2] == pytest.approx(1.0 / 3.0, rel=1e-15) and s[3] == 1.0
    # a lattice of one particle per sub-cell centroid in every cell scores 0; a cluster at a corner 1
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 3, 3)
    maps = CellMaps(mesh)
    sub = SubCells(maps.basix_cell, 2)
    m = maps.cells.shape[0]
    lattice = maps.push(np.repeat(np.arange(m), sub.num), np.tile(sub.centroids, (m, 1)))
    swarm = _placed(mesh, lattice)
    assert swarm.num_particles == m * sub.num
    assert np.all(cell_scores(swarm, 2) == 0.0)
    score = distribution_score(swarm, 2)
    assert (score.min, score.mean, score.max, score.std) == (0.0, 0.0, 0.0, 0.0)
    corner = maps.push(np.repeat(np.arange(m), 5), np.tile([[0.02, 0.03]], (5 * m, 1)))
    clustered = _placed(mesh, corner)
    assert np.all(cell_scores(clustered, 2) == 1.0)
    random = Swarm(mesh)
    generate(random, "random_uniform", num_particles=20 * m, seed=1)
    r = distribution_score(random, 2)
    assert 0.0 < r.min <= r.mean <= r.max < 1.0 and r.std > 0.0
    assert r.mean == pytest.approx(1.0 / 20.0, rel=0.5)  # E[S] = 1/n for n uniform particles


def test_density_method_keeps_the_bounds_and_counts_of_the_count_method():
    a, b = _varying(MPI.COMM_SELF), _varying(MPI.COMM_SELF)
    sa = control_population(a, min_per_cell=8, max_per_cell=16, seed=3, step=2, method="count")
    sb = control_population(b, min_per_cell=8, max_per_cell=16, seed=3, step=2, method="density")
    assert (sa.added, sa.removed) == (sb.added, sb.removed) and sb.added > 0 and sb.removed > 0
    assert np.array_equal(a.particles_per_cell(), b.particles_per_cell())
    assert b.particles_per_cell().min() >= 8 and b.particles_per_cell().max() <= 16
    new = b.ids >= 900
    assert np.array_equal(np.sort(b.ids[new]), 900 + np.arange(sb.added))
    assert np.all(np.isfinite(b.property("tag")))
    b.check_invariants()
    assert distribution_score(b, 2).mean < distribution_score(a, 2).mean
    with pytest.raises(ValueError, match="method"):
        PopulationControl(method="kde")
    with pytest.raises(ValueError, match="bandwidth"):
        PopulationControl(method="density", bandwidth=0.0)


def _gathered(comm, swarm, values):
    """Ids and ``values`` (rows per particle) of all ranks of ``comm``, sorted by id."""
    ids = np.concatenate(comm.allgather(swarm.ids))
    order = np.argsort(ids)
    return ids[order], np.concatenate(comm.allgather(values))[order]


@pytest.mark.mpi
def test_density_method_and_score_are_rank_count_independent():
    """The estimate, the particles after removal and addition, and the score: the same bits on the
    ranks of COMM_WORLD as on one rank (global checks)."""
    comm = MPI.COMM_WORLD
    results = []
    for c in (comm, MPI.COMM_SELF):
        swarm = _varying(c)
        rho = _gathered(c, swarm, particle_density(swarm, 0.3))
        stats = control_population(swarm, min_per_cell=8, max_per_cell=16, seed=3, step=1, method="density")
        ids, x = _gathered(c, swarm, swarm.x)
        tags = _gathered(c, swarm, swarm.property("tag"))[1]
        results.append((rho, (stats.global_added, stats.global_removed), ids, x, tags, distribution_score(swarm, 2)))
    par, ser = results
    same = all(np.array_equal(a, b) for a, b in zip(par[0], ser[0])) and par[1] == ser[1] and par[1][0] > 0 \
        and par[1][1] > 0 and all(np.array_equal(a, b) for a, b in zip(par[2:5], ser[2:5])) and par[5] == ser[5]
    assert comm.allreduce(bool(same), op=MPI.LAND)


def test_the_score_postprocessor_is_registered_and_only_on_request():
    from convection.postprocess.postprocessors import POSTPROCESSORS, ParticleDistribution

    assert POSTPROCESSORS.lookup("particle_distribution") is ParticleDistribution
    assert ParticleDistribution.by_default(None) is False
    assert ParticleDistribution.columns[0] == "distribution_score"
