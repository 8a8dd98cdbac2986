"""Per-step statistics written to ``<output>/statistics.csv`` as the run goes, and read back.

Rank 0 writes; each row is flushed and fsync'ed so a killed run keeps every finished step. Every
row ends with a line end, so a line without one (a write cut off by a kill or a full disk) is
known to be incomplete: :func:`read_table` leaves it out, the writer of a resumed run drops it,
and everything else that is not a complete row of numbers is reported as damage.
:class:`BalanceLog` writes ``<output>/balance.csv``: one row per repartition with the per-rank
cells and particles before and after (lists joined by ``;``).

This module does not import MPI itself (``convection.io.pictures`` reads statistics without it); the
writers take the run's communicator.
"""

from __future__ import annotations

import csv
import io
import os
import uuid
from pathlib import Path
from types import ModuleType
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

if TYPE_CHECKING:
    from mpi4py import MPI

__all__ = ["BalanceLog", "StatisticsFileError", "StatisticsTable", "StatisticsWriter", "read_table"]


class StatisticsFileError(ValueError):
    """A statistics CSV is damaged, cannot be continued or cannot be written (one line naming it)."""


class StatisticsTable(NamedTuple):
    """The complete rows of a statistics CSV (:func:`read_table`).

    Attributes:
        columns: The header.
        rows: Every complete row, as written (text), each with ``len(columns)`` fields.
        incomplete: The file ended in a line cut short (no line end), left out of ``rows``.
    """

    columns: list[str]
    rows: list[list[str]]
    incomplete: bool


def read_table(path: str | Path, /, *, numeric: bool = True) -> StatisticsTable:
    """Read a CSV written by :class:`StatisticsWriter`: a header and rows, each ending in a line end.

    Args:
        path: The file.
        numeric: Every field of every row must be a number (statistics.csv); False for
            balance.csv (per-rank lists).

    Raises:
        FileNotFoundError: No such file.
        StatisticsFileError: The file is not such a table: unreadable text, NUL bytes, no header, or a
            complete row with another number of fields than the header (or a field that is not a
            number); the message names the file and the line.
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise StatisticsFileError(f"{path}: damaged (not text: {err.reason} at byte {err.start})") from None
    except IsADirectoryError:
        raise StatisticsFileError(f"{path}: a folder, not a statistics file") from None
    lines = text.splitlines(keepends=True)
    incomplete = bool(lines) and not lines[-1].endswith(("\n", "\r"))
    if incomplete:
        lines.pop()
    if not lines:
        raise StatisticsFileError(f"{path}: damaged (no header line)")
    table = [_fields(path, number, line) for number, line in enumerate(lines, start=1)]
    columns, rows = table[0], table[1:]
    if not columns or any(not name for name in columns):
        raise StatisticsFileError(f"{path}: damaged header (line 1: {lines[0].strip()[:60]!r})")
    for number, row in enumerate(rows, start=2):
        if len(row) != len(columns):
            raise StatisticsFileError(f"{path}: line {number} is damaged ({len(row)} fields, the header has "
                                      f"{len(columns)})")
        if numeric:
            _check_numbers(path, number, row)
    return StatisticsTable(columns, rows, incomplete)


def _fields(path: Path, number: int, line: str) -> list[str]:
    if "\0" in line:
        raise StatisticsFileError(f"{path}: line {number} is damaged (NUL bytes: two runs writing one folder?)")
    return next(csv.reader(io.StringIO(line)), [])


def _check_numbers(path: Path, number: int, row: list[str]) -> None:
    for value in row:
        try:
            float(value)
        except ValueError:
            raise StatisticsFileError(f"{path}: line {number} is damaged ({value[:30]!r} is not a number)") from None


def _agreed(comm: MPI.Comm, action: Callable[[], Any]) -> Any:
    """``action()`` on rank 0 (None elsewhere); a :class:`StatisticsFileError` or OSError there is
    raised on every rank (collective)."""
    result, error = None, None
    if comm.rank == 0:
        try:
            result = action()
        except StatisticsFileError as err:
            error = str(err)
        except OSError as err:
            error = f"{err.filename or 'a statistics file'}: cannot be read or written ({err.strerror or err})"
    error = comm.bcast(error, root=0)
    if error is not None:
        raise StatisticsFileError(error)
    return result


def _mpi() -> ModuleType:
    """mpi4py's MPI module, imported when a writer is made (not by ``convection.io.pictures``)."""
    from mpi4py import MPI

    return MPI


