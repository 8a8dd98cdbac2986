"""Config input that reaches outside the program: the config text itself, folders and PETSc viewers.

- :func:`read_document` reads a config file of at most :data:`MAX_CONFIG_BYTES` as UTF-8 YAML, and
  :func:`safe_load` turns what PyYAML raises on hostile text (deep nesting, integers with more
  digits than Python converts, impossible dates) into a one-line :class:`ConfigError`;
- numbers are read as YAML 1.2 (and every other language) reads them: PyYAML follows YAML 1.1,
  where ``1e3``, ``1.0e3`` and ``-.5`` are text (a float needs a dot and a signed exponent, as in
  ``1.0e+3``); :class:`ConfigLoader` reads them as floats, so every numeric key, a viscosity or a
  law parameter included, takes them;
- the run folder's check lives with the run folder (:func:`convection.io.run_folder.check_output_directory`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from convection.schema import MAX_DEPTH, ConfigError

__all__ = ["MAX_CONFIG_BYTES", "ConfigLoader", "read_document", "safe_load"]

MAX_CONFIG_BYTES = 1 << 20
"""Largest config file (1 MiB; configs are a few kB)."""


class ConfigLoader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2's floats: ``1e3``, ``1.0e3``, ``1E-3``, ``+2.5e-7``, ``.5``
    and ``-.5`` are numbers (YAML 1.1 reads the first four and the last as text). Integers, the
    YAML 1.1 floats and every other scalar are read as before."""


ConfigLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)?$"),
    list("-+0123456789."))


def safe_load(text: str, where: str) -> Any:
    """``yaml.load(text, ConfigLoader)`` (safe, with YAML 1.2's floats); what else PyYAML raises on hostile input
    becomes a ConfigError naming ``where``: RecursionError (deep nesting), ValueError (an integer with more digits
    than Python converts, an impossible date), MemoryError.

    Raises:
        yaml.YAMLError: the text is not YAML.
    """
    try:
        return yaml.load(text, Loader=ConfigLoader)  # noqa: S506 - a SafeLoader
    except yaml.YAMLError:
        raise
    except RecursionError:
        raise ConfigError(f"{where}: nested too deeply (a config has at most {MAX_DEPTH} levels)") from None
    except MemoryError:
        raise ConfigError(f"{where}: too large to read") from None
    except (ValueError, OverflowError) as err:
        raise ConfigError(f"{where}: a value cannot be read: {str(err).split(';')[0]}") from None


def yaml_position(err: yaml.YAMLError, /) -> str:
    """`` at line L, column C: what was wrong`` of a YAML error (empty where PyYAML gives no place)."""
    mark = getattr(err, "problem_mark", None)
    if mark is None:
        return ""
    problem = getattr(err, "problem", None)
    return f" at line {mark.line + 1}, column {mark.column + 1}" + (f": {problem}" if problem else "")


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
        raise ConfigError(f"{where}: invalid YAML{yaml_position(err)}") from None
