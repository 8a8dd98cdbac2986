r"""The benchmark harness: what every benchmark script declares once.

A benchmark script is a module of this package, run from the project root as
``python -m benchmarks.<folder>.<script>`` (under mpirun too) and imported by its test as
``from benchmarks.<folder> import <script>``: no script edits ``sys.path``. It declares itself
once, at module level, and builds its command line, its load log and its outputs from that::

    BENCHMARK = Benchmark(__doc__, out=HERE, ranks=2)
    CASES = cases(Case("1a", "vankeken_1a.yaml"), Case("2", "vankeken_case2.yaml"))

    def main(argv=None):
        parser = BENCHMARK.parser(cases=CASES, default_cases=["1a"])  # --out, --ranks, --case
        parser.add_argument("--cells", type=int, default=64)          # the script's own options
        args = parser.parse_args(argv)
        BENCHMARK.log_load("start")          # "load average 0.52 0.61 0.70 on 2 cores, 2026-12-06 19:20 UTC"
        ...
        table = "\n".join(markdown_table(["case", "vrms"], rows)) + "\n"
        BENCHMARK.publish(args.out / "results.md", table)   # written as given, echoed, "wrote ..."
        curves_figure(args.out / "results.png", curves, xlabel="time", ylabel="vrms")

The common options, each present only when the declaration gives its default (or asks for it
with the default None): ``--out`` (a ``Path``), ``--results`` (a ``Path``, or None), ``--ranks``
(an int, or a list for a sweep), ``--quick`` (coarse smoke settings, with its help text), ``--set
KEY=VALUE`` (repeated config overrides), ``--no-run`` (re-measure existing runs) and ``--case``
(names from :func:`cases`). A script adds its own options to the parser it gets. The numbers and
the tables stay the script's: the harness writes the text it is given, byte for byte.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUTPUT = ROOT / "output" / "benchmarks"
"""Default home of run folders (not committed): ``output/benchmarks/<name>``."""

__all__ = ["OUTPUT", "ROOT", "Benchmark", "Case", "Load", "cases", "markdown_table"]


@dataclass(frozen=True)
class Case:
    """One named run of a benchmark: a config of ``configs/`` and its ``--set`` overrides.

    Attributes:
        name: The case's name on the command line (``--case NAME``).
        config: The config's file name under ``configs/``.
        overrides: ``key.sub=value`` strings applied to the config.
    """

    name: str
    config: str
    overrides: tuple[str, ...] = ()

    @property
    def path(self) -> Path:
        """The config file."""
        return ROOT / "configs" / self.config


def cases(*declared: Case) -> dict[str, Case]:
    """The cases by name, in declaration order (a name given twice is an error)."""
    named = {case.name: case for case in declared}
    if len(named) != len(declared):
        raise ValueError(f"case names repeat: {[case.name for case in declared]}")
    return named


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]], /) -> list[str]:
    """The lines of a markdown table: ``| a | b |``, ``|---|---|``, then a line per row (cells as ``str``
    gives them: format the numbers first)."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
            *("| " + " | ".join(str(cell) for cell in row) + " |" for row in rows)]


@dataclass(frozen=True)
class Load:
    """The machine's load when a benchmark measured: wall times mean little without it.

    Attributes:
        averages: 1, 5 and 15 minute load averages (``os.getloadavg``).
        cores: Number of cores (``os.cpu_count``).
        date: UTC date and time, ``YYYY-MM-DD HH:MM UTC``.
    """

    averages: tuple[float, float, float]
    cores: int
    date: str

    @classmethod
    def now(cls) -> Load:
        """The load now."""
        one, five, fifteen = os.getloadavg()
        return cls((one, five, fifteen), os.cpu_count() or 1, time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))

    def __str__(self) -> str:
        averages = " ".join(f"{value:.2f}" for value in self.averages)
        return f"load average {averages} on {self.cores} cores, {self.date}"

    def record(self) -> dict[str, object]:
        """JSON-able fields, for a script's JSON results or log lines."""
        return {"load_average": list(self.averages), "cores": self.cores, "date": self.date}


@dataclass(frozen=True)
class Benchmark:
    """A benchmark script's declaration: its description and the defaults of its common options.

    Attributes:
        doc: The script's docstring; its first line is the command line's description.
        out: Default of ``--out`` (None: no ``--out``, unless ``out_option``).
        out_option: Whether ``--out`` exists with the default None (the script then writes no file).
        results: Default of ``--results``, the folder of tables and pictures when it differs from
            ``--out`` (may be None: the script then decides).
        results_option: Whether ``--results`` exists.
        ranks: Default of ``--ranks`` (a tuple: a list of rank counts, ``nargs="+"``; None: no ``--ranks``).
        quick: Help text of ``--quick`` (None: no ``--quick``).
        overrides: Whether ``--set KEY=VALUE`` (repeatable) exists.
        no_run: Help text of ``--no-run`` (None: no ``--no-run``).
        helps: Help texts of the common options by name (``"out"``, ``"ranks"``, ...).
    """

    doc: str | None
    out: Path | None = None
    out_option: bool = False
    results: Path | None = None
    results_option: bool = False
    ranks: int | tuple[int, ...] | None = None
    quick: str | None = None
    overrides: bool = False
    no_run: str | None = None
    helps: Mapping[str, str] = field(default_factory=dict)

    @property
    def description(self) -> str:
        """The docstring's first line."""
        return (self.doc or "").strip().split("\n")[0]

    def parser(self, *, cases: Mapping[str, object] | Sequence[str] | None = None,
               default_cases: Sequence[str] | None = None, **kwargs: object) -> argparse.ArgumentParser:
        """A parser with the declared common options, and ``--case`` (several names allowed, default
        ``default_cases``, else the first) over the names of ``cases`` (:func:`cases`, or any mapping
        by name); ``kwargs`` go to ``ArgumentParser`` (``description``: the docstring's first line)."""
        kwargs.setdefault("description", self.description)
        parser = argparse.ArgumentParser(**kwargs)  # type: ignore[arg-type]
        if cases is not None:
            parser.add_argument("--case", nargs="+", default=list(default_cases or list(cases)[:1]),
                                choices=sorted(cases), help=self.helps.get("case"))
        if isinstance(self.ranks, tuple):
            parser.add_argument("--ranks", type=int, nargs="+", default=list(self.ranks), help=self.helps.get("ranks"))
        elif self.ranks is not None:
            parser.add_argument("--ranks", type=int, default=self.ranks, help=self.helps.get("ranks"))
        if self.quick is not None:
            parser.add_argument("--quick", action="store_true", help=self.quick or None)
        if self.out is not None or self.out_option:
            parser.add_argument("--out", type=Path, default=self.out, help=self.helps.get("out"))
        if self.results_option:
            parser.add_argument("--results", type=Path, default=self.results, help=self.helps.get("results"))
        if self.no_run is not None:
            parser.add_argument("--no-run", action="store_true", help=self.no_run or None)
        if self.overrides:
            parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                                help=self.helps.get("set", "extra config override"))
        return parser

    def log_load(self, moment: str, /) -> Load:
        """Print (and return) the machine's load at ``moment`` ("start", "end", ...) to the log."""
        load = Load.now()
        print(f"{moment}: {load}", flush=True)
        return load

    @staticmethod
    def publish(path: Path, text: str, /, *, echo: bool = True) -> Path:
        """Write ``text`` to ``path`` as given (making its folder), print it when ``echo``, and
        say where it went."""
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        if echo:
            print(text)
        print(f"wrote {path}", flush=True)
        return path
