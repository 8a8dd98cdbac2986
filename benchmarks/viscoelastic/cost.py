"""The cost of elasticity, side by side: the particles' stress update against the rest of the particle
time, and a visco-elastic step against a viscous step of the same model.

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
two paths' stresses is their round-off.

The step: the same cavity with elasticity off (a viscous fluid of the same viscosity; the same
particles, without ``elastic_stress``) and on, built one after the other in the same process;
after three steps (compilation) a block of five steps is timed three times and the best block
counts (best of three), split into the flow solve (``Model.solve_flow``: assembly and solve), the
particle time (as above) and the rest. The ratio of the per-step times is the cost of elasticity:
the stress interpolated onto the mesh (3 fields), the old stress's load assembled every step, the
stress update on the particles. Prints one JSON line last.
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


def document(cells: int, out: Path, *, elastic: bool = True) -> dict[str, Any]:
    """The cavity (module docstring); ``elastic=False``: the same viscous, its particles without stress."""
    return {
        "name": "elastic_cost", "mesh": {"cells": [cells, cells]},
        "physics": {"Ra": 0.0, "viscosity": {"law": 1.0}, "elasticity": {"enabled": elastic, "shear_modulus": 1.0}},
        "boundary": {"velocity": {"top": {"kind": "prescribed", "value": ["16*x*x*(1-x)*(1-x)", "0"]},
                                  "bottom": "no_slip", "left": "no_slip", "right": "no_slip"},
                     "temperature": {side: "insulating" for side in ("left", "right", "bottom", "top")}},
        "initial": {"temperature": "0"}, "energy": {"enabled": False}, "stokes": {"solver": "direct"},
        "particles": {"enabled": True, "generator": {"name": "random_uniform", "particles_per_cell": 16, "seed": 2},
                      "properties": ["elastic_stress"] if elastic else []},
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
    spent = {"particles": 0.0}
    _cpu_timed(model.particles, ("advance", "update"), spent, "particles")
    for _ in range(steps):
        model.step(0.05)
    model.destroy()
    particle = spent["particles"] / steps
    scale = float(np.abs(results["vectorised"]).max())
    return {"cells": cells, "particles": int(swarm.num_particles), "compiled": seconds["compiled"],
            "vectorised": seconds["vectorised"], "particle_time": particle,
            "difference": float(np.abs(results["compiled"] - results["vectorised"]).max()) / scale}


def _cpu_timed(owner: Any, names: tuple[str, ...], spent: dict[str, float], key: str) -> None:
    """Wrap the methods ``names`` of ``owner`` so that their CPU seconds add up in ``spent[key]``."""
    for name in names:
        method = getattr(owner, name)

        def timed(*args: Any, _method: Any = method, **kwargs: Any) -> Any:
            begin = time.process_time()
            try:
                return _method(*args, **kwargs)
            finally:
                spent[key] += time.process_time() - begin
        setattr(owner, name, timed)


def beam_document(cells: int, out: Path, *, elastic: bool = True) -> dict[str, Any]:
    """The bending beam of bending_beam.py with ``cells`` across and ``2 cells / 3`` up (30: 30 x 20);
    ``elastic=False``: the same viscous (no shear moduli), without stress on its particles."""
    from benchmarks.viscoelastic import bending_beam

    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "tip.txt", bending_beam.TIP)
    doc = bending_beam.document(cells=(cells, 2 * cells // 3), dt=bending_beam.DT, end=1e3, out=out,
                                tracers=out / "tip.txt")
    if not elastic:
        doc["physics"]["elasticity"]["enabled"] = False
        doc["materials"]["beam"].pop("shear_modulus")
        doc["particles"][0]["properties"] = []
    return doc


MODELS = {"cavity": (document, 0.05), "beam": (beam_document, 1.0)}
"""The models of the step measurement: their config (``cells``, ``out``, ``elastic``) and step."""


def measure_step(cells: int, out: Path, *, elastic: bool, model_name: str = "cavity", steps: int = 5,
                 repeats: int = 3) -> dict[str, float]:
    """CPU seconds per step of a model of :data:`MODELS`, viscous or visco-elastic: the best of ``repeats``
    blocks of ``steps`` steps, and the flow solve's and the particles' share of that block (serial)."""
    from convection.app.factory import build_model
    from convection.config.loader import load_config

    make, dt = MODELS[model_name]
    folder = out / f"{model_name}_{'elastic' if elastic else 'viscous'}"
    model = build_model(load_config(None, document=make(cells, folder, elastic=elastic)))
    model.start()
    for _ in range(3):
        model.step(dt)
    spent = {"flow": 0.0, "particles": 0.0}
    _cpu_timed(model, ("solve_flow",), spent, "flow")
    _cpu_timed(model.particles, ("advance", "update"), spent, "particles")
    blocks = []
    for _ in range(repeats):
        spent.update(flow=0.0, particles=0.0)
        begin = time.process_time()
        for _ in range(steps):
            model.step(dt)
        blocks.append({"step": (time.process_time() - begin) / steps, "flow": spent["flow"] / steps,
                       "particles": spent["particles"] / steps})
    model.destroy()
    return min(blocks, key=lambda block: block["step"])


def step_table(viscous: dict[str, float], elastic: dict[str, float]) -> str:
    """The markdown table of the step times, per part, in units of the viscous step."""
    def parts(block: dict[str, float]) -> list[float]:
        return [block["step"], block["flow"], block["particles"], block["step"] - block["flow"] - block["particles"]]
    base = viscous["step"]
    rows = [[name, *(f"{value / base:.3f}" for value in parts(block))]
            for name, block in (("viscous", viscous), ("visco-elastic", elastic))]
    rows.append(["ratio", *(f"{e / v:.2f}" if v > 0 else "" for v, e in zip(parts(viscous), parts(elastic)))])
    header = ["step (per viscous step)", "whole step", "flow solve", "particles", "rest"]
    return "\n".join(markdown_table(header, rows)) + "\n"


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
    text += "\n## A visco-elastic step against a viscous step\n"
    sizes = {"cavity": (cells, f"{cells} x {cells} cells"),
             "beam": (12 if args.quick else 30, "30 x 20 cells" if not args.quick else "12 x 8 cells")}
    for name, (n, size) in sizes.items():
        start = BENCHMARK.log_load("start")
        viscous = measure_step(n, args.out, elastic=False, model_name=name)
        elastic = measure_step(n, args.out, elastic=True, model_name=name)
        end = BENCHMARK.log_load("end")
        text += (f"\nThe {name} ({size}), elasticity off and on, CPU time per step, best of three blocks of five "
                 f"steps; {start} (start), {end} (end)\n\n{step_table(viscous, elastic)}\n")
        result[f"step_{name}"] = {"viscous": viscous, "elastic": elastic, "ratio": elastic["step"] / viscous["step"]}
    BENCHMARK.publish(HERE / "cost.md" if not args.quick else args.out / "cost.md", text)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
