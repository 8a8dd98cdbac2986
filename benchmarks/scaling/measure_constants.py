"""Measure the constants of the cost model (``cost_model.md``) on this machine.

Subcommands (each prints JSON lines; run from the repository root):

    mpirun -n 2 python -m benchmarks.scaling.measure_constants mpi          # allreduce / neighbour / allgather latency
    mpirun -n 2 python -m benchmarks.scaling.measure_constants migration    # Migrator.migrate: fixed + per-particle cost
    python -m benchmarks.scaling.measure_constants loops                    # O(P) Python/numpy code paths at fake P
    python -m benchmarks.scaling.measure_constants serialmesh               # rank-0 gather_cell_layout + create_mesh per cell
    python -m benchmarks.scaling.measure_constants stokes                   # Stokes: 2D direct, 3D iterative, per dof
    python -m benchmarks.scaling.measure_constants vortex -- <vortex.py args>   # vortex.py with Swarm.sort timed apart

Every number is wall time (``time.perf_counter``) on whatever the machine gives the process; the
machine is shared, so repeat and take the best.
"""

from __future__ import annotations

import json
import pickle
import runpy
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fembase.dolfinx_compat import function_space, geometry_dofmap

ROOT = Path(__file__).resolve().parents[2]


def _best(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _emit(comm: MPI.Comm, record: dict) -> None:
    if comm.rank == 0:
        print(json.dumps(record), flush=True)


# ---------------------------------------------------------------------------------------------- MPI
def mpi_latency() -> None:
    comm = MPI.COMM_WORLD
    other = (comm.rank + 1) % comm.size
    reps = 2000
    # allreduce of five int64 counts (what every migration does), lower-case (pickle) and buffer.
    for name, fn in [
        ("allreduce_5int64_pickle", lambda: comm.allreduce(np.arange(5, dtype=np.int64), op=MPI.SUM)),
        ("allreduce_int_pickle", lambda: comm.allreduce(1, op=MPI.SUM)),
        ("Allreduce_5int64_buffer", lambda: comm.Allreduce(np.arange(5, dtype=np.int64), np.empty(5, np.int64))),
        ("Barrier", comm.Barrier),
    ]:
        for _ in range(100):
            fn()
        comm.Barrier()
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        dt = (time.perf_counter() - t0) / reps
        best = np.inf  # best of 3 loops of 300 calls: the least disturbed figure on a shared machine
        for _ in range(3):
            comm.Barrier()
            t0 = time.perf_counter()
            for _ in range(300):
                fn()
            best = min(best, (time.perf_counter() - t0) / 300)
        _emit(comm, {"what": name, "ranks": comm.size, "seconds_per_call": comm.allreduce(dt, op=MPI.MAX),
                     "best_loop_seconds_per_call": comm.allreduce(best, op=MPI.MAX)})

    # Neighbour exchange as in Migrator._neighbour_exchange: counts, then one float64 table.
    ncols = 2 + 2 + 2 + 1  # 2D swarm with one property column
    for rows in (0, 10, 100, 1000, 10000, 100000):
        table = np.random.default_rng(0).random((rows, ncols))

        def exchange() -> None:
            sc, rc = np.array([rows], np.int64), np.zeros(1, np.int64)
            reqs = [comm.Irecv(rc, source=other, tag=1), comm.Isend(sc, dest=other, tag=1)]
            MPI.Request.Waitall(reqs)
            if rows:
                recv = np.empty((int(rc[0]), ncols))
                reqs = [comm.Irecv(recv, source=other, tag=2), comm.Isend(table, dest=other, tag=2)]
                MPI.Request.Waitall(reqs)

        n = 2000 if rows <= 1000 else 100
        for _ in range(20):
            exchange()
        comm.Barrier()
        t0 = time.perf_counter()
        for _ in range(n):
            exchange()
        dt = (time.perf_counter() - t0) / n
        _emit(comm, {"what": "neighbour_exchange", "ranks": comm.size, "rows": rows, "bytes": rows * ncols * 8,
                     "seconds_per_call": comm.allreduce(dt, op=MPI.MAX)})

    # Python cost of posting k Irecv/Isend pairs (to self) and waiting: per-neighbour overhead.
    for k in (1, 26):
        bufs = [np.zeros(1, np.int64) for _ in range(k)]
        rbufs = [np.zeros(1, np.int64) for _ in range(k)]

        def post() -> None:
            reqs = [comm.Irecv(rbufs[i], source=comm.rank, tag=10 + i) for i in range(k)]
            reqs += [comm.Isend(bufs[i], dest=comm.rank, tag=10 + i) for i in range(k)]
            MPI.Request.Waitall(reqs)

        t = _best(lambda: [post() for _ in range(100)], 5) / 100
        _emit(comm, {"what": "self_messages", "pairs": k, "seconds_per_round": comm.allreduce(t, op=MPI.MAX)})

    # Allgather of an 8 MB and 80 kB buffer (bandwidth) and of Python objects (pickle).
    for doubles in (1000, 10000, 1000000):
        send = np.ones(doubles)
        recv = np.empty(doubles * comm.size)
        n = 200 if doubles <= 10000 else 10
        t = _best(lambda: comm.Allgather(send, recv), n)
        _emit(comm, {"what": "Allgather_float64", "ranks": comm.size, "doubles_per_rank": doubles,
                     "seconds_per_call": comm.allreduce(t, op=MPI.MAX)})
    for doubles in (10000, 1000000):
        send = np.ones(doubles)
        t = _best(lambda: comm.gather(send, root=0), 10)
        _emit(comm, {"what": "gather_pickle_float64", "ranks": comm.size, "doubles_per_rank": doubles,
                     "seconds_per_call": comm.allreduce(t, op=MPI.MAX)})


# ----------------------------------------------------------------------------------------- migration
def migration_cost() -> None:
    import dolfinx.mesh

    from particles import Swarm
    from particles.parallel.migration import migrator_for

    comm = MPI.COMM_WORLD
    n = 64
    mesh = dolfinx.mesh.create_unit_square(comm, n, n)
    tdim = mesh.topology.dim
    imap = mesh.topology.index_map(tdim)
    num_owned, num_ghost = imap.size_local, imap.num_ghosts
    dofs = geometry_dofmap(mesh)
    coords = mesh.geometry.x[:, :2]
    rng = np.random.default_rng(comm.rank)
    per_cell = 48
    cells = np.repeat(np.arange(num_owned, dtype=np.int32), per_cell)
    r = rng.random((cells.shape[0], 2))
    flip = r.sum(axis=1) > 1
    r[flip] = 1 - r[flip]
    v = coords[dofs[cells]]
    x = v[:, 0] + r[:, :1] * (v[:, 1] - v[:, 0]) + r[:, 1:] * (v[:, 2] - v[:, 0])
    offset = comm.exscan(cells.shape[0]) or 0
    swarm = Swarm(mesh)
    swarm.add(offset + np.arange(cells.shape[0]), x, r, cells)
    migrator = migrator_for(mesh)
    ghost = np.arange(num_owned, num_owned + num_ghost, dtype=np.int32)
    gmid = coords[dofs[ghost]].mean(axis=1)
    third = np.full(2, 1.0 / 3.0)
    _emit(comm, {"what": "migration_setup", "ranks": comm.size, "cells_owned": num_owned, "ghost_cells": num_ghost,
                 "particles_per_rank": swarm.num_particles, "neighbours": [int(q) for q in migrator.neighbours]})
    for k in (0, 10, 100, 1000, 10000, 50000):
        wait, own, cpu, srt, sent = [], [], [], [], 0
        for rep in range(9):
            rows = rng.choice(swarm.num_particles, size=min(k, swarm.num_particles), replace=False)
            # in place (the setters would drop the buffers' spare rows); the last sort cleared the
            # relocation's pending counts, so migrate scans ``cells`` afresh
            pick = ghost[rng.integers(0, num_ghost, size=rows.shape[0])]
            swarm.cells[rows] = pick
            swarm.x[rows] = gmid[pick - num_owned]
            swarm.xref[rows] = third
            t0 = time.perf_counter()
            comm.Barrier()
            t1 = time.perf_counter()
            c1 = time.process_time()
            stats = migrator.migrate(swarm, sort=False)
            c2 = time.process_time()
            t2 = time.perf_counter()
            swarm.sort()
            t3 = time.perf_counter()
            wait.append(t1 - t0)
            own.append(t2 - t1)
            cpu.append(c2 - c1)
            srt.append(t3 - t2)
            sent = stats.global_sent
        own_max = comm.allreduce(min(own), op=MPI.MAX)
        _emit(comm, {"what": "migrate", "ranks": comm.size, "sent_per_rank": k, "global_sent": sent,
                     "particles_per_rank": swarm.num_particles, "migrate_seconds_best": own_max,
                     "migrate_seconds_median": comm.allreduce(float(np.median(own)), op=MPI.MAX),
                     "migrate_cpu_best": comm.allreduce(min(cpu), op=MPI.MAX),
                     "migrate_cpu_median": comm.allreduce(float(np.median(cpu)), op=MPI.MAX),
                     "sort_seconds_best": comm.allreduce(min(srt), op=MPI.MAX),
                     "barrier_wait_median": comm.allreduce(float(np.median(wait)), op=MPI.MAX)})


# ---------------------------------------------------------------------------------------- O(P) loops
def python_loops() -> None:
    """The code paths whose cost grows with the number of ranks P, run with fake P on one process."""
    import dolfinx.mesh

    from particles import Swarm
    from particles.parallel.migration import Migrator

    comm = MPI.COMM_WORLD
    # The real Migrator methods on one rank with the allgathered boxes replaced by P boxes.
    mesh = dolfinx.mesh.create_unit_cube(comm, 4, 4, 4)
    migrator = Migrator(mesh)
    swarm = Swarm(mesh)
    for P in (12, 768, 12288):
        rng = np.random.default_rng(4)
        lo = rng.random((P, 3)) * 0.9
        migrator.owned_boxes = np.stack([lo, lo + 0.1], axis=1)
        migrator._is_neighbour = np.zeros(P, dtype=bool)
        real = {}
        for m in (0, 160):
            xq = rng.random((m, 3))
            real[f"Migrator._box_candidates_m{m}"] = _best(lambda: migrator._box_candidates(xq), 5)
        empty = np.zeros((0, P), dtype=bool)
        real["Migrator._decide_m0"] = _best(lambda: migrator._decide(swarm, empty, {}, (1, 2)), 5)
        _emit(comm, {"what": "real_migrator_paths", "P": P, **real})
    for P in (12, 96, 768, 3072, 12288):
        # Migrator._decide: {r: ... for r in range(inside.shape[1]) if inside[:, r].any()} with m = 0
        # unlocated particles (every migration on more than one rank).
        inside0 = np.zeros((0, P), dtype=bool)
        t_decide0 = _best(lambda: {r: np.flatnonzero(inside0[:, r]) for r in range(inside0.shape[1])
                                   if inside0[:, r].any()}, 5)
        inside8 = np.zeros((8, P), dtype=bool)
        t_decide8 = _best(lambda: {r: np.flatnonzero(inside8[:, r]) for r in range(inside8.shape[1])
                                   if inside8[:, r].any()}, 5)
        # Migrator._box_candidates for m points against P boxes (m x P x gdim comparisons).
        boxes = np.random.default_rng(0).random((P, 2, 3))
        res = {}
        for m in (0, 8, 160):
            xq = np.random.default_rng(1).random((m, 3))

            def box() -> None:
                lower, upper = boxes[:, 0, :], boxes[:, 1, :]
                finite = boxes[np.isfinite(boxes)]
                tol = 1e-12 * max(1.0, float(np.abs(finite).max(initial=1.0)))
                inside = np.all((xq[:, None, :] >= lower[None] - tol) & (xq[:, None, :] <= upper[None] + tol), axis=2)
                inside[:, 0] = False
                inside.sum(axis=1)
                np.all(~inside | np.zeros(P, bool)[None, :], axis=1)

            res[m] = _best(box, 5)
        # _sparse_exchange / _fallback: a dict over range(P) of recv counts, and np.zeros(P) counts.
        recv_counts = np.zeros(P, dtype=np.int64)
        t_sparse = _best(lambda: {r: None for r in range(P) if recv_counts[r] > 0}, 5)
        # RankLoads.measure / timing: allgather of a tuple per rank, then zip over P entries.
        gathered = [(1000, 20000, 1200.0)] * P
        t_loads = _best(lambda: [np.array(col) for col in zip(*gathered)], 5)
        # wanted_levels: np.quantile over all cells (allgathered indicator) for 1000 cells per rank.
        ind = np.random.default_rng(2).random(P * 1000)
        t_quant = _best(lambda: (np.quantile(ind, 0.9), np.quantile(ind, 0.1)), 3)
        # generation/_ordering.key_order_offsets: P boolean masks over the m local keys, then a
        # pickled alltoall of P tuples (the pickling of the P-entry list is timed here).
        keys = np.random.default_rng(3).random((1000, 3))
        bucket = np.clip(np.floor(keys[:, 0] * P), 0, P - 1).astype(np.int64)
        cnt = np.ones(1000, dtype=np.int64)
        lidx = np.arange(1000)
        t_keyorder = _best(lambda: [(keys[bucket == r], cnt[bucket == r], lidx[bucket == r]) for r in range(P)], 3)
        outgoing = [(keys[bucket == r], cnt[bucket == r], lidx[bucket == r]) for r in range(P)]
        t_pickle = _best(lambda: pickle.loads(pickle.dumps(outgoing, protocol=5)), 3)
        _emit(comm, {"what": "python_loops", "P": P, "key_order_masks_m1000": t_keyorder,
                     "pickle_roundtrip_P_tuples": t_pickle, "decide_loop_m0": t_decide0, "decide_loop_m8": t_decide8,
                     "box_candidates_m0": res[0], "box_candidates_m8": res[8], "box_candidates_m160": res[160],
                     "sparse_exchange_dict": t_sparse, "rankloads_zip": t_loads,
                     "quantile_1000_cells_per_rank": t_quant})


# ------------------------------------------------------------------------------------- serial mesh
def serial_mesh() -> None:
    """Rank-0 part of a repartition: gather_cell_layout (np.unique of the corners) + create_mesh."""
    import ufl
    import dolfinx.mesh

    from fembase.distribute import create_partitioned_mesh, gather_cell_layout

    comm = MPI.COMM_WORLD
    for dim, n in ((2, 64), (2, 128), (2, 256), (3, 12), (3, 20), (3, 28)):
        mesh = (dolfinx.mesh.create_unit_square(comm, n, n) if dim == 2 else dolfinx.mesh.create_unit_cube(comm, n, n, n))
        num = mesh.topology.index_map(dim).size_local
        canonical = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[:num]
        t0 = time.perf_counter()
        layout = gather_cell_layout(mesh, canonical)
        t1 = time.perf_counter()
        owners = np.zeros(layout.num_cells, dtype=np.int32)
        create_partitioned_mesh(comm, layout, owners, ufl.Mesh(mesh.ufl_domain().ufl_coordinate_element()))
        t2 = time.perf_counter()
        _emit(comm, {"what": "serial_mesh", "dim": dim, "cells": int(layout.num_cells), "gather_layout_s": t1 - t0,
                     "create_mesh_s": t2 - t1, "per_cell_us": 1e6 * (t2 - t0) / layout.num_cells})


# ------------------------------------------------------------------------------------------- Stokes
def stokes_cost() -> None:
    import dolfinx.fem
    import dolfinx.mesh

    from convection.physics.approximation import BoussinesqApproximation
    from convection.geometry.boundary import VelocityBC
    from convection.geometry.box import SIDES_2D, SIDES_3D
    from convection.solvers.stokes.solver import StokesSolver

    comm = MPI.COMM_WORLD
    cases = [(2, 32, "direct"), (2, 64, "direct"), (2, 96, "direct"), (3, 6, "iterative"), (3, 10, "iterative")]
    for dim, n, solver in cases:
        if dim == 2:
            mesh = dolfinx.mesh.create_unit_square(comm, n, n)
            sides = SIDES_2D
        else:
            mesh = dolfinx.mesh.create_unit_cube(comm, n, n, n)
            sides = SIDES_3D
        T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
        T.interpolate(lambda x: 0.5 + 0.1 * np.sin(np.pi * x[dim - 1]) * np.cos(np.pi * x[0]))
        stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=1e6), bcs={s: VelocityBC("free_slip") for s in sides},
                              solver=solver)
        first = stokes.solve(T)
        T.interpolate(lambda x: 0.5 + 0.11 * np.sin(np.pi * x[dim - 1]) * np.cos(np.pi * x[0]))
        t0 = time.perf_counter()
        second = stokes.solve(T)  # operator unchanged (constant viscosity): warm start, no setup
        t1 = time.perf_counter()
        dofs = sum(V.dofmap.index_map.size_global * V.dofmap.index_map_bs for V in (stokes.V, stokes.Q))
        _emit(comm, {"what": "stokes", "dim": dim, "n": n, "solver": stokes.solver, "dofs": int(dofs),
                     "first": {"iterations": first.iterations, "assembly_s": first.assembly_seconds,
                               "solve_s": first.solve_seconds, "setup_s": first.setup_seconds},
                     "second": {"iterations": second.iterations, "assembly_s": second.assembly_seconds,
                                "solve_s": second.solve_seconds, "setup_s": second.setup_seconds, "wall_s": t1 - t0}})
        stokes.destroy()


