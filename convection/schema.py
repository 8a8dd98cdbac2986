"""A small declarative schema for YAML run configurations, and the parameters of components.

A component declares its parameters once, as a frozen settings dataclass whose fields are made by
:func:`param` (type from the annotation, default, bounds, allowed names, help) and
:func:`subsection` (a nested settings dataclass); that dataclass *is* the schema of its config
section (:func:`section_schema`) and is built from a checked section by :func:`settings_from`::

    @dataclass(frozen=True)
    class EnergySettings:
        enabled: bool = param(True, help="false: the temperature stays at its initial value")
        degree: int = param(2, minimum=1, maximum=MAX_DEGREE, help="temperature degree (Lagrange)")

A schema is a nested mapping of section names to :class:`Field` (a leaf) or to another mapping
(a section). :func:`validate` walks a user document against it, fills defaults, coerces numbers
written as strings (a quoted ``"1e4"``; :mod:`convection.config.files` reads ``1e4`` itself as a
number) and raises :class:`ConfigError` with one line naming the dotted key and what is allowed.

Hostile documents are answered with one short line too:

- every number must be finite: a float key refuses NaN and +-inf (YAML ``.nan``/``.inf``, the
  strings ``"nan"``/``"Infinity"``, a literal too large for a double); an integer key refuses
  values outside the int64 range; free-form values (``any``, ``mapping``) are searched for
  non-finite numbers too;
- :func:`check_document_shape` bounds the nesting depth and the number of values of a document
  (counting every use of a YAML alias, so an alias bomb is refused before anything expands it)
  and requires every mapping key to be text (YAML also reads ``1:``, ``null:`` or ``yes:`` as keys;
  keys of mixed types cannot even be sorted for a message);
- values shown in messages go through :func:`short_repr` (a bounded repr), and a
  :class:`ConfigError` keeps its message to one line of at most :data:`MAX_MESSAGE` characters.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import typing
from dataclasses import dataclass
from collections.abc import Callable, Mapping
from typing import Any

from fembase.params import (  # re-exported: the declaration helpers live in the floor
    MAX_ENTRIES, REQUIRED, Names, annotation_kind, param, settings_as_section, settings_from, short_repr, subsection,
)

__all__ = ["MAX_DEGREE", "MAX_DEPTH", "MAX_ENTRIES", "MAX_MESSAGE", "MAX_VALUES", "REQUIRED", "ConfigError", "Field",
           "Names", "check_document_shape", "check_finite_values", "check_value", "key_text", "param", "section_schema",
           "settings_as_section", "settings_from", "short_repr", "subsection", "validate"]

MAX_MESSAGE = 400
"""Longest error message (characters); longer ones are cut with ``...``."""
MAX_DEPTH = 32
"""Deepest nesting of sections, lists and mappings a config document may have (configs use < 8)."""
MAX_VALUES = 100_000
"""Most values (mappings, lists and scalars, each alias use counted) a config document may hold."""
MAX_DEGREE = 4
"""Highest polynomial degree of a field (form compilation time grows steeply with the degree)."""
INT64 = (-(2**63), 2**63 - 1)
"""Range of an integer key (every integer of a run ends up in int64 arrays or C longs)."""

class ConfigError(ValueError):
    """A configuration problem, described in one line that names the offending key.

    The message is made one line (runs of white space become one space) and cut to
    :data:`MAX_MESSAGE` characters.
    """

    def __init__(self, message: str) -> None:
        text = " ".join(str(message).split())
        if len(text) > MAX_MESSAGE:
            text = text[: MAX_MESSAGE - 3] + "..."
        super().__init__(text)


def check_document_shape(document: Any, /) -> None:
    """Refuse a document nested deeper than :data:`MAX_DEPTH`, holding more than :data:`MAX_VALUES`
    values (each use of a shared YAML alias counted, keys too) or with a mapping key that is not
    text. Iterative, stops at the first problem.

    Raises:
        ConfigError: naming the dotted key where the problem is.
    """
    stack: list[tuple[Any, int, str]] = [(document, 0, "")]
    count = 0
    while stack:
        value, depth, key = stack.pop()
        count += 1
        if count > MAX_VALUES:
            raise ConfigError(f"config key '{key}': the config holds more than {MAX_VALUES} values (a YAML alias "
                              "counts each time it is used)")
        if depth > MAX_DEPTH:
            raise ConfigError(f"config key '{key}': nested more than {MAX_DEPTH} levels deep")
        if isinstance(value, Mapping):
            for name, item in value.items():
                sub = f"{key}.{key_text(name)}" if key else key_text(name)
                if not isinstance(name, str):
                    raise ConfigError(f"config key '{sub}': keys must be names (text), got {_got(name)}")
                stack.extend(((name, depth + 1, sub), (item, depth + 1, sub)))
        elif isinstance(value, (list, tuple)):
            stack.extend((item, depth + 1, f"{key}[{i}]") for i, item in enumerate(value))


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
        maximum: Upper bound (inclusive) for numbers / each number of a list.
        exclusive_maximum: Upper bound (exclusive) for numbers.
        length: Allowed list lengths.
        check: Extra validation ``check(value) -> str | None`` returning a message on error.
        help: One-line description.
        items: For kind "mapping": a schema every value of the mapping is validated against
            (keys of the mapping are free names, e.g. material names).
        max_items: Most entries of a list or mapping value (each may cost a field, a property
            or an expression check in the run).
    """

    kind: str
    default: Any = REQUIRED
    choices: tuple[str, ...] | None = None
    nullable: bool = False
    minimum: float | None = None
    exclusive_minimum: float | None = None
    maximum: float | None = None
    exclusive_maximum: float | None = None
    length: tuple[int, ...] | None = None
    check: Callable[[Any], str | None] | None = None
    help: str = ""
    items: Mapping[str, Any] | None = None
    max_items: int | None = None

    def allowed(self) -> list[str] | None:
        """The allowed names (resolving a callable), or None."""
        if self.choices is None:
            return None
        return list(self.choices() if callable(self.choices) else self.choices)


