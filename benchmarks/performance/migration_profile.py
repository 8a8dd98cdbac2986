"""Where a migration's time goes on 2+ ranks (log/NOTES.md, "Issue 12 table, final sittings").

Runs ``vortex.py`` with its arguments, with a barrier before every migration of the timed loop (so
waiting for a slower rank is counted apart) and the parts of ``Migrator.migrate`` timed; prints
per rank one JSON line of milliseconds per migration (the first two migrations, before the loop,
are left out). Timing wrappers add a few microseconds per part.

Run: ``mpirun -n 2 python -m benchmarks.performance.migration_profile --cells 64 --particles
393216 --steps 50 --integrator euler --balance``.
"""

from __future__ import annotations

import collections
import json
import runpy
import sys
import time

from mpi4py import MPI

import particles.advection.advector as advection
import particles.parallel.migration as migration
import particles.storage.swarm as swarm_module

_totals: collections.Counter = collections.Counter()
_state = {"on": False, "calls": 0}


def _timed(name: str, function):
    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        result = function(*args, **kwargs)
        if _state["on"]:
            _totals[name] += time.perf_counter() - t0
        return result
    return wrapper


for _name in ("_neighbour_exchange", "_decide", "_box_candidates"):
    setattr(migration.Migrator, _name, _timed(_name, getattr(migration.Migrator, _name)))
migration._sum_over_ranks = _timed("count_allreduce", migration._sum_over_ranks)
migration.pack_by_slot = _timed("pack", migration.pack_by_slot)
for _name in ("outside_rows", "discard_rows", "append_rows", "append_packed"):
    setattr(swarm_module.Swarm, _name, _timed(_name, getattr(swarm_module.Swarm, _name)))
_migrate = advection._migrate


def _measured(swarm):
    _state["calls"] += 1
    counted = _state["calls"] > 2
    t0 = time.perf_counter()
    swarm.mesh.comm.Barrier()
    t1 = time.perf_counter()
    _state["on"] = counted
    result = _migrate(swarm)
    _state["on"] = False
    if counted:
        _totals["barrier_wait"] += t1 - t0
        _totals["migrate"] += time.perf_counter() - t1
        _totals["calls"] += 1
    return result


advection._migrate = _measured

if __name__ == "__main__":
    sys.argv = ["vortex.py"] + sys.argv[1:]
    try:
        runpy.run_module("benchmarks.performance.vortex", run_name="__main__")
    finally:
        calls = max(_totals.pop("calls", 0), 1)
        per_call = {k: round(v * 1e3 / calls, 4) for k, v in sorted(_totals.items())}
        print(json.dumps({"rank": MPI.COMM_WORLD.rank, "migrations": calls, "ms_per_migration": per_call}),
              file=sys.stderr, flush=True)
