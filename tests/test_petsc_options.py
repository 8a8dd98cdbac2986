"""Solvers rebuilt many times (as adaptivity does) must not exhaust PETSc's options database."""

import gc

from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.mesh

from convection.approximation import BoussinesqApproximation
from convection.boundary import TemperatureBC
from convection.transport import TransportSolver


def test_options_released_when_solvers_are_dropped():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    approx = BoussinesqApproximation(Ra=1.0)
    bcs = {"bottom": TemperatureBC("dirichlet", 1.0), "top": TemperatureBC("dirichlet", 0.0)}
    before = len(PETSc.Options().getAll())
    for _ in range(150):  # PETSc allows 512 options; each solver sets 4 or more
        TransportSolver(mesh, approx, bcs=bcs)
        gc.collect()
    assert len(PETSc.Options().getAll()) <= before + 20