def key_text(name: Any) -> str:
    """A mapping key as shown in a dotted key: a string as it is (cut to 80 characters), else its
    bounded repr (YAML allows keys of any type, e.g. ``1:``)."""
    if isinstance(name, str):
        return name if len(name) <= 80 else name[:77] + "..."
    return short_repr(name)


def _type_name(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _got(value: Any) -> str:
    """``"<type> <bounded repr>"`` of a value, for messages."""
    return f"{_type_name(value)} {short_repr(value)}"


def _finite(number: float, key: str) -> float:
    """``number`` if finite; NaN passes every ``<``/``<=`` bound, so it is refused here, by kind."""
    if not math.isfinite(number):
        raise ConfigError(f"config key '{key}': must be a finite number, got {number}")
    return number


def _to_float(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ConfigError(f"config key '{key}': expected a number, got {_got(value)}")
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise ConfigError(f"config key '{key}': expected a number, got {_got(value)}") from None
    try:
        return _finite(float(value), key)
    except OverflowError:  # an integer beyond the double range
        raise ConfigError(f"config key '{key}': must be a finite number, got {short_repr(value)}") from None


def _to_int(value: Any, key: str) -> int:
    number: int | None = None
    if isinstance(value, int) and not isinstance(value, bool):
        number = value
    elif isinstance(value, float) and value.is_integer():
        number = int(value)
    elif isinstance(value, str):
        try:
            number = int(value)
        except ValueError:  # not an integer, or more digits than Python converts
            pass
    if number is None:
        raise ConfigError(f"config key '{key}': expected an integer, got {_got(value)}")
    if not INT64[0] <= number <= INT64[1]:
        raise ConfigError(f"config key '{key}': must be an integer within +-2**63, got {short_repr(number)}")
    return number


def _coerce_scalar(kind: str, value: Any, key: str) -> Any:
    if kind == "float":
        return _to_float(value, key)
    if kind == "int":
        return _to_int(value, key)
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "yes", "no", "on", "off"):
            return value.lower() in ("true", "yes", "on")
        raise ConfigError(f"config key '{key}': expected true or false, got {_got(value)}")
    if kind == "str":
        if isinstance(value, str):
            return value
        raise ConfigError(f"config key '{key}': expected a string, got {_got(value)}")
    return value


def finite_number(value: Any) -> float | None:
    """``value`` as a float if it is a finite number (not a bool, not text), else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def _number_problem(value: Any) -> str | None:
    """What is wrong with ``value`` as a number of a run: non-finite (also as text, ``"nan"``,
    ``"1e999"``) or an integer beyond int64; None if nothing (or not a number)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int) and not INT64[0] <= value <= INT64[1]:
        return f"must be an integer within +-2**63, got {short_repr(value)}"
    if isinstance(value, (float, str)):
        try:
            number = float(value)
        except ValueError:
            return None
        if not math.isfinite(number):
            return f"must be a finite number, got {short_repr(value)}"
    return None