# ------------------------------------------------------------------------------- 3D RK2 advection
def advect3d(n: int = 12, per_cell: int = 20, steps: int = 10, integrator: str = "rk2") -> None:
    """RK2 in a unit cube of n^3 x 6 tetrahedra, P2 velocity of a rigid rotation about the z axis
    through (0.5, 0.5) scaled by (r_max - r) so that it vanishes before the walls (particles stay
    inside); per_cell random particles per cell. Per-phase wall and CPU seconds, slowest rank."""
    import dolfinx.fem
    import dolfinx.mesh

    from particles.advection import Advector
    from particles.parallel.migration import Migrator
    from particles.storage.swarm import Swarm

    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_cube(comm, n, n, n)
    tdim = 3
    num_owned = mesh.topology.index_map(tdim).size_local
    dofs = geometry_dofmap(mesh)
    coords = mesh.geometry.x
    rng = np.random.default_rng(comm.rank)
    cells = np.repeat(np.arange(num_owned, dtype=np.int32), per_cell)
    # uniform points in a tetrahedron: sorted uniforms give barycentric gaps
    u = np.sort(rng.random((cells.shape[0], 3)), axis=1)
    lam = np.diff(np.concatenate([np.zeros((u.shape[0], 1)), u, np.ones((u.shape[0], 1))], axis=1), axis=1)
    v = coords[dofs[cells]]
    x = np.einsum("pk,pkd->pd", lam, v)
    xref = lam[:, 1:]
    offset = comm.exscan(cells.shape[0]) or 0
    swarm = Swarm(mesh)
    swarm.add(offset + np.arange(cells.shape[0]), x, xref, cells)
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    uh = dolfinx.fem.Function(V)

    def rotation(xx):
        dx, dy = xx[0] - 0.5, xx[1] - 0.5
        r = np.sqrt(dx * dx + dy * dy)
        f = np.clip(0.45 - r, 0.0, None) / 0.45
        return np.stack([-dy * f, dx * f, 0.0 * dx])

    uh.interpolate(rotation)
    # dt: a particle at the fastest point moves about 0.5 cell per step (CFL 0.5 on h = 1/n)
    vmax = 0.225 * 0.225 / 0.45  # max of r (0.45 - r) / 0.45, at r = 0.225
    dt = 0.5 / n / vmax * (0.1125 / 0.125)  # the dt of the measured runs (they used vmax = 0.125)
    calls = {"sort": 0.0, "migrate": 0.0, "sort_cpu": 0.0, "migrate_cpu": 0.0, "migrations": 0, "sent": 0,
             "received": 0, "fallback_sent": 0}
    orig_sort, orig_migrate = Swarm.sort, Migrator.migrate

    def timed_sort(self, *a, **k):
        t0, c0 = time.perf_counter(), time.process_time()
        out = orig_sort(self, *a, **k)
        calls["sort"] += time.perf_counter() - t0
        calls["sort_cpu"] += time.process_time() - c0
        return out

    def timed_migrate(self, sw, *a, **k):
        t0, c0 = time.perf_counter(), time.process_time()
        out = orig_migrate(self, sw, *a, **k)
        calls["migrate"] += time.perf_counter() - t0
        calls["migrate_cpu"] += time.process_time() - c0
        calls["migrations"] += 1
        calls["sent"] += out.sent
        calls["received"] += out.received
        calls["fallback_sent"] += out.fallback_sent
        return out

    advector = Advector(swarm, integrator=integrator)
    advector.step(uh, uh, dt)  # warm-up (numba)
    Swarm.sort, Migrator.migrate = timed_sort, timed_migrate
    ev = rel = com = 0.0
    comm.Barrier()
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        st = advector.step(uh, uh, dt)
        ev += st.evaluation_seconds
        rel += st.relocation_seconds
        com += st.communication_seconds
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    Swarm.sort, Migrator.migrate = orig_sort, orig_migrate
    local = {"wall": wall, "cpu": cpu, "evaluation": ev, "relocation_incl_sort": rel, "communication": com, **calls,
             "particles": swarm.num_particles, "cells": num_owned}
    allr = comm.gather(local, root=0)
    if comm.rank == 0:
        total = sum(a["particles"] for a in allr)
        _emit(comm, {"what": "advect3d", "ranks": comm.size, "integrator": integrator, "n": n, "cells": 6 * n ** 3,
                     "particles": total, "steps": steps, "dt": dt, "per_rank": allr})


