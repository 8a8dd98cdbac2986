"""The table of an nsinker sitting (``benchmarks/nsinker/sitting.sh``'s log): per case, mesh and viscosity
ratio the iterations, the best time per solve of the rounds and the largest peak resident size per rank,
with the 1-minute load averages the log recorded.

Usage: ``python -m benchmarks.nsinker.sitting_table LOG [--out FILE.md]``
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections import defaultdict
from pathlib import Path

from benchmarks.harness import markdown_table

LINE = re.compile(r"^(?:\S+ load=(?P<load>\S+) )?(?P<label>[^:]+): (?P<cells>\d+)\^3 (?:multigrid )?DR=(?P<ratio>\S+): "
                  r"(?P<its>-?\d+) iterations,(?P<rest>.*?)(?P<sec>[0-9.]+|nan) s, peak (?P<rss>[0-9.]+|nan) MB")
LOAD = re.compile(r"^\S+ load=(?P<load>\S+) ")


def parse(text: str) -> tuple[dict[tuple[str, int, float], list[dict[str, float]]], list[float]]:
    """The runs by (label, cells, ratio), and every load average the log printed."""
    runs: dict[tuple[str, int, float], list[dict[str, float]]] = defaultdict(list)
    loads: list[float] = []
    for line in text.splitlines():
        if (load := LOAD.match(line)) is not None:
            loads.append(float(load["load"]))
        if (m := LINE.match(line)) is None:
            continue
        converged = "unconverged" not in m["rest"]
        runs[(m["label"].strip(), int(m["cells"]), float(m["ratio"]))].append(
            {"iterations": int(m["its"]), "seconds": float(m["sec"]) if converged else math.inf,
             "rss": float(m["rss"])})
    return runs, loads


def table(runs: dict[tuple[str, int, float], list[dict[str, float]]], loads: list[float]) -> str:
    """Markdown: a section per mesh, a row per case, iterations / best seconds per ratio."""
    labels = list(dict.fromkeys(key[0] for key in runs))
    ratios = sorted({key[2] for key in runs})
    lines = [f"Load averages during the sitting: {min(loads):.2f} to {max(loads):.2f} (1 minute).", ""] if loads else []
    for cells in sorted({key[1] for key in runs}):
        rounds = min(len(v) for v in runs.values())  # ours runs the first ratio twice a round
        lines += [f"### {cells}^3 (iterations / best seconds per solve of {rounds} rounds; peak MB per rank)", ""]
        rows = []
        for label in labels:
            cols, peak = [], 0.0
            for ratio in ratios:
                got = runs.get((label, cells, ratio), [])
                if not got:
                    cols.append("")
                    continue
                best = min(r["seconds"] for r in got)
                its = got[0]["iterations"]
                cols.append(f"> {its} / -" if math.isinf(best) else f"{its} / {best:.2f}")
                peak = max([peak] + [r["rss"] for r in got if not math.isnan(r["rss"])])
            rows.append([label, *cols, f"{peak:.0f}"])
        lines += markdown_table(["case", *(f"DR {q:.0e}" for q in ratios), "peak MB"], rows) + [""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    text = table(*parse(args.log.read_text()))
    if args.out:
        args.out.write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
