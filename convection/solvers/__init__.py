"""The solvers: Stokes (forms, linear system, nonlinear iterations, null spaces), the transport of
temperature and material fields, PETSc options and the time step."""

from convection.solvers.stokes import StokesResult, StokesSolver
from convection.solvers.timestep import cfl_timestep
from convection.solvers.transport import TransportSolver

__all__ = ["StokesResult", "StokesSolver", "TransportSolver", "cfl_timestep"]