def check_finite_values(value: Any, key: str) -> None:
    """Refuse a non-finite number or an integer beyond int64 anywhere in a free-form value (lists
    and mappings searched; the depth is bounded by :func:`check_document_shape`).

    Raises:
        ConfigError: naming the dotted key (``key.sub[2]``) of the first one.
    """
    stack: list[tuple[Any, str]] = [(value, key)]
    while stack:
        item, where = stack.pop()
        problem = _number_problem(item)
        if problem:
            raise ConfigError(f"config key '{where}': {problem}")
        if isinstance(item, Mapping):
            stack.extend((v, f"{where}.{key_text(k)}") for k, v in reversed(list(item.items())))
        elif isinstance(item, (list, tuple)):
            stack.extend((v, f"{where}[{i}]") for i, v in reversed(list(enumerate(item))))


def _check_leaf(spec: Field, value: Any, key: str) -> Any:
    if value is None:
        if spec.nullable:
            return None
        raise ConfigError(f"config key '{key}': must not be null ({spec.help or spec.kind})")
    if spec.max_items is not None and isinstance(value, (list, tuple, Mapping)) and len(value) > spec.max_items:
        raise ConfigError(f"config key '{key}': {len(value)} entries, more than {spec.max_items}")
    if spec.kind.startswith("list["):
        item_kind = spec.kind[5:-1]
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"config key '{key}': expected a list of {item_kind}, got {_got(value)}")
        if spec.length is not None and len(value) not in spec.length:
            lengths = " or ".join(str(n) for n in spec.length)
            raise ConfigError(f"config key '{key}': expected {lengths} entries, got {len(value)}")
        items = [_coerce_scalar(item_kind, v, f"{key}[{i}]") for i, v in enumerate(value)]
        for i, item in enumerate(items):
            _check_bounds(spec, item, f"{key}[{i}]")
        value = items
    elif spec.kind == "mapping":
        if not isinstance(value, Mapping):
            raise ConfigError(f"config key '{key}': expected a mapping, got {_got(value)}")
        value = dict(value)
        if spec.items is not None:
            for name in value:
                if not isinstance(name, str) or not name.isidentifier():
                    raise ConfigError(f"config key '{key}.{key_text(name)}': names must be identifiers "
                                      "(letters, digits, _)")
            value = {name: validate(spec.items, item, prefix=f"{key}.{name}.") for name, item in value.items()}
        else:
            check_finite_values(value, key)
    elif spec.kind == "any":
        check_finite_values(value, key)
    else:
        value = _coerce_scalar(spec.kind, value, key)
        _check_bounds(spec, value, key)
    allowed = spec.allowed()
    if allowed is not None:
        values = value if isinstance(value, list) else [value]
        for v in values:
            if v not in allowed:
                raise ConfigError(f"config key '{key}': {short_repr(v)} is not one of {allowed}")
    if spec.check is not None:
        message = spec.check(value)
        if message:
            raise ConfigError(f"config key '{key}': {message}")
    return value


def check_value(spec: Field, value: Any, key: str, /) -> Any:
    """One value checked against ``spec`` as a key's value is (coerced, bounds, names, ``check``).

    Raises:
        ConfigError: naming ``key``.
    """
    return _check_leaf(spec, value, key)


def _check_bounds(spec: Field, value: Any, key: str) -> None:
    if not isinstance(value, (int, float)):
        return
    if spec.minimum is not None and value < spec.minimum:
        raise ConfigError(f"config key '{key}': must be >= {spec.minimum}, got {value}")
    if spec.exclusive_minimum is not None and value <= spec.exclusive_minimum:
        raise ConfigError(f"config key '{key}': must be > {spec.exclusive_minimum}, got {value}")
    if spec.maximum is not None and value > spec.maximum:
        raise ConfigError(f"config key '{key}': must be <= {spec.maximum}, got {value}")
    if spec.exclusive_maximum is not None and value >= spec.exclusive_maximum:
        raise ConfigError(f"config key '{key}': must be < {spec.exclusive_maximum}, got {value}")


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
    unknown = sorted((name for name in document if name not in schema), key=repr)  # keys of any type
    if unknown:
        raise ConfigError(f"config key '{prefix}{key_text(unknown[0])}': unknown; allowed keys in {where}: "
                          f"{sorted(schema)}")
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


# ---------------------------------------------------------------------- declared parameters
def section_schema(cls: type, /) -> dict[str, Any]:
    """The config section a settings dataclass declares: key -> :class:`Field`, or a nested
    section for a :func:`subsection` field (in the order of the fields)."""
    hints = typing.get_type_hints(cls)
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if "section" in f.metadata:
            out[f.name] = section_schema(f.metadata["section"])
        elif "schema" in f.metadata:
            spec = dict(f.metadata["schema"])
            kind, nullable = annotation_kind(hints[f.name])
            spec["kind"] = spec["kind"] or kind
            if isinstance(spec["default"], tuple):  # a YAML list
                spec["default"] = list(spec["default"])
            out[f.name] = Field(nullable=nullable, **spec)
    return out


