"""Particle advection throughput on deal.II step-68's Rayleigh-Kothe vortex.

The unit square is split into ``cells x cells`` squares, each cut into two triangles. The velocity

    u(x, y, t) = cos(pi t / 4) (-2 sin^2(pi x) sin(pi y) cos(pi y),  2 sin^2(pi y) sin(pi x) cos(pi x))

is interpolated into a vector Lagrange space of degree ``--degree`` every time step (as step-68
does; as nodal values at the DOF coordinates, checked against ``Function.interpolate``). ``--particles`` particles, uniformly distributed in the annulus around (0.5, 0.75) with radii
0.01 and 0.15, are advected for ``--steps`` steps of dt = 0.002 with ``--integrator``.

The script prints one JSON line: ``particle_updates_per_second`` = particles * steps / seconds of
the timed loop, the time split (field_interpolation, evaluation_push, relocation, communication;
the slowest rank each), ``cpu_seconds`` (process CPU time of the loop: on a shared machine the
gap to ``seconds`` is time the process waited for a core), and ``warmup_seconds``, the numba compilation (or cache load) and first
DOLFINx calls, done on a small copy of the problem before the timed loop.

``--balance`` repartitions the mesh before the timed loop with cell loads ``1 + W n_particles``
(:func:`particles.balance.rebalance`; the particles sit in a small annulus, so the default cell
partition gives nearly all of them to one rank) and builds the velocity space on the new mesh.

``--naive`` runs the straightforward DOLFINx way instead (serial only): every step a bounding-box
collision search, ``compute_colliding_cells`` and ``Function.eval`` for every particle, Euler.

Run: ``python -m benchmarks.performance.vortex --cells 64 --particles 393216 --steps 50``
or under ``mpirun -n 2`` (particles then migrate between ranks).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from mpi4py import MPI

import dolfinx.fem
import dolfinx.geometry
import dolfinx.mesh

from benchmarks.harness import Benchmark
from fembase.dolfinx_compat import bounding_box_tree, compute_collisions, function_space
from fembase.evaluation import locate
from fembase.partition import PARTITIONERS
from particles import Swarm
from particles.advection import INTEGRATORS, Advector
from particles.balance import rebalance

BENCHMARK = Benchmark(__doc__)
DT = 0.002
CENTRE = np.array([0.5, 0.75])
RADII = (0.01, 0.15)


class Vortex:
    """The Rayleigh-Kothe velocity at time ``t`` (callable for ``Function.interpolate``)."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self, x: np.ndarray) -> np.ndarray:
        s = np.cos(np.pi * self.t / 4.0)
        px, py = np.pi * x[0], np.pi * x[1]
        return np.stack([
            -2.0 * s * np.sin(px) ** 2 * np.sin(py) * np.cos(py),
            2.0 * s * np.sin(py) ** 2 * np.sin(px) * np.cos(px),
        ])


