"""A small declarative schema for YAML run configurations.

A schema is a nested mapping of section names to :class:`Field` (a leaf) or to another mapping
(a section). :func:`validate` walks a user document against it, fills defaults, coerces numbers
written as strings (PyYAML reads ``1e4`` as a string) and raises :class:`ConfigError` with one
line naming the dotted key and what is allowed.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Union

__all__ = ["REQUIRED", "ConfigError", "Field", "validate"]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()
"""Marker default: the user must give this key."""


class ConfigError(ValueError):
    """A configuration problem, described in one line that names the offending key."""


Choices = Union[tuple[str, ...], Callable[[], Iterable[str]]]
"""Allowed names: a tuple, or a callable returning them (e.g. a registry's keys, read when checked)."""


@dataclass(frozen=True)
class Field:
    """One leaf of the schema.

    Attributes:
        kind: "float", "int", "bool", "str", "list[float]", "list[int]", "list[str]", "any",
            "mapping" (free-form mapping, checked by ``check`` only).
        default: Default value, or REQUIRED.
        choices: Allowed values for a "str" field (or each item of "list[str]"): a tuple, or a
            callable returning the names (so a plugin registry is the one list of names).
        nullable: Whether ``null`` is allowed.
        minimum: Lower bound (inclusive) for numbers / each number of a list.
        exclusive_minimum: Lower bound (exclusive) for numbers.
        length: Allowed list lengths.
        check: Extra validation ``check(value) -> str | None`` returning a message on error.
        help: One-line description.
        items: For kind "mapping": a schema every value of the mapping is validated against
            (keys of the mapping are free names, e.g. material names).
    """

    kind: str
    default: Any = REQUIRED
    choices: tuple[str, ...] | None = None
    nullable: bool = False
    minimum: float | None = None
    exclusive_minimum: float | None = None
    length: tuple[int, ...] | None = None
    check: Callable[[Any], str | None] | None = None
    help: str = ""
    items: Mapping[str, Any] | None = None

    def allowed(self) -> list[str] | None:
        """The allowed names (resolving a callable), or None."""
        if self.choices is None:
            return None
        return list(self.choices() if callable(self.choices) else self.choices)


def _type_name(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _coerce_scalar(kind: str, value: Any, key: str) -> Any:
    if kind == "float":
        if isinstance(value, bool):
            raise ConfigError(f"config key '{key}': expected a number, got {value!r}")
        if isinstance(value, (int, float)):
            return float(value)
        if isinstance(value, str):
            try:
                return float(value)
            except ValueError:
                pass
        raise ConfigError(f"config key '{key}': expected a number, got {_type_name(value)} {value!r}")
    if kind == "int":
        if isinstance(value, bool):
            raise ConfigError(f"config key '{key}': expected an integer, got {value!r}")
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        if isinstance(value, str):
            try:
                return int(value)
            except ValueError:
                pass
        raise ConfigError(f"config key '{key}': expected an integer, got {_type_name(value)} {value!r}")
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "yes", "no", "on", "off"):
            return value.lower() in ("true", "yes", "on")
        raise ConfigError(f"config key '{key}': expected true or false, got {_type_name(value)} {value!r}")
    if kind == "str":
        if isinstance(value, str):
            return value
        raise ConfigError(f"config key '{key}': expected a string, got {_type_name(value)} {value!r}")
    return value


def _check_leaf(spec: Field, value: Any, key: str) -> Any:
    if value is None:
        if spec.nullable:
            return None
        raise ConfigError(f"config key '{key}': must not be null ({spec.help or spec.kind})")
    if spec.kind.startswith("list["):
        item_kind = spec.kind[5:-1]
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"config key '{key}': expected a list of {item_kind}, got {_type_name(value)} {value!r}")
        if spec.length is not None and len(value) not in spec.length:
            allowed = " or ".join(str(n) for n in spec.length)
            raise ConfigError(f"config key '{key}': expected {allowed} entries, got {len(value)}")
        items = [_coerce_scalar(item_kind, v, f"{key}[{i}]") for i, v in enumerate(value)]
        for i, item in enumerate(items):
            _check_bounds(spec, item, f"{key}[{i}]")
        value = items
    elif spec.kind == "mapping":
        if not isinstance(value, Mapping):
            raise ConfigError(f"config key '{key}': expected a mapping, got {_type_name(value)} {value!r}")
        value = dict(value)
        if spec.items is not None:
            for name in value:
                if not isinstance(name, str) or not name.isidentifier():
                    raise ConfigError(f"config key '{key}.{name}': names must be identifiers (letters, digits, _)")
            value = {name: validate(spec.items, item, prefix=f"{key}.{name}.") for name, item in value.items()}
    elif spec.kind != "any":
        value = _coerce_scalar(spec.kind, value, key)
        _check_bounds(spec, value, key)
    allowed = spec.allowed()
    if allowed is not None:
        values = value if isinstance(value, list) else [value]
        for v in values:
            if v not in allowed:
                raise ConfigError(f"config key '{key}': {v!r} is not one of {allowed}")
    if spec.check is not None:
        message = spec.check(value)
        if message:
            raise ConfigError(f"config key '{key}': {message}")
    return value


def _check_bounds(spec: Field, value: Any, key: str) -> None:
    if not isinstance(value, (int, float)):
        return
    if spec.minimum is not None and value < spec.minimum:
        raise ConfigError(f"config key '{key}': must be >= {spec.minimum}, got {value}")
    if spec.exclusive_minimum is not None and value <= spec.exclusive_minimum:
        raise ConfigError(f"config key '{key}': must be > {spec.exclusive_minimum}, got {value}")


def validate(schema: Mapping[str, Any], document: Any, prefix: str = "") -> dict[str, Any]:
    """Validate ``document`` against ``schema`` and return a new dict with defaults filled in.

    Raises:
        ConfigError: unknown key, wrong type, value out of range, or missing required value.
    """
    where = prefix.rstrip(".") or "top level"
    if document is None:
        document = {}
    if not isinstance(document, Mapping):
        raise ConfigError(f"config section '{where}': expected a mapping, got {_type_name(document)}")
    unknown = sorted(set(document) - set(schema))
    if unknown:
        raise ConfigError(
            f"config key '{prefix}{unknown[0]}': unknown; allowed keys in {where}: {sorted(schema)}"
        )
    result: dict[str, Any] = {}
    for name, spec in schema.items():
        key = f"{prefix}{name}"
        if isinstance(spec, Field):
            if name in document:
                result[name] = _check_leaf(spec, document[name], key)
            elif spec.default is REQUIRED:
                raise ConfigError(f"config key '{key}': required value missing ({spec.help or spec.kind})")
            else:
                result[name] = copy.deepcopy(spec.default)
        else:
            result[name] = validate(spec, document.get(name), prefix=f"{key}.")
    return result
