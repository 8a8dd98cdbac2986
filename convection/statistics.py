"""Per-step statistics written to ``<output>/statistics.csv`` as the run goes.

Rank 0 writes; each row is flushed and fsync'ed so a killed run keeps every finished step.
:class:`BalanceLog` writes ``<output>/balance.csv``: one row per repartition with the per-rank
cells and particles before and after (lists joined by ``;``).
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from mpi4py import MPI

__all__ = ["BalanceLog", "StatisticsWriter"]


class StatisticsWriter:
    """CSV file with a header row and one row per step (collective construction, rank 0 writes).

    Args:
        path: The CSV file (created or truncated).
        columns: Column names in order.
        comm: Communicator; only its rank 0 touches the file.
        resume_after_step: Continue an existing file (a resumed run): its rows up to this step
            are kept, later ones dropped (the header must match ``columns``).
    """

    def __init__(self, path: str | Path, columns: Sequence[str], /, *, comm: MPI.Comm = MPI.COMM_WORLD,
                 resume_after_step: int | None = None) -> None:
        self.path = Path(path)
        self.columns = list(columns)
        self._rank = comm.rank
        self._file = None
        self._writer = None
        if self._rank == 0:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            kept = _rows_up_to(self.path, self.columns, resume_after_step) if resume_after_step is not None else []
            self._file = open(self.path, "w", newline="")
            self._writer = csv.writer(self._file)
            self._writer.writerow(self.columns)
            self._writer.writerows(kept)
            self._flush()

    def write(self, row: Mapping[str, float | int | str]) -> None:
        """Append one row; ``row`` must hold every column."""
        missing = [c for c in self.columns if c not in row]
        if missing:
            raise KeyError(f"statistics row lacks columns {missing}")
        if self._writer is not None:
            self._writer.writerow([_format(row[c]) for c in self.columns])
            self._flush()

    def _flush(self) -> None:
        assert self._file is not None
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
            self._writer = None


def _rows_up_to(path: Path, columns: list[str], step: int) -> list[list[str]]:
    """The rows of an existing CSV with ``step <= step`` (raises ValueError if its header differs)."""
    if not path.exists():
        raise ValueError(f"{path} is missing: cannot continue it")
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or rows[0] != columns:
        raise ValueError(f"{path}: its columns differ from this run's; cannot continue it")
    return [r for r in rows[1:] if r and int(float(r[0])) <= step]


def _format(value: float | int | str) -> str:
    if isinstance(value, float):
        return repr(value)
    return str(value)


BALANCE_COLUMNS = (
    "step", "cells_before", "cells_after", "particles_before", "particles_after",
    "cell_imbalance_before", "cell_imbalance_after", "particle_imbalance_before", "particle_imbalance_after",
    "load_imbalance_before", "load_imbalance_after",
)


class BalanceLog:
    """``balance.csv``: per-rank counts around each repartition (created at the first one).

    Args:
        path: The CSV file.
        comm: Communicator; rank 0 writes.
    """

    def __init__(self, path: str | Path, /, *, comm: MPI.Comm = MPI.COMM_WORLD,
                 resume_after_step: int | None = None) -> None:
        self.path = Path(path)
        self._rank = comm.rank  # only the rank: a mesh's communicator may be freed with its mesh
        self._writer: StatisticsWriter | None = None
        if resume_after_step is not None and self._rank == 0 and self.path.exists():
            self._writer = StatisticsWriter(self.path, BALANCE_COLUMNS, comm=MPI.COMM_SELF,
                                            resume_after_step=resume_after_step)

    def write(self, step: int, before: Any, after: Any) -> None:
        """Append a row; ``before``/``after`` have per-rank ``cells``, ``particles`` arrays and
        ``cell_imbalance``, ``particle_imbalance``, ``load_imbalance`` (collective)."""
        if self._writer is None and self._rank == 0:
            self._writer = StatisticsWriter(self.path, BALANCE_COLUMNS, comm=MPI.COMM_SELF)
        row: dict[str, float | int | str] = {"step": step}
        for label, loads in (("before", before), ("after", after)):
            row[f"cells_{label}"] = ";".join(str(int(c)) for c in loads.cells)
            row[f"particles_{label}"] = ";".join(str(int(c)) for c in loads.particles)
            for kind in ("cell", "particle", "load"):
                row[f"{kind}_imbalance_{label}"] = float(getattr(loads, f"{kind}_imbalance"))
        if self._writer is not None:
            self._writer.write(row)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
