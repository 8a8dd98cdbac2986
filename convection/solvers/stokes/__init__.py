"""Taylor–Hood Stokes: the forms, the linear system (direct or block-preconditioned), Picard and
Newton iterations for viscosities that depend on the flow, and the null spaces."""

from convection.solvers.stokes.nonlinear import NonlinearSettings
from convection.solvers.stokes.solver import StokesResult, StokesSolver

__all__ = ["NonlinearSettings", "StokesResult", "StokesSolver"]
