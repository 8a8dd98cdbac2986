"""Uniform-mesh particle scaling test: circular flow in an annulus (seed paper, uniform-mesh scaling).

The annulus ``R_IN <= r <= R_OUT`` is meshed by mapping a structured ``radial x angular`` grid of
(r, theta) quadrilaterals, each cut into two triangles, to polar coordinates; the last angular
column reuses the first column's vertices, so the mesh is conforming across the seam. Its boundary
is the polygon through ``angular`` vertices on each circle.

The velocity is purely azimuthal, ``u = f(r) (-y, x)``, interpolated into vector P2 once (the flow
is steady). Two profiles are registered in :data:`FLOWS`:

- ``wall`` (default): ``f(r) = OMEGA 4 (r - R_IN)(R_OUT - r) / (R_OUT - R_IN)^2``, zero on both
  circles. Its P2 interpolant has no normal component on the polygonal boundary (zero at the
  boundary vertices; at an edge midpoint it is parallel to the chord), so particles cannot leave
  the mesh except through the integrator's error, which vanishes at the walls.
- ``rigid``: ``f = OMEGA``, rigid rotation. The discrete boundary is a polygon, so a particle
  moving on a circle close to ``R_OUT`` crosses a chord and is lost (counted and reported).

``particles_per_cell * cells`` particles are placed with the ``random_uniform`` generator and
advected with RK2 at a fixed CFL number (``convection.timestep.cfl_timestep``: shortest edge over
velocity degree, as ASPECT does). Every step times, per rank:

- ``advect``: velocity evaluation and position updates (``AdvectionStats.evaluation_seconds``);
- ``sort``: transport between cells and the counting sort (``relocation_seconds``);
- ``communicate``: migration between ranks (``communication_seconds``);
- ``solve``: **stand-in** for a Stokes solve (the flow is prescribed, nothing needs solving): one
  P2 Poisson solve, ``-lap(phi) = 1``, ``phi = 0`` on the boundary, CG with hypre BoomerAMG (or
  GAMG), assembled once, solved from a zero guess every step. Its error against the exact radial
  solution is reported as a sanity check.

Each phase is summed over the steps per rank; the report gives the slowest rank's sum.

Usage (the driver runs every configuration under ``mpirun`` and collects one JSON line per run)::

    python benchmarks/scaling/circular.py                      # strong + weak, ranks 1 2 4
    python benchmarks/scaling/circular.py --study strong --ranks 1 2
    mpirun -n 2 python benchmarks/scaling/circular.py --worker --radial 32   # one run

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
from typing import Callable, NamedTuple

import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
for _path in (ROOT, HERE.parent / "performance"):
    if str(_path) not in sys.path:
        sys.path.insert(0, str(_path))

from convection.launch import mpi_environment  # noqa: E402
from convection.timestep import cfl_timestep  # noqa: E402
from particles import Swarm  # noqa: E402
from particles.advection import Advector  # noqa: E402
from particles.generation import generate  # noqa: E402
from vortex import NodalInterpolation  # noqa: E402

R_IN = 0.55
R_OUT = 1.0
OMEGA = 1.0

__all__ = [
    "FLOWS",
    "AnnulusLayout",
    "CircularProblem",
    "PhaseTimes",
    "PoissonStandIn",
    "RigidFlow",
    "WallFlow",
    "advance",
    "angular_divisions",
    "annulus_layout",
    "create_annulus",
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
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.triangle, 1))
    return dolfinx.mesh.create_mesh(comm, cells, points, domain, ghost_mode=dolfinx.mesh.GhostMode.shared_facet)


# ----------------------------------------------------------------------------------------- flows
@dataclass(frozen=True)
class WallFlow:
    """``u = f(r) (-y, x)`` with ``f(r) = omega 4 (r - r_in)(r_out - r) / (r_out - r_in)^2`` (zero at both walls)."""

    name = "wall"
    description = "azimuthal flow vanishing on both circles (keeps particles inside)"
    omega: float = OMEGA
    r_in: float = R_IN
    r_out: float = R_OUT

    def angular_velocity(self, r: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return self.omega * 4.0 * (r - self.r_in) * (self.r_out - r) / (self.r_out - self.r_in) ** 2

    def __call__(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Velocity at points x, shape=(gdim or 3, n) -> shape=(2, n)."""
        f = self.angular_velocity(np.hypot(x[0], x[1]))
        return np.stack([-f * x[1], f * x[0]])


