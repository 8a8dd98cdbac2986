"""Particle output: one HDF5 file per output step plus one XDMF time series (seed paper 2.8).

Every rank writes its own slice of ONE dataset per quantity into a shared HDF5 file with MPI-IO
(Debian's ``python3-h5py-mpi``): the slice starts at the exclusive prefix sum of the local particle
counts. A step's file holds

- ``ids``: global particle ids, shape=(N,), int64;
- ``positions``: shape=(N, 3), float64 (zero-padded in 1D/2D, as XDMF and ParaView expect);
- ``connectivity``: ``0..N-1``, shape=(N,), int64 (the Polyvertex topology);
- ``rank``: the rank that owned each particle, shape=(N,), int32 (for pictures of the partition);
- ``properties/<name>``: one dataset per property, shape=(N,) or (N, k), float64.

``particles.xdmf`` lists all steps as a Temporal collection of Polyvertex grids that reference the
datasets above, so ParaView opens the whole series at once. Every file appears atomically: it is
written under a hidden temporary name in the same directory and renamed (``os.replace``, by rank 0
after a barrier) only once complete, so a run killed at any moment leaves only complete files under
the final names (at worst a stray hidden temporary file).

If the h5py build is serial and more than one rank writes, the data are gathered to rank 0, which
writes alone (a :class:`RuntimeWarning` says so).

A particle output format has the one plugin shape (docs/developers.md): its ``Settings`` are a
particle system's ``output`` section (:class:`ParticleOutputSettings`, which names it in
``format``), and ``build(settings, context)`` makes it with a :class:`ParticleWriterContext`; it is
made only through :data:`PARTICLE_WRITERS`.

Mesh fields (e.g. a DG0 or P1 Function interpolated from particles) go through
:func:`write_mesh_fields`, a thin wrapper of :class:`dolfinx.io.XDMFFile`.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Sequence
from typing import ClassVar, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

import dolfinx.fem
import dolfinx.io
import dolfinx.mesh

from fembase.dolfinx_compat import element_degree, function_space, is_discontinuous, xdmf_lagrange_degree
from fembase.files import H5Sink, exclusive_offset
from fembase.params import Names, param
from fembase.registry import Registry
from fembase.xdmf import XdmfSeries, data_item
from particles.storage.swarm import Swarm

__all__ = ["PARTICLE_WRITERS", "OutputRecord", "ParticleOutput", "ParticleOutputSettings", "ParticleWriter",
           "ParticleWriterContext", "write_mesh_fields"]


class OutputRecord(NamedTuple):
    """One written output step.

    Attributes:
        step: Time step number.
        time: Simulation time.
        path: The step's HDF5 file.
        num_particles: Particles written (over all ranks).
    """

    step: int
    time: float
    path: Path
    num_particles: int


def _attribute_type(k: int) -> str:
    """XDMF AttributeType of a k-column property; 2 columns (2D vectors) are declared ``Vector``,
    which VTK's XdmfReader reads as one (zero-padded) vector per particle."""
    return {1: "Scalar", 2: "Vector", 3: "Vector", 6: "Tensor6", 9: "Tensor"}.get(k, "Matrix")


class ParticleOutput(Protocol):
    """A particle output format: writes the selected particles of a swarm at an output step
    (collective). An implementation is a class with ``name``, ``description``, ``Settings``
    (:class:`ParticleOutputSettings`) and ``build(settings, context)`` (see :class:`ParticleWriter`),
    registered in :data:`PARTICLE_WRITERS`."""

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]

    @classmethod
    def build(cls, settings: ParticleOutputSettings, context: ParticleWriterContext, /) -> ParticleOutput: ...

    def write(self, swarm: Swarm, t: float, step: int) -> OutputRecord: ...


class Conversion(Protocol):
    """``values = factor * values + offset`` in place (e.g. :class:`convection.io.output_units.Conversion`)."""

    label: str

    def apply(self, values: np.ndarray, /) -> None: ...


class OutputUnits(Protocol):
    """How the output is converted to physical units (e.g. :class:`convection.io.output_units.OutputUnits`):
    positions by ``length``, times by ``time``, a property by ``of(name)`` (None: as it is); the
    units are named in a JSON file by ``write_json(path, names)``."""

    length: Conversion
    time: Conversion

    def of(self, name: str, /) -> Conversion | None: ...

    def write_json(self, path: Path, names: Sequence[str], /) -> None: ...


@dataclass(frozen=True)
class ParticleOutputSettings:
    """When and what particle output is written: a particle system's ``output`` section."""

    every_steps: int | None = param(None, minimum=1, help="write particles every N steps")
    every_time: float | None = param(None, exclusive_minimum=0.0,
                                     help="write particles at the first step after every multiple of this time")
    properties: tuple[str, ...] | None = param(None, help="properties written (null: all)")
    every_nth: int = param(1, minimum=1, help="write only particles with id % every_nth == 0")
    format: str = param("xdmf", choices=Names(lambda: PARTICLE_WRITERS),
                        help="the particles' file format")