# ------------------------------------------------------------------------------------------- vortex
def vortex(argv: list[str]) -> None:
    """Run benchmarks/performance/vortex.py with Swarm.sort and Migrator.migrate timed apart."""
    from particles.parallel.migration import Migrator
    from particles.storage.swarm import Swarm

    calls: dict[str, list[tuple[int, float]]] = {"sort": [], "migrate": []}
    orig_sort, orig_migrate = Swarm.sort, Migrator.migrate

    def timed_sort(self, *a, **k):
        t0 = time.perf_counter()
        out = orig_sort(self, *a, **k)
        calls["sort"].append((self.num_particles, time.perf_counter() - t0))
        return out

    def timed_migrate(self, swarm, *a, **k):
        t0 = time.perf_counter()
        out = orig_migrate(self, swarm, *a, **k)
        calls["migrate"].append((swarm.num_particles, time.perf_counter() - t0))
        return out

    Swarm.sort, Migrator.migrate = timed_sort, timed_migrate
    sys.argv = ["vortex.py", *argv]
    runpy.run_module("benchmarks.performance.vortex", run_name="__main__")
    comm = MPI.COMM_WORLD
    big = {k: [(n, t) for n, t in v if n > 20000] for k, v in calls.items()}
    rec = {k: {"calls": len(v), "seconds": sum(t for _, t in v), "mean_particles": float(np.mean([n for n, _ in v])) if v else 0}
           for k, v in big.items()}
    allrec = comm.gather(rec, root=0)
    _emit(comm, {"what": "vortex_split", "per_rank": allrec})


if __name__ == "__main__":
    cmd = sys.argv[1]
    if cmd == "mpi":
        mpi_latency()
    elif cmd == "migration":
        migration_cost()
    elif cmd == "loops":
        python_loops()
    elif cmd == "serialmesh":
        serial_mesh()
    elif cmd == "stokes":
        stokes_cost()
    elif cmd == "advect3d":
        advect3d(*(int(a) for a in sys.argv[2:5]), *sys.argv[5:6])
    elif cmd == "vortex":
        vortex(sys.argv[3:] if len(sys.argv) > 2 and sys.argv[2] == "--" else sys.argv[2:])
    else:
        raise SystemExit(__doc__)