@dataclass(frozen=True)
class RigidFlow:
    """Rigid rotation ``u = omega (-y, x)``."""

    name = "rigid"
    description = "rigid rotation (particles near the outer circle can cross the polygonal boundary)"
    omega: float = OMEGA

    def __call__(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Velocity at points x, shape=(gdim or 3, n) -> shape=(2, n)."""
        return np.stack([-self.omega * x[1], self.omega * x[0]])


FLOWS: dict[str, type] = {cls.name: cls for cls in (WallFlow, RigidFlow)}
"""Flow profiles by name."""


def create_flow(name: str) -> Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]:
    """The registered flow ``name`` with default parameters (unknown names list the valid ones)."""
    try:
        return FLOWS[name]()
    except KeyError:
        valid = ", ".join(f"{k} ({v.description})" for k, v in FLOWS.items())
        raise ValueError(f"unknown flow {name!r}; valid: {valid}") from None


# ------------------------------------------------------------------------------ solver stand-in
class PoissonStandIn:
    """P2 Poisson problem ``-lap(phi) = 1``, ``phi = 0`` on the boundary: a stand-in for the per-step
    solver cost (assembled once; :meth:`solve` solves from a zero initial guess). Collective.

    Args:
        mesh: The annulus mesh.
        pc: ``"hypre"`` (BoomerAMG) or ``"gamg"``.
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /, *, pc: str = "hypre", rtol: float = 1e-8) -> None:
        V = dolfinx.fem.FunctionSpace(mesh, ("Lagrange", 2))
        mesh.topology.create_connectivity(1, 2)
        facets = dolfinx.mesh.exterior_facet_indices(mesh.topology)
        bc = dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dolfinx.fem.locate_dofs_topological(V, 1, facets), V)
        phi, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        a = dolfinx.fem.form(ufl.inner(ufl.grad(phi), ufl.grad(v)) * ufl.dx)
        L = dolfinx.fem.form(ufl.as_ufl(1.0) * v * ufl.dx)
        self.A = dolfinx.fem.petsc.assemble_matrix(a, bcs=[bc])
        self.A.assemble()
        self.b = dolfinx.fem.petsc.assemble_vector(L)
        dolfinx.fem.petsc.apply_lifting(self.b, [a], bcs=[[bc]])
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(self.b, [bc])
        self.solution = dolfinx.fem.Function(V)
        self.ksp = PETSc.KSP().create(mesh.comm)
        self.ksp.setOperators(self.A)
        self.ksp.setType("cg")
        self.ksp.getPC().setType(pc)
        if pc == "hypre":
            self.ksp.getPC().setHYPREType("boomeramg")
        self.ksp.setTolerances(rtol=rtol)
        self.num_dofs = V.dofmap.index_map.size_global
        self.iterations = 0

    def solve(self) -> int:
        """One solve from a zero guess; returns the CG iterations."""
        x = self.solution.vector
        x.set(0.0)
        self.ksp.solve(self.b, x)
        if self.ksp.getConvergedReason() <= 0:
            raise RuntimeError(f"stand-in solve diverged (reason {self.ksp.getConvergedReason()})")
        self.solution.x.scatter_forward()
        self.iterations = self.ksp.getIterationNumber()
        return self.iterations

    def max_error(self, r_in: float = R_IN, r_out: float = R_OUT) -> float:
        """Largest nodal error against ``phi(r) = (r_in^2 - r^2)/4 + c ln(r / r_in)`` (collective)."""
        V = self.solution.function_space
        n = V.dofmap.index_map.size_local
        r = np.hypot(*V.tabulate_dof_coordinates()[:n, :2].T)
        c = (r_out**2 - r_in**2) / (4.0 * math.log(r_out / r_in))
        exact = (r_in**2 - r**2) / 4.0 + c * np.log(r / r_in)
        local = float(np.max(np.abs(self.solution.x.array[:n] - exact))) if n else 0.0
        return float(V.mesh.comm.allreduce(local, op=MPI.MAX))


