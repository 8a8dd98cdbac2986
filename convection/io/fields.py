"""Field output to XDMF (ParaView) on meshes that change with adaptivity.

XDMF as written by :class:`dolfinx.io.XDMFFile` ties a time series to one mesh, so each mesh gets
its own file: ``fields_000.xdmf`` (+ ``.h5``) for the first mesh, ``fields_001.xdmf`` after the
first adaptation that changed the mesh, and so on. Higher-degree fields are interpolated to P1 at
the vertices (point data); DG0 fields are written as cell data.

Beside them, ``fields.xdmf`` lists every written time in ONE Temporal collection: one Uniform grid
per time, referencing the mesh (geometry, topology) of that time's epoch file and that time's
function datasets in the epoch ``.h5`` files. ParaView (or ``pyvista.get_reader``) opens the whole
run in one go, each time on its own mesh.

The epoch file is closed after every write (and reopened in append mode for the next one): HDF5
locks a file that is open for writing, and only a closed file is complete on disk, so everything
``fields.xdmf`` references can be read at any moment, also while the run goes on. Rank 0 rewrites
``fields.xdmf`` atomically (temporary file + ``os.replace``) after each write.

A model in physical units writes coordinates, times and fields in its output units
(:mod:`convection.io.output_units`) and names them in ``fields_units.json``.

A field output format has the one plugin shape (docs/developers.md): its ``Settings`` are the
``output`` section (:class:`OutputSettings`, which names it in ``output.fields_format``), and
``build(settings, context)`` makes it with a :class:`FieldWriterContext`; it is made only through
:data:`FIELD_WRITERS`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar, NamedTuple, Protocol

import dolfinx.fem
import dolfinx.io
import dolfinx.mesh
import numpy as np
from mpi4py import MPI

from convection.io.checkpoint import CheckpointSettings
from convection.io.output_units import OutputUnits
from convection.io.run_folder import check_output_directory
from convection.physics.elastic_outputs import ELASTIC_OUTPUTS
from convection.postprocess.postprocessors import POSTPROCESSORS
from convection.schema import REQUIRED, Names, param, subsection
from fembase.dolfinx_compat import (element_degree, function_space, is_discontinuous, xdmf_lagrange_degree,
                                    xdmf_value_shape)
from fembase.registry import Registry
from fembase.xdmf import XdmfSeries, declare_types, grid_time

__all__ = ["FIELD_WRITERS", "PROGRESS_MODES", "FieldOutput", "FieldWriter", "FieldWriterContext", "OutputSettings"]

PROGRESS_MODES = ("auto", "bar", "lines", "none")
"""The ``output.progress`` displays (:class:`convection.run.progress.Progress`)."""


@dataclass(frozen=True)
class OutputSettings:
    """The ``output`` config section: the run folder and what is written into it, when."""

    directory: str = param(REQUIRED, check=check_output_directory,
                           help="output folder (statistics.csv, fields, config)")
    fields_every: int = param(10, minimum=0, help="write the fields every K steps (0 = only at the end)")
    fields_format: str = param("xdmf", choices=Names(lambda: FIELD_WRITERS), help="the fields' file format")
    statistics: tuple[str, ...] | None = param(None, choices=Names(POSTPROCESSORS),
                                               help="postprocessors whose columns statistics.csv holds (null: all "
                                                    "that apply)")
    extra_fields: tuple[str, ...] | None = param(None, choices=ELASTIC_OUTPUTS,
                                                 help="optional fields beside the standard ones: the elastic outputs "
                                                      "(with physics.elasticity; null: all that apply)")
    checkpoint: CheckpointSettings = subsection(CheckpointSettings)
    progress: str = param("auto", choices=PROGRESS_MODES,
                          help="progress display: a bar on a terminal, lines in a log (auto: by stdout), or none")
    progress_every: int = param(10, minimum=1, help="steps between progress lines")


class FieldWriterContext(NamedTuple):
    """What a field writer is made from, beside its settings (the ``output`` section, whose
    ``directory`` it writes into).

    Attributes:
        resume_after: Continue the series already in the directory after this time (a resumed
            run); None: a new series.
        units: Write in these units (a model in physical units); None: the solver's numbers.
    """

    resume_after: float | None = None
    units: OutputUnits | None = None


class FieldWriter(Protocol):
    """A field output format (collective): writes named Functions of one mesh at a time (the mesh
    may change between calls) and closes its files. An implementation is a class with ``name``,
    ``description``, ``Settings`` (:class:`OutputSettings`) and ``build(settings, context)`` (see
    :class:`FieldOutput`), registered in :data:`FIELD_WRITERS`."""

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]

    @classmethod
    def build(cls, settings: OutputSettings, context: FieldWriterContext, /) -> FieldWriter: ...

    def write(self, functions: Mapping[str, dolfinx.fem.Function], t: float) -> None: ...

    def close(self) -> None: ...


class FieldOutput:
    """Writes named Functions every call, starting a new file when the mesh changes (collective).

    Files in ``directory``: ``{prefix}_{epoch:03d}.xdmf`` and ``.h5`` per mesh, and
    ``{prefix}.xdmf``, the time series over all meshes. A new :class:`FieldOutput` starts a new
    series (existing files of the same names are overwritten).

    Args:
        directory: Output folder (must exist).
        prefix: File name prefix.
        resume_after: Continue the series already in ``directory`` (a resumed run): its times up
            to this one are kept, later ones dropped, and new mesh files get numbers after the
            existing ones.
        units: Write in these units (:mod:`convection.io.output_units`: coordinates, times and
            fields converted, their units in ``{prefix}_units.json``); None: as given.

    Attributes:
        files: The per-mesh ``.xdmf`` files written so far, in order.
        series_path: The time series over all meshes, ``{directory}/{prefix}.xdmf``.

    Example:
        >>> out = FieldOutput("run")
        >>> out.write({"temperature": T, "velocity": u}, t)
        >>> out.close()
    """

    name: ClassVar[str] = "xdmf"
    description: ClassVar[str] = ("XDMF/HDF5 per mesh and one time series over all meshes (fields.xdmf; what the "
                                  "pictures read)")
    Settings: ClassVar[type] = OutputSettings

    @classmethod
    def build(cls, settings: OutputSettings, context: FieldWriterContext, /) -> FieldOutput:
        """The output into ``settings.directory`` (``fields*.xdmf``)."""
        return cls(settings.directory, resume_after=context.resume_after, units=context.units)

    def __init__(self, directory: str | Path, /, *, prefix: str = "fields", resume_after: float | None = None,
                 units: OutputUnits | None = None) -> None:
        self.directory = Path(directory)
        self.prefix = prefix
        self.epoch = -1
        self.units = units
        self._resume_after = None if resume_after is None else self._time(resume_after)
        self._names_written: list[str] = []
        self._mesh: dolfinx.mesh.Mesh | None = None
        self._file: dolfinx.io.XDMFFile | None = None
        self._out: dict[str, tuple[dolfinx.fem.Function, dolfinx.fem.Function | None]] = {}
        self.files: list[Path] = []
        self.series_path = self.directory / f"{prefix}.xdmf"
        self._series = XdmfSeries(self.series_path, prefix)

    def _open(self, mesh: dolfinx.mesh.Mesh) -> None:
        self.close()
        if self._resume_after is not None:
            self._continue_series(mesh.comm)
        self.epoch += 1
        path = self.directory / f"{self.prefix}_{self.epoch:03d}.xdmf"
        self._file = dolfinx.io.XDMFFile(mesh.comm, str(path), "w")
        length = None if self.units is None else self.units.length
        if length is None or length.factor == 1.0:
            self._file.write_mesh(mesh)
        else:  # the coordinates in the output unit, for the writing only
            x = mesh.geometry.x
            saved = x.copy()
            try:
                length.apply(x)
                self._file.write_mesh(mesh)
            finally:
                x[:] = saved
        self._mesh = mesh
        self._written_x = mesh.geometry.x.copy()
        self._out = {}
        self.files.append(path)

    def _moved(self, mesh: dolfinx.mesh.Mesh) -> bool:
        """Whether the mesh's nodes moved since its file was opened (a free surface: a new file
        holds the deformed mesh). Collective."""
        return bool(mesh.comm.allreduce(not np.array_equal(mesh.geometry.x, self._written_x), op=MPI.LOR))

    def _output_function(self, name: str, f: dolfinx.fem.Function) -> dolfinx.fem.Function:
        """``f`` in the written space (DG0 or the file's Lagrange degree), in the output's units; a 2D
        tensor as VTK's 3 x 3 (:func:`fembase.dolfinx_compat.xdmf_value_shape`)."""
        shape = tuple(f.ufl_shape)
        written = xdmf_value_shape(shape)
        if name not in self._out:
            mesh = f.function_space.mesh
            if is_discontinuous(f.function_space) and element_degree(f.function_space) == 0:
                family, degree = "DG", 0
            else:
                family, degree = "Lagrange", xdmf_lagrange_degree(mesh)
            out = dolfinx.fem.Function(function_space(mesh, family, degree, shape=written or None), name=name)
            mid = None if written == shape else dolfinx.fem.Function(function_space(mesh, family, degree, shape=shape))
            self._out[name] = (out, mid)
        out, mid = self._out[name]
        if mid is None:
            out.interpolate(f)
        else:
            mid.interpolate(f)
            out.x.array.reshape(-1, 9)[:, [0, 1, 3, 4]] = mid.x.array.reshape(-1, 4)
        conversion = None if self.units is None else self.units.of(name)
        if conversion is not None:
            conversion.apply(out.x.array)
        return out

    def _time(self, t: float) -> float:
        """A simulation time in the output's unit."""
        return float(t) if self.units is None else float(t) * self.units.time.factor

    def write(self, functions: Mapping[str, dolfinx.fem.Function], t: float) -> None:
        """Write every Function (all on one mesh) at time ``t`` (collective).

        Adds ``t`` to the current mesh's file (a new file if the mesh changed or its nodes moved
        since the last write), closes that file, then adds a grid for ``t`` to the series ``{prefix}.xdmf``.
        Writing a time that is already in the series replaces its grid there.

        Args:
            functions: Name -> Function; the names become the field names in the files.
            t: Simulation time (nondimensional; written in the output's time unit).

        Raises:
            ValueError: ``functions`` is empty.
            RuntimeError: Rank 0 could not write the series file (raised on every rank).
        """
        if not functions:
            raise ValueError("FieldOutput.write needs at least one Function")
        mesh = next(iter(functions.values())).function_space.mesh
        if mesh is not self._mesh or self._moved(mesh):
            self._open(mesh)
        elif self._file is None:
            self._file = dolfinx.io.XDMFFile(mesh.comm, str(self.files[-1]), "a")
        assert self._file is not None
        t = self._time(t)
        for name, f in functions.items():
            self._file.write_function(self._output_function(name, f), t)
        self.close()
        error = None
        if mesh.comm.rank == 0:
            try:
                self._add_grid(self.files[-1], list(functions), t)
                self._series.write()
                if self.units is not None and list(functions) != self._names_written:
                    self.units.write_json(self.directory / f"{self.prefix}_units.json", functions)
                    self._names_written = list(functions)
            except Exception as exc:  # noqa: BLE001 - re-raised on every rank below
                error = f"{type(exc).__name__}: {exc}"
        error = mesh.comm.bcast(error, root=0)
        if error is not None:
            raise RuntimeError(f"could not write {self.series_path}: {error}")

    def close(self) -> None:
        """Close the current mesh's file (collective; :meth:`write` reopens it when needed)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def _continue_series(self, comm) -> None:
        """Keep the existing series up to ``resume_after``; number new files after the old ones."""
        last = -1
        if comm.rank == 0:
            numbers = [int(p.stem.rsplit("_", 1)[1])
                       for p in self.directory.glob(f"{self.prefix}_[0-9][0-9][0-9].xdmf")]
            last = max(numbers, default=-1)
            self._series.load(grid_time)
            self._series.keep(lambda t: t <= self._resume_after * (1.0 + 1e-14))
        self.epoch = comm.bcast(last, root=0)
        self._resume_after = None

    # ------------------------------------------------------------------ series (rank 0 only)
    def _add_grid(self, epoch_file: Path, names: list[str], t: float) -> None:
        """Append the grid of time ``t`` built from the epoch file that dolfinx just wrote."""
        domain = ET.parse(epoch_file).getroot().find("Domain")
        if domain is None:
            raise ValueError(f"{epoch_file.name} has no Domain")
        mesh_grid = next((g for g in domain.findall("Grid") if g.get("GridType") == "Uniform"), None)
        if mesh_grid is None:
            raise ValueError(f"{epoch_file.name} has no mesh grid")
        grid = ET.Element("Grid", Name=f"{self.prefix}_{len(self._series.grids):06d}", GridType="Uniform")
        ET.SubElement(grid, "Time", Value=repr(t))
        for tag in ("Topology", "Geometry"):
            node = mesh_grid.find(tag)
            if node is None:
                raise ValueError(f"{epoch_file.name}: mesh grid without {tag}")
            grid.append(node)
        collections = {g.get("Name"): g for g in domain.findall("Grid") if g.get("GridType") == "Collection"}
        for name in names:
            steps = collections[name].findall("Grid") if name in collections else []
            if not steps:
                raise ValueError(f"{epoch_file.name} has no time series '{name}'")
            # dolfinx appended this write's time last; its Time is the double printed in full.
            written = float(steps[-1].find("Time").get("Value"))
            if written != t:
                raise ValueError(f"{epoch_file.name}: last '{name}' is at t = {written!r}, expected {t!r}")
            grid.extend(steps[-1].findall("Attribute"))
        declare_types(grid, self.directory)
        self._series.keep(lambda s: s != t)
        self._series.append(t, grid)


FIELD_WRITERS: Registry[type[FieldWriter]] = Registry("field writer", (FieldOutput,))
"""Every field output format by its config name (``output.fields_format``)."""