class ParticleWriterContext(NamedTuple):
    """What a particle writer is made from, beside its settings.

    Attributes:
        directory: The output directory.
        name: The file name stem (a particle system's name).
        units: Write in these units (:class:`OutputUnits`); None: as they are.
    """

    directory: str | os.PathLike[str]
    name: str = "particles"
    units: OutputUnits | None = None


class ParticleWriter:
    """Write particles with chosen properties, one HDF5 file per step and one XDMF series.

    Files in ``directory``: ``{name}_{step:06d}.h5`` and ``{name}.xdmf``. An existing XDMF file
    there is read on construction; its entries for steps before the step being written are kept
    (so a restarted run continues its series), later ones are replaced.

    Args:
        directory: Output directory (created if missing).
        name: File name stem.
        properties: Property names to write; ``None`` writes all (except names starting with
            ``_``, which are temporary columns such as integrator stages).
        every_nth: Write only particles whose ``id % every_nth == 0`` (a rank-independent subset).
        ids: Write only these particle ids (combined with ``every_nth`` if both are given).
        units: Write positions, times and properties converted (:class:`OutputUnits`; their
            units in ``{name}_units.json``); None: as they are.

    Example:
        >>> writer = ParticleWriter("out", properties=["temperature"], every_nth=10)
        >>> writer.write(swarm, t, step)
    """

    name: ClassVar[str] = "xdmf"
    description: ClassVar[str] = "one HDF5 file per output step and one XDMF time series (particles.xdmf)"
    Settings: ClassVar[type] = ParticleOutputSettings

    @classmethod
    def build(cls, settings: ParticleOutputSettings, context: ParticleWriterContext, /) -> ParticleWriter:
        """The writer of ``settings.properties`` (every ``settings.every_nth``-th particle) into
        ``context.directory``."""
        return cls(context.directory, name=context.name,
                   properties=None if settings.properties is None else list(settings.properties),
                   every_nth=settings.every_nth, units=context.units)

    def __init__(
        self,
        directory: str | os.PathLike[str],
        /,
        *,
        name: str = "particles",
        properties: Sequence[str] | None = None,
        every_nth: int = 1,
        ids: npt.ArrayLike | None = None,
        units: OutputUnits | None = None,
    ) -> None:
        if every_nth < 1:
            raise ValueError(f"every_nth must be >= 1, got {every_nth}")
        self.directory = Path(directory)
        self.name = name
        self.properties = None if properties is None else list(properties)
        self.every_nth = int(every_nth)
        self.ids = None if ids is None else np.unique(np.asarray(ids, dtype=np.int64))
        self.xdmf_path = self.directory / f"{name}.xdmf"
        self.units = units
        self._series: XdmfSeries | None = None

    def h5_path(self, step: int) -> Path:
        """The HDF5 file of output step ``step``."""
        return self.directory / f"{self.name}_{step:06d}.h5"

    def selection(self, swarm: Swarm, /) -> npt.NDArray[np.int64]:
        """Local rows of ``swarm`` that are written, shape=(m,), int64 (in storage order)."""
        keep = np.ones(swarm.num_particles, dtype=bool)
        if self.every_nth > 1:
            keep &= swarm.ids % self.every_nth == 0
        if self.ids is not None:
            keep &= np.isin(swarm.ids, self.ids)
        return np.flatnonzero(keep)

    def _property_names(self, swarm: Swarm) -> list[str]:
        if self.properties is None:
            return [p for p in swarm.property_names if not p.startswith("_")]
        for p in self.properties:
            swarm.layout(p)  # KeyError listing the known names
        return self.properties

    def write(self, swarm: Swarm, t: float, step: int) -> OutputRecord:
        """Write the selected particles at time ``t`` as output step ``step`` (collective).

        Args:
            swarm: The particles.
            t: Simulation time (the XDMF time value, converted by ``units``).
            step: Step number (names the HDF5 file).

        Returns:
            :class:`OutputRecord` of the written step (same on all ranks).
        """
        comm = swarm.comm
        if comm.rank == 0:
            self.directory.mkdir(parents=True, exist_ok=True)
        comm.Barrier()
        rows = self.selection(swarm)
        names = self._property_names(swarm)
        n = rows.shape[0]
        positions = np.zeros((n, 3), dtype=np.float64)
        positions[:, : swarm.gdim] = swarm.x[rows]
        if self.units is not None:
            self.units.length.apply(positions)
            time = np.array([float(t)])
            self.units.time.apply(time)
            t = float(time[0])
        path = self.h5_path(step)
        with H5Sink(path, comm) as sink:
            offset, total = exclusive_offset(comm, n)
            sink.distributed("ids", swarm.ids[rows])
            sink.distributed("positions", positions)
            sink.distributed("connectivity", np.arange(offset, offset + n, dtype=np.int64))
            sink.distributed("rank", np.full(n, comm.rank, dtype=np.int32))
            shapes: dict[str, tuple[int, ...]] = {}
            for p in names:
                values = swarm.property(p)[rows]
                values = values[:, 0] if values.shape[1] == 1 else values
                conversion = None if self.units is None else self.units.of(p)
                if conversion is not None:
                    values = values.copy()
                    conversion.apply(values)
                sink.distributed(f"properties/{p}", values)
                shapes[p] = (total, *values.shape[1:])
            sink.attrs(time=float(t), step=int(step), num_ranks=comm.size, gdim=swarm.gdim)
        if comm.rank == 0:
            self._add_grid(step, float(t), path.name, total, shapes)
            self._series.write()
            if self.units is not None:
                self.units.write_json(self.directory / f"{self.name}_units.json", names)
        comm.Barrier()
        return OutputRecord(int(step), float(t), path, total)

    # ------------------------------------------------------------------ XDMF (rank 0 only)
    def _add_grid(self, step: int, t: float, h5name: str, total: int, shapes: dict[str, tuple[int, ...]]) -> None:
        """The grid of output step ``step``; the series keeps the steps before it (a restarted run
        replaces the later ones)."""
        if self._series is None:
            self._series = XdmfSeries(self.xdmf_path, self.name)
            self._series.load(_step_of, strict=False)
        self._series.keep(lambda s: s < step)
        grid = ET.Element("Grid", Name=f"step_{step}", GridType="Uniform")
        ET.SubElement(grid, "Time", Value=repr(t))
        topo = ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(total),
                             NodesPerElement="1")
        topo.append(data_item(h5name, "connectivity", (total,), np.dtype(np.int64)))
        geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
        geom.append(data_item(h5name, "positions", (total, 3), np.dtype(np.float64)))
        fields = [("id", "ids", (total,), np.dtype(np.int64)), ("rank", "rank", (total,), np.dtype(np.int32))]
        fields += [(p, f"properties/{p}", shape, np.dtype(np.float64)) for p, shape in shapes.items()]
        for label, dataset, shape, dtype in fields:
            k = int(np.prod(shape[1:])) if len(shape) > 1 else 1
            attr = ET.SubElement(grid, "Attribute", Name=label, AttributeType=_attribute_type(k), Center="Node")
            attr.append(data_item(h5name, dataset, shape, dtype))
        self._series.append(step, grid)