# ------------------------------------------------------------------------------------ problem
@dataclass
class CircularProblem:
    """The particles, the velocity and the time step of one run."""

    mesh: dolfinx.mesh.Mesh
    swarm: Swarm
    velocity: dolfinx.fem.Function
    advector: Advector
    dt: float
    num_particles: int


class PhaseTimes(NamedTuple):
    """Seconds summed over the steps on this rank, and counts.

    Attributes:
        advect, sort, communicate, solve: Phase seconds (``solve`` is the stand-in, 0 without it).
        particle_seconds: Wall time of the advection steps (advect + sort + communicate).
        loop_seconds: Wall time of the whole loop.
        particle_cpu_seconds, solve_cpu_seconds: Process CPU time of the advection steps and of the
            solves (on a loaded machine the gap to the wall time is time spent waiting for a core).
        lost: Particles lost on all ranks (sum over steps).
        sent: Particles this rank sent to other ranks.
        changed_cell: Particle relocations that left the old cell (this rank, all stages).
        relocations: Particle relocations (this rank, all stages).
    """

    advect: float
    sort: float
    communicate: float
    solve: float
    particle_seconds: float
    loop_seconds: float
    particle_cpu_seconds: float
    solve_cpu_seconds: float
    lost: int
    sent: int
    changed_cell: int
    relocations: int


def setup_problem(
    mesh: dolfinx.mesh.Mesh, /, *, particles_per_cell: float, flow: str = "wall", cfl: float = 0.5,
    integrator: str = "rk2", seed: int = 0,
) -> CircularProblem:
    """P2 velocity of ``flow``, ``particles_per_cell * cells`` random_uniform particles, CFL time step (collective)."""
    V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 2))
    u = dolfinx.fem.Function(V)
    NodalInterpolation(V)(u, create_flow(flow))
    dt = cfl_timestep(u, cfl)
    cells = mesh.topology.index_map(mesh.topology.dim).size_global
    n = int(round(particles_per_cell * cells))
    swarm = Swarm(mesh)
    generate(swarm, "random_uniform", num_particles=n, seed=seed)
    return CircularProblem(mesh, swarm, u, Advector(swarm, integrator=integrator), dt, n)


def advance(problem: CircularProblem, steps: int, /, *, solver: PoissonStandIn | None = None) -> PhaseTimes:
    """Run ``steps`` time steps, each: one stand-in solve (if given) and one advection step (collective)."""
    advect = sort = comm_time = solve = particle = particle_cpu = solve_cpu = 0.0
    lost = sent = changed = total = 0
    u = problem.velocity
    problem.mesh.comm.Barrier()
    start = time.perf_counter()
    for _ in range(steps):
        if solver is not None:
            t0, c0 = time.perf_counter(), time.process_time()
            solver.solve()
            solve += time.perf_counter() - t0
            solve_cpu += time.process_time() - c0
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
    return PhaseTimes(advect, sort, comm_time, solve, particle, loop, particle_cpu, solve_cpu, lost, sent, changed, total)


# ------------------------------------------------------------------------------------- worker
def _id_checksum(swarm: Swarm) -> list[int]:
    """Global count, sum of ids and sum of (id mod 1000003)^2 (collective; equal sets give equal sums)."""
    ids = swarm.ids
    local = np.array([ids.shape[0], ids.sum(), np.sum((ids % 1000003) ** 2)], dtype=np.int64)
    return [int(v) for v in swarm.comm.allreduce(local, op=MPI.SUM)]


