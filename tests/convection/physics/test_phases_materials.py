"""Phase transitions per material (convection.physics.phases ``materials``): the density and viscosity
jumps weighted by the fraction of the materials a transition applies to, a hydrostatic column whose
pressure follows from one material's jump only, and the checks (global integrals and point values:
the same on any number of ranks)."""

from __future__ import annotations

import math
from pathlib import Path

import dolfinx
import pytest
import ufl
from mpi4py import MPI

from convection.config.loader import ConfigError, load_config
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.physics.phases import PhaseTransition, PhaseTransitions, material_indices

ROOT = Path(__file__).resolve().parents[3]


def _integral(mesh, expr) -> float:
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 10})
    return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * dx)), op=MPI.SUM)


@pytest.fixture(scope="module")
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)


def _transition(materials, **kw) -> PhaseTransition:
    return PhaseTransition("p", depth=0.6, width=0.05, temperature=0.5, clapeyron=-0.1, materials=materials, **kw)


@pytest.mark.parametrize("materials, share", [(None, 1.0), ((1,), 0.5), ((0,), 0.5), ((0, 1), 1.0), ((2,), 0.0)])
def test_buoyancy_jump_is_weighted_by_the_materials_fraction(mesh, materials, share):
    """Material 1 fills x < 1/2, material 2 nowhere: the body force falls by Rb int phi Gamma, with
    T = T0 int Gamma = 1 - d0 over a column (tanh odd), times the share of the columns phi covers."""
    x = ufl.SpatialCoordinate(mesh)
    C = (ufl.conditional(ufl.lt(x[0], 0.5), 1.0, 0.0), ufl.as_ufl(0.0))
    plain = BoussinesqApproximation(Ra=1.0, Rb=(0.0, 0.0))
    phased = BoussinesqApproximation(Ra=1.0, Rb=(0.0, 0.0),
                                     phases=PhaseTransitions((_transition(materials, Rb=200.0),)))
    T = ufl.as_ufl(0.5)
    difference = _integral(mesh, (phased.buoyancy(T, C, 2, x=x) - plain.buoyancy(T, C, 2, x=x))[1])
    assert difference == pytest.approx(-200.0 * (1.0 - 0.6) * share, rel=1e-6, abs=1e-9)


@pytest.mark.parametrize("materials, share", [((1,), 0.5), ((0,), 0.5), (None, 1.0)])
def test_viscosity_jump_is_weighted_by_the_materials_fraction(mesh, materials, share):
    """Geometric mixing: ln eta gains phi Gamma ln f; int over the square = ln f (1 - d0) share."""
    x = ufl.SpatialCoordinate(mesh)
    C = ufl.conditional(ufl.lt(x[0], 0.5), 1.0, 0.0)
    law = ViscosityLaw(material_viscosities=(1.0, 3.0))
    plain = BoussinesqApproximation(Ra=1.0, Rb=(0.0,), viscosity=law)
    phased = BoussinesqApproximation(Ra=1.0, Rb=(0.0,), viscosity=law,
                                     phases=PhaseTransitions((_transition(materials, viscosity_jump=10.0),)))
    ratio = _integral(mesh, ufl.ln(phased.viscosity(0.5, C, x=x) / plain.viscosity(0.5, C, x=x)))
    assert ratio == pytest.approx(math.log(10.0) * (1.0 - 0.6) * share, rel=1e-6)


def test_material_names_become_indices():
    assert material_indices(None, ("a",)) is None
    assert material_indices(("b", "background"), ("a", "b")) == (2, 0)
    with pytest.raises(ValueError, match="unknown material 'c'"):
        material_indices(("c",), ("a", "b"))
    with pytest.raises(ValueError, match="distinct indices"):
        _transition((1, 1))
    with pytest.raises(ValueError, match="applies to material 2, the model has 1"):
        _transition((2,), Rb=1.0).fraction((ufl.as_ufl(1.0),))


COLUMN = ["mesh.cells=[2,40]", "energy.enabled=false", "initial.temperature='0'",
          "materials={lid: {initial: 'z > 0.5'}}", "boundary.velocity={left: free_slip, right: free_slip, "
          "bottom: free_slip, top: free_slip}", "diagnostics.points={top: [0.5, 0.99], bottom: [0.5, 0.01]}",
          "output.statistics=[time, velocity, points]", "stokes.solver=direct", "time.max_steps=1",
          "time.end=1", "output.progress=none", "output.fields_every=0"]
"""A unit column, the material ``lid`` above z = 1/2, no temperature buoyancy: only the transitions push."""


def _column(out: Path, transitions: str) -> tuple[float, float]:
    """(p_bottom - p_top, vrms) of the column with ``transitions`` (a YAML mapping)."""
    from convection.app.factory import run_config
    from convection.io.pictures import read_statistics

    config = load_config(None, document={"physics": {"Ra": 0.0}, "mesh": {"cells": [2, 40]}, "time": {"end": 1.0},
                                         "output": {"directory": str(out)}},
                         overrides=[*COLUMN, f"phase_transitions={transitions}"])
    run_config(config, comm=MPI.COMM_WORLD)
    statistics = read_statistics(out / "statistics.csv")
    return statistics["p_bottom"][-1] - statistics["p_top"][-1], statistics["vrms"][-1]


def test_hydrostatic_column_feels_only_its_materials_jump(tmp_path_factory):
    """The 'lid' (depth < 1/2) crosses a transition at depth 1/4; a transition at depth 3/4 for the lid
    only lies in the background and adds nothing; for the background it adds its Rb (0.99 - 3/4) down to
    the probe at depth 0.99. At rest, dp/dz = -Rb phi Gamma: p_bottom - p_top = Rb int phi Gamma dz =
    100 (1/2 - 1/4) (+ 100 (0.99 - 3/4))."""
    tmp_path = tmp_path_factory.mktemp("column") if MPI.COMM_WORLD.rank == 0 else None
    tmp_path = Path(MPI.COMM_WORLD.bcast(str(tmp_path)))
    shallow, deep = "{depth: 0.25, width: 0.01, Rb: 100, materials: [lid]}", "depth: 0.75, width: 0.01, Rb: 100"
    lid_only, vrms = _column(tmp_path / "lid", f"{{p1: {shallow}, p2: {{{deep}, materials: [lid]}}}}")
    assert lid_only == pytest.approx(25.0, rel=0.01)
    assert vrms < 1e-5 * lid_only  # at rest, but for the discretisation's spurious flow at the lid's edge
    both, _ = _column(tmp_path / "both", f"{{p1: {shallow}, p2: {{{deep}, materials: [background]}}}}")
    assert both == pytest.approx(49.0, rel=0.01)


@pytest.mark.parametrize("spec, needle", [
    ("{depth: 0.5, width: 0.05, Rb: 1, materials: [rock]}", "materials': unknown material 'rock'"),
    ("{depth: 0.5, width: 0.05, Rb: 1, materials: [lid, lid]}", "materials': expected distinct material names"),
    ("{depth: 0.5, width: 0.05, entropy_change: 0.1, materials: [lid]}", "materials': latent heat applies to every"),
])
def test_check_refuses_materials(spec, needle):
    with pytest.raises(ConfigError, match=f"^config key 'phase_transitions.p.{needle}"):
        load_config(ROOT / "configs" / "blankenbach_1a.yaml",
                    ["materials={lid: {initial: 'z > 0.5'}}", f"phase_transitions={{p: {spec}}}"])
