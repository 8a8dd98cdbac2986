"""Per-step statistics written to ``<output>/statistics.csv`` as the run goes.

Rank 0 writes; each row is flushed and fsync'ed so a killed run keeps every finished step.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Mapping, Sequence

from mpi4py import MPI

__all__ = ["StatisticsWriter"]


class StatisticsWriter:
    """CSV file with a header row and one row per step (collective construction, rank 0 writes).

    Args:
        path: The CSV file (created or truncated).
        columns: Column names in order.
        comm: Communicator; only its rank 0 touches the file.
    """

    def __init__(self, path: str | Path, columns: Sequence[str], /, *, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
        self.path = Path(path)
        self.columns = list(columns)
        self._rank = comm.rank
        self._file = None
        self._writer = None
        if self._rank == 0:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w", newline="")
            self._writer = csv.writer(self._file)
            self._writer.writerow(self.columns)
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


def _format(value: float | int | str) -> str:
    if isinstance(value, float):
        return repr(value)
    return str(value)
