"""Config input that reaches outside the program: the config text itself, folders and PETSc viewers.

- :func:`read_document` reads a config file of at most :data:`MAX_CONFIG_BYTES` as UTF-8 YAML, and
  :func:`safe_load` turns what PyYAML raises on hostile text (deep nesting, integers with more
  digits than Python converts, impossible dates) into a one-line :class:`ConfigError`;
- :func:`check_output_directory` and :func:`check_petsc_options` are schema checks: the run folder
  must be a creatable folder (not ``''``, not an existing file), and PETSc viewer options may only
  print, so PETSc writes no file outside the run folder.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import yaml

from convection.schema import MAX_DEPTH, ConfigError, short_repr

__all__ = ["MAX_CONFIG_BYTES", "check_output_directory", "check_petsc_options", "read_document", "safe_load"]

MAX_CONFIG_BYTES = 1 << 20
"""Largest config file (1 MiB; configs are a few kB)."""
_PETSC_WORD = re.compile(r"[A-Za-z0-9_]+")
_VIEWER_WORDS = frozenset({"view", "monitor", "reason", "draw", "log", "viewer", "lg", "dump", "history"})
"""Words of PETSc option names whose value is a viewer (``ksp_view``, ``ksp_monitor_true_residual``,
``ksp_converged_reason``, ``mat_view``, ...)."""
_PRINTING_VIEWERS = ("", "ascii")
_STANDARD_STREAMS = ("", "stdout", "stderr")


def check_petsc_options(options: dict[str, Any]) -> str | None:
    """PETSc options must be plain ``name: scalar`` pairs, and a viewer option may only print
    (``ascii`` to stdout/stderr, any format): a viewer that names a file (``ascii:/some/path``),
    writes PETSc's default file (``binary``) or opens a window (``draw``) is refused, since PETSc
    would create it outside the run folder."""
    for name, value in options.items():
        if not isinstance(name, str) or not _PETSC_WORD.fullmatch(name):
            return f"option name {short_repr(name)} must be letters, digits and _ (without the leading -)"
        if value is not None and not isinstance(value, (str, int, float)):
            return f"option {name}: the value must be a number, text, true/false or null, got {short_repr(value)}"
        if _VIEWER_WORDS.isdisjoint(name.lower().split("_")) or value is None or isinstance(value, bool):
            continue
        kind, _, rest = str(value).partition(":")
        filename = rest.partition(":")[0]
        if kind.strip().lower() not in _PRINTING_VIEWERS or filename.strip() not in _STANDARD_STREAMS:
            return (f"option {name}: {short_repr(value)} would make PETSc write a file or open a window outside "
                    "the run folder; viewers may only print (e.g. ascii, ::ascii_info_detail)")
    return None


def check_output_directory(text: str) -> str | None:
    """The run folder must be named, be a folder if it exists, and be creatable otherwise."""
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


def safe_load(text: str, where: str) -> Any:
    """``yaml.safe_load(text)``; what else PyYAML raises on hostile input becomes a ConfigError
    naming ``where``: RecursionError (deep nesting), ValueError (an integer with more digits than
    Python converts, an impossible date), MemoryError.

    Raises:
        yaml.YAMLError: the text is not YAML.
    """
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        raise
    except RecursionError:
        raise ConfigError(f"{where}: nested too deeply (a config has at most {MAX_DEPTH} levels)") from None
    except MemoryError:
        raise ConfigError(f"{where}: too large to read") from None
    except (ValueError, OverflowError) as err:
        raise ConfigError(f"{where}: a value cannot be read: {str(err).split(';')[0]}") from None


def read_document(p: Path) -> Any:
    """The parsed YAML of a config file (at most :data:`MAX_CONFIG_BYTES`, UTF-8)."""
    where = f"config file '{p}'"
    if not p.is_file():
        raise ConfigError(f"{where} not found")
    try:
        size = p.stat().st_size
        if size > MAX_CONFIG_BYTES:
            raise ConfigError(f"{where}: {size / 2**20:.1f} MiB, more than a config may have "
                              f"({MAX_CONFIG_BYTES // 2**20} MiB)")
        data = p.read_bytes()[: MAX_CONFIG_BYTES + 1]
    except OSError as err:
        raise ConfigError(f"{where}: cannot be read: {err.strerror or err}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise ConfigError(f"{where}: not UTF-8 text (byte 0x{data[err.start]:02x} at line {line})") from None
    try:
        return safe_load(text, where)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{where}: invalid YAML{at}") from None