def worker(args: argparse.Namespace) -> dict:
    """One configuration on MPI.COMM_WORLD; returns the record (rank 0 prints it)."""
    comm = MPI.COMM_WORLD
    load_start = os.getloadavg()
    t0 = time.perf_counter()
    mesh = create_annulus(comm, args.radial)
    # Warm-up on a small problem: numba compilation / cache load, form JIT, first DOLFINx calls.
    small = setup_problem(mesh, particles_per_cell=min(args.particles_per_cell, 0.05), flow=args.flow,
                          cfl=args.cfl, integrator=args.integrator, seed=args.seed + 1)
    advance(small, 2)
    del small
    problem = setup_problem(mesh, particles_per_cell=args.particles_per_cell, flow=args.flow, cfl=args.cfl,
                            integrator=args.integrator, seed=args.seed)
    solver = PoissonStandIn(mesh, pc=args.pc) if args.solve else None
    if solver is not None:
        solver.solve()
    setup = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    before = _id_checksum(problem.swarm)
    local_counts = comm.allgather(problem.swarm.num_particles)
    cpu0 = time.process_time()
    times = advance(problem, args.steps, solver=solver)
    cpu = comm.allreduce(time.process_time() - cpu0, op=MPI.MAX)
    after = _id_checksum(problem.swarm)
    slowest = {k: comm.allreduce(getattr(times, k), op=MPI.MAX)
               for k in ("advect", "sort", "communicate", "solve", "particle_seconds", "loop_seconds",
                         "particle_cpu_seconds", "solve_cpu_seconds")}
    cell_map = mesh.topology.index_map(2)
    n = problem.num_particles
    changed = comm.allreduce(times.changed_cell, op=MPI.SUM)
    relocations = comm.allreduce(times.relocations, op=MPI.SUM)
    return {
        "ranks": comm.size,
        "radial": args.radial,
        "angular": angular_divisions(args.radial),
        "cells": cell_map.size_global,
        "cells_per_rank_max": comm.allreduce(cell_map.size_local, op=MPI.MAX),
        "particles": n,
        "particles_per_rank": local_counts,
        "particles_final": after[0],
        "ids_unchanged": before == after,
        "lost": times.lost,
        "sent_per_step": comm.allreduce(times.sent, op=MPI.SUM) / max(args.steps, 1),
        "changed_cell_fraction": changed / max(relocations, 1),
        "flow": args.flow,
        "integrator": args.integrator,
        "cfl": args.cfl,
        "dt": problem.dt,
        "steps": args.steps,
        **slowest,
        "cpu_seconds": cpu,
        "particle_updates_per_second": n * args.steps / slowest["particle_seconds"] if slowest["particle_seconds"] else 0.0,
        "solve_dofs": solver.num_dofs if solver else 0,
        "solve_iterations": solver.iterations if solver else 0,
        "solve_max_error": solver.max_error() if solver else 0.0,
        "setup_seconds": setup,
        "load_start": load_start[0],
        "load_end": os.getloadavg()[0],
    }


# ------------------------------------------------------------------------------------- driver
@dataclass(frozen=True)
class RunSpec:
    """One configuration: study name, ranks and mesh layers."""

    study: str
    ranks: int
    radial: int


def plan(studies: list[str], ranks: list[int], strong_radial: int, weak_radial: int) -> list[RunSpec]:
    """The runs: strong keeps ``strong_radial``; weak scales cells with ranks (radial ~ sqrt(ranks))."""
    runs = []
    for study in studies:
        for n in ranks:
            radial = strong_radial if study == "strong" else int(round(weak_radial * math.sqrt(n)))
            runs.append(RunSpec(study, n, radial))
    return runs


