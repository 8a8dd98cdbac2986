"""Run a configuration with the CLI in a subprocess, under MPI's launcher when more than one rank
is asked; and the launcher itself, for the MPI this Python uses.

Benchmark scripts drive whole runs this way (each run its own MPI job), then read the run's
``statistics.csv``. Two MPIs are in use: Debian's Open MPI (the Debian packages' DOLFINx) and
MPICH from the PyPI ``mpich`` wheel (the PyPI route, ``PIC_DOLFINX=pypi scripts/setup.sh``), whose
launcher is ``mpiexec`` in the venv's ``bin``. :func:`mpirun` gives the launcher's command prefix:
Open MPI's gets ``--oversubscribe`` (more ranks than cores; MPICH's Hydra allows that by itself
and knows no such option). The rank of a launched process is ``OMPI_COMM_WORLD_RANK`` under Open
MPI and ``PMI_RANK`` under MPICH (:func:`launched_rank`).

``python -m convection.launch N`` prints the prefix for N ranks, one word a line (for shell
scripts: ``mapfile -t mpirun < <(.venv/bin/python -m convection.launch 2)``).
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
from pathlib import Path
from collections.abc import Mapping, Sequence

__all__ = ["cli_command", "launched_rank", "launcher", "mpi_environment", "mpirun", "run_config"]


@functools.cache
def launcher() -> tuple[str, bool]:
    """(path, is_open_mpi) of the MPI launcher for this Python's MPI: ``$PIC_MPIEXEC`` if set, else
    ``mpiexec`` beside this Python (a venv whose MPI came from a wheel: the PyPI route), else
    ``mpirun`` on PATH (Debian's Open MPI). Raises RuntimeError if there is none."""
    path = os.environ.get("PIC_MPIEXEC") or None
    if path is None:
        beside = Path(sys.executable).parent / "mpiexec"
        path = str(beside) if beside.is_file() and os.access(beside, os.X_OK) else shutil.which("mpirun")
    if path is None:
        raise RuntimeError("mpirun not found on PATH (needed for runs on more than one rank)")
    try:
        version = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=60,
                                 env=mpi_environment()).stdout
    except (OSError, subprocess.TimeoutExpired) as err:
        raise RuntimeError(f"MPI launcher {path} does not run: {err}") from None
    return path, "Open MPI" in version or "OpenRTE" in version


def mpirun(ranks: int, /) -> list[str]:
    """The command prefix that starts ``ranks`` processes: ``[mpirun, -n, N, --oversubscribe]``
    with Open MPI, ``[mpiexec, -n, N]`` with MPICH."""
    path, open_mpi = launcher()
    return [path, "-n", str(ranks), *(["--oversubscribe"] if open_mpi else [])]


def launched_rank(environ: Mapping[str, str] | None = None, /) -> int | None:
    """The rank the launcher gave this process (None: not started by a launcher), read from the
    environment without initialising MPI."""
    variables = os.environ if environ is None else environ
    for name in ("OMPI_COMM_WORLD_RANK", "PMI_RANK"):
        if variables.get(name, "").isdigit():
            return int(variables[name])
    return None


RANK_SHELL = "${OMPI_COMM_WORLD_RANK:-${PMI_RANK:-}}"
"""The launched rank in a POSIX shell command (Open MPI's variable, else MPICH's)."""


def cli_command(config: str | Path, output: str | Path, /, *, ranks: int = 1,
                overrides: Sequence[str] = ()) -> list[str]:
    """The command line that runs ``config`` into ``output`` with ``--set`` ``overrides``."""
    cmd = [sys.executable, "-m", "convection", "run", str(config), "--output", str(output)]
    for item in overrides:
        cmd += ["--set", item]
    if ranks > 1:
        cmd = [*mpirun(ranks), *cmd]
    return cmd


def mpi_environment() -> dict[str, str]:
    """This process's environment plus the variables that let Open MPI run as root, and TCP on IPv4
    only: Open MPI 5 (Debian 13) warns on every rank that it finds no "reachable pairing" between
    IPv4 and IPv6 interfaces on one machine (open-mpi/ompi issue 14079); harmless with Open MPI 4,
    ignored by MPICH."""
    return dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
                OMPI_MCA_btl_tcp_disable_family="6")


def run_config(config: str | Path, output: str | Path, /, *, ranks: int = 1, overrides: Sequence[str] = (),
               cwd: str | Path | None = None, echo: bool = True) -> Path:
    """Run ``config`` to completion (raises CalledProcessError on failure); returns ``output``."""
    cmd = cli_command(config, output, ranks=ranks, overrides=overrides)
    if echo:
        print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=cwd, env=mpi_environment(), check=True)
    return Path(output)


if __name__ == "__main__":
    if len(sys.argv) != 2 or not sys.argv[1].isdigit():
        sys.exit("usage: python -m convection.launch RANKS   (prints the launcher prefix, a word a line)")
    print("\n".join(mpirun(int(sys.argv[1]))))
