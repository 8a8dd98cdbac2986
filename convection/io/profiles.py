"""Profiles written with the fields: a quantity along a line at each field-output time (the
topography of a surface, :class:`convection.postprocess.geodynamics.Topography`).

``<name>_profile.csv`` holds one row per sample and output time: ``time``, the sample's
coordinates, the values; in the model's units where it has them (``time [Myr], x [km],
topography [km]``). A resumed run keeps the rows up to the time it resumes from.
"""

from __future__ import annotations

import csv
from pathlib import Path
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from convection.physics.scaling import ColumnUnits, Scaling
from fembase.files import atomic_write_text

__all__ = ["ProfileFile"]


class ProfileFile:
    """One profile's CSV file (rank 0 writes; the calls are collective only in that every rank
    makes them).

    Args:
        path: The file.
        comm: The run's communicator (its rank is kept: a mesh's communicator is freed with the
            mesh, which adaptivity and balancing replace).
        kinds: Column -> unit kind (:data:`convection.physics.scaling.UNIT_KINDS`) of the profile's
            columns (coordinates and values); the time column is added.
        scaling: The model's scaling (None: nondimensional).
        resume_after: Keep the existing rows up to this (nondimensional) time; None: a new file.
    """

    def __init__(self, path: Path, comm: MPI.Comm, kinds: Mapping[str, str], /, *, scaling: Scaling | None = None,
                 resume_after: float | None = None) -> None:
        self.path = Path(path)
        self.rank = comm.rank
        self.scaling = scaling
        self.kinds = {"time": "time", **kinds}
        self.header: list[str] | None = None
        self._resume_after = resume_after

    def write(self, t: float, profile: Mapping[str, np.ndarray], /) -> None:
        """Append the profile at time ``t`` (nondimensional; converted here)."""
        if self.rank != 0:
            return
        columns = ["time", *profile]
        units = ColumnUnits(self.scaling, columns, self.kinds) if self.scaling is not None else None
        if self.header is None:
            self._start(units.header if units is not None else columns)
        n = len(next(iter(profile.values())))
        rows = [{"time": t, **{c: float(profile[c][i]) for c in columns[1:]}} for i in range(n)]
        if units is not None:
            rows = [units.convert(row) for row in rows]
        with open(self.path, "a", newline="") as f:
            csv.writer(f).writerows([[repr(float(v)) for v in row.values()] for row in rows])

    def _start(self, header: list[str]) -> None:
        kept: list[list[str]] = []
        if self._resume_after is not None and self.path.exists():
            with open(self.path, newline="") as f:
                rows = list(csv.reader(f))
            factor = self.scaling.factor("time") if self.scaling is not None else 1.0
            limit = self._resume_after * factor * (1.0 + 1e-12)
            if rows and rows[0] == header:
                kept = [r for r in rows[1:] if r and float(r[0]) <= limit]
        text = ",".join(header) + "\n" + "".join(",".join(r) + "\n" for r in kept)
        atomic_write_text(self.path, text)
        self.header = header
