"""Reading a run folder for its pictures: the statistics, the field files (``fields_NNN.h5``), the
units of the output (``fields_units.json``) and the particle series; which fields are materials.

None of this needs DOLFINx, MPI or VTK (h5py is imported when a field file is read).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any
from collections.abc import Callable

import numpy as np

from convection.io.statistics import read_table
from convection.io.xdmf_check import RunFilesError

__all__ = ["MATERIAL_FIELDS", "NON_MATERIAL_FIELDS", "RunFilesError", "check_run_folder", "field_files", "field_names",
           "field_units", "particle_series", "read_last_field", "read_statistics"]


_FIELD_FILE = re.compile(r"fields_([0-9]+)\.h5")
"""The per-mesh field files :class:`convection.io.fields.FieldOutput` writes."""


def read_statistics(path: str | Path, *, log: Callable[[str], None] | None = None) -> dict[str, np.ndarray]:
    """Columns of a statistics.csv as float arrays, shape=(rows,) each ({} without rows); a last
    line cut off by a kill is left out (and ``log`` told so).

    Raises:
        FileNotFoundError: No such file.
        convection.io.statistics.StatisticsFileError: The file is damaged (one line naming the line).
    """
    table = read_table(path)
    if table.incomplete and log is not None:
        log(f"{path}: its last line was cut off (the run was stopped while writing it); left out")
    if not table.rows:
        return {}
    values = np.array([[float(v) for v in row] for row in table.rows], dtype=np.float64)
    return {name: values[:, i] for i, name in enumerate(table.columns)}


def field_files(directory: str | Path) -> list[Path]:
    """The ``fields_NNN.h5`` files of a run folder in the order they were written (by NNN)."""
    numbered = [(p, _FIELD_FILE.fullmatch(p.name)) for p in Path(directory).glob("fields_*.h5")]
    return [p for _, p in sorted((int(match.group(1)), p) for p, match in numbered if match is not None)]


def read_last_field(directory: str | Path, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(points (n, 3), cells (m, k), values, time) of the latest step of field ``name``.

    Raises:
        RunFilesError: No field file, or the last one is damaged or lacks the field.
    """
    import h5py

    files = field_files(directory)
    if not files:
        raise RunFilesError(f"no fields_NNN.h5 in {directory}")
    try:
        with h5py.File(files[-1], "r") as h5:
            if f"Function/{name}" not in h5:
                raise RunFilesError(f"{files[-1]}: no field {name!r} (damaged?)")
            points = h5["Mesh/mesh/geometry"][...]
            cells = h5["Mesh/mesh/topology"][...]
            steps = h5[f"Function/{name}"]
            key = max(steps.keys(), key=lambda k: float(k.replace("_", ".")))
            values = steps[key][...]
    except RunFilesError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as err:
        raise RunFilesError(f"{files[-1]}: damaged HDF5 file ({' '.join(str(err).split())})") from None
    return points, cells, values, float(key.replace("_", "."))


def check_run_folder(directory: str | Path) -> Path:
    """``directory`` as a Path if it is a run folder with a ``statistics.csv``.

    Raises:
        RunFilesError: It is missing, not a folder, empty, or has no statistics.csv.
    """
    directory = Path(directory)
    if not directory.exists():
        raise RunFilesError(f"run folder '{directory}' not found")
    if not directory.is_dir():
        raise RunFilesError(f"'{directory}' is not a run folder (not a folder)")
    if not (directory / "statistics.csv").is_file():
        what = "is empty" if not any(directory.iterdir()) else "has no statistics.csv"
        raise RunFilesError(f"run folder '{directory}' {what}: nothing to draw")
    return directory


def field_names(directory: Path) -> list[str]:
    """The fields of the last field file (empty if it cannot be read)."""
    import h5py

    files = field_files(directory)
    try:
        with h5py.File(files[-1], "r") as h5:
            return list(h5["Function"].keys()) if "Function" in h5 else []
    except (OSError, KeyError, ValueError, IndexError):
        return []


NON_MATERIAL_FIELDS = ("temperature", "pressure", "velocity", "strain_rate_II", "stress_II")
MATERIAL_FIELDS = ("material", "composition")


def field_units(directory: str | Path) -> dict[str, Any] | None:
    """The units of a run's field output (``fields_units.json``: ``{"time", "length", "fields"}``,
    written by a model in physical units), or None (nondimensional output)."""
    path = Path(directory) / "fields_units.json"
    try:
        units = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return units if isinstance(units, dict) else None


def particle_series(directory: Path, system: str | None = None, /) -> Path | None:
    """The particle output (XDMF series) a picture draws: system ``system``'s
    (``particles_<name>.xdmf``), or by default ``particles.xdmf``, else the first system's by name;
    None if the run wrote no particles.

    Raises:
        ValueError: ``system`` wrote no output here (naming those that did).
    """
    written = sorted(directory.glob("particles*.xdmf"))
    if system is None:
        default = directory / "particles.xdmf"
        return default if default.is_file() else (written[0] if written else None)
    path = directory / ("particles.xdmf" if system == "particles" else f"particles_{system}.xdmf")
    if not path.is_file():
        names = [p.stem.removeprefix("particles_") for p in written]
        raise ValueError(f"no output of the particle system {system!r} in {directory} (written: {names or 'none'})")
    return path
