"""One run of the rigid-shear benchmark: particles carry the density, an interpolator turns it into a
mesh field, the Stokes solve uses it as buoyancy; the time-dependent problem advects the particles
with the computed velocity to the end time (see problem.py for the equations).

The choices:

- ``interpolator``: ``exact`` (no particles: the exact density in the buoyancy, the finite-element
  limit), ``cell_average`` (DG0), ``least_squares`` (DG1), ``least_squares_limited`` (DG1, clipped
  to the particles' range), ``quadratic_least_squares`` (DG2), ``quadratic_least_squares_limited``;
- ``ppc``: particles per triangle (``random_uniform``: ``ppc x cells`` particles placed uniformly at
  random; every triangle gets ``ppc`` of them up to the rounding of the cell areas);
- ``integrator``: ``none`` (instantaneous problem) or a Runge-Kutta scheme of
  :data:`particles.advection.INTEGRATORS` (``rk2``, ``rk4``; time-dependent problem).

Time-dependent problem (ASPECT's ``steady-state`` set-up of the paper): the Stokes solve at t = 0,
then steps of ``dt = cfl h / (2 max|u|)`` (ASPECT's time step with CFL number ``cfl`` and
degree-2 fields; ``max|u| = 1``), shortened to end exactly at ``end_time``: advect the particles
over the step with the velocity of the last solve (the flow is steady), interpolate the density,
solve. The errors are those at the end time.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

import dolfinx.fem

from benchmarks.rigid_shear.problem import StokesSolver, exact_density
from particles.generation import RandomUniform
from particles.interpolation import CellAverage, Interpolator, LeastSquares, QuadraticLeastSquares
from particles.manager import ParticleManager
from particles.properties.function import FunctionProperty

__all__ = ["INTERPOLATORS", "Case", "run_case"]

INTERPOLATORS: dict[str, tuple[Interpolator | None, int]] = {
    "exact": (None, 0),
    "cell_average": (CellAverage(), 0),
    "least_squares": (LeastSquares(), 1),
    "least_squares_limited": (LeastSquares(LeastSquares.Settings(limit=True)), 1),
    "quadratic_least_squares": (QuadraticLeastSquares(), 2),
    "quadratic_least_squares_limited": (QuadraticLeastSquares(QuadraticLeastSquares.Settings(limit=True)), 2),
}
"""Interpolator choices: (interpolator, degree of the DG density field)."""


@dataclass(frozen=True)
class Case:
    """One run.

    Attributes:
        problem: "instantaneous" or "time_dependent".
        cells: Squares per side (h = 1 / cells; 2 cells**2 triangles).
        ppc: Particles per triangle (0 with the exact density).
        interpolator: A key of :data:`INTERPOLATORS`.
        integrator: "none" (instantaneous) or a Runge-Kutta name.
        end_time: End time of the time-dependent problem.
        cfl: CFL number of its time step.
        seed: Seed of the particle positions.
    """

    problem: str
    cells: int
    ppc: int
    interpolator: str
    integrator: str = "none"
    end_time: float = 0.1
    cfl: float = 1.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.problem not in ("instantaneous", "time_dependent"):
            raise ValueError(f"unknown problem {self.problem!r}")
        if self.interpolator not in INTERPOLATORS:
            raise ValueError(f"unknown interpolator {self.interpolator!r}; valid: {sorted(INTERPOLATORS)}")
        if (self.integrator == "none") != (self.problem == "instantaneous" or self.interpolator == "exact"):
            raise ValueError("the instantaneous problem and the exact density take integrator 'none', the "
                             "time-dependent problem with particles a Runge-Kutta scheme")

    @property
    def key(self) -> tuple[Any, ...]:
        """What identifies the run in results.json."""
        return (self.problem, self.cells, self.ppc, self.interpolator, self.integrator, self.end_time, self.cfl,
                self.seed)

    def steps(self) -> int:
        """Number of time steps (0 for the instantaneous problem)."""
        if self.problem == "instantaneous" or self.interpolator == "exact":
            return 0
        return math.ceil(self.end_time / (self.cfl / self.cells / 2.0) * (1.0 - 1e-12))


def _manager(case: Case, solver: StokesSolver) -> ParticleManager:
    """The particles of ``case`` with their density, tracked into the DG field."""
    interpolator, degree = INTERPOLATORS[case.interpolator]
    mesh = solver.mesh
    num_cells = mesh.topology.index_map(mesh.topology.dim).size_global
    manager = ParticleManager(
        mesh, generator=RandomUniform(RandomUniform.Settings(case.ppc * num_cells, case.seed)),
        integrator=case.integrator if case.integrator != "none" else "rk2",
        properties=[FunctionProperty(FunctionProperty.Settings(function=exact_density, label="density"))],
        interpolator=interpolator, field_degree=degree)
    manager.track("density")
    return manager


def run_case(case: Case, solver: StokesSolver, /) -> dict[str, Any]:
    """Run ``case`` on ``solver``'s mesh (``case.cells`` squares a side); returns the case's
    fields with the L2 errors (``u``, ``p``, ``rho``), ``steps``, ``particles`` (at the end),
    ``lost``, particles per cell (``ppc_min``, ``ppc_max`` at the end) and ``seconds``
    (collective; the same dict on every rank)."""
    t0 = time.perf_counter()
    density: dolfinx.fem.Function | None = None
    counts: tuple[int, float, int] = (0, 0.0, 0)
    particles = lost = 0
    steps = case.steps()
    if case.interpolator != "exact":
        manager = _manager(case, solver)
        density = manager.field("density")
    solver.solve(density)
    for step in range(steps):
        manager.advance(solver.u, solver.u, case.end_time / steps, step=step)
        density = manager.field("density")
        solver.solve(density)
    errors = solver.errors(density)
    if case.interpolator != "exact":
        counts, particles, lost = manager.particles_per_cell(), manager.num_particles, manager.lost
    seconds = solver.mesh.comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    return {**asdict(case), "u": errors.u, "p": errors.p, "rho": errors.rho, "steps": steps,
            "particles": int(particles), "lost": int(lost), "ppc_min": int(counts[0]), "ppc_max": int(counts[2]),
            "seconds": float(np.round(seconds, 3))}

