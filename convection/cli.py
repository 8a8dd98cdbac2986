"""Command line: ``python -m convection run configs/NAME.yaml [--set key.sub=value ...] [--output DIR]``.

Configuration problems print one line naming the key (``error: config key 'time.end': ...``) on
rank 0 and exit with code 2 on every rank, before any collective call, so mpirun never hangs.
SIGINT/SIGTERM stop the run at the end of the current step with the statistics flushed.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from typing import Sequence

from mpi4py import MPI

from convection.config import ConfigError, load_config

__all__ = ["main"]

EXIT_CONFIG_ERROR = 2


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m convection", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a configuration")
    run.add_argument("config", help="YAML configuration file")
    run.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                     help="override a config value, e.g. --set mesh.cells=[64,64] (repeatable)")
    run.add_argument("--output", default=None, help="output folder (overrides output.directory)")
    check = sub.add_parser("check", help="validate a configuration and print it fully resolved")
    check.add_argument("config")
    check.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    check.add_argument("--output", default=None)
    return parser


class _StopFlag:
    """Set by SIGINT/SIGTERM; a second signal restores the default action."""

    def __init__(self) -> None:
        self.requested = False
        self.signum = 0

    def __call__(self, signum: int, frame: object) -> None:
        self.requested = True
        self.signum = signum
        signal.signal(signum, signal.SIG_DFL)

    def __bool__(self) -> bool:
        return self.requested


class _WarningsOnly(logging.Filter):
    """Drops INFO/DEBUG records of the root logger: the form compiler's build steps log there, and
    the build tools reset the root level to INFO while compiling."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.WARNING


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    logging.getLogger().setLevel(logging.WARNING)
    logging.getLogger().addFilter(_WarningsOnly())
    args = _parser().parse_args(argv)
    comm = MPI.COMM_WORLD
    overrides = list(args.overrides)
    if args.output is not None:
        overrides.append(f"output.directory={args.output}")
    try:
        config = load_config(args.config, overrides)
    except ConfigError as err:
        if comm.rank == 0:
            print(f"error: {err}", file=sys.stderr, flush=True)
        return EXIT_CONFIG_ERROR
    if args.command == "check":
        if comm.rank == 0:
            from convection.config import dump_config

            print(dump_config(config), end="")
        return 0

    from convection.factory import run_config

    stop = _StopFlag()
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    summary = run_config(config, comm=comm, should_stop=lambda: stop.requested)
    # Stopped by a signal: the shell convention 128 + signal number (on the ranks that got it).
    return 128 + stop.signum if summary.reason == "stopped by signal" and stop.signum else 0


if __name__ == "__main__":
    sys.exit(main())
