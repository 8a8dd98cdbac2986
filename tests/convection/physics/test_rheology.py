"""Viscosity laws (convection.physics.rheology): values against their formulas, config errors, and the
nonlinear Stokes solve (Picard and Newton) on a Tosi-like viscoplastic problem."""

from __future__ import annotations

import dataclasses
import math
import types

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.geometry.boundary import VelocityBC
from convection.config.loader import load_config
from convection.physics.rheology import (
    VISCOSITY_LAWS, FlowState, LawContext, build_law, law_settings, make_law, weakening_factor, yield_law,
)
from convection.schema import ConfigError
from convection.solvers.stokes.solver import StokesSolver
from convection.solvers.stokes.nonlinear import NonlinearSettings, NonlinearSolveError
from fembase.dolfinx_compat import function_space

# A uniform state: T, p constant; u = (a y, b x) has the constant strain rate [[0, c], [c, 0]],
# c = (a + b) / 2, so eps:eps = 2 c^2, eps_II = |c| and |eps| = sqrt(2) |c|.
T0, P0, A, B = 0.3, 0.7, 1.5, 0.5
C = (A + B) / 2


@pytest.fixture(scope="module")
def state():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    V = function_space(mesh, "Lagrange", 2, shape=(2,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([A * x[1], B * x[0]]))
    x = ufl.SpatialCoordinate(mesh)
    plastic = dolfinx.fem.Constant(mesh, 1.0)
    return mesh, plastic, FlowState(T=dolfinx.fem.Constant(mesh, T0), strain_rate=ufl.sym(ufl.grad(u)),
                                    pressure=dolfinx.fem.Constant(mesh, P0), depth=1.0 - x[1],
                                    fields={"plastic_strain": plastic}, gdim=2)


def mean(mesh, expression, degree: int = 12) -> float:
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": degree})
    value = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expression * dx))
    return mesh.comm.allreduce(value, op=MPI.SUM)


def law(spec):
    return build_law(spec, "physics.viscosity.law")


def test_values_follow_their_formulas(state):
    mesh, plastic, s = state
    depth_mean = 0.5  # mean of 1 - y
    gT, gz = math.log(1e5), math.log(10.0)
    # exponential: mean over the square of exp(-gT T + gz (1 - y)) = exp(-gT T) (e^gz - 1) / gz
    assert mean(mesh, law({"name": "exponential", "gamma_T": gT, "gamma_z": gz})(s)) == pytest.approx(
        math.exp(-gT * T0) * (math.exp(gz) - 1) / gz, rel=1e-6)
    # power law with n = 3 at eps_II = C, eps_ref = 0.5
    assert mean(mesh, law({"name": "power_law", "n": 3, "eta0": 2.0, "reference_strain_rate": 0.5})(s)) == \
        pytest.approx(2.0 * (C / 0.5) ** (-2.0 / 3.0), rel=1e-12)
    # von Mises, both strain-rate measures
    assert mean(mesh, law({"name": "von_mises", "yield_stress": 2.0, "eta_star": 0.1})(s)) == pytest.approx(
        0.1 + 2.0 / (2 * C), rel=1e-12)
    assert mean(mesh, law({"name": "von_mises", "yield_stress": 2.0, "strain_rate_measure": "norm"})(s)) == \
        pytest.approx(2.0 / (math.sqrt(2) * C), rel=1e-12)
    # Drucker-Prager in 2D: sigma_y = C cos phi + p sin phi
    phi = math.radians(30.0)
    assert mean(mesh, law({"name": "drucker_prager", "cohesion": 1.0, "friction_angle": 30.0})(s)) == \
        pytest.approx((math.cos(phi) + P0 * math.sin(phi)) / (2 * C), rel=1e-12)
    # Tosi's combination 2 / (1/eta_lin + 1/eta_plast) and ASPECT's minimum
    lin = {"name": "exponential", "gamma_T": gT}
    plast = {"name": "von_mises", "yield_stress": 1.0, "eta_star": 1e-3, "strain_rate_measure": "norm"}
    eta_lin = math.exp(-gT * T0)
    eta_plast = 1e-3 + 1.0 / (math.sqrt(2) * C)
    assert mean(mesh, law({"name": "viscoplastic", "viscous": lin, "plastic": plast})(s)) == pytest.approx(
        2 / (1 / eta_lin + 1 / eta_plast), rel=1e-12)
    assert mean(mesh, law({"name": "viscoplastic", "viscous": lin, "plastic": plast, "combination": "minimum"})(s)) \
        == pytest.approx(min(eta_lin, eta_plast), rel=1e-12)
    # composite creep and bounds
    assert mean(mesh, law({"name": "composite", "laws": [2.0, 3.0]})(s)) == pytest.approx(1.2, rel=1e-12)
    assert mean(mesh, law({"name": "constant", "eta0": 5.0, "max_viscosity": 2.0})(s)) == pytest.approx(2.0)
    assert mean(mesh, law({"name": "constant", "eta0": 5.0, "min_viscosity": 7.0})(s)) == pytest.approx(7.0)
    # Arrhenius is eta0 at T_ref and depth_ref
    arr = law({"name": "arrhenius", "E": 5.0, "V": 0.0, "T_offset": 0.5, "T_ref": T0})
    assert mean(mesh, arr(s)) == pytest.approx(1.0, rel=1e-12)
    # depth table: linear from factor 1 at depth 0 to 3 at depth 1: mean 2
    assert mean(mesh, law({"name": "depth_table", "table": [[0.0, 1.0], [1.0, 3.0]]})(s)) == pytest.approx(
        1.0 + 2.0 * depth_mean, rel=1e-12)


