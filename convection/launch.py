"""Run a configuration with the CLI in a subprocess, under mpirun when more than one rank is asked.

Benchmark scripts drive whole runs this way (each run its own MPI job), then read the run's
``statistics.csv``. mpirun is given ``--oversubscribe`` so more ranks than cores are allowed (the
scripts say so where they use it) and the environment variables that let Open MPI run as root.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Sequence

__all__ = ["cli_command", "mpi_environment", "run_config"]


def cli_command(config: str | Path, output: str | Path, /, *, ranks: int = 1,
                overrides: Sequence[str] = ()) -> list[str]:
    """The command line that runs ``config`` into ``output`` with ``--set`` ``overrides``."""
    cmd = [sys.executable, "-m", "convection", "run", str(config), "--output", str(output)]
    for item in overrides:
        cmd += ["--set", item]
    if ranks > 1:
        mpirun = shutil.which("mpirun")
        if mpirun is None:
            raise RuntimeError("mpirun not found on PATH (needed for runs on more than one rank)")
        cmd = [mpirun, "-n", str(ranks), "--oversubscribe", *cmd]
    return cmd


def mpi_environment() -> dict[str, str]:
    """This process's environment plus the variables that let Open MPI run as root, and TCP on IPv4
    only: Open MPI 5 (Debian 13) warns on every rank that it finds no "reachable pairing" between
    IPv4 and IPv6 interfaces on one machine (open-mpi/ompi issue 14079); harmless with Open MPI 4."""
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
