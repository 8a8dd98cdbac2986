"""The compressible approximations (EBA, TALA): reference state, what the solvers ask, and the
discrete invariants of the TALA Stokes problem (global sums: the same on any number of ranks)."""

from __future__ import annotations

import math

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from convection.geometry.boundary import VelocityBC
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.physics.compressible import APPROXIMATIONS, ReferenceState, shear_heating
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space

FREE_SLIP = {side: VelocityBC("free_slip") for side in ("left", "right", "bottom", "top")}


def _integral(mesh, expr) -> float:
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * ufl.dx(domain=mesh, metadata={"quadrature_degree": 8})))
    return mesh.comm.allreduce(local, op=MPI.SUM)


@pytest.fixture(scope="module")
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)


def test_reference_state_of_king_et_al(mesh):
    """rho_r = exp(Di d / gamma): 1 at the top, exp(Di / gamma) at the bottom; the adiabat rises
    from 0 by T0 (exp(Di) - 1); its mean over the unit square is gamma / Di (exp(Di / gamma) - 1)."""
    ref = ReferenceState(Di=0.5, gruneisen=2.0, surface_temperature=0.091)
    depth = 1.0 - ufl.SpatialCoordinate(mesh)[1]
    assert _integral(mesh, ref.density(depth)) == pytest.approx(4.0 * (math.exp(0.25) - 1.0), rel=1e-10)
    assert _integral(mesh, ref.adiabat(depth)) == pytest.approx(0.091 * ((math.exp(0.5) - 1.0) / 0.5 - 1.0), rel=1e-10)
    for wrong in ({"Di": -0.1}, {"gruneisen": 0.0}, {"surface_temperature": -1.0}):
        with pytest.raises(ValueError):
            ReferenceState(**wrong)


def test_each_approximation_says_what_it_changes():
    assert [(f.name, f.dissipation, f.reference_density) for f in APPROXIMATIONS.values()] == [
        ("boussinesq", False, False), ("eba", True, False), ("tala", True, True), ("ala", True, True)]
    boussinesq = BoussinesqApproximation(Ra=1e4)
    x = ufl.SpatialCoordinate(dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 1, 1))
    assert boussinesq.continuity_density(x) is None and boussinesq.energy_terms(0.0, 0.0, None, x) is None
    assert not boussinesq.dissipates
    eba = BoussinesqApproximation(Ra=1e4, formulation="eba", reference=ReferenceState(Di=0.5))
    assert eba.dissipates and eba.continuity_density(x) is None
    assert eba.energy_terms(0.0, 0.0, ufl.as_vector((x[1], 0.0 * x[0])), x).capacity == 1.0


@pytest.mark.parametrize("kwargs, message", [
    ({"formulation": "boussinesq", "reference": ReferenceState(Di=0.5)}, "no dissipation number"),
    ({"formulation": "tala"}, "needs a dissipation number"),
    ({"formulation": "eba", "reference": ReferenceState(Di=0.5), "Ra": 0.0}, "needs Ra > 0"),
    ({"formulation": "tala", "reference": ReferenceState(Di=0.5),
      "viscosity": ViscosityLaw(material_viscosities=(1, 2))}, "temperature and depth only"),
    ({"formulation": "ala"}, "needs a dissipation number"),
    ({"formulation": "bla", "reference": ReferenceState(Di=0.5)}, "bla"),
])
def test_inconsistent_approximations_are_refused(kwargs, message):
    with pytest.raises((ValueError, KeyError), match=message):
        BoussinesqApproximation(**{"Ra": 1e4, **kwargs})


def test_shear_heating_is_deviatoric(mesh):
    """Phi = 2 eta (eps : eps - (div u)^2 / 3): u = (x, y) has eps = I, div u = 2, Phi = 2 (2 - 4/3);
    the simple shear u = (y, 0) has eps : eps = 1/2, div u = 0, Phi = 2 eta / 2."""
    x = ufl.SpatialCoordinate(mesh)
    assert _integral(mesh, shear_heating(1.0, ufl.as_vector((x[0], x[1])))) == pytest.approx(4.0 / 3.0, rel=1e-12)
    assert _integral(mesh, shear_heating(2.0, ufl.as_vector((x[1], 0.0)))) == pytest.approx(2.0, rel=1e-12)


def _tala_flow(mesh, formulation: str, Di: float):
    approximation = BoussinesqApproximation(Ra=1e4, formulation=formulation,
                                            reference=ReferenceState(Di=Di, surface_temperature=0.091))
    stokes = StokesSolver(mesh, approximation, bcs=FREE_SLIP, solver="direct")
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(lambda p: 1.0 - p[1] + 0.1 * np.cos(np.pi * p[0]) * np.sin(np.pi * p[1]))
    stokes.solve(T)
    return approximation, stokes, T


@pytest.mark.parametrize("formulation", ["eba", "tala"])
def test_continuity_holds_against_every_pressure_test_function(mesh, formulation):
    """TALA: (q, div(rho_r u)) = 0 for every q in the pressure space (z among them: int rho_r w = 0),
    but (q, div u) is not; EBA the other way round."""
    _, stokes, _ = _tala_flow(mesh, formulation, 1.0)
    x = ufl.SpatialCoordinate(mesh)
    rho = ReferenceState(Di=1.0).density(1.0 - x[1])
    q = dolfinx.fem.Function(stokes.Q)
    q.interpolate(lambda p: np.sin(3.0 * p[0]) * np.cos(2.0 * p[1]) + p[0] * p[1])
    scale = _integral(mesh, abs(ufl.div(stokes.u)))
    kept, broken = _integral(mesh, ufl.div(rho * stokes.u) * q), _integral(mesh, ufl.div(stokes.u) * q)
    if formulation == "eba":
        kept, broken = broken, kept
    assert abs(kept) < 1e-10 * scale
    assert abs(broken) > 1e-3 * scale
    assert abs(_integral(mesh, (rho if formulation == "tala" else 1.0) * stokes.u[1])) < 1e-10 * scale


@pytest.mark.parametrize("formulation", ["eba", "tala"])
def test_dissipation_is_buoyancy_work_plus_pressure_work(mesh, formulation):
    """Testing the momentum equation with the solution: int 2 eta eps:eps = int f . u + int p div u
    exactly; under EBA the pressure work vanishes (div u = 0 weakly), under TALA it does not."""
    approximation, stokes, T = _tala_flow(mesh, formulation, 0.5)
    x = ufl.SpatialCoordinate(mesh)
    u, p = stokes.u, stokes.p
    eps = ufl.sym(ufl.grad(u))
    dissipation = _integral(mesh, 2.0 * ufl.inner(eps, eps))
    buoyancy = _integral(mesh, ufl.dot(approximation.buoyancy(T, None, 2, x=x), u))
    pressure = _integral(mesh, p * ufl.div(u))
    assert dissipation == pytest.approx(buoyancy + pressure, rel=1e-9)
    if formulation == "eba":
        assert abs(pressure) < 1e-9 * dissipation
    else:
        assert abs(pressure) > 1e-3 * dissipation