class StatisticsWriter:
    """CSV file with a header row and one row per step (collective construction, rank 0 writes).

    Args:
        path: The CSV file (created or truncated).
        columns: Column names in order.
        comm: Communicator (default ``MPI.COMM_WORLD``); only its rank 0 touches the file.
        resume_after_step: Continue an existing file (a resumed run): its rows up to this step
            are kept, later ones and an incomplete last line dropped (the header must match
            ``columns``, whose first is the step). The kept rows are rewritten atomically.
        numeric: Every field is a number (False: balance.csv).

    Attributes:
        dropped_incomplete: On resuming, the file ended in an incomplete line (dropped); the same
            on every rank.

    Raises:
        StatisticsFileError: On every rank: the file to continue is missing, damaged or has other
            columns, or the file cannot be written.
    """

    def __init__(self, path: str | Path, columns: Sequence[str], /, *, comm: MPI.Comm | None = None,
                 resume_after_step: int | None = None, numeric: bool = True) -> None:
        comm = comm if comm is not None else _mpi().COMM_WORLD
        self.path = Path(path)
        self.columns = list(columns)
        self._file: Any = None
        self._writer: Any = None
        self.dropped_incomplete = bool(_agreed(comm, lambda: self._open(resume_after_step, numeric)))

    def _open(self, resume_after_step: int | None, numeric: bool) -> bool:
        """Open the file (rank 0); returns whether an incomplete last line was dropped."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        dropped = False
        if resume_after_step is None:
            self._file = open(self.path, "w", newline="")
            self._writer = csv.writer(self._file)
            self._writer.writerow(self.columns)
        else:
            kept, dropped = _rows_up_to(self.path, self.columns, resume_after_step, numeric)
            _replace(self.path, [self.columns, *kept])
            self._file = open(self.path, "a", newline="")
            self._writer = csv.writer(self._file)
        self._flush()
        return dropped

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


def _rows_up_to(path: Path, columns: list[str], step: int, numeric: bool) -> tuple[list[list[str]], bool]:
    """The complete rows of an existing CSV with ``step <= step``, and whether an incomplete last
    line was dropped."""
    try:
        table = read_table(path, numeric=numeric)
    except FileNotFoundError:
        raise StatisticsFileError(f"{path} is missing: cannot continue it") from None
    if table.columns != columns:
        raise StatisticsFileError(f"{path}: its columns differ from this run's; cannot continue it")
    try:
        kept = [r for r in table.rows if int(float(r[0])) <= step]
    except ValueError:
        raise StatisticsFileError(f"{path}: a step (first column) is not a number; cannot continue it") from None
    return kept, table.incomplete


def _replace(path: Path, rows: list[list[str]]) -> None:
    """Write ``rows`` to ``path`` through a temporary file and ``os.replace`` (never a half-written file)."""
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:12]}.tmp"
    try:
        with open(tmp, "w", newline="") as f:
            csv.writer(f).writerows(rows)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


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
        comm: Communicator (default ``MPI.COMM_WORLD``); rank 0 writes.
        resume_after_step: Continue an existing file (see :class:`StatisticsWriter`).

    Raises:
        StatisticsFileError: On every rank, if the file to continue is damaged.
    """

    def __init__(self, path: str | Path, /, *, comm: MPI.Comm | None = None,
                 resume_after_step: int | None = None) -> None:
        comm = comm if comm is not None else _mpi().COMM_WORLD
        self.path = Path(path)
        self._rank = comm.rank  # only the rank: a mesh's communicator may be freed with its mesh
        self._writer: StatisticsWriter | None = None
        if resume_after_step is not None:
            self._writer = _agreed(comm, lambda: self._continue(resume_after_step))

    def _continue(self, step: int) -> StatisticsWriter | None:
        if not self.path.exists():
            return None
        return StatisticsWriter(self.path, BALANCE_COLUMNS, comm=_mpi().COMM_SELF, resume_after_step=step,
                                numeric=False)

    def write(self, step: int, before: Any, after: Any) -> None:
        """Append a row; ``before``/``after`` have per-rank ``cells``, ``particles`` arrays and
        ``cell_imbalance``, ``particle_imbalance``, ``load_imbalance`` (collective)."""
        if self._writer is None and self._rank == 0:
            self._writer = StatisticsWriter(self.path, BALANCE_COLUMNS, comm=_mpi().COMM_SELF, numeric=False)
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