@pytest.mark.parametrize("e, expected", [(0.0, 2.0), (0.5, 2.0), (1.0, 2.0 * (1 - 0.75 * 0.5)), (1.5, 0.5), (9.0, 0.5)])
def test_strain_weakening_of_the_yield_stress(state, e, expected):
    """ASPECT's convention: the yield stress goes linearly from its value at e <= 0.5 to 0.25 x at e >= 1.5."""
    mesh, plastic, s = state
    plastic.value = e
    weak = law({"name": "von_mises", "yield_stress": 2.0,
                "weakening": {"field": "plastic_strain", "start": 0.5, "end": 1.5, "factor": 0.25}})
    assert weak.depends_on >= {"field:plastic_strain", "strain_rate"}
    assert mean(mesh, weak(s)) * 2 * C == pytest.approx(expected, rel=1e-12)
    assert weakening_factor(e, 0.5, 1.5, 0.25) * 2.0 == pytest.approx(expected, rel=1e-12)


def test_every_law_is_registered_with_a_description():
    assert {"constant", "exponential", "arrhenius", "depth_table", "power_law", "composite", "von_mises",
            "drucker_prager", "viscoplastic", "weakened", "damaged"} <= set(VISCOSITY_LAWS)
    for cls in VISCOSITY_LAWS.values():
        assert cls.description and "\n" not in cls.description


def test_every_law_is_a_plugin_of_the_one_shape():
    """A law declares its parameters once (``Settings``, fields made by ``param`` with their help:
    the config reference and ``check`` read them there) and is built through the registry."""
    for name, cls in VISCOSITY_LAWS.items():
        fields = dataclasses.fields(cls.Settings)
        assert fields and cls.Settings.__dataclass_params__.frozen, name
        assert all(f.metadata["schema"]["help"] for f in fields), name
        assert isinstance(cls.build, types.MethodType) and cls.build.__self__ is cls, name
    spec = {"name": "viscoplastic", "viscous": {"name": "composite", "laws": [2.0, {"name": "power_law", "n": 3}]},
            "plastic": {"name": "von_mises", "yield_stress": 1.0, "max_viscosity": 5.0}, "min_viscosity": 0.1}
    settings = law_settings(spec, "law")
    assert settings.settings.plastic.max_viscosity == 5.0 and settings.min_viscosity == 0.1
    assert settings.settings.viscous.settings.laws[1].settings.n == 3.0  # checked, nested, typed
    built = make_law(settings, LawContext("law"))
    assert built == build_law(spec, "law") and yield_law(built) is not None
    assert built.is_nonlinear and built.depends_on == {"strain_rate"}
    with pytest.raises(TypeError, match="Constant takes a ConstantSettings, got float"):
        VISCOSITY_LAWS["constant"](5.0)
    assert VISCOSITY_LAWS.build("constant", settings.settings.viscous.settings.laws[0].settings,
                                LawContext("x")).constant_value() == 2.0


TOSI = {"name": "viscoplastic", "viscous": {"name": "exponential", "gamma_T": 11.5},
        "plastic": {"name": "von_mises", "yield_stress": 1.0, "eta_star": 1e-3}}


