"""Command line: run, resume and check configurations; print the config reference.

    python -m convection run configs/NAME.yaml [--set key.sub=value ...] [--output DIR] [--resume]
                                               [--initial-from RUN_DIR]
    python -m convection resume RUN_DIR [--set time.end=...] [--checkpoint PATH]
    python -m convection check configs/NAME.yaml [--set ...]
    python -m convection schema [--format markdown|yaml]     # the config reference

Problems print one line on rank 0 and exit with the same code on every rank, before any
collective call that could hang: configuration problems (naming the key) and command-line
mistakes with code 2; other expected problems (a missing run folder, a damaged checkpoint, ...)
with code 1; a run that blew up or whose solver failed (naming the step and what failed) with
code 3. Anything unexpected while the config is read and checked (no communication happens
there, so every rank meets it alike) prints one line with code 1; anything unexpected later
prints one line too and stops every rank (MPI abort). ``--debug`` (or ``CONVECTION_DEBUG=1``)
shows the traceback as well. SIGINT/SIGTERM stop the run at the end of the current step with
everything written and a checkpoint (exit code 128 + signal number).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import traceback
from pathlib import Path
from collections.abc import Sequence
from typing import Any

from mpi4py import MPI

from convection.config.loader import ConfigError, load_config
from convection.schema import MAX_MESSAGE

__all__ = ["main"]

EXIT_RUNTIME_ERROR = 1
EXIT_CONFIG_ERROR = 2
EXIT_RUN_FAILED = 3

RESUMABLE = ("time.", "output.progress", "output.fields_every", "output.checkpoint.", "blowup.")
_RESUMABLE_TEXT = "time.*, output.progress*, output.fields_every, output.checkpoint.*, blowup.*"
"""Config keys a resumed run may change (the rest defines the model and must stay)."""
SAME_MODEL = ("name", "mesh", "physics", "materials", "boundary", "initial", "stokes", "energy", "composition",
              "particles", "adaptivity", "balance", "diagnostics")
"""Sections that must equal the checkpoint's for ``run --resume``."""


def _one_line(text: str) -> str:
    """``text`` as one line of at most :data:`convection.schema.MAX_MESSAGE` characters."""
    line = " ".join(str(text).split())
    return line if len(line) <= MAX_MESSAGE else line[: MAX_MESSAGE - 3] + "..."


class _Parser(argparse.ArgumentParser):
    """argparse with a command-line mistake as one line on rank 0 and exit code 2 on every rank."""

    def error(self, message: str) -> None:  # type: ignore[override]
        if MPI.COMM_WORLD.rank == 0:
            print(f"error: {_one_line(message)} (see {self.prog} --help)", file=sys.stderr, flush=True)
        sys.exit(EXIT_CONFIG_ERROR)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m convection", description=__doc__.split("\n")[0])
    parser.add_argument("--debug", dest="debug_all", action="store_true", help="show tracebacks of errors")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a configuration")
    run.add_argument("config", help="YAML configuration file")
    run.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                     help="override a config value, e.g. --set mesh.cells=[64,64] (repeatable)")
    run.add_argument("--output", default=None, help="output folder (overrides output.directory)")
    run.add_argument("--resume", action="store_true",
                     help="continue from the newest checkpoint in the output folder if there is one")
    run.add_argument("--initial-from", default=None, metavar="RUN_DIR",
                     help="start from another run's temperature (its folder or a checkpoint folder), interpolated "
                          "onto this run's mesh (sets initial.from_run)")
    run.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    resume = sub.add_parser("resume", help="continue a run from its newest checkpoint")
    resume.add_argument("directory", help="the run's output folder")
    resume.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help=f"change a setting that does not define the model ({_RESUMABLE_TEXT})")
    resume.add_argument("--checkpoint", default=None, help="a checkpoint folder (default: the newest)")
    resume.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    check = sub.add_parser("check", help="validate a configuration and print it fully resolved")
    check.add_argument("config")
    check.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    check.add_argument("--output", default=None)
    check.add_argument("--initial-from", default=None, metavar="RUN_DIR")
    schema = sub.add_parser("schema", help="print the config reference: every key, default, allowed value and "
                                           "plugin parameter")
    schema.add_argument("--format", choices=("markdown", "yaml"), default="markdown",
                        help="markdown: the reference (docs/config-reference.md); yaml: every key at its default")
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


