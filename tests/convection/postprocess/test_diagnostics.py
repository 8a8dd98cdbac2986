"""Diagnostics and CFL time step: exact values on representable fields, Nusselt consistency,
serial == parallel."""

from __future__ import annotations

import math

import numpy as np
import pytest
import dolfinx
from mpi4py import MPI

from convection.physics.approximation import BoussinesqApproximation
from convection.geometry.boundary import TemperatureBC
from convection.postprocess.diagnostics import SUPPORT, nusselt, on_support, temperature_stats, vrms
from convection.solvers.timestep import cfl_timestep
from convection.solvers.transport import TransportSolver
from fembase.dolfinx_compat import function_space


def _vector_p2(mesh):
    return function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))


def _rectangle(comm=MPI.COMM_WORLD, n=8):
    return dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [2 * n, n])


def test_vrms_of_quadratic_field_is_exact():
    """u = (x, -y) on [0,2]x[0,1]: int |u|^2 = 8/3 + 2/3, volume 2 -> vrms = sqrt(5/3)."""
    u = dolfinx.fem.Function(_vector_p2(_rectangle()))
    u.interpolate(lambda x: np.vstack([x[0], -x[1]]))
    assert abs(vrms(u) - math.sqrt(5.0 / 3.0)) < 1e-13


def test_vrms_3d():
    """u = (z, 0, x y) on the unit cube: int = 1/3 + 1/9 -> vrms = sqrt(4/9) = 2/3."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2)
    u = dolfinx.fem.Function(_vector_p2(mesh))
    u.interpolate(lambda x: np.vstack([x[2], np.zeros(x.shape[1]), x[0] * x[1]]))
    assert abs(vrms(u) - 2.0 / 3.0) < 1e-13


def test_temperature_stats_exact():
    mesh = _rectangle()
    V = function_space(mesh, "Lagrange", 2)
    T = dolfinx.fem.Function(V)
    T.interpolate(lambda x: x[0] + 2 * x[1] ** 2)
    stats = temperature_stats(T)
    # mean = (int x + 2 y^2) / 2 = (2 + 4/3) / 2
    assert abs(stats.mean - 5.0 / 3.0) < 1e-13
    assert abs(stats.min - 0.0) < 1e-14 and abs(stats.max - 4.0) < 1e-14


def _conduction_solver(mesh, height, comm_steps=0):
    bcs = {"bottom": TemperatureBC("dirichlet", 1.0), "top": TemperatureBC("dirichlet", 0.0)}
    energy = TransportSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=bcs)
    gdim = mesh.geometry.dim
    energy.set_initial(lambda x: 1.0 - x[gdim - 1] / height)
    return energy


@pytest.mark.parametrize("steps", [0, 2])
def test_nusselt_of_conduction_is_one(steps):
    mesh = _rectangle()
    energy = _conduction_solver(mesh, 1.0)
    u = dolfinx.fem.Function(_vector_p2(mesh))
    for _ in range(steps):
        energy.step(u, 0.1)
    assert abs(nusselt(energy, u, "top") - 1.0) < 1e-12
    assert abs(nusselt(energy, u, "bottom") - 1.0) < 1e-12


def test_nusselt_of_conduction_is_one_3d_box():
    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0.0, 0.0, 0.0], [1.5, 1.0, 2.0]], [3, 2, 4])
    energy = _conduction_solver(mesh, 2.0)
    u = dolfinx.fem.Function(_vector_p2(mesh))
    assert abs(nusselt(energy, u, "top") - 1.0) < 1e-12
    assert abs(nusselt(energy, u, "bottom") - 1.0) < 1e-12


def _cellular_steady_state(comm, n=12):
    """Steady temperature in the unit square under the prescribed cell u = curl(A sin(pi x)
    sin(pi z)); returns (energy solver, velocity)."""
    mesh = dolfinx.mesh.create_unit_square(comm, n, n)
    bcs = {"bottom": TemperatureBC("dirichlet", 1.0), "top": TemperatureBC("dirichlet", 0.0)}
    energy = TransportSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=bcs)
    energy.set_initial(lambda x: 1.0 - x[1])
    u = dolfinx.fem.Function(_vector_p2(mesh))
    amp = 20.0
    u.interpolate(lambda x: np.vstack([amp * np.pi * np.sin(np.pi * x[0]) * np.cos(np.pi * x[1]),
                                       -amp * np.pi * np.cos(np.pi * x[0]) * np.sin(np.pi * x[1])]))
    for _ in range(4):
        energy.step(u, 100.0)
    return energy, u


def test_nusselt_top_equals_bottom_at_steady_state():
    """Heat in through the bottom equals heat out through the top at steady state (the
    consistent fluxes are exactly conservative up to the interpolated velocity's divergence)."""
    energy, u = _cellular_steady_state(MPI.COMM_WORLD)
    nu_top, nu_bottom = nusselt(energy, u, "top"), nusselt(energy, u, "bottom")
    assert nu_top > 2.0
    assert abs(nu_top - nu_bottom) < 1e-3 * nu_top


@pytest.mark.mpi
@pytest.mark.parametrize("side", ["top", "bottom"])
def test_flux_on_support_is_the_whole_mesh_value(side):
    """The consistent flux integrated over the cells where its test function lives equals, to the
    last digit, the one over every cell (the others add exact zeros), on a fraction of the cells."""
    energy, u = _cellular_steady_state(MPI.COMM_WORLD)
    w = dolfinx.fem.Function(energy.V)
    w.x.array[energy.domain.locate_dofs(energy.V, side)] = 1.0
    full = energy.last_step_residual(u, w)
    restricted = on_support(full, w)
    values = [energy.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(f)), op=MPI.SUM)
              for f in (full, restricted)]
    assert values[0] == values[1] and values[0] != 0.0
    tags = [i.subdomain_data() for i in restricted.integrals() if i.integral_type() == "cell"]
    assert tags and all(i.subdomain_id() == SUPPORT for i in restricted.integrals() if i.integral_type() == "cell")
    tagged = energy.mesh.comm.allreduce(tags[0].indices.size, op=MPI.SUM)
    cells = energy.mesh.topology.index_map(2).size_global
    assert 0 < tagged <= cells // 4  # the cells along one side of 12 x 12


def test_cfl_timestep():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    u = dolfinx.fem.Function(_vector_p2(mesh))
    assert cfl_timestep(u, 0.5) == math.inf
    assert cfl_timestep(u, 0.5, dt_max=0.3) == 0.3
    u.interpolate(lambda x: np.vstack([np.full(x.shape[1], 2.0), np.zeros(x.shape[1])]))
    # shortest edge 1/4, degree 2, |u| = 2: dt = cfl * (1/4) / (2 * 2)
    assert abs(cfl_timestep(u, 0.5) - 0.5 / 16) < 1e-14
    assert cfl_timestep(u, 0.5, dt_max=0.01) == 0.01
    with pytest.raises(ValueError):
        cfl_timestep(u, 0.0)


@pytest.mark.mpi
def test_diagnostics_parallel_equal_serial():
    results = {}
    for name, comm in (("world", MPI.COMM_WORLD), ("self", MPI.COMM_SELF)):
        energy, u = _cellular_steady_state(comm)
        stats = temperature_stats(energy.T)
        results[name] = np.array([vrms(u), nusselt(energy, u, "top"), nusselt(energy, u, "bottom"),
                                  stats.mean, stats.min, stats.max, cfl_timestep(u, 1.0)])
    assert np.allclose(results["world"], results["self"], rtol=1e-8, atol=1e-12), results
