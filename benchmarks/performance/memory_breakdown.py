"""Where the bytes go in a 3D run: resident size around the set-up stages, the PETSc matrices of the
Stokes solver one by one (operator, Schur preconditioning matrix, fieldsplit's copies, the multigrid's
prolongations and Galerkin coarse operators), the transport solver's, the Krylov vectors and the
particles' arrays (issue 50, item 1).

Usage (2 ranks, the 3D thick layer at 16^3 with the multigrid)::

    mpirun -n 2 python -m benchmarks.performance.memory_breakdown --cells 16 --steps 2

Prints a markdown table (bytes summed over the ranks; resident sizes per rank, the largest rank)
and the bytes per Stokes unknown and per particle. PETSc's ``MatGetInfo`` gives the matrices'
allocated nonzeros (a value and a column index each, plus two indices a row: AIJ's storage); the resident size (``/proc/self/status``) counts everything else besides (the
DOLFINx mesh, dofmaps and compiled forms, Python, MPI).
"""

from __future__ import annotations

import gc
import sys
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from benchmarks.harness import ROOT, Benchmark, markdown_table

BENCHMARK = Benchmark(__doc__, overrides=True)
MB = 1024.0 ** 2


def rss() -> tuple[float, float]:
    """(VmRSS, VmHWM) of this process [bytes]."""
    values = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(("VmRSS:", "VmHWM:")):
            key, amount, _ = line.split()
            values[key[:-1]] = float(amount) * 1024.0
    return values["VmRSS"], values["VmHWM"]


def mat_bytes(mat: PETSc.Mat | None) -> float:
    """Allocated bytes of ``mat`` over all ranks (0 for None or a shell/Schur-complement matrix; a
    MATNEST: its blocks')."""
    if mat is not None and mat.getType() == "nest":
        rows, columns = mat.getNestSize()
        return sum(mat_bytes(mat.getNestSubMatrix(i, j)) for i in range(rows) for j in range(columns))
    if mat is None or mat.getType() in ("schurcomplement", "shell", "python"):
        return 0.0
    info = mat.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)  # its "memory" is no longer kept by PETSc (0)
    scalar, index = np.dtype(PETSc.ScalarType).itemsize, np.dtype(PETSc.IntType).itemsize
    return float(info["nz_allocated"] * (scalar + index) + mat.getSize()[0] * 2 * index)


def numpy_bytes(obj: Any, /, *, depth: int = 6, seen: set[int] | None = None) -> int:
    """Bytes of the numpy arrays reachable from ``obj`` through attributes, dicts, lists and tuples
    (``depth`` levels; each buffer once)."""
    seen = set() if seen is None else seen
    if id(obj) in seen or depth < 0:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        base = obj if obj.base is None else obj.base
        if isinstance(base, np.ndarray) and base is not obj:
            if id(base) in seen:
                return 0
            seen.add(id(base))
            return base.nbytes
        return obj.nbytes
    children: Any
    if isinstance(obj, dict):
        children = obj.values()
    elif isinstance(obj, (list, tuple, set)):
        children = obj
    elif hasattr(obj, "__dict__") and type(obj).__module__.split(".")[0] in ("particles", "fembase", "convection"):
        children = vars(obj).values()
    else:
        return 0
    return sum(numpy_bytes(child, depth=depth - 1, seen=seen) for child in children)


def stokes_matrices(stokes: Any) -> list[tuple[str, float]]:
    """The Stokes solver's matrices by role, bytes over all ranks."""
    system = stokes.linear_system
    rows = [("Stokes operator K (velocity, coupling and pressure blocks)", mat_bytes(system._A)),
            ("semi-implicit copy A0 of the operator", mat_bytes(system._A0)),
            ("preconditioning matrix P (where not K itself)", mat_bytes(system._P)),
            ("Schur preconditioning matrix -M_p/eta", mat_bytes(system._S))]
    term = system._term
    if term is not None and term.block is not None:  # on a box: one component's block and A0's values there
        comm = stokes.mesh.comm
        rows.append(("semi-implicit term: its component matrix", mat_bytes(term.block.M)))
        rows.append(("semi-implicit term: the fixed values and indices of that block (numpy)",
                     comm.allreduce(float(numpy_bytes(term.block)), op=MPI.SUM)))
    pc = stokes.ksp.getPC()
    if pc.getType() == "fieldsplit":
        ksp_u, ksp_p = pc.getFieldSplitSubKSP()
        nest = system.P.getType() == "nest"  # fieldsplit takes P's blocks as they are: no copies
        if not nest:
            rows.append(("fieldsplit's velocity block A00 (a copy)", mat_bytes(ksp_u.getOperators()[0])))
            # Fieldsplit's Schur factorisation holds B^T and B extracted from P (petsc4py does not hand
            # them out): their size is that of K's coupling blocks, extracted here once and freed.
            is_u, is_p = system.index_sets()
            coupling = 0.0
            for rows_is, cols_is in ((is_u, is_p), (is_p, is_u)):
                block = system.P.createSubMatrix(rows_is, cols_is)
                coupling += mat_bytes(block)
                block.destroy()
            rows.append(("fieldsplit's coupling blocks B^T, B (copies; sized from P)", coupling))
        elif ksp_u.getOperators()[0].handle != system.P.getNestSubMatrix(0, 0).handle:
            rows.append(("fieldsplit's velocity block A00 (a copy of P's)", mat_bytes(ksp_u.getOperators()[0])))
        pressure = ksp_p.getOperators()[1]
        if system._S is None or pressure.handle != system._S.handle:
            rows.append(("fieldsplit's pressure preconditioning block (a copy)", mat_bytes(pressure)))
        pc_u = ksp_u.getPC()
        if pc_u.getType() == "mg":
            levels = pc_u.getMGLevels()
            galerkin = sum(mat_bytes(pc_u.getMGSmoother(level).getOperators()[0]) for level in range(levels - 1))
            rows.append((f"multigrid Galerkin coarse operators ({levels - 1} levels)", galerkin))
            rows.append(("multigrid prolongations", sum(mat_bytes(P) for P in system.multigrid.interpolations)))
    return rows


