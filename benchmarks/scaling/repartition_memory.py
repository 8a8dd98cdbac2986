"""Rank memory of a repartition: the gathered path (every cell through rank 0) against the
distributed one (every rank hands ``create_mesh`` its own cells).

    mpirun -n 2 python -m benchmarks.scaling.repartition_memory gathered --cells 224
    mpirun -n 2 python -m benchmarks.scaling.repartition_memory distributed --cells 224
    mpirun -n 2 python -m benchmarks.scaling.repartition_memory distributed --dim 3 --cells 26

A unit square of 2 n^2 triangles (or a unit cube of 6 n^3 tetrahedra) is redistributed to diagonal
bands. Per rank it prints the
rows handed to ``create_mesh`` (cells and nodes), the owned cells before and after, and the peak
resident memory during the repartition above the resident memory before it (VmHWM reset through
``/proc/self/clear_refs`` just before, Linux).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from mpi4py import MPI

import dolfinx.mesh
import ufl

from benchmarks.harness import Benchmark
from fembase.distribute import create_partitioned_mesh, gather_cell_layout, redistribute

BENCHMARK = Benchmark(__doc__)


def _status(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1])  # kB
    raise KeyError(key)


def main() -> None:
    parser = BENCHMARK.parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("path", choices=["gathered", "distributed"])
    parser.add_argument("--cells", type=int, default=224, help="cells per side n")
    parser.add_argument("--dim", type=int, choices=[2, 3], default=2)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    n, d = args.cells, args.dim
    mesh = (dolfinx.mesh.create_unit_square(comm, n, n) if d == 2 else dolfinx.mesh.create_unit_cube(comm, n, n, n))
    num_owned = mesh.topology.index_map(d).size_local
    mid = dolfinx.mesh.compute_midpoints(mesh, d, np.arange(num_owned, dtype=np.int32))
    owners = np.minimum(mid[:, :d].sum(axis=1) / d * comm.size, comm.size - 1).astype(np.int32)
    passed = []
    original = dolfinx.mesh.create_mesh

    def create_mesh(c, cells, x, domain, *a, **k):
        passed.append((np.asarray(cells).shape[0], np.asarray(x).shape[0]))
        return original(c, cells, x, domain, *a, **k)

    dolfinx.mesh.create_mesh = create_mesh
    comm.Barrier()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset the peak resident set size to the current one
    rss0 = _status("VmRSS:")
    t0 = time.perf_counter()
    if args.path == "gathered":
        offset = comm.exscan(num_owned) or 0
        layout = gather_cell_layout(mesh, np.arange(offset, offset + num_owned, dtype=np.int64))
        gathered = comm.gather(owners, root=0)
        new = create_partitioned_mesh(comm, layout, np.concatenate(gathered) if comm.rank == 0 else None,
                                      ufl.Mesh(mesh.ufl_domain().ufl_coordinate_element())).mesh
    else:
        new = redistribute(mesh, owners)
    seconds = time.perf_counter() - t0
    peak = _status("VmHWM:") - rss0
    rows = comm.gather((comm.rank, passed, num_owned, new.topology.index_map(d).size_local,
                        new.topology.index_map(d).num_ghosts, peak, seconds), root=0)
    if comm.rank == 0:
        print(f"{args.path}: {mesh.topology.index_map(d).size_global} cells on {comm.size} ranks")
        for rank, p, before, after, ghosts, kb, s in rows:
            print(f"  rank {rank}: create_mesh got {p[0][0]} cells, {p[0][1]} nodes; owned cells {before} -> {after} "
                  f"(+{ghosts} ghosts); peak RSS above start {kb / 1024:.1f} MiB; {s:.2f} s")


if __name__ == "__main__":
    main()
