"""A reference state of physical parameters (issue 49): the thermal expansivity and heat capacity
with depth (:class:`~convection.physics.compressible.ReferenceProfile`), the adiabat and density
they give, what the solvers take of them, and the units pass (Di, T0, the profile) against a
nondimensional twin. Integrals over the mesh are global sums: the same on 1, 2 and 3 ranks."""

from __future__ import annotations

import math

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from scipy.integrate import quad

from convection.physics.approximation import BoussinesqApproximation
from convection.physics.compressible import NUMPY_OPS, ReferenceProfile, ReferenceState
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space
from test_compressible import FREE_SLIP, _integral

PROFILE = ReferenceProfile(depth=(0.0, 0.25, 1.0), thermal_expansivity=(1.0, 0.6, 0.3), heat_capacity=(1.0, 1.0, 1.3))
"""alpha_r falls to 0.3, cp_r rises to 1.3: both branches of the integral (a constant and a sloped cp_r)."""


@pytest.fixture(scope="module")
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)


def _ratio(profile: ReferenceProfile, d: float) -> float:
    return float(profile.value("thermal_expansivity", d, NUMPY_OPS) / profile.value("heat_capacity", d, NUMPY_OPS))


@pytest.mark.parametrize("profile", [PROFILE, ReferenceProfile(depth=(0.1, 0.5, 0.9), heat_capacity=(1.0, 1.0002, 0.7)),
                                     ReferenceProfile(depth=(0.0, 1.0), thermal_expansivity=(2.0, 1.0))])
def test_integral_of_alpha_over_cp_is_exact(profile):
    """I(d) = int_0^d alpha_r / cp_r against adaptive quadrature, above, inside and below the rows
    (the second profile's first interval takes the series for a nearly constant cp_r)."""
    for d in (0.05, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0, 1.4):
        exact, _ = quad(lambda s: _ratio(profile, s), 0.0, d, points=[p for p in profile.depth if p < d],
                        epsabs=1e-14, epsrel=1e-13)
        assert float(profile.integral(np.asarray(d), NUMPY_OPS)) == pytest.approx(exact, rel=1e-11), d


def test_constant_profile_is_king_et_al(mesh):
    """alpha_r = cp_r = 1 as a table gives King et al.'s closed forms (their integrals over the square)."""
    ones = ReferenceState(Di=0.5, gruneisen=2.0, surface_temperature=0.091,
                          profile=ReferenceProfile(depth=(0.0, 1.0), thermal_expansivity=(1.0, 1.0)))
    depth = 1.0 - ufl.SpatialCoordinate(mesh)[1]
    assert _integral(mesh, ones.density(depth)) == pytest.approx(4.0 * (math.exp(0.25) - 1.0), rel=1e-10)
    assert _integral(mesh, ones.adiabat(depth)) == pytest.approx(0.091 * ((math.exp(0.5) - 1.0) / 0.5 - 1.0), rel=1e-10)


def test_adiabat_and_density_follow_the_adiabatic_gradients(mesh):
    """d ln(T_ad + T0) / dd = Di alpha_r / cp_r (the adiabat from the potential temperature) and
    d ln rho_r / dd = Di alpha_r / (gamma cp_r) (Adams-Williamson, K_S = gamma rho cp / alpha)."""
    ref = ReferenceState(Di=0.7, gruneisen=1.3, surface_temperature=0.091, potential_temperature=0.44, profile=PROFILE)
    d = np.linspace(0.02, 0.98, 25)
    h = 1e-6
    slope = (np.log(ref.adiabat_at(d + h) + 0.091) - np.log(ref.adiabat_at(d - h) + 0.091)) / (2 * h)
    assert np.allclose(slope, [0.7 * _ratio(PROFILE, x) for x in d], rtol=1e-7)
    assert ref.adiabat_at(0.0) == pytest.approx(0.44, rel=1e-15)
    depth = 1.0 - ufl.SpatialCoordinate(mesh)[1]
    for form, numbers in ((ref.density(depth), lambda s: math.exp(0.7 / 1.3 * PROFILE.integral(s, NUMPY_OPS))),
                          (ref.adiabat(depth), ref.adiabat_at)):
        exact, _ = quad(numbers, 0.0, 1.0, points=[0.25], epsabs=1e-13)
        assert _integral(mesh, form) == pytest.approx(exact, rel=1e-6)


