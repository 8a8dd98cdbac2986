"""Every shipped config at CI size, its statistics recorded, and two recordings compared to the
last digit: the check that a refactoring changed no number.

Usage::

    python scripts/config_statistics.py record OUT [--tree PATH] [--ranks 2] [--steps 10] [--only NAME ...]
    python scripts/config_statistics.py compare A B

``record`` runs ``python -m convection run`` on every ``configs/*.yaml`` of the checkout ``--tree``
(default: this one; give a ``git worktree`` of an older commit to record *before* a change) with
that checkout's own code, shrunk as the resume tests shrink them (a box: a third of the cells per
direction; a shell: 1.8 times coarser; at most 3000 particles or 8 per cell; ``--steps`` steps;
adaptation every 4 steps) and keeps each run's ``statistics.csv`` as ``OUT/<config>.csv``.
``compare`` reads two such folders and checks every column but ``wall_time`` of every row for
string equality; it prints one line per config and exits 1 on the first difference in any.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from convection.config.particle_systems import document_generators

HERE = Path(__file__).resolve().parents[1]
IGNORED = ("wall_time",)


def _shrunk(config: Path, steps: int) -> list[str]:
    """``--set`` overrides that make ``config`` CI-sized and keep its features."""
    raw = yaml.safe_load(config.read_text())
    mesh = raw["mesh"]
    if "cells" in mesh:
        extra = [f"mesh.cells=[{','.join(str(max(4, c // 3)) for c in mesh['cells'])}]"]
    else:
        extra = [f"mesh.resolution={mesh['resolution'] * 1.8:.3g}"]
    for prefix, generator in document_generators(raw).items():
        if "particles_per_cell" in generator:
            extra.append(f"{prefix}.generator.particles_per_cell={min(8, generator['particles_per_cell'])}")
        if "num_particles" in generator:
            extra.append(f"{prefix}.generator.num_particles={min(3000, generator['num_particles'])}")
    if (raw.get("adaptivity") or {}).get("enabled"):
        extra.append(f"adaptivity.every={min(4, raw['adaptivity'].get('every', 10))}")
    extra += [f"time.max_steps={steps}", "output.progress=none", "output.fields_every=5"]
    return [a for item in extra for a in ("--set", item)]


def _launcher(tree: Path, ranks: int) -> list[str]:
    if ranks == 1:
        return []
    out = subprocess.run([sys.executable, "-m", "convection.launch", str(ranks)], cwd=tree, check=True,
                         capture_output=True, text=True).stdout
    return out.splitlines()


def record(out: Path, tree: Path, ranks: int, steps: int, only: list[str]) -> int:
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_rmaps_base_oversubscribe": "1", "PYTHONDONTWRITEBYTECODE": "1", "PYTHONPATH": str(tree)}
    failed = 0
    for config in sorted((tree / "configs").glob("*.yaml")):
        if only and config.stem not in only:
            continue
        with tempfile.TemporaryDirectory() as tmp:
            run_dir = Path(tmp) / "run"
            cmd = [*_launcher(tree, ranks), sys.executable, "-m", "convection", "run", str(config),
                   "--output", str(run_dir), *_shrunk(config, steps)]
            t0 = time.monotonic()
            proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                print(f"{config.stem}: FAILED (exit {proc.returncode})\n{proc.stderr[-3000:]}", flush=True)
                failed += 1
                continue
            (out / f"{config.stem}.csv").write_text((run_dir / "statistics.csv").read_text())
            print(f"{config.stem}: {time.monotonic() - t0:.0f} s", flush=True)
    return 1 if failed else 0


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def compare(a: Path, b: Path) -> int:
    names = sorted({p.stem for p in a.glob("*.csv")} | {p.stem for p in b.glob("*.csv")})
    differing = 0
    for name in names:
        pa, pb = a / f"{name}.csv", b / f"{name}.csv"
        if not (pa.exists() and pb.exists()):
            print(f"{name}: only in {a if pa.exists() else b}")
            differing += 1
            continue
        ra, rb = _rows(pa), _rows(pb)
        problem = None
        if len(ra) != len(rb):
            problem = f"{len(ra)} rows against {len(rb)}"
        elif ra and list(ra[0]) != list(rb[0]):
            problem = f"columns differ: {list(ra[0])} against {list(rb[0])}"
        else:
            for x, y in zip(ra, rb):
                keys = [k for k in x if k not in IGNORED and x[k] != y[k]]
                if keys:
                    problem = f"step {x.get('step')}: {keys[0]} {x[keys[0]]} against {y[keys[0]]}"
                    break
        columns = len(ra[0]) - len(IGNORED) if ra else 0
        print(f"{name}: {'identical' if problem is None else 'DIFFERENT: ' + problem} "
              f"({len(ra)} rows, {columns} columns)")
        differing += problem is not None
    print(f"{len(names) - differing} of {len(names)} configs identical in every column but {', '.join(IGNORED)}")
    return 1 if differing else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="run every shipped config at CI size and keep its statistics")
    rec.add_argument("out", type=Path)
    rec.add_argument("--tree", type=Path, default=HERE, help="the checkout whose configs and code run")
    rec.add_argument("--ranks", type=int, default=2)
    rec.add_argument("--steps", type=int, default=10)
    rec.add_argument("--only", nargs="*", default=[], help="config names (default: all)")
    cmp_ = sub.add_parser("compare", help="compare two recordings to the last digit")
    cmp_.add_argument("a", type=Path)
    cmp_.add_argument("b", type=Path)
    args = parser.parse_args(argv)
    if args.command == "record":
        return record(args.out, args.tree.resolve(), args.ranks, args.steps, args.only)
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
