"""Files written safely by all ranks: parallel HDF5 datasets (:class:`H5Sink`, MPI-IO with Debian's
``python3-h5py-mpi``, gathered to rank 0 with a serial h5py) and text files that appear atomically
(:func:`atomic_write_text`: a hidden temporary name, fsync, rename).
"""

from __future__ import annotations

import os
import uuid
import warnings
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

__all__ = ["H5Sink", "atomic_write_text", "exclusive_offset"]


def exclusive_offset(comm: MPI.Intracomm, count: int, /) -> tuple[int, int]:
    """Start of this rank's slice and the global total for local ``count`` rows (collective).

    Returns:
        ``(offset, total)``: the exclusive prefix sum of the counts, and their sum.
    """
    offset = comm.exscan(int(count), op=MPI.SUM)
    total = comm.allreduce(int(count), op=MPI.SUM)
    return (0 if offset is None or comm.rank == 0 else int(offset)), int(total)


def _mpi_h5py() -> bool:
    return bool(h5py.get_config().mpi)


class H5Sink:
    """An HDF5 file written collectively under a temporary name and renamed when complete.

    With an MPI build of h5py (or a single rank) every rank writes its slice of each distributed
    dataset itself (``driver="mpio"``); otherwise the slices are gathered and rank 0 writes. Use
    as a context manager: leaving the block normally publishes the file (:meth:`commit`), an
    exception removes the temporary file.

    Args:
        path: Final file name (same on all ranks).
        comm: The communicator of the ranks that write.
        parallel: Force MPI-IO (True) or gather-to-rank-0 (False); by default MPI-IO whenever the
            h5py build supports it.
    """

    def __init__(self, path: str | os.PathLike[str], comm: MPI.Intracomm, /, *, parallel: bool | None = None) -> None:
        self.path = Path(path)
        self.comm = comm
        if parallel is None:
            parallel = comm.size == 1 or _mpi_h5py()
            if not parallel:
                warnings.warn(
                    f"h5py is a serial build: gathering particle data to rank 0 to write {self.path.name}",
                    RuntimeWarning,
                    stacklevel=2,
                )
        elif parallel and comm.size > 1 and not _mpi_h5py():
            raise RuntimeError("parallel HDF5 output needs an MPI build of h5py")
        self.parallel = parallel
        name = f".{self.path.name}.{uuid.uuid4().hex[:12]}.tmp" if comm.rank == 0 else None
        self.tmp = self.path.parent / comm.bcast(name, root=0)
        self.file: h5py.File | None = None
        if self.parallel and comm.size > 1:
            self.file = h5py.File(self.tmp, "w", driver="mpio", comm=comm)
        elif comm.rank == 0:
            self.file = h5py.File(self.tmp, "w")

    def __enter__(self) -> H5Sink:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()

    def distributed(self, name: str, local: npt.ArrayLike) -> None:
        """Dataset ``name`` = concatenation over ranks (in rank order) of ``local`` (collective).

        ``local`` has shape=(n, ...) with the same trailing shape and dtype on every rank.
        """
        local = np.ascontiguousarray(local)
        if self.parallel:
            offset, total = exclusive_offset(self.comm, local.shape[0])
            dset = self._create(name, (total, *local.shape[1:]), local.dtype)
            if local.shape[0]:
                dset[offset : offset + local.shape[0]] = local
        else:
            pieces = self.comm.gather(local, root=0)
            if pieces is not None:  # rank 0
                self._create(name, None, None, data=np.concatenate(pieces))

    def replicated(self, name: str, value: npt.ArrayLike) -> None:
        """Dataset ``name`` holding rank 0's ``value`` (collective; shape and dtype from rank 0)."""
        array = np.ascontiguousarray(value) if self.comm.rank == 0 else None
        meta = self.comm.bcast((array.shape, array.dtype.str) if array is not None else None, root=0)
        if self.parallel and self.comm.size > 1:
            dset = self._create(name, meta[0], np.dtype(meta[1]))
            if array is not None and array.size:  # rank 0
                dset[...] = array
        elif array is not None:  # rank 0
            self._create(name, None, None, data=array)

    def attrs(self, **values: object) -> None:
        """Root attributes (rank 0's values are written; collective)."""
        values = self.comm.bcast(values if self.comm.rank == 0 else None, root=0)
        if self.file is not None:
            for key, value in values.items():
                self.file.attrs[key] = value

    def _create(self, name: str, shape: tuple[int, ...] | None, dtype: np.dtype | None,
                data: npt.NDArray | None = None) -> h5py.Dataset:
        assert self.file is not None
        if data is not None:
            return self.file.create_dataset(name, data=data)
        return self.file.create_dataset(name, shape=shape, dtype=dtype)

    def commit(self) -> Path:
        """Close, then publish the file under its final name (collective). Returns the path."""
        if self.file is not None:
            self.file.close()
            self.file = None
        self.comm.Barrier()
        if self.comm.rank == 0:
            _fsync(self.tmp)
            os.replace(self.tmp, self.path)
        self.comm.Barrier()
        return self.path

    def abort(self) -> None:
        """Close and delete the temporary file (best effort, no communication)."""
        if self.file is not None:
            try:
                self.file.close()
            except Exception:  # noqa: BLE001 - already failing; keep the original error
                pass
            self.file = None
        if self.comm.rank == 0:
            self.tmp.unlink(missing_ok=True)


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and ``os.replace`` (one process)."""
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:12]}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