class NodalInterpolation:
    """Lagrange interpolation as point values at the DOF coordinates (owned and ghost).

    Gives the same coefficients as ``Function.interpolate`` for Lagrange spaces (checked once
    here) without DOLFINx's per-cell evaluation of the Python callable.
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace) -> None:
        self.points = V.tabulate_dof_coordinates()[:, : V.mesh.geometry.dim].T.copy()
        self.bs = V.dofmap.bs
        check, reference = dolfinx.fem.Function(V), dolfinx.fem.Function(V)
        field = Vortex(0.3)
        self(check, field)
        reference.interpolate(field)
        if not np.allclose(check.x.array, reference.x.array, atol=1e-13):
            raise RuntimeError("nodal interpolation differs from Function.interpolate")

    def __call__(self, u: dolfinx.fem.Function, field: Vortex) -> None:
        u.x.array.reshape(-1, self.bs)[:] = field(self.points).T


def annulus_points(n: int, seed: int) -> np.ndarray:
    """``n`` points uniformly distributed in the annulus, shape=(n, 2) (same on every rank)."""
    rng = np.random.default_rng(seed)
    r = np.sqrt(RADII[0] ** 2 + rng.random(n) * (RADII[1] ** 2 - RADII[0] ** 2))
    phi = 2.0 * np.pi * rng.random(n)
    return CENTRE + r[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=1)


def place(mesh: dolfinx.mesh.Mesh, n: int, seed: int) -> Swarm:
    """Swarm with ids 0..n-1 at the annulus points; each point goes to the lowest rank owning it."""
    comm = mesh.comm
    swarm = Swarm(mesh)
    pts = annulus_points(n, seed)
    found = locate(mesh, pts, geometry=swarm.geometry)
    mine = (found.cells >= 0) & (found.cells < swarm.num_owned_cells)
    if comm.size > 1:
        owner = np.where(mine, comm.rank, comm.size).astype(np.int32)
        lowest = np.empty_like(owner)
        comm.Allreduce(owner, lowest, op=MPI.MIN)
        mine &= lowest == comm.rank
    swarm.add(np.flatnonzero(mine), pts[mine], found.xref[mine], found.cells[mine])
    return swarm


def run_particles(args: argparse.Namespace, mesh: dolfinx.mesh.Mesh, n: int, steps: int) -> dict:
    """Advect with the particles package; returns the timings of this rank."""
    swarm = place(mesh, n, args.seed)
    t0 = time.perf_counter()
    if args.balance:
        options = {} if args.balance_method != "rcb" else {
            "balance": tuple(args.balance_quantities), "axes": tuple(args.balance_axes)}
        swarm = rebalance(swarm, particle_weight=args.particle_weight, method=args.balance_method, **options)
        mesh = swarm.mesh
    t_balance = time.perf_counter() - t0
    V = function_space(mesh, "Lagrange", args.degree, shape=(mesh.geometry.dim,))
    u_old, u_new = dolfinx.fem.Function(V), dolfinx.fem.Function(V)
    field = Vortex(0.0)
    interpolate = NodalInterpolation(V)
    interpolate(u_new, field)
    advector = Advector(swarm, integrator=args.integrator)
    t_interp = t_eval = t_reloc = t_comm = 0.0
    loop = 0.0
    lost = 0
    paths = np.zeros(4, dtype=np.int64)
    sorted_every_step = True
    mesh.comm.Barrier()
    cpu0 = time.process_time()
    for step in range(steps):
        t0 = time.perf_counter()
        u_old, u_new = u_new, u_old
        field.t = (step + 1) * DT
        interpolate(u_new, field)
        t1 = time.perf_counter()
        stats = advector.step(u_old, u_new, DT)
        t2 = time.perf_counter()
        loop += t2 - t0
        t_interp += t1 - t0
        t_eval += stats.evaluation_seconds
        t_reloc += stats.relocation_seconds
        t_comm += stats.communication_seconds
        lost += stats.lost
        paths += np.array(stats.transport)
        sorted_every_step &= bool(np.all(np.diff(swarm.cells) >= 0)) and bool(
            np.all(swarm.cells < swarm.num_owned_cells)) and swarm.offsets[-1] == swarm.num_particles
    cpu = time.process_time() - cpu0
    return {
        "seconds": loop, "cpu_seconds": cpu, "field_interpolation": t_interp, "evaluation_push": t_eval,
        "relocation": t_reloc, "communication": t_comm, "lost": lost, "paths": paths, "sorted": sorted_every_step,
        "final": swarm.num_particles, "initial": n, "balance_seconds": t_balance,
        "particles_per_rank": swarm.num_particles, "cells_per_rank": swarm.num_owned_cells,
    }


def run_naive(args: argparse.Namespace, mesh: dolfinx.mesh.Mesh, n: int, steps: int) -> dict:
    """The plain DOLFINx way: search + Function.eval for every particle every step (Euler)."""
    V = function_space(mesh, "Lagrange", args.degree, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    field = Vortex(0.0)
    x = np.zeros((n, 3))
    x[:, :2] = annulus_points(n, args.seed)
    tree = bounding_box_tree(mesh, mesh.topology.dim)
    t_interp = t_eval = t_search = 0.0
    lost = 0
    loop = 0.0
    cpu0 = time.process_time()
    for step in range(steps):
        t0 = time.perf_counter()
        field.t = step * DT
        u.interpolate(field)
        t1 = time.perf_counter()
        candidates = compute_collisions(tree, x)
        colliding = dolfinx.geometry.compute_colliding_cells(mesh, candidates, x)
        offsets = np.asarray(colliding.offsets)
        found = np.diff(offsets) > 0
        lost += int(np.count_nonzero(~found))
        x = x[found]
        cells = np.asarray(colliding.array)[offsets[:-1][found]]
        t2 = time.perf_counter()
        x[:, :2] += DT * u.eval(x, cells)
        t3 = time.perf_counter()
        loop += t3 - t0
        t_interp += t1 - t0
        t_search += t2 - t1
        t_eval += t3 - t2
    return {
        "seconds": loop, "cpu_seconds": time.process_time() - cpu0, "field_interpolation": t_interp,
        "evaluation_push": t_eval, "relocation": t_search,
        "communication": 0.0, "lost": lost, "paths": np.zeros(4, dtype=np.int64), "sorted": False,
        "final": x.shape[0], "initial": n, "balance_seconds": 0.0,
        "particles_per_rank": x.shape[0], "cells_per_rank": mesh.topology.index_map(2).size_local,
    }


def main() -> None:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cells", type=int, default=64, help="squares per side (each split in 2 triangles)")
    parser.add_argument("--degree", type=int, default=2, help="velocity Lagrange degree")
    parser.add_argument("--particles", type=int, default=393216)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--integrator", default="euler", choices=sorted(INTEGRATORS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--naive", action="store_true", help="plain DOLFINx search + eval every step (serial)")
    parser.add_argument("--balance", action="store_true",
                        help="repartition the mesh for the particles before the timed loop (particles.balance.rebalance)")
    parser.add_argument("--balance-method", default="rcb", choices=sorted(PARTITIONERS))
    parser.add_argument("--particle-weight", type=float, default=1.0, help="W in the cell load 1 + W n_particles")
    parser.add_argument("--balance-quantities", nargs="+", default=["load"], choices=["cells", "particles", "load"],
                        help="what every rcb cut balances (convection runs use all three)")
    parser.add_argument("--balance-axes", nargs="+", type=int, default=[1],
                        help="axes rcb cuts may be perpendicular to (1: horizontal cuts, parallel to the vortex's "
                             "flow through the annulus; 0 1: any)")
    args = parser.parse_args()

    comm = MPI.COMM_WORLD
    if args.naive and comm.size > 1:
        raise SystemExit("--naive runs on one rank only")
    if args.naive and args.balance:
        raise SystemExit("--balance applies to the particle runs only")
    mesh = dolfinx.mesh.create_unit_square(comm, args.cells, args.cells)
    runner = run_naive if args.naive else run_particles

    t0 = time.perf_counter()
    runner(args, mesh, min(args.particles, 1000), 2)
    warmup = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)

    local = runner(args, mesh, args.particles, args.steps)
    slowest = {k: comm.allreduce(local[k], op=MPI.MAX)
               for k in ("seconds", "cpu_seconds", "field_interpolation", "evaluation_push", "relocation", "communication")}
    paths = comm.allreduce(local["paths"], op=MPI.SUM)
    per_rank = comm.allgather((local["particles_per_rank"], local["cells_per_rank"]))
    final = comm.allreduce(local["final"], op=MPI.SUM)
    result = {
        "method": "naive" if args.naive else "particles",
        "particle_updates_per_second": args.particles * args.steps / slowest["seconds"],
        "ns_per_particle_update": 1e9 * slowest["seconds"] / (args.particles * args.steps),
        "particles": args.particles,
        "particles_final": final,
        "cells": mesh.topology.index_map(2).size_global,
        "degree": args.degree,
        "steps": args.steps,
        "integrator": "euler" if args.naive else args.integrator,
        "ranks": comm.size,
        **slowest,
        "warmup_seconds": warmup,
        "balance": (f"{args.balance_method} W={args.particle_weight:g} balance={','.join(args.balance_quantities)} "
                    f"axes={','.join(map(str, args.balance_axes))}") if args.balance else "none",
        "balance_seconds": comm.allreduce(local["balance_seconds"], op=MPI.MAX),
        "particles_per_rank_final": [p for p, _ in per_rank],
        "cells_per_rank": [c for _, c in per_rank],
        "transport_paths": dict(zip(("stayed", "neighbour", "fallback", "not_found"), (int(p) for p in paths))),
        "sorted_after_every_step": bool(comm.allreduce(bool(local["sorted"]), op=MPI.LAND)),
        "load_average_1min": os.getloadavg()[0],
    }
    if comm.rank == 0:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