PARTICLE_WRITERS: Registry[type[ParticleOutput]] = Registry("particle writer", (ParticleWriter,))
"""Every particle output format by its config name (``particles.output.format``)."""


def _step_of(grid: ET.Element) -> int | None:
    """The output step of a grid of the series (``step_N``), or None."""
    label = grid.get("Name", "")
    return int(label[5:]) if label.startswith("step_") else None


def write_mesh_fields(
    path: str | os.PathLike[str],
    mesh: dolfinx.mesh.Mesh,
    fields: Sequence[dolfinx.fem.Function],
    t: float,
    /,
    *,
    append: bool = False,
) -> None:
    """Write mesh Functions (e.g. fields interpolated from particles) at time ``t`` to XDMF (collective).

    DG0 fields are written as cell data; other fields are interpolated to (vector) P1 first,
    which is what :class:`dolfinx.io.XDMFFile` stores as point data on a linear mesh.

    Args:
        path: The ``.xdmf`` file (its ``.h5`` sits beside it).
        mesh: The mesh of all ``fields``.
        fields: Functions to write; their names become the XDMF attribute names.
        t: Time value.
        append: Add this time to an existing file written before by this function with the same
            mesh; otherwise the file is (re)created and the mesh written.
    """
    out: list[dolfinx.fem.Function] = []
    lagrange = xdmf_lagrange_degree(mesh)
    for f in fields:
        degree = element_degree(f.function_space)
        if degree == 0 or (degree == lagrange and not is_discontinuous(f.function_space)):
            out.append(f)
            continue
        g = dolfinx.fem.Function(function_space(mesh, "Lagrange", lagrange, shape=f.ufl_shape or None), name=f.name)
        g.interpolate(f)
        out.append(g)
    with dolfinx.io.XDMFFile(mesh.comm, str(path), "a" if append else "w") as xdmf:
        if not append:
            xdmf.write_mesh(mesh)
        for f in out:
            xdmf.write_function(f, float(t))