def test_solvers_take_alpha_and_cp(mesh):
    """The buoyancy is Ra rho_r alpha_r T, the heat capacity rho_r cp_r, the adiabatic heating
    Di alpha_r rho_r w (T + T0), the ALA's compressibility times alpha_r / cp_r (pointwise, at the
    quadrature points: integrals of the difference vanish)."""
    ref = ReferenceState(Di=0.5, surface_temperature=0.091, profile=PROFILE)
    approximation = BoussinesqApproximation(Ra=1e4, formulation="ala", reference=ref)
    x = ufl.SpatialCoordinate(mesh)
    depth = 1.0 - x[1]
    T, u = 1.0 - x[1], ufl.as_vector((x[1] * (1 - x[1]), x[0] * (1 - x[0])))
    alpha, cp = PROFILE.value("thermal_expansivity", depth), PROFILE.value("heat_capacity", depth)
    rho = ref.density(depth)
    terms = approximation.energy_terms(T, T, u, x)
    adiabatic, _ = approximation.heating_rates(T, T, u, x)
    checks = [(approximation.buoyancy(T, None, 2, x=x)[1], 1e4 * rho * alpha * T), (terms.capacity, rho * cp),
              (adiabatic, 0.5 * alpha * rho * u[1] * (T + 0.091)),
              (approximation.pressure_buoyancy(x), 0.5 * rho * alpha / cp)]
    for ours, expected in checks:
        assert abs(_integral(mesh, (ours - expected) ** 2)) < 1e-24 * _integral(mesh, expected ** 2)
    assert _integral(mesh, alpha) < 0.7  # alpha_r does fall with depth


def test_tala_with_a_profile_golden(mesh):
    """A TALA Stokes solve with the profile at 8 x 8: mass is conserved against rho_r (the discrete
    div(rho_r u) vanishes against the pressure space, div u does not), and vrms, a golden number,
    is the same on any rank count (global sums)."""
    ref = ReferenceState(Di=0.5, surface_temperature=0.091, profile=PROFILE)
    approximation = BoussinesqApproximation(Ra=1e4, formulation="tala", reference=ref)
    stokes = StokesSolver(mesh, approximation, bcs=FREE_SLIP, solver="direct")
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(lambda p: 1.0 - p[1] + 0.1 * np.cos(np.pi * p[0]) * np.sin(np.pi * p[1]))
    stokes.solve(T)
    x = ufl.SpatialCoordinate(mesh)
    rho = ref.density(1.0 - x[1])
    vrms = math.sqrt(_integral(mesh, ufl.inner(stokes.u, stokes.u)))
    def tested(q, flux):  # with the quadrature UFL estimates, as the solver's continuity form
        return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(q * flux * ufl.dx)), op=MPI.SUM)

    q = dolfinx.fem.Function(function_space(mesh, "Lagrange", 1))  # in the pressure space
    q.interpolate(lambda p: p[1] ** 2 * (1.0 + p[0]))
    assert abs(tested(q, ufl.div(rho * stokes.u))) < 1e-10 * vrms  # div(rho_r u) vanishes against it,
    assert abs(tested(q, ufl.div(stokes.u))) > 1e-3 * vrms  # div u does not
    assert vrms == pytest.approx(GOLDEN_VRMS, rel=1e-9)


GOLDEN_VRMS = 10.614990105458036
"""TALA with PROFILE, Di = 0.5, Ra = 1e4, 8 x 8, MUMPS, on 1 rank (2026-12-07)."""


@pytest.mark.parametrize("kwargs, message", [
    ({"depth": (0.0, 1.0), "thermal_expansivity": (1.0,)}, "2 depth"),
    ({"depth": (0.0, 0.5, 0.4), "heat_capacity": (1.0, 1.0, 1.0)}, "must increase"),
    ({"depth": (0.0, 1.0), "heat_capacity": (1.0, 0.0)}, "must be positive"),
    ({"depth": (-0.1, 1.0), "heat_capacity": (1.0, 1.0)}, "above the surface"),
    ({"depth": (0.0, 1.0)}, "neither"),
    ({"thermal_expansivity": (1.0, 1.0)}, "0 depth"),
])
def test_bad_profiles_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ReferenceProfile(**kwargs)