def run_one(spec: RunSpec, args: argparse.Namespace) -> dict:
    """Run one configuration under mpirun and parse its JSON line."""
    env = dict(mpi_environment(), PYTHONUNBUFFERED="1")
    cmd = [shutil.which("mpirun") or "mpirun", "-n", str(spec.ranks), "--bind-to", "none"]
    if args.yield_when_idle:
        cmd += ["--mca", "mpi_yield_when_idle", "1"]
    if spec.ranks > (os.cpu_count() or 1):
        cmd.append("--oversubscribe")
    cmd += [sys.executable, str(Path(__file__).resolve()), "--worker", "--radial", str(spec.radial),
            "--particles-per-cell", str(args.particles_per_cell), "--steps", str(args.steps), "--cfl", str(args.cfl),
            "--flow", args.flow, "--integrator", args.integrator, "--pc", args.pc, "--seed", str(args.seed)]
    if not args.solve:
        cmd.append("--no-solve")
    print("$", " ".join(cmd), flush=True)
    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    out = subprocess.run(cmd, cwd=ROOT, env=env, check=True, capture_output=True, text=True, timeout=900).stdout
    record = json.loads([line for line in out.splitlines() if line.startswith("{")][-1])
    record["study"] = spec.study
    record["uptime"] = uptime
    record["load_5min"] = os.getloadavg()[1]
    record["oversubscribed"] = spec.ranks > (os.cpu_count() or 1)
    print(json.dumps(record), flush=True)
    return record


PHASES = ("advect", "sort", "communicate", "solve")


def efficiencies(records: list[dict]) -> None:
    """Add ``efficiency`` (total) and ``particle_efficiency`` relative to the 1-rank run of the study."""
    base = next((r for r in records if r["ranks"] == 1), None)
    for r in records:
        if base is None:
            r["efficiency"] = r["particle_efficiency"] = float("nan")
            continue
        scale = r["ranks"] if r["study"] == "strong" else 1
        work = 1.0 if r["study"] == "strong" else r["particles"] / (base["particles"] * r["ranks"])
        r["efficiency"] = base["loop_seconds"] * work / (scale * r["loop_seconds"])
        r["particle_efficiency"] = base["particle_seconds"] * work / (scale * r["particle_seconds"])


def _ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}" if b > 0 else "-"


