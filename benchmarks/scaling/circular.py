"""Uniform-mesh scaling test with the Stokes solve: circular flow in an annulus or a spherical shell
(seed paper, section 3.1).

The domain is the shell ``R_IN <= |x| <= R_OUT`` (radius ratio 0.55, the Earth's core to surface):

- 2D: a structured annulus: a ``radial x angular`` grid of (r, theta) quadrilaterals, each cut into
  two triangles, mapped to polar coordinates; the last angular column reuses the first column's
  vertices, so the mesh is conforming across the seam. Its boundary is the polygon through
  ``angular`` vertices on each circle.
- 3D: a spherical shell meshed by gmsh (:func:`convection.geometry.mesh.create_shell_mesh`) with target cell
  size ``resolution`` and straight-sided (affine) tetrahedra, whose boundary vertices lie on the
  spheres.

Affine cells keep the particle kernels compiled (curved cells take the vectorised Newton path,
about 10x slower per relocation) and allow ``random_uniform`` generation.

**The flow is solved, not prescribed.** Every time step solves the Stokes equations
(:class:`convection.solvers.stokes.solver.StokesSolver`, Taylor-Hood P2-P1, no buoyancy) with the velocity
prescribed on both surfaces as rotations about the z axis: ``omega_inner (-y, x)`` on the inner and
``omega_outer (-y, x)`` on the outer surface (strong conditions; defaults -1 and 1, counter-rotating).
Its exact solution is circular Couette flow, ``u = f(r) (-y, x)`` (3D: ``(-y, x, 0)``) with
``f(r) = A + B / r^d`` (``d = 2`` in 2D, ``d = 3`` in 3D, ``f(R_IN) = omega_inner``,
``f(R_OUT) = omega_outer``); the largest nodal error of the solve is reported as a check.

What a step costs depends on what changes between steps. By default the viscosity law is
``eta = exp(-gamma T)`` at ``T = 0``: the viscosity is 1, but the solver treats it as variable, so
the operator is assembled and the solver set up again at every step (the MUMPS factorisation, or
the AMG hierarchy), as in a convection run with temperature-dependent viscosity; the iterative
solver starts from a zero guess. ``--solver auto`` (the default, as ``stokes.solver`` of a run) is
MUMPS in 2D and FGMRES with the block Schur preconditioner (BoomerAMG on the velocity) in 3D.
``--constant-viscosity`` lets the solver reuse its factorisation, as an isoviscous run does (then a
step is one right-hand side assembly and back-substitution).

``particles_per_cell * cells`` particles are placed with ``random_uniform`` and advected with RK2
in the solved velocity at a fixed CFL number (``convection.solvers.timestep.cfl_timestep``: shortest edge
over velocity degree, as ASPECT). The straight-sided boundary lies inside the circle/sphere
between its vertices while the prescribed velocity is tangent to the circle/sphere, so particles
next to a surface can step across a boundary facet; stage positions are moved back radially by
``shell_confinement`` (margin ``h_max^2 / (4 R_IN)``, more than the facets' sagitta), as in
convection runs on shells. Every step times, per rank:

- ``assemble``: Stokes operator (when it changes) and right-hand side;
- ``solve``: Stokes linear solve (factorisation or AMG set-up, solve, residual check);
- ``advect``: velocity evaluation and position updates (``AdvectionStats.evaluation_seconds``);
- ``sort``: confinement, transport between cells and the counting sort (``relocation_seconds``);
- ``communicate``: migration between ranks (``communication_seconds``).

Each phase is summed over the steps per rank; the report gives the slowest rank's sum.

Usage (the driver runs every configuration under ``mpirun`` and collects one JSON line per run)::

    python -m benchmarks.scaling.circular                          # 2D strong + weak, ranks 1 2 4
    python -m benchmarks.scaling.circular --dim 3 --steps 20       # spherical shell, FGMRES + AMG
    mpirun -n 2 python -m benchmarks.scaling.circular --worker --radial 32    # one 2D run
    mpirun -n 2 python -m benchmarks.scaling.circular --worker --dim 3 --resolution 0.2

Four ranks on the 2-core machine run with ``--oversubscribe`` and are marked as oversubscribed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from benchmarks.harness import Benchmark
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.geometry.boundary import VelocityBC
from convection.launch import mpi_environment
from convection.geometry.shell import ShellSpec, create_shell_mesh, shell_confinement, shell_domain
from convection.solvers.stokes.solver import STOKES_SOLVER_NAMES, StokesSolver
from convection.solvers.timestep import cfl_timestep
from fembase.dolfinx_compat import coordinate_element_from, geometry_dofmap, mesh_domain
from fembase.dolfinx_compat import create_mesh as compat_create_mesh
from particles import Swarm
from particles.advection import Advector
from particles.generation import generate

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=HERE, ranks=(1, 2, 4))

R_IN = 0.55
R_OUT = 1.0

__all__ = [
    "AnnulusLayout",
    "CircularProblem",
    "CouetteFlow",
    "PhaseTimes",
    "StokesFlow",
    "advance",
    "angular_divisions",
    "annulus_layout",
    "create_annulus",
    "create_domain",
    "create_spherical_shell",
    "setup_problem",
]


# ----------------------------------------------------------------------------------------- mesh
class AnnulusLayout(NamedTuple):
    """Serial description of the annulus mesh.

    Attributes:
        points: Vertex coordinates, shape=(radial + 1) * angular, 2), float64; vertex
            ``i * angular + j`` sits at radius ``r_i`` and angle ``2 pi j / angular``.
        cells: Triangles as vertex indices, shape=(2 * radial * angular, 3), int64.
    """

    points: npt.NDArray[np.float64]
    cells: npt.NDArray[np.int64]


def angular_divisions(radial: int, r_in: float = R_IN, r_out: float = R_OUT) -> int:
    """Angular divisions that make the mid-radius cells about square, for ``radial`` layers."""
    h = (r_out - r_in) / radial
    return max(3, int(round(2.0 * math.pi * 0.5 * (r_in + r_out) / h)))


def annulus_layout(radial: int, angular: int, /, *, r_in: float = R_IN, r_out: float = R_OUT) -> AnnulusLayout:
    """Points and triangles of the structured annulus (the seam column reuses the first column).

    Args:
        radial: Number of cell layers between the circles (>= 1).
        angular: Number of divisions around the circle (>= 3).
    """
    if radial < 1 or angular < 3:
        raise ValueError(f"need radial >= 1 and angular >= 3, got {radial}, {angular}")
    r = np.linspace(r_in, r_out, radial + 1)
    theta = 2.0 * np.pi * np.arange(angular) / angular
    rr, tt = np.meshgrid(r, theta, indexing="ij")
    points = np.stack([(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel()], axis=1)
    i, j = np.meshgrid(np.arange(radial), np.arange(angular), indexing="ij")
    i, j = i.ravel(), j.ravel()
    jn = (j + 1) % angular
    v00, v10, v01, v11 = i * angular + j, (i + 1) * angular + j, i * angular + jn, (i + 1) * angular + jn
    # Alternate the diagonal in a checkerboard so the mesh has no preferred direction.
    even = (i + j) % 2 == 0
    lower = np.where(even[:, None], np.stack([v00, v10, v11], 1), np.stack([v00, v10, v01], 1))
    upper = np.where(even[:, None], np.stack([v00, v11, v01], 1), np.stack([v10, v11, v01], 1))
    cells = np.concatenate([lower, upper]).astype(np.int64)
    return AnnulusLayout(points, cells)


def create_annulus(
    comm: MPI.Comm, radial: int, /, *, angular: int | None = None, r_in: float = R_IN, r_out: float = R_OUT
) -> dolfinx.mesh.Mesh:
    """Distributed P1 triangle mesh of the annulus (collective; built on rank 0, then partitioned).

    Args:
        comm: Communicator.
        radial: Cell layers between the circles.
        angular: Divisions around the circle; default :func:`angular_divisions`.
    """
    angular = angular_divisions(radial, r_in, r_out) if angular is None else angular
    if comm.rank == 0:
        layout = annulus_layout(radial, angular, r_in=r_in, r_out=r_out)
        points, cells = layout.points, layout.cells
    else:
        points, cells = np.zeros((0, 2)), np.zeros((0, 3), dtype=np.int64)
    return compat_create_mesh(comm, cells, points, mesh_domain(coordinate_element_from(("triangle", 1, 2))))


def create_spherical_shell(comm: MPI.Comm, resolution: float, /) -> dolfinx.mesh.Mesh:
    """Distributed straight-sided tetrahedral mesh of the shell ``R_IN <= |x| <= R_OUT`` (gmsh on rank
    0, cell size ``resolution``; collective)."""
    return create_shell_mesh(comm, ShellSpec(3, R_IN, R_OUT, resolution, geometry_degree=1))


def create_domain(comm: MPI.Comm, dim: int, size: float, /) -> dolfinx.mesh.Mesh:
    """The annulus with ``int(size)`` radial layers (``dim = 2``) or the spherical shell with cell size
    ``size`` (``dim = 3``). Collective."""
    if dim == 2:
        return create_annulus(comm, int(size))
    if dim == 3:
        return create_spherical_shell(comm, float(size))
    raise ValueError(f"dim must be 2 or 3, got {dim}")


def longest_edge(mesh: dolfinx.mesh.Mesh, /) -> float:
    """Longest cell edge over all ranks (affine cells; collective)."""
    tdim = mesh.topology.dim
    n = mesh.topology.index_map(tdim).size_local
    nodes = geometry_dofmap(mesh)[:n]
    x = mesh.geometry.x[nodes]
    local = 0.0
    for i in range(tdim + 1):
        for j in range(i + 1, tdim + 1):
            local = max(local, float(np.max(np.linalg.norm(x[:, i] - x[:, j], axis=1), initial=0.0)))
    return float(mesh.comm.allreduce(local, op=MPI.MAX))


# ----------------------------------------------------------------------------------------- flow
@dataclass(frozen=True)
class CouetteFlow:
    """Circular Couette flow between rotating surfaces: ``u = f(r) (-y, x)`` (3D: ``(-y, x, 0)``),
    ``f(r) = A + B / r^dim``, the Stokes solution with ``f(R_IN) = omega_inner`` and
    ``f(R_OUT) = omega_outer`` (2D: ``u_theta = A r + B / r``; 3D: ``u_phi = (A r + B / r^2) sin(theta)``).
    """

    dim: int = 2
    omega_inner: float = -1.0
    omega_outer: float = 1.0
    r_in: float = R_IN
    r_out: float = R_OUT

    @property
    def coefficients(self) -> tuple[float, float]:
        """``(A, B)``."""
        d = self.dim
        b = (self.omega_inner - self.omega_outer) / (self.r_in ** -d - self.r_out ** -d)
        return self.omega_outer - b * self.r_out ** -d, b

    def angular_velocity(self, r: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """``f(r)``."""
        a, b = self.coefficients
        return a + b * r ** -float(self.dim)

    def __call__(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Velocity at points x, shape=(3, n) -> shape=(dim, n)."""
        f = self.angular_velocity(np.linalg.norm(x[: self.dim], axis=0))
        rows = [-f * x[1], f * x[0]] + ([np.zeros_like(f)] if self.dim == 3 else [])
        return np.stack(rows)

    def boundary_conditions(self) -> dict[str, VelocityBC]:
        """Rotations about z prescribed on ``inner`` and ``outer`` (expression texts)."""
        zero = ("0",) if self.dim == 3 else ()

        def rotation(omega: float) -> VelocityBC:
            return VelocityBC("prescribed", (f"{-omega!r} * y", f"{omega!r} * x", *zero))

        return {"inner": rotation(self.omega_inner), "outer": rotation(self.omega_outer)}


