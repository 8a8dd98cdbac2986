"""The semi-implicit buoyancy's term on a box through its scalar component form
(convection/solvers/stokes/axis_block.py): the Stokes matrix is the same as with the term's vector
form added cell by cell -- to the last bit on one rank, to one unit in the last place on several
(PETSc sums the contributions it sends to another rank's rows in an order that depends on what else
it sends) -- with free-slip, no-slip and prescribed velocities, for a second solve with another step
and other fields, and with a viscosity that changes the fixed operator."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

from convection.geometry.boundary import VelocityBC
from convection.geometry.box import SIDES_2D, SIDES_3D
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.physics.buoyancy import SemiImplicitBuoyancy
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space


def _fields(mesh, shift: float):
    """A P2 temperature and a DG0 dense layer whose interface is wavy (stable and unstable parts)."""
    z = mesh.geometry.dim - 1
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(lambda x: 1.0 - x[z] + 0.2 * np.sin(np.pi * (x[0] + shift)) * np.sin(np.pi * x[z]))
    C = dolfinx.fem.Function(function_space(mesh, "DG", 0))
    C.interpolate(lambda x: (x[z] < 0.4 + 0.1 * np.cos(np.pi * (x[0] + shift))).astype(float))
    return T, C


def _matrices(mesh, bcs, viscosity, solver, component: bool, monkeypatch) -> list[tuple[np.ndarray, ...]]:
    """The local CSR of A after each of two solves (other fields, another step)."""
    with monkeypatch.context() as patch:
        if not component:
            patch.setattr(SemiImplicitBuoyancy, "axis", property(lambda self: None))
        approximation = BoussinesqApproximation(Ra=1e5, Rb=2e5, viscosity=viscosity)
        stokes = StokesSolver(mesh, approximation, bcs=bcs, solver=solver, buoyancy_theta=1.0)
        out = []
        for shift, dt in ((0.0, 1e-5), (0.3, 3e-5)):
            T, C = _fields(mesh, shift)
            stokes.solve(T, C, dt=dt)
            indptr, columns, values = stokes.linear_system.A.getValuesCSR()
            out.append((indptr.copy(), columns.copy(), values.copy()))
        assert (stokes.linear_system._term.block is not None) == component
        stokes.destroy()
    return out


BOUNDARIES_3D = {
    "free slip": {side: VelocityBC("free_slip") for side in SIDES_3D},
    "no slip and a prescribed top": {**{side: VelocityBC("free_slip") for side in SIDES_3D},
                                     "bottom": VelocityBC("no_slip"), "top": VelocityBC("prescribed", (1.0, 0.0, 0.0))},
}


@pytest.mark.parametrize("boundaries", sorted(BOUNDARIES_3D))
@pytest.mark.parametrize("viscosity", ["constant", "temperature"])
def test_component_block_is_the_vector_term_bit_for_bit_3d(world, monkeypatch, boundaries, viscosity):
    mesh = dolfinx.mesh.create_unit_cube(world, 4, 4, 4)
    law = (ViscosityLaw() if viscosity == "constant"
           else ViscosityLaw(temperature_law="frank_kamenetskii", gamma=np.log(1e3)))
    bcs = BOUNDARIES_3D[boundaries]
    fast = _matrices(mesh, bcs, law, "iterative", True, monkeypatch)
    slow = _matrices(mesh, bcs, law, "iterative", False, monkeypatch)
    _assert_same(mesh.comm, fast, slow)
    assert not np.array_equal(fast[0][2], fast[1][2])  # the term changed between the solves


def _assert_same(comm, fast, slow) -> None:
    for (indptr, columns, values), (indptr0, columns0, values0) in zip(fast, slow):
        assert np.array_equal(indptr, indptr0) and np.array_equal(columns, columns0)
        if comm.size == 1:
            ok = np.array_equal(values, values0)
        else:  # round-off of sums of a few terms, against the matrix's scale; a few entries only
            scale = comm.allreduce(np.abs(values0).max(initial=0.0), op=MPI.MAX)
            ok = (np.abs(values - values0).max(initial=0.0) <= 8 * np.finfo(float).eps * scale
                  and np.count_nonzero(values != values0) <= max(2, 1e-3 * len(values)))
        assert comm.allreduce(bool(ok), op=MPI.LAND)  # on every rank (no rank left waiting)


def test_component_block_is_the_vector_term_bit_for_bit_2d_direct(world, monkeypatch):
    mesh = dolfinx.mesh.create_unit_square(world, 8, 8)
    bcs = {side: VelocityBC("free_slip") for side in SIDES_2D}
    fast = _matrices(mesh, bcs, ViscosityLaw(), "direct", True, monkeypatch)
    slow = _matrices(mesh, bcs, ViscosityLaw(), "direct", False, monkeypatch)
    _assert_same(mesh.comm, fast, slow)
