"""A run folder is used by one run at a time.

:class:`RunFolderLock` creates the folder and locks it for as long as the run goes: rank 0 holds an
exclusive ``fcntl.flock`` on ``RUN_DIR/.lock`` and writes into it who holds it (pid and host).
A second run or resume of the same folder — while the first still goes — is refused on every rank
before it writes anything, with one line naming the folder and the holder. The kernel releases a
flock when the holding process ends, however it ends (SIGKILL too), so a killed run leaves
nothing that blocks the next one or its resume; the file itself stays (its text only names the
last holder). On a file system without flock the run goes on unprotected, saying so in one line.
"""

from __future__ import annotations

import errno
import fcntl
import os
import socket
import sys
from pathlib import Path
from types import TracebackType

from mpi4py import MPI

from convection.schema import short_repr
from particles.io.swarm_checkpoint import CheckpointError

__all__ = ["LOCK_NAME", "RunFolderError", "RunFolderLock", "check_output_directory"]

LOCK_NAME = ".lock"
"""The lock file in a run folder."""

_UNSUPPORTED = (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL)
"""flock errors of file systems that do not lock (the run goes on unprotected)."""


def check_output_directory(text: str) -> str | None:
    """The run folder must be named, be a folder if it exists, and be creatable otherwise (the
    ``output.directory`` config key's check)."""
    if not text.strip():
        return "must name a folder (an empty name would write into the current folder)"
    if "\0" in text:
        return "must not contain a NUL character"
    try:
        path = Path(text).absolute()
        if path.exists() and not path.is_dir():
            return f"{short_repr(text)} exists and is not a folder"
        parent = next(p for p in path.parents if p.exists())
        if not parent.is_dir():
            return f"{short_repr(text)} lies inside {short_repr(str(parent))}, which is not a folder"
        if not path.exists() and not os.access(parent, os.W_OK | os.X_OK):
            return f"cannot create {short_repr(text)}: no write permission in {short_repr(str(parent))}"
    except OSError as err:
        return f"{short_repr(text)} cannot be used: {err.strerror or err}"
    return None


class RunFolderError(CheckpointError):
    """A run folder cannot be used: in use by another run, not creatable, or one of its files
    damaged. Raised on every rank alike; a :class:`~particles.io.swarm_checkpoint.CheckpointError`, so the
    command line reports it as a missing or damaged folder (one line, exit code 1)."""


class RunFolderLock:
    """Create ``directory`` and hold its lock while the context is open (collective).

    Args:
        directory: The run folder (created with its parents if missing).
        comm: The run's communicator; its rank 0 holds the lock.

    Raises:
        RunFolderError: On every rank, on entering: the folder is locked by another process, or
            cannot be created or locked.

    Example:
        >>> with RunFolderLock(Path("output/run"), MPI.COMM_WORLD):
        ...     run(...)
    """

    def __init__(self, directory: str | os.PathLike[str], comm: MPI.Comm, /) -> None:
        self.directory = Path(directory)
        self.comm = comm
        self._fd: int | None = None

    def __enter__(self) -> RunFolderLock:
        problem, note = None, None
        if self.comm.rank == 0:
            problem, note = self._acquire()
        problem, note = self.comm.bcast((problem, note), root=0)
        if note is not None and self.comm.rank == 0:
            print(note, file=sys.stderr, flush=True)
        if problem is not None:
            raise RunFolderError(problem)
        return self

    def _acquire(self) -> tuple[str | None, str | None]:
        """Take the lock (rank 0): (what stops the run, a note); both None when locked."""
        where = f"run folder '{self.directory}'"
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.directory / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as err:
            return f"{where}: cannot be created or written ({err.strerror or err})", None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            os.close(fd)
            return f"{where} is in use by another run ({holder}); wait for it to end or use another folder", None
        except OSError as err:
            if err.errno in _UNSUPPORTED:
                self._fd = fd
                return None, f"warning: {where}: this file system cannot lock ({err.strerror}); " \
                             "nothing stops a second run from writing into it"
            os.close(fd)
            return f"{where}: cannot be locked ({err.strerror or err})", None
        self._fd = fd
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode())
        return None, None

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.release()

    def release(self) -> None:
        """Let the folder go (closing the file releases the lock; the file stays)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    @property
    def held(self) -> bool:
        """Whether this rank holds the lock (only rank 0 ever does)."""
        return self._fd is not None


def _read_holder(fd: int) -> str:
    """Who holds the lock, as its holder wrote it ("pid N on HOST"), or a placeholder."""
    try:
        text = os.pread(fd, 200, 0).decode(errors="replace").strip()
    except OSError:
        text = ""
    return text or "holder unknown"

