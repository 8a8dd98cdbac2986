"""The quadratic least-squares interpolator (particles/interpolation/quadratic_least_squares.py):
a quadratic is reproduced exactly in every cell with enough particles; a smooth field's L2 error
falls at third order with the cell size (the linear fit's at second); the limiter keeps each
cell's values within its particles' range; cells with too few particles take the linear fit."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl

from fembase.dolfinx_compat import function_space
from particles import Swarm
from particles.generation import generate
from particles.interpolation import interpolate_to_mesh
from particles.interpolation.quadratic_least_squares import monomials


def _swarm(n: int, per_cell: int, f, seed: int = 3) -> Swarm:
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, n, n)
    swarm = Swarm(mesh)
    generate(swarm, "random_uniform", num_particles=per_cell * 2 * n * n, seed=seed)
    swarm.add_property("v")
    swarm.property("v")[:, 0] = f(swarm.x)
    return swarm


def _quadratic(x):
    return 1.0 + 2.0 * x[:, 0] - x[:, 1] + 3.0 * x[:, 0] ** 2 - 4.0 * x[:, 0] * x[:, 1] + 0.5 * x[:, 1] ** 2


def _smooth(x):
    return np.sin(3.0 * x[:, 0]) * np.cos(2.0 * x[:, 1])


def _l2_error(u, exact) -> float:
    x = ufl.SpatialCoordinate(u.function_space.mesh)
    form = dolfinx.fem.form((u - exact(x)) ** 2 * ufl.dx)
    return float(np.sqrt(dolfinx.fem.assemble_scalar(form)))


def test_monomials_of_degree_two():
    xi = np.array([[2.0, 3.0]])
    assert np.allclose(monomials(xi), [[1.0, 2.0, 3.0, 4.0, 6.0, 9.0]])
    assert monomials(np.zeros((1, 3))).shape == (1, 10)


def test_a_quadratic_is_reproduced_in_every_cell():
    swarm = _swarm(6, 20, _quadratic)
    u = dolfinx.fem.Function(function_space(swarm.mesh, "DG", 2))
    stats = interpolate_to_mesh(swarm, "v", u, method="quadratic_least_squares")
    assert stats.method == "quadratic_least_squares" and stats.empty_cells == 0
    points = u.function_space.tabulate_dof_coordinates()[:, :2]
    assert np.allclose(u.x.array, _quadratic(points), atol=1e-10)


def test_third_order_for_a_smooth_field():
    """20 particles per cell on 4, 8 and 16 squares a side: the quadratic fit's L2 error falls
    about 8 times a halving, the linear fit's about 4 times."""
    errors = {"quadratic_least_squares": [], "least_squares": []}
    for n in (4, 8, 16):
        swarm = _swarm(n, 20, _smooth)
        for method, degree in (("quadratic_least_squares", 2), ("least_squares", 1)):
            u = dolfinx.fem.Function(function_space(swarm.mesh, "DG", degree))
            interpolate_to_mesh(swarm, "v", u, method=method)
            errors[method].append(_l2_error(u, lambda x: ufl.sin(3.0 * x[0]) * ufl.cos(2.0 * x[1])))
    orders = {m: np.log2(np.asarray(e[:-1]) / np.asarray(e[1:])) for m, e in errors.items()}
    assert np.all(orders["quadratic_least_squares"] > 2.6), orders
    assert np.all(orders["least_squares"] > 1.6), orders
    assert errors["quadratic_least_squares"][-1] < 0.2 * errors["least_squares"][-1]


def test_the_limiter_keeps_each_cells_range():
    step = lambda x: np.where(x[:, 0] > 0.45, 1.0, 0.0)  # noqa: E731 - a jump inside cells
    swarm = _swarm(5, 20, step)
    u = dolfinx.fem.Function(function_space(swarm.mesh, "DG", 2))
    interpolate_to_mesh(swarm, "v", u, method="quadratic_least_squares", limit=True)
    assert u.x.array.min() >= -1e-12 and u.x.array.max() <= 1.0 + 1e-12
    free = dolfinx.fem.Function(function_space(swarm.mesh, "DG", 2))
    interpolate_to_mesh(swarm, "v", free, method="quadratic_least_squares")
    assert free.x.array.min() < -1e-3 or free.x.array.max() > 1.0 + 1e-3  # without it, over- and undershoots


def test_cells_with_too_few_particles_take_the_linear_fit():
    linear = lambda x: 4.0 + 2.0 * x[:, 0] - 3.0 * x[:, 1]  # noqa: E731
    swarm = _swarm(6, 4, linear)  # 4 per cell: fewer than the 6 monomials
    u = dolfinx.fem.Function(function_space(swarm.mesh, "DG", 2))
    interpolate_to_mesh(swarm, "v", u, method="quadratic_least_squares")
    points = u.function_space.tabulate_dof_coordinates()[:, :2]
    assert np.allclose(u.x.array, linear(points), atol=1e-10)


def test_the_config_asks_for_dg2():
    from convection.config.loader import load_config
    from convection.schema import ConfigError
    from _runs import CONFIGS

    with pytest.raises(ConfigError, match="composition.degree"):
        load_config(CONFIGS / "rayleigh_taylor_3.yaml", ["particles.interpolator={name: quadratic_least_squares}"])
    config = load_config(CONFIGS / "rayleigh_taylor_3.yaml", ["particles.interpolator={name: quadratic_least_squares}",
                                                             "composition.degree=2"])
    assert config["particles"]["interpolator"]["name"] == "quadratic_least_squares"


def test_a_config_run_with_the_quadratic_fit(tmp_path):
    """configs/rayleigh_taylor_3.yaml with its materials on DG2 fields from the quadratic fit, on 2
    ranks: it runs, no particle lost, the same particles as on 1 rank."""
    from _runs import CONFIGS, rows, run_on_ranks

    extra = ["particles.interpolator={name: quadratic_least_squares, limit: true}", "composition.degree=2",
             "mesh.cells=[12,12]", "time.end=60", "output.progress=none", "output.fields_every=0",
             "particles.output=null"]
    runs = run_on_ranks(CONFIGS / "rayleigh_taylor_3.yaml", {1: tmp_path / "1", 2: tmp_path / "2"}, extra)
    a, b = rows(runs[1]), rows(runs[2])
    assert len(a) == len(b) > 2 and all(r["n_lost"] == "0" for r in a + b)
    for x, y in zip(a, b):
        assert x["n_particles"] == y["n_particles"]
        assert float(y["vrms"]) == pytest.approx(float(x["vrms"]), rel=1e-6)