class _Refused(Exception):
    """An expected problem, raised on every rank alike: one line, exit code ``code``."""

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code


def _local(function: Any, /, *args: Any, **kwargs: Any) -> Any:
    """Call ``function`` (reading and checking a config: no communication), turning an unexpected
    exception into an expected problem (one line, exit code 1): every rank meets it alike, so no
    MPI abort is needed."""
    try:
        return function(*args, **kwargs)
    except ConfigError:
        raise
    except Exception as err:  # noqa: BLE001 - a bug met while checking: reported, not aborted
        raise _Refused(f"unexpected {type(err).__name__} while checking the config: {err} "
                       "(--debug shows the traceback)", EXIT_RUNTIME_ERROR) from err


def _literal(key: str, text: str) -> str:
    """A ``--set`` override giving ``key`` the string ``text`` as it is (not read as YAML: a folder
    named ``123``, ``run #1`` or ``''`` stays that text). A JSON string is a YAML string."""
    return f"{key}={json.dumps(str(text), ensure_ascii=False)}"


def _checked_overrides(overrides: list[str]) -> list[str]:
    for item in overrides:
        key = item.split("=", 1)[0].strip()
        if not key.startswith(RESUMABLE):
            raise ConfigError(f"config key '{key}': cannot change when resuming (allowed: {_RESUMABLE_TEXT})")
    return overrides


def _resume(comm: MPI.Comm, directory: str, overrides: list[str], checkpoint: str | None) -> tuple[dict, Any]:
    """The config and checkpoint to continue the run in ``directory`` from."""
    from convection.io.checkpoint import latest_checkpoint, read_checkpoint

    run_dir = Path(directory)
    if not run_dir.is_dir():
        raise _Refused(f"run folder '{run_dir}' not found", EXIT_RUNTIME_ERROR)
    path = Path(checkpoint) if checkpoint else latest_checkpoint(run_dir)
    if path is None:
        raise _Refused(f"run folder '{run_dir}' has no complete checkpoint (checkpoints/checkpoint_*)",
                       EXIT_RUNTIME_ERROR)
    saved = read_checkpoint(path, comm)
    config = _local(load_config, None, [*_checked_overrides(overrides), _literal("output.directory", str(run_dir))],
                    document=saved.config)
    return config, saved


def _run(args: argparse.Namespace, comm: MPI.Comm) -> int:
    stop = _StopFlag()
    saved = None
    if args.command == "schema":
        if comm.rank == 0:
            from convection.config.reference import render_markdown, render_yaml

            print(render_markdown() if args.format == "markdown" else render_yaml(), end="")
        return 0
    if args.command == "resume":
        config, saved = _resume(comm, args.directory, list(args.overrides), args.checkpoint)
    else:
        overrides = list(args.overrides)
        if args.output is not None:
            overrides.append(_literal("output.directory", args.output))
        if args.initial_from is not None:
            overrides.append(_literal("initial.from_run", args.initial_from))
        config = _local(load_config, args.config, overrides)
        if not (args.command == "run" and args.resume):  # a resumed run continues its own temperature
            from convection.config.continuation import check_source

            _local(check_source, config)  # initial.from_run, if given
        if args.command == "check":
            if comm.rank == 0:
                from convection.config.loader import dump_config

                print(dump_config(config), end="")
            return 0
        from convection.config.settings import run_settings
        from convection.io.checkpoint import latest_checkpoint, read_checkpoint

        directory = run_settings(config).output.directory
        if args.resume and latest_checkpoint(directory) is not None:
            saved = read_checkpoint(latest_checkpoint(directory), comm)
            changed = [key for key in SAME_MODEL if saved.config.get(key) != config.get(key)]
            if changed:
                raise ConfigError(f"config key '{changed[0]}': differs from the checkpoint's; only "
                                  f"{_RESUMABLE_TEXT} may change when resuming")
    from convection.app.factory import run_config
    from convection.run.loop import RunFailure

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    try:
        summary = run_config(config, comm=comm, should_stop=lambda: stop.requested, resume=saved)
    except RunFailure as err:
        raise _Refused(f"run {err}", EXIT_RUN_FAILED) from None
    # Stopped by a signal: the shell convention 128 + signal number (on the ranks that got it).
    return 128 + stop.signum if summary.reason == "stopped by signal" and stop.signum else 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    logging.getLogger().setLevel(logging.WARNING)
    logging.getLogger().addFilter(_WarningsOnly())
    args = _parser().parse_args(argv)
    debug = args.debug_all or getattr(args, "debug", False) or os.environ.get("CONVECTION_DEBUG", "") not in ("", "0")
    comm = MPI.COMM_WORLD
    errors = comm.Dup() if comm.size > 1 else comm  # the error report's own channel (_report)
    try:
        return _run(args, comm)
    except Exception as err:  # noqa: BLE001 - sorted out by _expected_code
        return _report(err, errors, debug)


