"""Phase transitions (convection.physics.phases): the phase function, its density jump, latent heat
and viscosity jump as the solvers ask them, the units pass and the checks (global integrals: the
same on any number of ranks)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from convection.config.loader import ConfigError, load_config
from convection.physics.approximation import BoussinesqApproximation
from convection.physics.phases import PhaseTransition, PhaseTransitions

ROOT = Path(__file__).resolve().parents[3]
P660 = PhaseTransition("p660", depth=0.6, width=0.05, temperature=0.5, clapeyron=-0.1, Rb=200.0,
                       entropy_change=-0.05, viscosity_jump=10.0)


def _integral(mesh, expr) -> float:
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 10})
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * dx))
    return mesh.comm.allreduce(local, op=MPI.SUM)


@pytest.fixture(scope="module")
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)


def test_phase_function_is_half_on_the_deflected_boundary():
    """Gamma = 1/2 at d0 + gamma (T - T0), 0 above, 1 below; a hot 660 (gamma < 0) lies shallower."""
    for T in (0.3, 0.5, 0.9):
        d = 0.6 - 0.1 * (T - 0.5)
        assert P660.phase_at(T, d) == pytest.approx(0.5, abs=1e-15)
        assert P660.phase_at(T, d - 0.5) < 1e-8 and P660.phase_at(T, d + 0.5) > 1.0 - 1e-8
    assert P660.boundary_depth(0.9) < P660.depth < P660.boundary_depth(0.1)


def test_phase_derivative_is_that_of_the_phase(mesh):
    """Gamma' = dGamma/dpi, against the derivative of Gamma in depth (int over the square)."""
    depth = 1.0 - ufl.SpatialCoordinate(mesh)[1]
    T = ufl.as_ufl(0.7)
    # int_0^1 Gamma'(pi(d)) dd = Gamma(d=1) - Gamma(d=0) (T uniform: dpi = dd)
    total = _integral(mesh, P660.phase_derivative(T, depth))
    assert total == pytest.approx(P660.phase_at(0.7, 1.0) - P660.phase_at(0.7, 0.0), rel=1e-4)


def test_buoyancy_gains_the_deep_phase_weight(mesh):
    """The body force's vertical integral falls by Rb int Gamma; with T = T0 int Gamma = 1 - d0 (tanh odd)."""
    x = ufl.SpatialCoordinate(mesh)
    plain = BoussinesqApproximation(Ra=1.0)
    phased = BoussinesqApproximation(Ra=1.0, phases=PhaseTransitions((P660,)))
    T = ufl.as_ufl(0.5)
    difference = _integral(mesh, (phased.buoyancy(T, None, 2, x=x) - plain.buoyancy(T, None, 2, x=x))[1])
    assert difference == pytest.approx(-200.0 * (1.0 - 0.6), rel=1e-6)


def test_viscosity_jumps_by_its_factor(mesh):
    x = ufl.SpatialCoordinate(mesh)
    phased = BoussinesqApproximation(Ra=1.0, phases=PhaseTransitions((P660,)))
    assert phased.is_variable_viscosity and not BoussinesqApproximation(Ra=1.0).is_variable_viscosity
    eta = phased.viscosity(0.5, None, x=x)
    # 10 ** Gamma: 1 above, 10 below; int over the square between
    value = _integral(mesh, eta)
    assert 1.0 + 9.0 * 0.3 < value < 1.0 + 9.0 * 0.5


def test_latent_heat_terms(mesh):
    """c = 1 + L gamma Gamma' (T + T_s) >= 1 and q = -L Gamma' (T + T_s) w_up; Boussinesq without
    latent heat asks for no terms."""
    x = ufl.SpatialCoordinate(mesh)
    phases = PhaseTransitions((P660,), surface_temperature=0.1)
    phased = BoussinesqApproximation(Ra=1.0, phases=phases)
    assert BoussinesqApproximation(Ra=1.0).energy_terms(0.5, 0.5, ufl.as_vector((0.0, -1.0)), x) is None
    u = ufl.as_vector((0.0, -2.0))
    capacity, heating = phased.energy_terms(ufl.as_ufl(0.5), ufl.as_ufl(0.5), u, x)
    depth = 1.0 - x[1]
    gamma_prime = P660.phase_derivative(ufl.as_ufl(0.5), depth)
    expected_c = 1.0 + 0.005 * gamma_prime * 0.6
    expected_q = 0.05 * gamma_prime * 0.6 * (-2.0)
    assert _integral(mesh, (capacity - expected_c) ** 2) == pytest.approx(0.0, abs=1e-20)
    assert _integral(mesh, (heating - expected_q) ** 2) == pytest.approx(0.0, abs=1e-20)
    assert _integral(mesh, capacity) > 1.0