@pytest.mark.parametrize("override, key, words", [
    ("physics.viscosity.law.plastic={name: drucker_prager, cohesion: 1, friction_angle: -5}",
     "physics.viscosity.law.plastic.friction_angle", "must be >= 0"),
    ("physics.viscosity.law={name: power_law, n: 0}", "physics.viscosity.law.n", "must be > 0"),
    ("physics.viscosity.law={name: power_law, n: -2}", "physics.viscosity.law.n", "must be > 0"),
    ("physics.viscosity.law.plastic.yield_stress=abc", "physics.viscosity.law.plastic.yield_stress",
     "expected a number"),
    ("physics.viscosity.law={name: plastic_flow}", "physics.viscosity.law.name", "unknown viscosity law"),
    ("physics.viscosity.law.plastic.cohesion=1", "physics.viscosity.law.plastic.cohesion", "not a parameter"),
    ("physics.viscosity.law.plastic={name: exponential}", "physics.viscosity.law.plastic", "must be a yield law"),
    ("physics.viscosity.law.combination=mean", "physics.viscosity.law.combination", "is not one of"),
    ("physics.viscosity.temperature_law=frank_kamenetskii", "physics.viscosity.temperature_law", "not with"),
    ("physics.viscosity.law.plastic={name: drucker_prager, cohesion: 1, friction_angle: 90}",
     "physics.viscosity.law.plastic.friction_angle", "must be < 90"),
    ("physics.viscosity.law.plastic={name: drucker_prager, cohesion: 1}",
     "physics.viscosity.law.plastic.friction_angle", "required by viscosity law 'drucker_prager' (friction angle"),
    ("physics.viscosity.law={name: composite, laws: [1, {name: power_law, n: -1}]}",
     "physics.viscosity.law.laws[1].n", "must be > 0"),
    ("physics.viscosity.law={name: weakened, law: 1, weakening: null}", "physics.viscosity.law.weakening",
     "must not be null"),
    ("physics.viscosity.law.plastic.weakening={start: 1, end: 0.5}", "physics.viscosity.law.plastic.weakening.end",
     "must be > 1.0"),
    ("physics.viscosity.law.plastic.weakening={foo: 1}", "physics.viscosity.law.plastic.weakening.foo",
     "not a weakening parameter"),
    ("physics.viscosity.law={name: depth_table, table: [[0, 1], [a, 2]]}", "physics.viscosity.law.table[1][0]",
     "expected a number"),
    ("physics.viscosity.law.viscous={name: arrhenius, E: 1, T_ref: -1}", "physics.viscosity.law.viscous.T_offset",
     "T_ref + T_offset must be > 0"),
    ("physics.viscosity.law.max_viscosity=-1", "physics.viscosity.law.max_viscosity", "must be > 0"),
    ("physics.viscosity.law={name: constant, min_viscosity: 2, max_viscosity: 1}",
     "physics.viscosity.law.max_viscosity", "must exceed min_viscosity"),
    ("stokes.nonlinear.method=quasi", "stokes.nonlinear.method", ""),
])
def test_bad_rheology_parameters_fail_at_config_time_in_one_line(override, key, words):
    document = {"mesh": {"cells": [4, 4]}, "physics": {"Ra": 100.0, "viscosity": {"law": TOSI}},
                "time": {"end": 1.0}, "output": {"directory": "unused"}}
    with pytest.raises(ConfigError) as info:
        load_config(None, [override], document=document)
    message = str(info.value)
    assert "\n" not in message and f"'{key}'" in message and words in message


def test_newton_needs_a_pressure_level_with_drucker_prager():
    law_dp = {"name": "viscoplastic", "combination": "minimum", "viscous": 1.0,
              "plastic": {"name": "drucker_prager", "cohesion": 1.0, "friction_angle": 20.0}}
    document = {"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0, "viscosity": {"law": law_dp}},
                "time": {"end": 1.0}, "output": {"directory": "unused"}}
    with pytest.raises(ConfigError, match="stokes.nonlinear.method"):
        load_config(None, [], document=document)
    load_config(None, ["stokes.nonlinear.method=picard"], document=document)
    load_config(None, ["boundary.velocity.top=null"], document=document)  # a traction-free top: fine