def _expected_code(err: Exception) -> int | None:
    """The exit code of an expected problem (raised on every rank alike), or None."""
    if isinstance(err, ConfigError):
        return EXIT_CONFIG_ERROR
    if isinstance(err, _Refused):
        return err.code
    checkpoint = sys.modules.get("particles.io.swarm_checkpoint")  # loaded by whatever raised one (it loads slowly)
    if checkpoint is not None and isinstance(err, checkpoint.CheckpointError):
        return EXIT_RUNTIME_ERROR
    return None


def _report(err: Exception, comm: MPI.Comm, debug: bool) -> int:
    """Print ``err`` (one line; with ``debug`` the traceback too) and return the exit code; an
    unexpected error stops every rank (MPI abort), as the others may wait in a collective call."""
    code = _expected_code(err)
    if code is not None:
        if debug:
            traceback.print_exc()
        if comm.rank == 0:
            print(f"error: {_one_line(str(err))}", file=sys.stderr, flush=True)
        return code
    if debug:
        traceback.print_exc()
    line = f"{_one_line(f'{type(err).__name__}: {err}')} (--debug shows the traceback)"
    if comm.size > 1 and _all_ranks_failed(comm):
        lines = comm.gather(line, root=0)
        if comm.rank == 0 and not debug:
            for text in dict.fromkeys(lines or ()):  # each distinct message once, in rank order
                ranks = [r for r, other in enumerate(lines or ()) if other == text]
                where = "every rank" if len(ranks) == comm.size else f"rank{'s' if len(ranks) > 1 else ''} " \
                    + ", ".join(map(str, ranks))
                print(f"error ({where}): {text}", file=sys.stderr, flush=True)
        return EXIT_RUNTIME_ERROR
    if not debug:
        where = f" (rank {comm.rank})" if comm.size > 1 else ""
        print(f"error{where}: {line}", file=sys.stderr, flush=True)
    if comm.size > 1:
        comm.Abort(EXIT_RUNTIME_ERROR)
    return EXIT_RUNTIME_ERROR


ALL_FAILED_WAIT = 2.0
"""Seconds a rank with an unexpected error waits for the others to report one too (then it stops
every rank)."""


def _all_ranks_failed(comm: MPI.Comm) -> bool:
    """Whether every rank of ``comm`` (the report's own channel, so no other call can match it)
    reached the error report within :data:`ALL_FAILED_WAIT` seconds: then the ranks can agree on
    one report and exit without an MPI abort. Collective only among failing ranks."""
    import time

    request = comm.Ibarrier()
    deadline = time.monotonic() + ALL_FAILED_WAIT
    while time.monotonic() < deadline:
        if request.Test():
            return True
        time.sleep(0.01)
    return False


if __name__ == "__main__":
    sys.exit(main())