def test_temperature_below_is_the_exponential_closed_form():
    t = PhaseTransition("p", depth=0.5, width=0.02, entropy_change=0.1)
    assert t.temperature_below(1.0, 0.25) == pytest.approx(1.25 * math.exp(0.1) - 0.25, rel=1e-15)


def test_units_pass_gives_the_nondimensional_keys():
    """-2.5 MPa/K, +8 %, Clausius-Clapeyron in configs/phase_deflection.yaml (L = 1000 km, dT = 2000 K)."""
    config = load_config(ROOT / "configs" / "phase_deflection.yaml")
    p = config["phase_transitions"]["p660"]
    assert p["depth"] == pytest.approx(0.66) and p["width"] == pytest.approx(0.01)
    assert p["temperature"] == pytest.approx((1900.0 - 300.0) / 2000.0)
    assert p["clapeyron"] == pytest.approx(-2.5e6 * 2000.0 / (3300.0 * 10.0 * 1e6), rel=1e-12)
    assert p["Rb"] == pytest.approx(0.08 * 3300.0 * 10.0 * 1e18 / (1e21 * 1e-6), rel=1e-12)
    assert p["entropy_change"] == pytest.approx(-2.5e6 * 0.08 / (3300.0 * 1250.0), rel=1e-12)
    assert config["physics"]["reference"]["surface_temperature"] == pytest.approx(300.0 / 2000.0)
    again = load_config(None, document={k: v for k, v in config.items()})
    assert again["phase_transitions"] == config["phase_transitions"]


@pytest.mark.parametrize("overrides, needle", [
    (["phase_transitions.p660.Rb=1"], "config key 'phase_transitions.p660.Rb': not with"),
    (["phase_transitions.p660.clapeyron=-2.5 MPa"],
     "config key 'phase_transitions.p660.clapeyron': '-2.5 MPa' is not a pressure per temperature"),
    (["phase_transitions.p660.clapeyron=-0.1"], "config key 'phase_transitions.p660.entropy_change': "
                                                "clausius_clapeyron needs"),
    (["phase_transitions.p660.width=0 km"], "config key 'phase_transitions.p660.width'"),
    (["phase_transitions.p660.depth=660 K"], "config key 'phase_transitions.p660.depth'"),
    (["energy.enabled=false"], "config key 'phase_transitions.p660.entropy_change': latent heat needs"),
    (["stokes.buoyancy_theta=0.5"], "config key 'phase_transitions.p660': not with stokes.buoyancy_theta"),
])
def test_check_refuses(overrides, needle):
    with pytest.raises(ConfigError, match="^" + needle.replace("(", r"\(").replace(".", r"\.")):
        load_config(ROOT / "configs" / "phase_deflection.yaml", overrides)


def test_density_jump_needs_the_scaling():
    with pytest.raises(ConfigError, match="density_jump': needs the scaling section"):
        load_config(ROOT / "configs" / "blankenbach_1a.yaml",
                    ["phase_transitions={p: {depth: 0.5, width: 0.05, density_jump: 0.08}}"])


def test_check_exits_2_in_one_line():
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("a subprocess per test, once")
    proc = subprocess.run([sys.executable, "-m", "convection", "check", "configs/blankenbach_1a.yaml", "--set",
                           "phase_transitions={p: {depth: 0.5, width: -1}}"], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "phase_transitions.p.width" in proc.stderr


def test_phase_field_of_a_model_on_any_rank_count():
    """The model's output field phase_p660 crosses 1/2 where the closed form says (benchmarks/phase_transitions)."""
    from benchmarks.phase_transitions.run import deflection, deflection_error

    result = deflection(["mesh.cells=[8,50]"], comm=MPI.COMM_WORLD)
    assert deflection_error(result) < 0.01
    assert np.allclose([r["measured"] for r in result["rows"]][::-1],
                       [2 * 660.0 - r["measured"] for r in result["rows"]], atol=1e-9)
