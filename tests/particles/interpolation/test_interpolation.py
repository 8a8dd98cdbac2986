"""Particle -> mesh interpolators: registry, exactness, means, empty cells, 1 rank vs N ranks."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from fembase.dolfinx_compat import cell_dofmap, function_space
from particles import Swarm
from particles.generation import generate
from particles.interpolation.fill import neighbour_sums
from particles.interpolation import (
    INTERPOLATORS,
    InterpolatorContext,
    LeastSquares,
    describe_interpolators,
    interpolate_to_mesh,
)

CASES = [
    ("nearest", ("DG", 0), {}),
    ("nearest", ("DG", 1), {}),
    ("cell_average", ("DG", 0), {"mean": "arithmetic"}),
    ("cell_average", ("DG", 0), {"mean": "geometric"}),
    ("cell_average", ("DG", 0), {"mean": "harmonic"}),
    ("distance_weighted", ("DG", 0), {}),
    ("distance_weighted", ("DG", 1), {"use_neighbours": True}),
    ("distance_weighted", ("Lagrange", 1), {"power": 3.0}),
    ("shape_function", ("Lagrange", 1), {}),
    ("shape_function", ("DG", 0), {}),
    ("shape_function", ("DG", 1), {}),
    ("least_squares", ("DG", 1), {}),
    ("least_squares", ("DG", 1), {"limit": True}),
    ("quadratic_least_squares", ("DG", 2), {}),
    ("quadratic_least_squares", ("DG", 2), {"limit": True}),
]


def _mesh(comm, n=6, ghost_mode=dolfinx.mesh.GhostMode.shared_facet):
    return dolfinx.mesh.create_unit_square(comm, n, n, ghost_mode=ghost_mode)


def _swarm(mesh, num, seed=1, f=lambda x: 4.0 + 2.0 * x[:, 0] - 3.0 * x[:, 1]):
    swarm = Swarm(mesh)
    generate(swarm, "random_uniform", num_particles=num, seed=seed)
    swarm.add_property("v")
    swarm.property("v")[:, 0] = f(swarm.x)
    return swarm


def _linear(x):
    return 4.0 + 2.0 * x[:, 0] - 3.0 * x[:, 1]


def _owned_dofs_table(u, num_owned_cells):
    """Rows [cell midpoint, dof point, value] for every dof of every owned cell."""
    V = u.function_space
    mesh = V.mesh
    gdim = mesh.geometry.dim
    dofs = cell_dofmap(V)[:num_owned_cells]
    mid = dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim, np.arange(num_owned_cells, dtype=np.int32))[:, :gdim]
    pts = V.tabulate_dof_coordinates()[:, :gdim]
    k = dofs.shape[1]
    return np.concatenate([np.repeat(mid, k, axis=0), pts[dofs.reshape(-1)], u.x.array[dofs.reshape(-1)][:, None]],
                          axis=1)


def _sorted_rows(table, ncols_key):
    key = np.round(table[:, :ncols_key], 9)
    return table[np.lexsort(key.T[::-1])]


# ----------------------------------------------------------------------------------- registry
def test_registry_and_errors():
    assert set(INTERPOLATORS) == {"nearest", "cell_average", "distance_weighted", "shape_function", "least_squares",
                                  "quadratic_least_squares"}
    assert all(name == name.lower() and text for name, text in describe_interpolators().items())
    with pytest.raises(ValueError, match="cell_average"):
        INTERPOLATORS.lookup("bilinear")
    with pytest.raises(ValueError, match="arithmetic"):
        INTERPOLATORS.settings("cell_average", mean="median")
    with pytest.raises(ValueError, match="^particle interpolator 'nearest' has no parameter 'mean'"):
        INTERPOLATORS.settings("nearest", mean="harmonic")
    made = INTERPOLATORS.build("least_squares", INTERPOLATORS.settings("least_squares", limit=True),
                               InterpolatorContext())
    assert made == LeastSquares(LeastSquares.Settings(limit=True)) and made.target_degree == 1
    mesh = _mesh(MPI.COMM_SELF, 2)
    swarm = _swarm(mesh, 40)
    swarm.add_property("vec", 2, 1.0)
    u = dolfinx.fem.Function(function_space(mesh, "DG", 0))
    with pytest.raises(ValueError, match="component"):
        interpolate_to_mesh(swarm, "vec", u)
    interpolate_to_mesh(swarm, "vec", u, component=1)
    assert np.allclose(u.x.array, 1.0)
    with pytest.raises(ValueError, match="continuous"):
        interpolate_to_mesh(swarm, "v", dolfinx.fem.Function(function_space(mesh, "Lagrange", 1)),
                            method="nearest")
    with pytest.raises(ValueError, match="positive"):
        swarm.property("v")[0] = -1.0
        interpolate_to_mesh(swarm, "v", u, mean="harmonic")


# ----------------------------------------------------------------------------------- exactness
@pytest.mark.parametrize("method,space,params", CASES)
def test_constant_reproduced(method, space, params):
    mesh = _mesh(MPI.COMM_SELF)
    swarm = _swarm(mesh, 400, f=lambda x: np.full(x.shape[0], 2.5))
    u = dolfinx.fem.Function(function_space(mesh, space))
    interpolate_to_mesh(swarm, "v", u, method=method, **params)
    assert np.max(np.abs(u.x.array - 2.5)) < 1e-12


def test_least_squares_reproduces_linear_in_every_cell():
    mesh = _mesh(MPI.COMM_SELF)
    swarm = _swarm(mesh, 300)  # ~4 per cell; thin out the left half: cells with 0-2 need the neighbour fit
    swarm.remove((swarm.x[:, 0] < 0.5) & (swarm.ids % 3 != 0))
    swarm.remove(np.isin(swarm.cells, [3, 20]))
    assert np.min(np.diff(swarm.offsets)) == 0
    V = function_space(mesh, "DG", 1)
    u = dolfinx.fem.Function(V)
    stats = interpolate_to_mesh(swarm, "v", u, method="least_squares")
    x = V.tabulate_dof_coordinates()[:, :2]
    assert np.max(np.abs(u.x.array - _linear(x))) < 1e-12
    assert stats.global_empty_cells == int(np.count_nonzero(np.diff(swarm.offsets) == 0))
    assert stats.global_filled_dofs == 0  # empty cells were fitted from their neighbours


def test_least_squares_limiter_stays_in_cell_range():
    mesh = _mesh(MPI.COMM_SELF)
    swarm = _swarm(mesh, 1500, f=lambda x: np.sin(6.0 * x[:, 0]) + x[:, 1] ** 2)
    V = function_space(mesh, "DG", 1)
    u = dolfinx.fem.Function(V)
    interpolate_to_mesh(swarm, "v", u, method="least_squares", limit=True)
    counts = np.diff(swarm.offsets)
    assert counts.min() >= 3
    v = swarm.property("v")[:, 0]
    lo = np.minimum.reduceat(v, swarm.offsets[:-1])
    hi = np.maximum.reduceat(v, swarm.offsets[:-1])
    dofs = cell_dofmap(V)[: swarm.num_owned_cells]
    vals = u.x.array[dofs]
    assert np.all(vals >= lo[:, None] - 1e-14) and np.all(vals <= hi[:, None] + 1e-14)
    unlimited = dolfinx.fem.Function(V)
    interpolate_to_mesh(swarm, "v", unlimited, method="least_squares")
    assert np.any(unlimited.x.array[dofs] > hi[:, None] + 1e-6)  # the limiter had work to do


def test_shape_function_linear_at_weighted_centroid_and_symmetric_layout():
    mesh = _mesh(MPI.COMM_SELF)
    swarm = _swarm(mesh, 500)
    swarm.add_property("px")
    swarm.add_property("py")
    swarm.property("px")[:, 0] = swarm.x[:, 0]
    swarm.property("py")[:, 0] = swarm.x[:, 1]
    V = function_space(mesh, "Lagrange", 1)
    u, cx, cy = (dolfinx.fem.Function(V) for _ in range(3))
    for name, f in (("v", u), ("px", cx), ("py", cy)):
        interpolate_to_mesh(swarm, name, f, method="shape_function")
    centroid = np.stack([cx.x.array, cy.x.array], axis=1)
    assert np.max(np.abs(u.x.array - _linear(centroid))) < 1e-12  # u_i = f(xbar_i) for any layout
    x = V.tabulate_dof_coordinates()[:, :2]
    assert np.max(np.abs(u.x.array - _linear(x))) > 1e-3  # ... but not f(x_i) for random particles
    sym = Swarm(mesh)
    generate(sym, "reference_points", kind="quadrature", degree=2)
    sym.add_property("v")
    sym.property("v")[:, 0] = _linear(sym.x)
    interpolate_to_mesh(sym, "v", u, method="shape_function")
    interior = np.all((x > 1e-9) & (x < 1 - 1e-9), axis=1)
    assert np.max(np.abs(u.x.array[interior] - _linear(x[interior]))) < 1e-12


def test_means_match_hand_computed_values():
    mesh = _mesh(MPI.COMM_SELF, 1)
    swarm = Swarm(mesh)
    swarm.add_property("v")
    centres = swarm.geometry.centres
    x = np.repeat(centres, 3, axis=0) + 0.01 * np.tile([[0, 0], [1, 0], [0, 1]], (2, 1))
    cells = np.repeat(np.arange(2, dtype=np.int32), 3)
    swarm.add(np.arange(6), x, swarm.geometry.pull_back(cells, x), cells,
              np.array([1.0, 2.0, 4.0, 3.0, 3.0, 12.0])[:, None])
    u = dolfinx.fem.Function(function_space(mesh, "DG", 0))
    expected = {"arithmetic": [7 / 3, 6.0], "geometric": [2.0, 108 ** (1 / 3)],
                "harmonic": [12 / 7, 3 / (2 / 3 + 1 / 12)]}
    for mean, values in expected.items():
        interpolate_to_mesh(swarm, "v", u, mean=mean)
        assert np.allclose(u.x.array, values, rtol=1e-14, atol=0), mean


@pytest.mark.parametrize("method,space,params", CASES)
def test_empty_cells_give_finite_values(method, space, params):
    mesh = _mesh(MPI.COMM_SELF)
    swarm = _swarm(mesh, 300)
    swarm.remove(swarm.x[:, 0] > 0.4)  # more than half the mesh empty: several fill rounds
    u = dolfinx.fem.Function(function_space(mesh, space))
    stats = interpolate_to_mesh(swarm, "v", u, method=method, **params)
    assert np.all(np.isfinite(u.x.array))
    assert stats.empty_cells == int(np.count_nonzero(np.diff(swarm.offsets) == 0)) > 0
    assert stats.filled_dofs > 0 and stats.fill_rounds >= 3
    lo, hi = swarm.property("v").min(), swarm.property("v").max()
    if not (method in ("least_squares", "quadratic_least_squares") and not params.get("limit")):  # fits extrapolate
        assert np.all(u.x.array >= lo - 1e-12) and np.all(u.x.array <= hi + 1e-12)
    empty = Swarm(mesh)
    empty.add_property("v")
    stats = interpolate_to_mesh(empty, "v", u, method=method, **params)
    assert np.all(u.x.array == 0.0) and stats.global_empty_cells == mesh.topology.index_map(2).size_global


def test_fill_rule_is_neighbour_average():
    mesh = _mesh(MPI.COMM_SELF, 4)
    swarm = _swarm(mesh, 0)
    geo = swarm.geometry
    cells = np.array([0], dtype=np.int32)
    swarm.add([7], geo.centres[cells], geo.pull_back(cells, geo.centres[cells]), cells, [[5.0]])
    u = dolfinx.fem.Function(function_space(mesh, "DG", 0))
    stats = interpolate_to_mesh(swarm, "v", u)
    assert np.allclose(u.x.array, 5.0) and stats.empty_cells == swarm.num_owned_cells - 1


def test_neighbour_sums_are_the_bits_of_bincount():
    """The empty-cell rule's kernel sums each cell's neighbours in the order of the vectorised
    ``np.bincount`` it replaced, so the filled values keep their bits; known cells are left alone."""
    rng = np.random.default_rng(3)
    n, halo = 200, 40
    counts = rng.integers(0, 30, n)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    nbrs = rng.integers(0, n + halo, offsets[-1]).astype(np.int32)
    values = rng.normal(size=n + halo) * 10.0 ** rng.integers(-8, 8, n + halo)
    weights = (rng.random(n + halo) < 0.6).astype(np.float64)
    known = rng.random(n) < 0.3
    rows = np.repeat(np.arange(n), counts)
    expected_s = np.bincount(rows, weights=values[nbrs] * weights[nbrs], minlength=n)
    expected_c = np.bincount(rows, weights=weights[nbrs], minlength=n)
    s, c = np.full(n, -1.0), np.full(n, -1.0)
    neighbour_sums(offsets, nbrs, values, weights, known, s, c)
    assert np.array_equal(s[~known], expected_s[~known]) and np.array_equal(c[~known], expected_c[~known])
    assert np.all(s[known] == -1.0) and np.all(c[known] == -1.0)


# ----------------------------------------------------------------------------------- MPI
PARALLEL_CASES = [
    ("nearest", ("DG", 0), {}),
    ("cell_average", ("DG", 0), {"mean": "harmonic"}),
    ("distance_weighted", ("DG", 1), {"use_neighbours": True}),
    ("distance_weighted", ("Lagrange", 1), {}),
    ("shape_function", ("Lagrange", 1), {}),
    ("least_squares", ("DG", 1), {"limit": True}),
    ("least_squares", ("DG", 1), {}),
    ("quadratic_least_squares", ("DG", 2), {}),
    ("quadratic_least_squares", ("DG", 2), {"limit": True}),
]


@pytest.mark.mpi
@pytest.mark.parametrize("ghost_mode", [dolfinx.mesh.GhostMode.shared_facet, dolfinx.mesh.GhostMode.none])
def test_parallel_equals_serial(ghost_mode):
    """Sparse particles (~3 per cell, a region left empty): neighbour fits, IDW over neighbours,
    P1 sums across ranks and empty-cell filling across rank boundaries all match one rank."""
    comm = MPI.COMM_WORLD

    def f(x):
        return 2.0 + np.sin(3.0 * x[:, 0]) * x[:, 1]

    results = []
    for c in (comm, MPI.COMM_SELF):
        mesh = _mesh(c, 10, ghost_mode=ghost_mode if c is comm else dolfinx.mesh.GhostMode.shared_facet)
        swarm = _swarm(mesh, 600, seed=5, f=f)
        swarm.remove((swarm.x[:, 0] - 0.5) ** 2 + (swarm.x[:, 1] - 0.5) ** 2 < 0.06)
        tables, stats = [], []
        for method, space, params in PARALLEL_CASES:
            u = dolfinx.fem.Function(function_space(mesh, space))
            st = interpolate_to_mesh(swarm, "v", u, method=method, **params)
            stats.append((st.global_empty_cells, st.global_filled_dofs, st.fill_rounds))
            t = _owned_dofs_table(u, swarm.num_owned_cells)
            t = np.concatenate(c.allgather(t)) if c is comm else t
            tables.append(_sorted_rows(t, 4))
        results.append((tables, stats))
    (par, par_stats), (ser, ser_stats) = results
    errors = [float(np.max(np.abs(p - s))) if p.shape == s.shape else np.inf for p, s in zip(par, ser)]
    ok = comm.allreduce(max(errors) < 1e-12 and par_stats == ser_stats, op=MPI.LAND)
    assert ok, (errors, par_stats, ser_stats)
    assert ser_stats[0][0] > 0  # the hole is empty: filling happened
