"""Viscosity laws and buoyancy of the Boussinesq approximation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import ufl
import dolfinx
from mpi4py import MPI

from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw


@pytest.fixture(scope="module")
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)


def _value(mesh, expr) -> float:
    """Mean of a (constant) scalar UFL expression over the unit square."""
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * ufl.dx(domain=mesh)))
    return mesh.comm.allreduce(local, op=MPI.SUM)


def _evaluator(mesh, law):
    """f(T, C) -> value of law(T, C), compiled once with Constant T and C."""
    T = dolfinx.fem.Constant(mesh, 0.0)
    C = dolfinx.fem.Constant(mesh, 0.0)
    form = dolfinx.fem.form(law(T, C) * ufl.dx(domain=mesh))

    def evaluate(t: float, c: float) -> float:
        T.value, C.value = t, c
        return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)

    return evaluate


@pytest.mark.parametrize("mixing, expected", [
    ("geometric", lambda c: 0.1 ** (1 - c) * 1000.0 ** c),
    ("arithmetic", lambda c: (1 - c) * 0.1 + c * 1000.0),
    ("harmonic", lambda c: 1.0 / ((1 - c) / 0.1 + c / 1000.0)),
])
def test_mixing_rules_and_clipping(mesh, mixing, expected):
    eta = _evaluator(mesh, ViscosityLaw((0.1, 1000.0), mixing=mixing))
    for c in (0.0, 0.3, 1.0):
        assert eta(0.0, c) == pytest.approx(expected(c), rel=1e-12)
    assert eta(0.0, -0.5) == pytest.approx(0.1, rel=1e-12)
    assert eta(0.0, 1.7) == pytest.approx(1000.0, rel=1e-12)


def test_frank_kamenetskii(mesh):
    law = ViscosityLaw(temperature_law="frank_kamenetskii", gamma=math.log(1e4))
    approx = BoussinesqApproximation(Ra=1.0, viscosity=law)
    assert approx.is_variable_viscosity
    eta = _evaluator(mesh, approx.viscosity)
    assert eta(1.0, 0.0) == pytest.approx(1e-4, rel=1e-12)
    assert eta(0.0, 0.0) == pytest.approx(1.0, rel=1e-12)


def test_constant_viscosity_flags(mesh):
    assert not BoussinesqApproximation(Ra=1.0).is_variable_viscosity
    assert not BoussinesqApproximation(Ra=1.0, viscosity=ViscosityLaw((2.0, 2.0))).is_variable_viscosity
    assert BoussinesqApproximation(Ra=1.0, viscosity=ViscosityLaw((1.0, 2.0))).is_variable_viscosity
    assert _value(mesh, BoussinesqApproximation(Ra=1.0).viscosity(0.5, 0.5)) == pytest.approx(1.0)


def test_buoyancy_points_up(mesh):
    approx = BoussinesqApproximation(Ra=10.0, Rb=4.0)
    x = ufl.SpatialCoordinate(mesh)
    f = approx.buoyancy(0.5, 0.25, 2, x=x)
    assert f.ufl_shape == (2,)
    values = [_value(mesh, f[i]) for i in range(2)]
    assert np.allclose(values, [0.0, 10.0 * 0.5 - 4.0 * 0.25])
    assert _value(mesh, approx.buoyancy(1.0, None, 2, x=x)[1]) == pytest.approx(10.0)
    with pytest.raises(ValueError, match="x has 2 components, the buoyancy 3"):
        approx.buoyancy(1.0, None, 3, x=x)


def test_unknown_names_are_rejected():
    with pytest.raises(ValueError, match="valid names"):
        ViscosityLaw(mixing="median")
    with pytest.raises(ValueError, match="valid names"):
        ViscosityLaw(temperature_law="arrhenius")
    with pytest.raises(ValueError):
        ViscosityLaw((1.0, -1.0))


def test_numbers_are_constant_laws_of_one_path(mesh):
    """Numbers (the classic keys) are Constant laws mixed in closed form: a background viscosity
    is kept when no material has one of its own (it was dropped for 1 before the two viscosity
    paths became one), and numbers mix as before (geometric: eta_0 exp(C ln(eta_1 / eta_0)))."""
    from convection.physics.materials import Material, Materials
    from convection.physics.rheology import Constant

    region = lambda x: x[0] < 0.5  # noqa: E731
    alone = Materials((Material("a", region),), background_viscosity=5.0).viscosity_law()
    assert alone.laws == (Constant.of(5.0), Constant.of(5.0)) and alone.numbers == (5.0, 5.0) and alone.is_constant
    assert _value(mesh, alone(0.0, 0.5)) == pytest.approx(5.0, rel=1e-14)
    law = ViscosityLaw((0.1, 1.0))
    assert law.numbers == (0.1, 1.0) and not law.is_constant
    assert _value(mesh, law(0.0, 0.5)) == pytest.approx(0.1 * math.exp(0.5 * math.log(10.0)), rel=1e-12)


def _three_material_evaluator(mesh, law):
    """f(C_1, C_2) -> law(0, (C_1, C_2)), compiled once with Constant fractions."""
    cs = (dolfinx.fem.Constant(mesh, 0.0), dolfinx.fem.Constant(mesh, 0.0))
    form = dolfinx.fem.form(law(0.0, cs) * ufl.dx(domain=mesh))

    def evaluate(c1: float, c2: float) -> float:
        cs[0].value, cs[1].value = c1, c2
        return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)

    return evaluate


def test_sharp_material_enters_by_threshold(mesh):
    """Sticky air (material 1, eta 1e-2) sharp, lithosphere (material 2, eta 1e2) and mantle (background,
    1) mixed geometrically: a plate cell 10 % air keeps the plate's viscosity (geometric mixing
    would give 10^1.4), a cell at least half air is air, and without air the rule is the plain one."""
    plain = _three_material_evaluator(mesh, ViscosityLaw((1.0, 1e-2, 1e2)))
    eta = _three_material_evaluator(mesh, ViscosityLaw((1.0, 1e-2, 1e2), sharp=(1,)))
    assert plain(0.1, 0.9) == pytest.approx(10 ** 1.6, rel=1e-12)
    assert eta(0.1, 0.9) == pytest.approx(1e2, rel=1e-12)
    assert eta(0.2, 0.4) == pytest.approx(10.0, rel=1e-12)  # mantle and plate 1:1 -> sqrt(1 * 100)
    assert eta(0.5, 0.5) == pytest.approx(1e-2, rel=1e-12)
    assert eta(1.0, 0.0) == pytest.approx(1e-2, rel=1e-12)
    for c2 in (0.0, 0.3, 1.0):
        assert eta(0.0, c2) == pytest.approx(plain(0.0, c2), rel=1e-12)
    harmonic = _three_material_evaluator(mesh, ViscosityLaw((1.0, 1e-2, 1e2), mixing="harmonic", sharp=(1,)))
    assert harmonic(0.3, 0.35) == pytest.approx(1.0 / (0.5 / 1.0 + 0.5 / 1e2), rel=1e-12)


def test_sharp_needs_materials():
    with pytest.raises(ValueError, match="sharp"):
        ViscosityLaw((1.0, 2.0), sharp=(0,))
    with pytest.raises(ValueError, match="sharp"):
        ViscosityLaw((1.0, 2.0), sharp=(2,))


def test_materials_name_their_sharp_ones():
    from convection.physics.materials import Material, Materials

    def nothing(x):
        return np.zeros(x.shape[1])

    air, lith = Material("air", nothing, viscosity=1e-2), Material("lithosphere", nothing, viscosity=1e2)
    assert Materials((air, lith), sharp=("air",)).viscosity_law().sharp == (1,)
    with pytest.raises(ValueError, match="sharp"):
        Materials((air, lith), sharp=("water",))
