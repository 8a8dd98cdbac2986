"""The anelastic liquid approximation (ALA): TALA plus the dynamic pressure's buoyancy
``-(Di / gamma) (cp / cv) rho_r p e_up``. Its Stokes problem at 8 x 8: it tends to TALA linearly as the
term vanishes, the momentum equation tested with the solution closes, and the pressure's mode
(:class:`~convection.solvers.stokes.nullspace.PressureMode`) fixes the gauge whatever dof is pinned
(global sums and golden numbers: the same on 1, 2 and 3 ranks)."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from convection.physics.approximation import BoussinesqApproximation
from convection.physics.compressible import APPROXIMATIONS, ReferenceState, shear_heating
from convection.solvers.stokes.nullspace import PressureMode
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space
from test_compressible import FREE_SLIP, _integral


@pytest.fixture(scope="module")
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)


def _flow(mesh, formulation: str, ratio: float = 1.0, Di: float = 1.0):
    approximation = BoussinesqApproximation(Ra=1e4, formulation=formulation, reference=ReferenceState(
        Di=Di, surface_temperature=0.091, heat_capacity_ratio=ratio))
    stokes = StokesSolver(mesh, approximation, bcs=FREE_SLIP, solver="direct")
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(lambda p: 1.0 - p[1] + 0.1 * np.cos(np.pi * p[0]) * np.sin(np.pi * p[1]))
    stokes.solve(T)
    return approximation, stokes, T


def _velocity_difference(mesh, a, b) -> float:
    return np.sqrt(_integral(mesh, ufl.inner(a.u - b.u, a.u - b.u)) / _integral(mesh, ufl.inner(b.u, b.u)))


def test_ala_is_tala_with_the_pressure_buoyancy():
    ala = APPROXIMATIONS["ala"]
    assert (ala.dissipation, ala.reference_density, ala.pressure_buoyancy) == (True, True, True)
    assert not any(f.pressure_buoyancy for name, f in APPROXIMATIONS.items() if name != "ala")
    x = ufl.SpatialCoordinate(dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 1, 1))
    tala = BoussinesqApproximation(Ra=1e4, formulation="tala", reference=ReferenceState(Di=0.5))
    assert tala.pressure_buoyancy(x) is None
    with pytest.raises(ValueError, match="cp / cv"):
        ReferenceState(Di=0.5, heat_capacity_ratio=-1.0)


def test_ala_tends_to_tala_linearly(mesh):
    """The departure from cp / cv = 0 is linear in cp / cv; cp / cv = 0 is TALA but for the
    compressible stress's -(2/3) eta div u I, which TALA's pressure takes up (constant viscosity)
    and the discrete pressure nearly: their velocities differ by O(h^2)."""
    _, zero, _ = _flow(mesh, "ala", 0.0)
    small, double = (_velocity_difference(mesh, _flow(mesh, "ala", r)[1], zero) for r in (1e-3, 2e-3))
    assert small > 1e-6
    assert double / small == pytest.approx(2.0, rel=1e-2)
    assert _velocity_difference(mesh, _flow(mesh, "ala", 1.0)[1], zero) > 1e-2
    fine = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 16, 16)
    coarse_gap, fine_gap = (_velocity_difference(m, _flow(m, "ala", 0.0)[1], _flow(m, "tala")[1]) for m in (mesh, fine))
    assert coarse_gap < 1e-3
    assert fine_gap < coarse_gap / 3.5


def test_momentum_tested_with_the_solution_closes(mesh):
    """int Phi = int f . u + int p div u - int c p w, exactly, Phi = 2 eta (eps:eps - (div u)^2 / 3)
    the compressible stress's dissipation (the gauge moves along the operator's null vector, so the
    shifted solution still solves the system)."""
    approximation, stokes, T = _flow(mesh, "ala")
    x = ufl.SpatialCoordinate(mesh)
    u, p = stokes.u, stokes.p
    dissipation = _integral(mesh, shear_heating(1.0, u))
    buoyancy = _integral(mesh, ufl.dot(approximation.buoyancy(T, None, 2, x=x), u))
    pressure = _integral(mesh, p * ufl.div(u))
    compression = _integral(mesh, approximation.pressure_buoyancy(x) * p * u[1])
    assert dissipation == pytest.approx(buoyancy + pressure - compression, rel=1e-9)
    assert abs(compression) > 1e-3 * dissipation


def test_pressure_mode_and_gauge(mesh):
    """The mode p_0 follows the continuous one, exp((cp / cv) rho_r) (grad p_0 = -c p_0 e_up), to the
    discretisation; the solution has int p = 0; golden numbers at 8 x 8 hold on any rank count
    (a pinned gauge would not: the pinned dof is global dof 0, a different point per partition)."""
    _, stokes, _ = _flow(mesh, "ala")
    mode = stokes._pressure_mean
    assert isinstance(mode, PressureMode)
    x = ufl.SpatialCoordinate(mesh)
    exact = ufl.exp(ReferenceState(Di=1.0).density(1.0 - x[1]))
    scale = _integral(mesh, mode.p0 * exact) / _integral(mesh, exact * exact)
    misfit = np.sqrt(_integral(mesh, (mode.p0 - scale * exact) ** 2) / _integral(mesh, mode.p0 ** 2))
    assert misfit < 1e-2  # 4.4e-3 at 8 x 8
    assert abs(_integral(mesh, stokes.p)) < 1e-10 * np.sqrt(_integral(mesh, stokes.p ** 2))
    vrms = np.sqrt(_integral(mesh, ufl.inner(stokes.u, stokes.u)))
    assert vrms == pytest.approx(GOLDEN["vrms"], rel=1e-9)
    assert np.sqrt(_integral(mesh, stokes.p ** 2)) == pytest.approx(GOLDEN["p_rms"], rel=1e-9)


GOLDEN = {"vrms": 29.2241158197677, "p_rms": 3003.34002497495}
"""ALA, Di = 1, cp / cv = 1, 8 x 8, MUMPS, on 1 rank (2026-12-07)."""