def measure(config_path: Path, overrides: list[str], steps: int, comm: MPI.Comm) -> None:
    from convection import build_model, load_config

    stages = [("imports", rss())]
    config = load_config(config_path, overrides)
    model = build_model(config, comm=comm)
    gc.collect()
    stages.append(("model built (mesh, spaces, forms, solvers, particles)", rss()))
    model.start()
    stages.append(("first Stokes solve (matrices, preconditioner)", rss()))
    for _ in range(steps):
        model.step(model.cfl_dt(float(config["time"]["cfl"])))
    stages.append((f"after {steps} steps", rss()))
    stokes = model.stokes
    V, Q = stokes.V, stokes.Q
    unknowns = V.dofmap.index_map.size_global * V.dofmap.index_map_bs + Q.dofmap.index_map.size_global
    matrices = stokes_matrices(stokes)
    transport = model.temperature
    if transport is not None:
        matrices.append(("temperature matrix", mat_bytes(getattr(transport, "_A", None))))
    local_n = V.dofmap.index_map.size_local * V.dofmap.index_map_bs + Q.dofmap.index_map.size_local
    krylov = comm.allreduce(local_n * 8.0, op=MPI.SUM)  # one Stokes vector over all ranks
    iterations = stokes.linear_system.iterations
    matrices.append((f"FGMRES vectors (2 per iteration, last solve {iterations} iterations; estimate)",
                     2.0 * (iterations + 1) * krylov))
    particles = model.particles
    count, particle_bytes = 0, 0.0
    if particles is not None:
        for manager in particles:
            count += comm.allreduce(manager.swarm.num_particles, op=MPI.SUM)
            particle_bytes += comm.allreduce(float(numpy_bytes(manager)), op=MPI.SUM)
    peaks = [comm.allreduce(value, op=MPI.MAX) for _, (_, value) in stages]
    currents = [comm.allreduce(value, op=MPI.MAX) for _, (value, _) in stages]
    if comm.rank == 0:
        print(f"{comm.size} ranks, {unknowns} Stokes unknowns, {count} particles, solver {stokes.description}\n")
        print("\n".join(markdown_table(["stage", "RSS [MB] (largest rank)", "peak RSS [MB]"],
                                       [(name, f"{c / MB:.0f}", f"{p / MB:.0f}")
                                        for (name, _), c, p in zip(stages, currents, peaks)])))
        print()
        total = sum(b for _, b in matrices)
        rows = [(name, f"{b / MB:.1f}", f"{b / unknowns:.0f}") for name, b in matrices if b]
        rows.append(("sum of the above", f"{total / MB:.1f}", f"{total / unknowns:.0f}"))
        rows.append((f"particle arrays ({count} particles)", f"{particle_bytes / MB:.1f}",
                     f"{particle_bytes / max(count, 1):.0f} per particle"))
        print("\n".join(markdown_table(["object (summed over ranks)", "MB", "bytes per Stokes unknown"], rows)))
    model.destroy()


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--config", default="thick_layer_3d.yaml")
    parser.add_argument("--cells", type=int, default=16)
    parser.add_argument("--steps", type=int, default=2)
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        BENCHMARK.log_load("start")
    overrides = [f"mesh.cells=[{args.cells},{args.cells},{args.cells}]", "stokes.solver=multigrid",
                 "output.directory=/tmp/memory_breakdown", "output.progress=none", *args.set]
    measure(ROOT / "configs" / args.config, overrides, args.steps, comm)
    return 0


if __name__ == "__main__":
    sys.exit(main())