# ---------------------------------------------------------------------- nonlinear Stokes
def tosi_problem(method: str, *, rtol: float = 1e-8, max_iterations: int = 300, mesh=None):
    """A Tosi et al. (2015) case 2 Stokes problem at a fixed temperature with two plumes (collective)."""
    mesh = mesh if mesh is not None else dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 12, 12)
    spec = {"name": "viscoplastic", "combination": "tosi",
            "viscous": {"name": "exponential", "gamma_T": math.log(1e5)},
            "plastic": {"name": "von_mises", "yield_stress": 1.0, "eta_star": 1e-3, "strain_rate_measure": "norm"}}
    approximation = BoussinesqApproximation(Ra=100.0, viscosity=ViscosityLaw(laws=(law(spec),)))
    bcs = {side: VelocityBC("free_slip") for side in ("left", "right", "bottom", "top")}
    stokes = StokesSolver(mesh, approximation, bcs=bcs, solver="direct",
                          nonlinear=NonlinearSettings(method=method, rtol=rtol, max_iterations=max_iterations))
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    # a hot plume on the left and a cold one on the right: a yielding lid
    T.interpolate(lambda x: 1 - x[1] + 0.3 * np.cos(np.pi * x[0]) * np.sin(np.pi * x[1]))
    return stokes, T


def test_newton_converges_faster_than_picard_to_the_same_solution(world):
    results, velocities = {}, {}
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 12, 12)  # one mesh: the same dof numbering
    for method in ("picard", "newton"):
        stokes, T = tosi_problem(method, mesh=mesh)
        results[method] = stokes.solve(T).nonlinear
        velocities[method] = stokes.u.x.array.copy()
        # Galerkin: at the converged solution, int 2 eta eps:eps = Ra int T u_z (energy balance)
        u = stokes.u
        eta = stokes.discretisation.viscosity(T, None, {"u": u, "p": stokes.p, "fields": {}})
        eps = ufl.sym(ufl.grad(u))
        # (with the solver's quadrature, degree 3 k = 6, for which the identity is exact)
        phi = mean(stokes.mesh, 2 * eta * ufl.inner(eps, eps), 6)
        work = mean(stokes.mesh, 100.0 * T * u[1], 6)
        assert abs(phi - work) / work < 1e-7
        stokes.destroy()
    picard, newton = results["picard"], results["newton"]
    assert picard.residual <= 1e-8 and newton.residual <= 1e-8
    assert newton.iterations < picard.iterations / 2, (newton.iterations, picard.iterations)
    # quadratic convergence at the end: each Newton step squares the residual (up to a constant)
    tail = newton.history[newton.picard_iterations:]
    assert len(tail) >= 3 and tail[-1] < 1e-3 * tail[-2]
    # same solution: the difference is of the order of the tolerance
    difference = np.abs(velocities["picard"] - velocities["newton"]).max()
    scale = np.abs(velocities["newton"]).max()
    assert MPI.COMM_WORLD.allreduce(difference, op=MPI.MAX) < 1e-6 * MPI.COMM_WORLD.allreduce(scale, op=MPI.MAX)


def test_not_converging_is_a_solver_error(world):
    stokes, T = tosi_problem("picard", rtol=1e-12, max_iterations=3)
    with pytest.raises(NonlinearSolveError, match="did not reach the relative residual"):
        stokes.solve(T)
    stokes.destroy()


def test_a_constant_law_is_the_linear_solve(world):
    """A config law that is a number changes nothing: one linear solve, no nonlinear iteration."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 6, 6)
    bcs = {side: VelocityBC("free_slip") for side in ("left", "right", "bottom", "top")}
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(lambda x: 1 - x[1] + 0.1 * np.cos(np.pi * x[0]))
    out = []
    for viscosity in (ViscosityLaw(), ViscosityLaw(laws=(law(1.0),))):
        stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=1e4, viscosity=viscosity), bcs=bcs, solver="direct")
        assert not stokes.is_nonlinear and not stokes.approximation.is_variable_viscosity
        result = stokes.solve(T)
        assert result.nonlinear is None
        out.append(stokes.u.x.array.copy())
        stokes.destroy()
    # The same linear solve; the law's form is compiled separately, so MUMPS on 3 ranks may differ
    # in the last digits (5e-14 of 34 seen on DOLFINx 0.5).
    np.testing.assert_allclose(out[1], out[0], rtol=0, atol=1e-12 * np.abs(out[0]).max())
