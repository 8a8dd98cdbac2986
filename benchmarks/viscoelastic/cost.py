"""The cost of the particles' stress update against the rest of the particle time, side by side.

Usage::

    python -m benchmarks.viscoelastic.cost               # 32 x 32 cells, 16 particles per cell
    python -m benchmarks.viscoelastic.cost --quick       # 8 x 8 cells (the CI size)

A lid-driven cavity of a Maxwell material (eta = G = 1, steps of 0.05: the stress varies in space
and the flow turns it) carries ``elastic_stress`` on its particles. After three steps the update
``tau <- 2 eta_ve eps + chi R tau R^T`` (``ElasticStress.refresh``) is timed alone on the same
particles, once with the compiled loop (particles/properties/elastic_kernel.py) and once with the
vectorised path, and the particle time of five more steps (the particle systems' ``advance`` and
``update``: advection, sorting, population, the tracked fields, the properties) is measured around
it. Times are CPU seconds of the process (``time.process_time``), so that the machine's load,
logged at the start and the end, moves them less than wall time. The table gives the update, the
rest of the particle time and their ratio (issue 48: at most +20 %); the largest difference of the
two paths' stresses is their round-off. Prints one JSON line last.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.harness import OUTPUT, Benchmark, markdown_table

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "viscoelastic_cost", quick="8 x 8 cells (the CI size)",
                      helps={"out": "the run folder"})


def document(cells: int, out: Path) -> dict[str, Any]:
    """The cavity (module docstring)."""
    return {
        "name": "elastic_cost", "mesh": {"cells": [cells, cells]},
        "physics": {"Ra": 0.0, "viscosity": {"law": 1.0}, "elasticity": {"enabled": True, "shear_modulus": 1.0}},
        "boundary": {"velocity": {"top": {"kind": "prescribed", "value": ["16*x*x*(1-x)*(1-x)", "0"]},
                                  "bottom": "no_slip", "left": "no_slip", "right": "no_slip"},
                     "temperature": {side: "insulating" for side in ("left", "right", "bottom", "top")}},
        "initial": {"temperature": "0"}, "energy": {"enabled": False}, "stokes": {"solver": "direct"},
        "particles": {"enabled": True, "generator": {"name": "random_uniform", "particles_per_cell": 16, "seed": 2},
                      "properties": ["elastic_stress"]},
        "time": {"end": 10.0, "cfl": 100.0, "dt_max": 0.05},
        "output": {"directory": str(out), "fields_every": 0, "progress": "none"},
    }


def measure(cells: int, out: Path, *, repeats: int = 20, steps: int = 5) -> dict[str, Any]:
    """The update's CPU time on both paths and the particle time of a step (module docstring; serial)."""
    import particles.properties.elastic_stress as module
    from convection.app.factory import build_model
    from convection.config.loader import load_config

    model = build_model(load_config(None, document=document(cells, out)))
    model.start()
    for _ in range(3):
        model.step(0.05)
    manager = model.particles.primary
    stress = next(p for p in manager.properties.properties if p.name == "elastic_stress")
    manager.properties.set_context(model.property_context())
    context = manager.properties.context  # with the manager's evaluators
    swarm = manager.swarm
    saved = swarm.properties.copy()
    seconds, results = {}, {}
    compiled = module.fast_update
    for path, update in (("compiled", compiled), ("vectorised", lambda *args: False)):
        module.fast_update = update
        start = time.process_time()
        for _ in range(repeats):
            swarm.properties[:] = saved
            stress.refresh(swarm, context)
        seconds[path] = (time.process_time() - start) / repeats
        results[path] = swarm.properties.copy()
    module.fast_update = compiled
    swarm.properties[:] = saved
    spent = 0.0
    systems = model.particles
    for name in ("advance", "update"):
        method = getattr(systems, name)

        def timed(*args: Any, _method: Any = method, **kwargs: Any) -> Any:
            nonlocal spent
            begin = time.process_time()
            try:
                return _method(*args, **kwargs)
            finally:
                spent += time.process_time() - begin
        setattr(systems, name, timed)
    for _ in range(steps):
        model.step(0.05)
    model.destroy()
    particle = spent / steps
    scale = float(np.abs(results["vectorised"]).max())
    return {"cells": cells, "particles": int(swarm.num_particles), "compiled": seconds["compiled"],
            "vectorised": seconds["vectorised"], "particle_time": particle,
            "difference": float(np.abs(results["compiled"] - results["vectorised"]).max()) / scale}


def table(result: dict[str, Any]) -> str:
    """The markdown table of one measurement."""
    rest = result["particle_time"] - result["compiled"]
    rows = [[path, f"{result[path] * 1e3:.2f} ms", f"{rest * 1e3:.2f} ms", f"+{result[path] / rest * 100:.0f} %"]
            for path in ("compiled", "vectorised")]
    header = ["stress update", "CPU time", "rest of the particle time", "update / rest"]
    return "\n".join(markdown_table(header, rows)) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", type=int, default=32, help="cells per side")
    args = parser.parse_args(argv)
    cells = 8 if args.quick else args.cells
    start = BENCHMARK.log_load("start")
    result = measure(cells, args.out)
    end = BENCHMARK.log_load("end")
    text = (f"{result['cells']} x {result['cells']} cells, {result['particles']} particles, 1 rank; {start} (start), "
            f"{end} (end)\n\n{table(result)}\nlargest difference of the two paths' stresses: "
            f"{result['difference']:.1e} of the largest stress\n")
    BENCHMARK.publish(HERE / "cost.md" if not args.quick else args.out / "cost.md", text)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