class StokesFlow:
    """The Stokes solve of one time step (collective): no buoyancy, rotations prescribed on both
    surfaces (:meth:`CouetteFlow.boundary_conditions`).

    Args:
        mesh: The shell mesh.
        flow: Boundary rotations (and the exact solution).
        solver: a name in :data:`convection.solvers.stokes.solver.STOKES_SOLVER_NAMES` (``"auto"``: MUMPS in 2D,
            FGMRES + block Schur preconditioner in 3D).
        variable_viscosity: Treat the (unit) viscosity as variable: reassemble and set the solver up
            at every step (see the module docstring).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, flow: CouetteFlow, /, *, solver: str = "auto",
                 variable_viscosity: bool = True) -> None:
        law = ViscosityLaw(temperature_law="frank_kamenetskii", gamma=1.0) if variable_viscosity else ViscosityLaw()
        domain = shell_domain(ShellSpec(flow.dim, R_IN, R_OUT))  # the boundaries are found on the mesh
        approximation = BoussinesqApproximation(Ra=0.0, viscosity=law, gravity=domain.gravity)
        self.flow = flow
        self.stokes = StokesSolver(mesh, approximation, bcs=flow.boundary_conditions(), domain=domain, solver=solver)
        self.temperature = dolfinx.fem.Constant(mesh, 0.0)
        V, Q = self.stokes.V, self.stokes.Q
        self.num_dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs + Q.dofmap.index_map.size_global
        self.iterations = 0

    @property
    def velocity(self) -> dolfinx.fem.Function:
        return self.stokes.u

    def solve(self) -> tuple[float, float]:
        """One solve from a zero initial guess; returns (assembly, solve) seconds on this rank."""
        self.stokes.u.x.array[:] = 0.0
        self.stokes.p.x.array[:] = 0.0
        result = self.stokes.solve(self.temperature)
        self.iterations = result.iterations
        return result.assembly_seconds, result.solve_seconds

    def max_error(self) -> float:
        """Largest nodal velocity error against the exact Couette flow, relative to the largest
        prescribed speed (collective)."""
        V = self.stokes.V
        n = V.dofmap.index_map.size_local
        dim = V.mesh.geometry.dim
        x = V.tabulate_dof_coordinates()[:n].T
        exact = self.flow(x).T
        u = self.stokes.u.x.array.reshape(-1, dim)[:n]
        local = float(np.max(np.abs(u - exact), initial=0.0))
        scale = max(abs(self.flow.omega_inner) * R_IN, abs(self.flow.omega_outer) * R_OUT)
        return float(V.mesh.comm.allreduce(local, op=MPI.MAX)) / scale


# ------------------------------------------------------------------------------------ problem
@dataclass
class CircularProblem:
    """The particles, the flow and the time step of one run."""

    mesh: dolfinx.mesh.Mesh
    swarm: Swarm
    flow: StokesFlow
    advector: Advector
    dt: float
    num_particles: int


class PhaseTimes(NamedTuple):
    """Seconds summed over the steps on this rank, and counts.

    Attributes:
        advect, sort, communicate: Particle phase seconds.
        assemble, solve: Stokes assembly and linear solve seconds (0 without solves).
        particle_seconds: Wall time of the advection steps (advect + sort + communicate).
        stokes_seconds: Wall time of the Stokes steps (assemble + solve + bookkeeping).
        loop_seconds: Wall time of the whole loop.
        particle_cpu_seconds, stokes_cpu_seconds: Process CPU time of the advection steps and of the
            solves (on a loaded machine the gap to the wall time is time spent waiting for a core).
        lost: Particles lost on all ranks (sum over steps).
        sent: Particles this rank sent to other ranks.
        changed_cell: Particle relocations that left the old cell (this rank, all stages).
        relocations: Particle relocations (this rank, all stages).
    """

    advect: float
    sort: float
    communicate: float
    assemble: float
    solve: float
    particle_seconds: float
    stokes_seconds: float
    loop_seconds: float
    particle_cpu_seconds: float
    stokes_cpu_seconds: float
    lost: int
    sent: int
    changed_cell: int
    relocations: int


def setup_problem(
    mesh: dolfinx.mesh.Mesh, /, *, particles_per_cell: float, flow: CouetteFlow | None = None,
    solver: str = "auto", variable_viscosity: bool = True, cfl: float = 0.5, integrator: str = "rk2",
    seed: int = 0,
) -> CircularProblem:
    """Stokes flow (solved once here), ``particles_per_cell * cells`` random_uniform particles kept in
    the shell, CFL time step (collective)."""
    dim = mesh.geometry.dim
    flow = flow if flow is not None else CouetteFlow(dim)
    stokes = StokesFlow(mesh, flow, solver=solver, variable_viscosity=variable_viscosity)
    stokes.solve()
    dt = cfl_timestep(stokes.velocity, cfl)
    cells = mesh.topology.index_map(mesh.topology.dim).size_global
    n = int(round(particles_per_cell * cells))
    swarm = Swarm(mesh)
    generate(swarm, "random_uniform", num_particles=n, seed=seed)
    confine = shell_confinement(mesh, ShellSpec(dim, R_IN, R_OUT, longest_edge(mesh), geometry_degree=1))
    return CircularProblem(mesh, swarm, stokes, Advector(swarm, integrator=integrator, confine=confine), dt, n)


def advance(problem: CircularProblem, steps: int, /, *, solve: bool = True) -> PhaseTimes:
    """Run ``steps`` time steps, each: one Stokes solve (if ``solve``) and one advection step in its
    velocity (collective)."""
    advect = sort = comm_time = assemble = solve_time = particle = stokes = particle_cpu = stokes_cpu = 0.0
    lost = sent = changed = total = 0
    problem.mesh.comm.Barrier()
    start = time.perf_counter()
    for _ in range(steps):
        if solve:
            t0, c0 = time.perf_counter(), time.process_time()
            seconds = problem.flow.solve()
            assemble += seconds[0]
            solve_time += seconds[1]
            stokes += time.perf_counter() - t0
            stokes_cpu += time.process_time() - c0
        u = problem.flow.velocity
        t0, c0 = time.perf_counter(), time.process_time()
        stats = problem.advector.step(u, u, problem.dt)
        particle += time.perf_counter() - t0
        particle_cpu += time.process_time() - c0
        advect += stats.evaluation_seconds
        sort += stats.relocation_seconds
        comm_time += stats.communication_seconds
        lost += stats.global_lost
        sent += stats.sent
        changed += stats.transport.neighbour + stats.transport.fallback + stats.transport.not_found
        total += sum(stats.transport)
    loop = time.perf_counter() - start
    return PhaseTimes(advect, sort, comm_time, assemble, solve_time, particle, stokes, loop, particle_cpu, stokes_cpu,
                      lost, sent, changed, total)


# ------------------------------------------------------------------------------------- worker
def _id_checksum(swarm: Swarm) -> list[int]:
    """Global count, sum of ids and sum of (id mod 1000003)^2 (collective; equal sets give equal sums)."""
    ids = swarm.ids
    local = np.array([ids.shape[0], ids.sum(), np.sum((ids % 1000003) ** 2)], dtype=np.int64)
    return [int(v) for v in swarm.comm.allreduce(local, op=MPI.SUM)]


def _radii_range(swarm: Swarm) -> tuple[float, float]:
    r = np.linalg.norm(swarm.x, axis=1)
    lo = swarm.comm.allreduce(float(r.min(initial=np.inf)), op=MPI.MIN)
    hi = swarm.comm.allreduce(float(r.max(initial=-np.inf)), op=MPI.MAX)
    return lo, hi


def worker(args: argparse.Namespace) -> dict:
    """One configuration on MPI.COMM_WORLD; returns the record (rank 0 prints it)."""
    comm = MPI.COMM_WORLD
    load_start = os.getloadavg()
    t0 = time.perf_counter()
    size = args.radial if args.dim == 2 else args.resolution
    mesh = create_domain(comm, args.dim, size)
    flow = CouetteFlow(args.dim, args.omega_inner, args.omega_outer)
    options = dict(flow=flow, solver=args.solver, variable_viscosity=args.variable_viscosity, cfl=args.cfl,
                   integrator=args.integrator)
    # Warm-up on a small problem: numba compilation / cache load, form JIT, first DOLFINx calls.
    small = setup_problem(mesh, particles_per_cell=min(args.particles_per_cell, 0.05), seed=args.seed + 1, **options)
    advance(small, 2, solve=False)
    del small
    problem = setup_problem(mesh, particles_per_cell=args.particles_per_cell, seed=args.seed, **options)
    setup = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    before = _id_checksum(problem.swarm)
    local_counts = comm.allgather(problem.swarm.num_particles)
    times = advance(problem, args.steps, solve=args.solve)
    after = _id_checksum(problem.swarm)
    slowest = {k: comm.allreduce(getattr(times, k), op=MPI.MAX)
               for k in ("advect", "sort", "communicate", "assemble", "solve", "particle_seconds", "stokes_seconds",
                         "loop_seconds", "particle_cpu_seconds", "stokes_cpu_seconds")}
    cell_map = mesh.topology.index_map(mesh.topology.dim)
    n = problem.num_particles
    changed = comm.allreduce(times.changed_cell, op=MPI.SUM)
    relocations = comm.allreduce(times.relocations, op=MPI.SUM)
    r_min, r_max = _radii_range(problem.swarm)
    return {
        "dim": args.dim,
        "ranks": comm.size,
        "size": size,
        "cells": cell_map.size_global,
        "cells_per_rank_max": comm.allreduce(cell_map.size_local, op=MPI.MAX),
        "h_max": longest_edge(mesh),
        "particles": n,
        "particles_per_rank": local_counts,
        "particles_final": after[0],
        "ids_unchanged": before == after,
        "lost": times.lost,
        "radius_min": r_min,
        "radius_max": r_max,
        "sent_per_step": comm.allreduce(times.sent, op=MPI.SUM) / max(args.steps, 1),
        "changed_cell_fraction": changed / max(relocations, 1),
        "omega": [flow.omega_inner, flow.omega_outer],
        "integrator": args.integrator,
        "cfl": args.cfl,
        "dt": problem.dt,
        "steps": args.steps,
        **slowest,
        "particle_updates_per_second": n * args.steps / slowest["particle_seconds"] if slowest["particle_seconds"] else 0.0,
        "solver": problem.flow.stokes.solver,
        "variable_viscosity": args.variable_viscosity,
        "stokes_dofs": problem.flow.num_dofs,
        "stokes_iterations": problem.flow.iterations,
        "velocity_error": problem.flow.max_error(),
        "setup_seconds": setup,
        "load_start": load_start[0],
        "load_end": os.getloadavg()[0],
    }


# ------------------------------------------------------------------------------------- driver
@dataclass(frozen=True)
class RunSpec:
    """One configuration: study name, ranks and mesh size (2D: radial layers; 3D: cell size)."""

    study: str
    ranks: int
    size: float


def plan(studies: list[str], ranks: list[int], strong_size: float, weak_size: float, dim: int = 2) -> list[RunSpec]:
    """The runs: strong keeps ``strong_size``; weak scales the cells with the ranks (2D: radial layers
    ~ sqrt(ranks); 3D: cell size ~ ranks^(-1/3))."""
    runs = []
    for study in studies:
        for n in ranks:
            if study == "strong":
                size = strong_size
            elif dim == 2:
                size = int(round(weak_size * math.sqrt(n)))
            else:
                size = round(weak_size / n ** (1.0 / 3.0), 4)
            runs.append(RunSpec(study, n, size))
    return runs


def run_one(spec: RunSpec, args: argparse.Namespace) -> dict:
    """Run one configuration under mpirun and parse its JSON line."""
    env = dict(mpi_environment(), PYTHONUNBUFFERED="1")
    cmd = [shutil.which("mpirun") or "mpirun", "-n", str(spec.ranks), "--bind-to", "none"]
    if args.yield_when_idle:
        cmd += ["--mca", "mpi_yield_when_idle", "1"]
    if spec.ranks > (os.cpu_count() or 1):
        cmd.append("--oversubscribe")
    size = ["--radial", str(int(spec.size))] if args.dim == 2 else ["--resolution", str(spec.size)]
    cmd += [sys.executable, "-m", "benchmarks.scaling.circular", "--worker", "--dim", str(args.dim), *size,
            "--particles-per-cell", str(args.particles_per_cell), "--steps", str(args.steps), "--cfl", str(args.cfl),
            "--omega-inner", str(args.omega_inner), "--omega-outer", str(args.omega_outer),
            "--integrator", args.integrator, "--solver", args.solver, "--seed", str(args.seed)]
    if not args.solve:
        cmd.append("--no-solve")
    if not args.variable_viscosity:
        cmd.append("--constant-viscosity")
    print("$", " ".join(cmd), flush=True)
    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    out = subprocess.run(cmd, cwd=ROOT, env=env, check=True, capture_output=True, text=True, timeout=3600).stdout
    record = json.loads([line for line in out.splitlines() if line.startswith("{")][-1])
    record["study"] = spec.study
    record["uptime"] = uptime
    record["load_5min"] = os.getloadavg()[1]
    record["oversubscribed"] = spec.ranks > (os.cpu_count() or 1)
    print(json.dumps(record), flush=True)
    return record


def efficiencies(records: list[dict]) -> None:
    """Add ``efficiency`` (total), ``particle_efficiency`` and ``stokes_efficiency`` relative to the
    1-rank run of the study (weak: work measured by particles, and by Stokes dofs for the solve)."""
    base = next((r for r in records if r["ranks"] == 1), None)
    for r in records:
        if base is None:
            r["efficiency"] = r["particle_efficiency"] = r["stokes_efficiency"] = float("nan")
            continue
        scale = r["ranks"] if r["study"] == "strong" else 1
        weak = r["study"] != "strong"
        work = r["particles"] / (base["particles"] * r["ranks"]) if weak else 1.0
        dof_work = r.get("stokes_dofs", 1) / (base.get("stokes_dofs", 1) * r["ranks"]) if weak else 1.0
        r["efficiency"] = base["loop_seconds"] * work / (scale * r["loop_seconds"])
        r["particle_efficiency"] = base["particle_seconds"] * work / (scale * r["particle_seconds"])
        stokes = r.get("stokes_seconds", 0.0)
        r["stokes_efficiency"] = base.get("stokes_seconds", 0.0) * dof_work / (scale * stokes) if stokes else float("nan")


def _ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}" if b > 0 else "-"


def table(records: list[dict]) -> str:
    """Markdown table of one study."""
    head = ("| ranks | cells | Stokes dofs | particles | assemble s | solve s | advect s | sort s | communicate s "
            "| total s | particle updates/s | efficiency total / Stokes / particles "
            "| cpu/wall (Stokes, particles) | lost | load 1-min start/end |")
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in records:
        ranks = f"{r['ranks']} (oversubscribed)" if r["oversubscribed"] else str(r["ranks"])
        rows.append(
            f"| {ranks} | {r['cells']} | {r['stokes_dofs']} | {r['particles']} | {r['assemble']:.2f} | {r['solve']:.2f} "
            f"| {r['advect']:.2f} | {r['sort']:.2f} | {r['communicate']:.2f} | {r['loop_seconds']:.2f} "
            f"| {r['particle_updates_per_second'] / 1e6:.2f} M "
            f"| {r['efficiency']:.2f} / {r['stokes_efficiency']:.2f} / {r['particle_efficiency']:.2f} "
            f"| {_ratio(r['stokes_cpu_seconds'], r['stokes_seconds'])}, "
            f"{_ratio(r['particle_cpu_seconds'], r['particle_seconds'])} "
            f"| {r['lost']} | {r['load_start']:.1f} / {r['load_end']:.1f} |")
    return "\n".join(rows) + "\n"


PHASES = (("loop_seconds", "total"), ("assemble", "Stokes assemble"), ("solve", "Stokes solve"),
          ("advect", "advect"), ("sort", "sort/relocate"), ("communicate", "communicate"))


def plot(records: list[dict], path: Path) -> None:
    """Strong and weak panels: seconds per phase and total against ranks (hollow = oversubscribed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, study in zip(axes, ("strong", "weak")):
        recs = sorted((r for r in records if r["study"] == study), key=lambda r: r["ranks"])
        if not recs:
            ax.set_visible(False)
            continue
        ranks = np.array([r["ranks"] for r in recs])
        for key, label in PHASES:
            y = np.array([max(r[key], 1e-3) for r in recs])
            line, = ax.plot(ranks, y, "-", label=label)
            for n, v, r in zip(ranks, y, recs):
                ax.plot(n, v, "o", color=line.get_color(), mfc="none" if r["oversubscribed"] else line.get_color())
        t1 = recs[0]["loop_seconds"] * recs[0]["ranks"]
        ideal = t1 / ranks if study == "strong" else np.full(len(ranks), recs[0]["loop_seconds"])
        ax.plot(ranks, ideal, "k:", label="ideal (total)")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xticks(ranks)
        ax.set_xticklabels([f"{n}*" if r["oversubscribed"] else str(n) for n, r in zip(ranks, recs)])
        ax.set_xlabel("ranks (* = oversubscribed, 2 cores)")
        ax.set_ylabel("seconds (slowest rank, summed over steps)")
        loads = [x for r in recs for x in (r["load_start"], r["load_end"])]
        domain = "annulus" if recs[0]["dim"] == 2 else "spherical shell"
        ax.set_title(f"{study} scaling, {domain}, {recs[0]['steps']} steps (Stokes {recs[0]['solver']} + "
                     f"{recs[0]['integrator']})\n(1-min load {min(loads):.1f}-{max(loads):.1f} on {os.cpu_count()} "
                     "cores)", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def report(records: list[dict], args: argparse.Namespace) -> str:
    """Markdown report of all runs."""
    mpi = "waiting ranks yield the core (`--mca mpi_yield_when_idle 1`)" if args.yield_when_idle else "waiting ranks spin"
    domain = (f"Structured annulus {R_IN} <= r <= {R_OUT}" if args.dim == 2
              else f"Spherical shell {R_IN} <= r <= {R_OUT} (gmsh, straight-sided tetrahedra)")
    solver = records[0]["solver"] if records else args.solver
    names = {"direct": "MUMPS", "iterative": "FGMRES + block Schur preconditioner, BoomerAMG on velocity",
             "iterative_gamg": "FGMRES + block Schur preconditioner, GAMG on velocity"}
    solve = (f"Stokes P2-P1 {solver} ({names.get(solver, solver)}), "
             + ("operator reassembled and solver set up again every step (variable-viscosity path), zero initial guess"
                if args.variable_viscosity else "factorisation / preconditioner reused (constant viscosity)"))
    parts = [
        f"# Circular flow with the Stokes solve: scaling, {args.dim}D "
        f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})\n",
        f"{domain}; Couette flow between surfaces rotating at omega = {args.omega_inner:g} (inner) and "
        f"{args.omega_outer:g} (outer) about z, **solved every step**: {solve}. {args.integrator}, CFL {args.cfl}, "
        f"{args.steps} steps, {args.particles_per_cell:g} particles per cell (random_uniform). Phase seconds are the "
        "slowest rank's sum over the steps: assemble / solve = Stokes assembly / linear solve, advect = velocity "
        "evaluation + push, sort = confinement + relocation between cells + sort, communicate = migration. "
        "'total' is the loop wall time; particle updates/s = particles x steps / wall time of the advection steps. "
        "Efficiency: strong T1 / (N TN), weak T1 (work_N / (N work_1)) / TN (work: particles for total and "
        "particles, Stokes dofs for the Stokes column). cpu/wall: process CPU time over wall time (slowest rank "
        f"each). Best of {args.repeat} run(s) per row. {os.cpu_count()} cores shared with other agents; {mpi}; "
        "4 ranks are oversubscribed.\n",
    ]
    for study in ("strong", "weak"):
        recs = [r for r in records if r["study"] == study]
        if not recs:
            continue
        parts.append(f"## {study.capitalize()} scaling\n")
        parts.append(table(recs))
        for r in recs:
            parts.append(
                f"- {r['ranks']} ranks: mesh size {r['size']}, dt {r['dt']:.3g}, "
                f"{100 * r['changed_cell_fraction']:.1f} % of relocations changed cell, {r['sent_per_step']:.0f} "
                f"particles sent between ranks per step, particles per rank at start {r['particles_per_rank']}, "
                f"Stokes {r['stokes_iterations']} iteration(s), largest nodal velocity error against Couette flow "
                f"{r['velocity_error']:.1e}, particle radii {r['radius_min']:.6f} ... {r['radius_max']:.6f}, ids "
                f"unchanged {r['ids_unchanged']}, totals of the repeats "
                f"{[round(t, 2) for t in r['repeats_total_seconds']]} s; `{r['uptime']}`")
        parts.append("")
    return "\n".join(parts)