def table(records: list[dict]) -> str:
    """Markdown table of one study."""
    head = ("| ranks | cells | particles | advect s | sort s | communicate s | solve s (stand-in) | total s "
            "| particle updates/s | efficiency (total) | efficiency (particles) | cpu/wall (particles, solve) "
            "| lost | load 1-min start/end |")
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in records:
        ranks = f"{r['ranks']} (oversubscribed)" if r["oversubscribed"] else str(r["ranks"])
        rows.append(
            f"| {ranks} | {r['cells']} | {r['particles']} | {r['advect']:.2f} | {r['sort']:.2f} | {r['communicate']:.2f} "
            f"| {r['solve']:.2f} | {r['loop_seconds']:.2f} | {r['particle_updates_per_second'] / 1e6:.2f} M "
            f"| {r['efficiency']:.2f} | {r['particle_efficiency']:.2f} "
            f"| {_ratio(r['particle_cpu_seconds'], r['particle_seconds'])}, {_ratio(r['solve_cpu_seconds'], r['solve'])} "
            f"| {r['lost']} | {r['load_start']:.1f} / {r['load_end']:.1f} |")
    return "\n".join(rows) + "\n"


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
        for key, label in (("loop_seconds", "total"), ("advect", "advect"), ("sort", "sort/relocate"),
                           ("communicate", "communicate"), ("solve", "solve (stand-in)")):
            y = np.array([r[key] for r in recs])
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
        ax.set_title(f"{study} scaling, annulus, {recs[0]['steps']} {recs[0]['integrator']} steps\n"
                     f"(1-min load {min(loads):.1f}-{max(loads):.1f} on {os.cpu_count()} cores)", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def report(records: list[dict], args: argparse.Namespace) -> str:
    """Markdown report of all runs."""
    mpi = "waiting ranks yield the core (`--mca mpi_yield_when_idle 1`)" if args.yield_when_idle else "waiting ranks spin"
    parts = [
        f"# Circular flow in an annulus: particle scaling ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})\n",
        f"Annulus {R_IN} <= r <= {R_OUT}, flow `{args.flow}`, {args.integrator}, CFL {args.cfl}, {args.steps} steps, "
        f"{args.particles_per_cell:g} particles per cell (random_uniform). Phase seconds are the slowest rank's sum "
        f"over the steps: advect = velocity evaluation + push, sort = relocation between cells + sort, "
        f"communicate = migration, solve = **stand-in** (P2 Poisson, CG + {args.pc}, once per step; the flow is "
        f"prescribed). 'total' is the loop wall time; particle updates/s = particles x steps / wall time of the "
        f"advection steps. Efficiency: strong T1 / (N TN), weak T1 (work_N / (N work_1)) / TN. cpu/wall: process "
        f"CPU time over wall time (slowest rank each). Best of {args.repeat} run(s) per row. "
        f"{os.cpu_count()} cores shared with other agents; {mpi}; 4 ranks are oversubscribed.\n",
    ]
    for study in ("strong", "weak"):
        recs = [r for r in records if r["study"] == study]
        if not recs:
            continue
        parts.append(f"## {study.capitalize()} scaling\n")
        parts.append(table(recs))
        for r in recs:
            parts.append(
                f"- {r['ranks']} ranks: dt {r['dt']:.3g}, {100 * r['changed_cell_fraction']:.1f} % of relocations changed "
                f"cell, {r['sent_per_step']:.0f} particles sent between ranks per step, particles per rank at start "
                f"{r['particles_per_rank']}, stand-in {r['solve_dofs']} dofs / {r['solve_iterations']} CG iterations "
                f"(max nodal error {r['solve_max_error']:.1e}), ids unchanged {r['ids_unchanged']}, "
                f"totals of the repeats {[round(t, 2) for t in r['repeats_total_seconds']]} s; `{r['uptime']}`")
        parts.append("")
    return "\n".join(parts)


def driver(args: argparse.Namespace) -> int:
    studies = ["strong", "weak"] if args.study == "both" else [args.study]
    records: list[dict] = []
    everything: list[dict] = []
    for spec in plan(studies, args.ranks, args.strong_radial, args.weak_radial):
        runs = [run_one(spec, args) for _ in range(args.repeat)]
        best = min(runs, key=lambda r: r["loop_seconds"])
        best["repeats_total_seconds"] = [r["loop_seconds"] for r in runs]
        everything += runs
        records.append(best)
    for study in studies:
        efficiencies([r for r in records if r["study"] == study])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    text = report(records, args)
    (out / "results_circular.md").write_text(text)
    (out / "results_circular.jsonl").write_text("".join(json.dumps(r) + "\n" for r in everything))
    plot(records, out / "scaling_circular.png")
    print(text)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--worker", action="store_true", help="run one configuration (under mpirun)")
    parser.add_argument("--radial", type=int, default=32, help="worker: cell layers between the circles")
    parser.add_argument("--study", choices=("strong", "weak", "both"), default="both")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--strong-radial", type=int, default=32, help="strong scaling: cell layers")
    parser.add_argument("--weak-radial", type=int, default=24, help="weak scaling: cell layers on 1 rank")
    parser.add_argument("--particles-per-cell", type=float, default=16.0)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--cfl", type=float, default=0.5)
    parser.add_argument("--flow", default="wall", choices=sorted(FLOWS))
    parser.add_argument("--integrator", default="rk2")
    parser.add_argument("--pc", default="hypre", choices=("hypre", "gamg"))
    parser.add_argument("--no-solve", dest="solve", action="store_false", help="skip the stand-in solve")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=1, help="runs per configuration; the table keeps the fastest")
    parser.add_argument("--no-yield", dest="yield_when_idle", action="store_false",
                        help="let waiting ranks spin (OpenMPI default without --oversubscribe)")
    parser.add_argument("--out", default=str(HERE))
    args = parser.parse_args(argv)
    if args.worker:
        record = worker(args)
        if MPI.COMM_WORLD.rank == 0:
            print(json.dumps(record), flush=True)
        return 0
    return driver(args)


if __name__ == "__main__":
    sys.exit(main())
