"""Checkpoint and restart of a particle swarm (one parallel HDF5 file).

:func:`save_checkpoint` writes, with every rank writing its slice (MPI-IO, see
:class:`fembase.files.H5Sink`), in the order the particles are stored:

- ``ids`` (N,) int64, ``x`` (N, gdim) float64, ``xref`` (N, tdim) float64;
- ``cells`` (N,) int64: the GLOBAL index of each particle's cell;
- ``properties`` (N, num_columns) float64 and the layout ``layout/names``, ``layout/starts``,
  ``layout/sizes``;
- ``rank_offsets`` (num_ranks + 1,) int64: rank r wrote rows ``rank_offsets[r]:rank_offsets[r+1]``;
- ``cell_ranges`` (num_ranks, 2) int64: the global range of the cells rank r owned;
- ``rng_state`` (JSON as uint8 bytes) and ``extra/<name>`` for user arrays;
- root attributes ``format``, ``version``, ``num_ranks``, ``step``, ``time``, ``gdim``, ``tdim``,
  ``num_global_cells``, and ``token`` if one is given: a string the caller also writes into the
  other parts of a checkpoint and compares on reading, to prove the parts belong together.

The file appears atomically (temporary name, then ``os.replace``).

:func:`load_checkpoint` restores exactly (same particles on the same ranks in the same order, same
``xref`` bit for bit) when the rank count and the cell partition are the same as when saving and
the stored reference positions map back to the stored positions. Otherwise each rank reads an
equal slice, locates its particles and :func:`particles.parallel.migration.migrate` hands them to their
owners; ids, positions and properties are preserved. A missing or damaged file raises
:class:`CheckpointError` on every rank: rank 0 checks the file alone and broadcasts its verdict
before any collective open, and read errors in the collective phase are reduced over all ranks.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, NamedTuple

import h5py
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase.files import H5Sink
from particles.parallel.migration import migrate
from particles.storage.swarm import Swarm

__all__ = ["FORMAT", "VERSION", "CheckpointError", "Restored", "load_checkpoint", "save_checkpoint"]

FORMAT = "particles-checkpoint"
"""Value of the ``format`` attribute of a checkpoint file."""
VERSION = 1
"""Checkpoint format version this code writes and reads."""

_REQUIRED = ("ids", "x", "xref", "cells", "properties", "rank_offsets", "cell_ranges",
             "layout/names", "layout/starts", "layout/sizes")
_ATTRS = ("format", "version", "num_ranks", "step", "time", "gdim", "tdim", "num_global_cells")


class CheckpointError(RuntimeError):
    """A checkpoint file is missing, unreadable or inconsistent (one-line message naming the file)."""


class Restored(NamedTuple):
    """Result of :func:`load_checkpoint`.

    Attributes:
        swarm: The restored particles on the given mesh.
        step: Step number saved with the checkpoint.
        time: Simulation time saved with the checkpoint.
        rng_state: The saved random-generator state (``None`` if none was saved).
        extra: The saved extra arrays by name.
        exact: True if the particles were restored on the ranks and in the order they were saved.
    """

    swarm: Swarm
    step: int
    time: float
    rng_state: dict[str, Any] | None
    extra: dict[str, npt.NDArray]
    exact: bool


# ---------------------------------------------------------------------- JSON for RNG states
def _to_json(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return {"__ndarray__": obj.tolist(), "dtype": obj.dtype.str}
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in an rng_state")


def _from_json(obj: dict[str, Any]) -> Any:
    if "__ndarray__" in obj and "dtype" in obj:
        return np.asarray(obj["__ndarray__"], dtype=np.dtype(obj["dtype"]))
    return obj


def _one_line(path: Path, what: str) -> str:
    return " ".join(f"checkpoint {path}: {what}".split())


# ---------------------------------------------------------------------- save
def save_checkpoint(
    path: str | os.PathLike[str],
    swarm: Swarm,
    /,
    *,
    step: int,
    time: float,
    rng_state: dict[str, Any] | None = None,
    extra: dict[str, npt.ArrayLike] | None = None,
    token: str | None = None,
) -> Path:
    """Write the swarm and the run state to one HDF5 file (collective, atomic).

    Args:
        path: Checkpoint file (same on all ranks).
        swarm: Particles, all in owned cells (as after a completed step).
        step: Step number to restore.
        time: Simulation time to restore.
        rng_state: JSON-able state (numpy arrays allowed, e.g. ``Generator.bit_generator.state``);
            must be the same on all ranks.
        extra: Arrays to restore with the checkpoint; rank 0's values are stored.
        token: Stored as the ``token`` attribute (rank 0's value), e.g. the token of the run
            checkpoint this file is a part of.

    Returns:
        The path of the published file.

    Raises:
        ValueError: On every rank, if some particle is not in an owned cell, or ``rng_state``
            differs between ranks.
    """
    comm = swarm.comm
    path = Path(comm.bcast(str(path) if comm.rank == 0 else None, root=0))
    cells = swarm.cells
    bad = bool(np.any((cells < 0) | (cells >= swarm.num_owned_cells)))
    if comm.allreduce(bad, op=MPI.LOR):
        raise ValueError("save_checkpoint needs every particle in an owned cell (relocate and migrate first)")
    states = comm.allgather(None if rng_state is None else json.dumps(rng_state, default=_to_json, sort_keys=True))
    if any(s != states[0] for s in states):
        raise ValueError("save_checkpoint: rng_state differs between ranks")
    extra = dict(extra or {}) if comm.rank == 0 else {}
    extra_names = comm.bcast(sorted(extra), root=0)
    for name in extra_names:
        if "/" in name or not name:
            raise ValueError(f"invalid extra name {name!r}")
    tdim = swarm.tdim
    cell_map = swarm.mesh.topology.index_map(tdim)
    local_range = np.asarray(cell_map.local_range, dtype=np.int64)
    layouts = sorted((swarm.layout(n) for n in swarm.property_names), key=lambda lay: lay.start)
    counts = np.asarray(comm.allgather(swarm.num_particles), dtype=np.int64)
    rank_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    cell_ranges = np.asarray(comm.allgather(local_range), dtype=np.int64).reshape(comm.size, 2)
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
    comm.Barrier()
    with H5Sink(path, comm) as sink:
        sink.distributed("ids", swarm.ids)
        sink.distributed("x", swarm.x)
        sink.distributed("xref", swarm.xref)
        sink.distributed("cells", swarm.cells.astype(np.int64) + local_range[0])
        sink.distributed("properties", np.ascontiguousarray(swarm.properties, dtype=np.float64))
        sink.replicated("rank_offsets", rank_offsets)
        sink.replicated("cell_ranges", cell_ranges)
        sink.replicated("layout/names", np.array([lay.name.encode() for lay in layouts], dtype="S"))
        sink.replicated("layout/starts", np.array([lay.start for lay in layouts], dtype=np.int64))
        sink.replicated("layout/sizes", np.array([lay.size for lay in layouts], dtype=np.int64))
        if states[0] is not None:
            sink.replicated("rng_state", np.frombuffer(states[0].encode(), dtype=np.uint8))
        for name in extra_names:
            sink.replicated(f"extra/{name}", np.asarray(extra[name]) if comm.rank == 0 else None)
        sink.attrs(format=FORMAT, version=VERSION, num_ranks=comm.size, step=int(step), time=float(time),
                   gdim=swarm.gdim, tdim=tdim, num_global_cells=int(cell_map.size_global))
        if token is not None:
            sink.attrs(token=str(token))
    return path


# ---------------------------------------------------------------------- load
class _Header(NamedTuple):
    num_ranks: int
    step: int
    time: float
    num_global_cells: int
    rank_offsets: npt.NDArray[np.int64]
    cell_ranges: npt.NDArray[np.int64]
    names: list[str]
    starts: list[int]
    sizes: list[int]
    rng_state: dict[str, Any] | None
    extra: dict[str, npt.NDArray]


def _inspect(path: Path, gdim: int, tdim: int) -> _Header | str:
    """Check the file alone (rank 0). Returns the header, or what is wrong."""
    if not path.exists():
        return "missing (no such file)"
    if not path.is_file():
        return "not a regular file"
    if not os.access(path, os.R_OK):
        return "not readable"
    try:
        if not h5py.is_hdf5(path):
            return "not an HDF5 file"
        with h5py.File(path, "r") as f:
            return _read_header(f, gdim, tdim)
    except (OSError, ValueError, KeyError, TypeError) as err:
        return f"damaged HDF5 file ({err})"


def _read_header(f: h5py.File, gdim: int, tdim: int) -> _Header | str:
    if f.attrs.get("format") != FORMAT:
        return f"not a particle checkpoint (format attribute {f.attrs.get('format')!r})"
    version = int(f.attrs.get("version", -1))
    if version != VERSION:
        return f"version mismatch: file has format version {version}, this code reads {VERSION}"
    for key in _ATTRS:
        if key not in f.attrs:
            return f"missing attribute {key!r}"
    for name in _REQUIRED:
        if name not in f or not isinstance(f[name], h5py.Dataset):
            return f"missing dataset {name!r}"
    if int(f.attrs["gdim"]) != gdim or int(f.attrs["tdim"]) != tdim:
        return (f"dimension mismatch: saved gdim={int(f.attrs['gdim'])}, tdim={int(f.attrs['tdim'])}; "
                f"mesh has gdim={gdim}, tdim={tdim}")
    n = f["ids"].shape[0] if f["ids"].ndim == 1 else -1
    num_ranks = int(f.attrs["num_ranks"])
    sizes = f["layout/sizes"][...].astype(np.int64)
    starts = f["layout/starts"][...].astype(np.int64)
    names = [s.decode() for s in f["layout/names"][...]]
    offsets = f["rank_offsets"][...].astype(np.int64)
    ncols = int(sizes.sum())
    expect = {"ids": (n,), "x": (n, gdim), "xref": (n, tdim), "cells": (n,), "properties": (n, ncols),
              "rank_offsets": (num_ranks + 1,), "cell_ranges": (num_ranks, 2)}
    for name, shape in expect.items():
        if f[name].shape != shape:
            return f"size mismatch: dataset {name!r} has shape {f[name].shape}, expected {shape}"
    if len(names) != len(starts) or len(names) != len(sizes):
        return "size mismatch: the property layout datasets differ in length"
    if ncols and not np.array_equal(starts, np.concatenate([[0], np.cumsum(sizes)[:-1]])):
        return "size mismatch: property layout starts do not follow the sizes"
    if offsets[0] != 0 or offsets[-1] != n or np.any(np.diff(offsets) < 0):
        return f"size mismatch: rank_offsets do not partition the {n} particles"
    rng_state = None
    if "rng_state" in f:
        rng_state = json.loads(f["rng_state"][...].tobytes().decode(), object_hook=_from_json)
    extra = {}
    if "extra" in f:
        extra = {name: f["extra"][name][...] for name in f["extra"]}
    return _Header(num_ranks, int(f.attrs["step"]), float(f.attrs["time"]), int(f.attrs["num_global_cells"]),
                   offsets, f["cell_ranges"][...].astype(np.int64), names, [int(s) for s in starts],
                   [int(s) for s in sizes], rng_state, extra)


class _Rows(NamedTuple):
    ids: npt.NDArray[np.int64]
    x: npt.NDArray[np.float64]
    xref: npt.NDArray[np.float64]
    cells: npt.NDArray[np.int64]
    properties: npt.NDArray[np.float64]


def _read_rows(f: h5py.File, start: int, stop: int) -> _Rows:
    def get(name: str) -> npt.NDArray:
        dset = f[name]
        if stop > start:
            return dset[start:stop]
        return np.empty((0, *dset.shape[1:]), dtype=dset.dtype)

    return _Rows(get("ids").astype(np.int64), get("x").astype(np.float64), get("xref").astype(np.float64),
                 get("cells").astype(np.int64), get("properties").astype(np.float64))


def _open_collective(path: Path, comm: MPI.Intracomm) -> h5py.File:
    if comm.size > 1 and h5py.get_config().mpi:
        return h5py.File(path, "r", driver="mpio", comm=comm)
    return h5py.File(path, "r")


def _read_slice(path: Path, comm: MPI.Intracomm, start: int, stop: int) -> _Rows:
    """Rows ``start:stop`` of the per-particle datasets (collective; read errors raised on all ranks)."""
    rows: _Rows | None = None
    error = ""
    try:
        with _open_collective(path, comm) as f:
            rows = _read_rows(f, start, stop)
    except (OSError, ValueError, KeyError, TypeError) as err:
        error = _one_line(path, f"damaged HDF5 file ({err})")
    errors = [e for e in comm.allgather(error) if e]
    if errors:
        raise CheckpointError(errors[0])
    assert rows is not None
    return rows


def load_checkpoint(path: str | os.PathLike[str], mesh: dolfinx.mesh.Mesh, /) -> Restored:
    """Restore a swarm saved with :func:`save_checkpoint` on ``mesh`` (collective).

    Args:
        path: Checkpoint file.
        mesh: The mesh to restore on: the same mesh (and partition) for an exact restore, or any
            mesh covering the saved particles (e.g. another rank count).

    Returns:
        :class:`Restored` with the swarm, step, time, RNG state and extra arrays.

    Raises:
        CheckpointError: On every rank, with a one-line message, if the file is missing, not
            HDF5, damaged, of another format version, inconsistent in its sizes, or holds
            particles outside ``mesh``.
    """
    comm = mesh.comm
    gdim, tdim = mesh.geometry.dim, mesh.topology.dim
    path = Path(comm.bcast(str(path) if comm.rank == 0 else None, root=0))
    header = _inspect(path, gdim, tdim) if comm.rank == 0 else None
    header = comm.bcast(header, root=0)
    if isinstance(header, str):
        raise CheckpointError(_one_line(path, header))

    swarm = Swarm(mesh)
    for name, size in zip(header.names, header.sizes):
        swarm.add_property(name, size)
    cell_map = mesh.topology.index_map(tdim)
    local_range = np.asarray(cell_map.local_range, dtype=np.int64)
    same_partition = (
        header.num_ranks == comm.size
        and header.num_global_cells == cell_map.size_global
        and np.array_equal(header.cell_ranges[comm.rank], local_range)
    )
    exact = bool(comm.allreduce(same_partition, op=MPI.LAND))
    n = int(header.rank_offsets[-1])
    balanced = (n * comm.rank // comm.size, n * (comm.rank + 1) // comm.size)
    if exact:
        rows = _read_slice(path, comm, int(header.rank_offsets[comm.rank]), int(header.rank_offsets[comm.rank + 1]))
        local = rows.cells - local_range[0]
        fits = bool(np.all((local >= 0) & (local < swarm.num_owned_cells)))
        if fits and local.size:
            x = swarm.geometry.push_forward(local.astype(np.int32), rows.xref)
            scale = max(1.0, float(np.abs(rows.x).max()))
            fits = bool(np.all(np.abs(x - rows.x) <= 1e-9 * scale))
        exact = bool(comm.allreduce(fits, op=MPI.LAND))
        if exact:
            swarm.add(rows.ids, rows.x, rows.xref, local.astype(np.int32), rows.properties)
    if not exact:
        rows = _read_slice(path, comm, *balanced)
        located = swarm.geometry.locate(rows.x)
        swarm.add(rows.ids, rows.x, located.xref, located.cells, rows.properties)
        stats = migrate(swarm)
        if stats.global_lost:
            raise CheckpointError(_one_line(path, f"{stats.global_lost} saved particles lie outside the given mesh"))
    return Restored(swarm, header.step, header.time, header.rng_state, header.extra, exact)