def driver(args: argparse.Namespace) -> int:
    studies = ["strong", "weak"] if args.study == "both" else [args.study]
    strong = args.strong_size if args.strong_size is not None else (32 if args.dim == 2 else 0.2)
    weak = args.weak_size if args.weak_size is not None else (24 if args.dim == 2 else 0.25)
    records: list[dict] = []
    everything: list[dict] = []
    for spec in plan(studies, args.ranks, strong, weak, args.dim):
        runs = [run_one(spec, args) for _ in range(args.repeat)]
        best = min(runs, key=lambda r: r["loop_seconds"])
        best["repeats_total_seconds"] = [r["loop_seconds"] for r in runs]
        everything += runs
        records.append(best)
    for study in studies:
        efficiencies([r for r in records if r["study"] == study])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = f"results_circular_stokes_{args.dim}d"
    text = report(records, args)
    (out / f"{stem}.md").write_text(text)
    (out / f"{stem}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in everything))
    plot(records, out / f"scaling_circular_stokes_{args.dim}d.png")
    print(text)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--worker", action="store_true", help="run one configuration (under mpirun)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2, help="2: annulus; 3: spherical shell")
    parser.add_argument("--radial", type=int, default=32, help="worker, 2D: cell layers between the circles")
    parser.add_argument("--resolution", type=float, default=0.2, help="worker, 3D: gmsh cell size")
    parser.add_argument("--study", choices=("strong", "weak", "both"), default="both")
    parser.add_argument("--strong-size", type=float, default=None,
                        help="strong scaling mesh: radial layers (2D, default 32) or cell size (3D, default 0.2)")
    parser.add_argument("--weak-size", type=float, default=None,
                        help="weak scaling mesh on 1 rank: radial layers (2D, default 24) or cell size (3D, 0.25)")
    parser.add_argument("--particles-per-cell", type=float, default=16.0)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--cfl", type=float, default=0.5)
    parser.add_argument("--omega-inner", type=float, default=-1.0, help="rotation rate of the inner surface")
    parser.add_argument("--omega-outer", type=float, default=1.0, help="rotation rate of the outer surface")
    parser.add_argument("--integrator", default="rk2")
    parser.add_argument("--solver", default="auto", choices=STOKES_SOLVER_NAMES,
                        help="Stokes solver (auto: direct in 2D, iterative in 3D)")
    parser.add_argument("--constant-viscosity", dest="variable_viscosity", action="store_false",
                        help="let the Stokes solver reuse its factorisation / preconditioner between steps")
    parser.add_argument("--no-solve", dest="solve", action="store_false",
                        help="solve the Stokes flow once before the loop only")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=1, help="runs per configuration; the table keeps the fastest")
    parser.add_argument("--no-yield", dest="yield_when_idle", action="store_false",
                        help="let waiting ranks spin (OpenMPI default without --oversubscribe)")
    args = parser.parse_args(argv)
    if args.worker:
        record = worker(args)
        if MPI.COMM_WORLD.rank == 0:
            print(json.dumps(record), flush=True)
        return 0
    BENCHMARK.log_load("start")
    return driver(args)


if __name__ == "__main__":
    sys.exit(main())
