"""Declared parameters: a component's settings are a frozen dataclass whose fields say their
default, bounds, allowed names and help (:func:`param`), possibly nested (:func:`subsection`).

The dataclass is the one declaration of the component's parameters: the Python defaults are its
defaults, and a configuration front end (``convection.schema.section_schema``) turns it into the
schema of a config section, whose checked values make the dataclass again (:func:`settings_from`).
This module is the floor of that machinery, so that ``particles`` (which imports nothing of
``convection``) declares its settings the same way::

    @dataclass(frozen=True)
    class PopulationSettings:
        min_per_cell: int = param(0, minimum=0, help="cells with fewer particles get new ones")
"""

from __future__ import annotations

import collections.abc
import copy
import dataclasses
import reprlib
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Union

__all__ = ["MAX_ENTRIES", "REQUIRED", "Choices", "Names", "annotation_kind", "param", "settings_as_section",
           "settings_from", "short_repr", "subsection"]


MAX_ENTRIES = 100
"""Most materials, particle properties, PETSc options or constants (each costs a field, a column, an
entry of PETSc's options database (512 in all) or an expression check)."""

_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict, _REPR.maxset = 2, 5, 5, 5, 5
_REPR.maxstring, _REPR.maxlong, _REPR.maxother = 80, 40, 80
_REPR_CHARACTERS = 120


def short_repr(value: Any) -> str:
    """``repr(value)`` bounded in length and depth (for error messages: never expands a large value)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"<integer of about {int(value.bit_length() * 0.30103)} digits>"
    text = _REPR.repr(value)
    return text if len(text) <= _REPR_CHARACTERS else text[: _REPR_CHARACTERS - 3] + "..."


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()
"""Marker default: the user must give this key."""


Choices = tuple[str, ...] | Callable[[], Iterable[str]]
"""Allowed names: a tuple, or a callable returning them (e.g. a registry's keys, read when checked)."""


class Names:
    """Allowed names that are a registry's keys, read when a config is checked (so the registry is
    the one list of names); :meth:`registry` gives the registry itself (the config reference lists
    its entries' descriptions).

    Args:
        registry: The registry (name -> entry), or a callable returning it (a registry of a module
            imported only when needed).
    """

    def __init__(self, registry: Mapping[str, Any] | Callable[[], Mapping[str, Any]], /) -> None:
        self._registry = registry

    def registry(self) -> Mapping[str, Any]:
        return self._registry if isinstance(self._registry, Mapping) else self._registry()

    def __call__(self) -> list[str]:
        return list(self.registry())


_SCALAR_KINDS = {int: "int", float: "float", str: "str", bool: "bool"}


def param(default: Any = REQUIRED, /, *, help: str, kind: str | None = None, choices: Choices | None = None,
          minimum: float | None = None, exclusive_minimum: float | None = None, maximum: float | None = None,
          exclusive_maximum: float | None = None, length: tuple[int, ...] | None = None,
          check: Callable[[Any], str | None] | None = None,
          items: Mapping[str, Any] | None = None, max_items: int | None = None) -> Any:
    """A field of a settings dataclass that is a key of its config section (see the module
    docstring): the default (``REQUIRED``: none), the checks of :class:`Field` and a one-line help.
    The kind (and whether ``null`` is allowed) follows from the field's annotation unless given:
    ``int``, ``float``, ``str``, ``bool``, ``tuple[int, ...]`` (a list in YAML), ``Mapping``, ``Any``,
    each ``| None`` for nullable."""
    spec = {"kind": kind, "default": default, "choices": choices, "minimum": minimum,
            "exclusive_minimum": exclusive_minimum, "maximum": maximum, "exclusive_maximum": exclusive_maximum,
            "length": length, "check": check, "help": help, "items": items, "max_items": max_items}
    metadata = {"schema": spec}
    if default is REQUIRED:
        return dataclasses.field(metadata=metadata)
    if isinstance(default, (list, dict)):
        return dataclasses.field(default_factory=lambda: copy.deepcopy(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def subsection(cls: type, /) -> Any:
    """A field of a settings dataclass that is a nested config section declared by ``cls``."""
    return dataclasses.field(default_factory=cls, metadata={"section": cls})


def annotation_kind(annotation: Any) -> tuple[str, bool]:
    """(Field kind, nullable) of a field annotation."""
    nullable = False
    if typing.get_origin(annotation) in (Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        nullable = len(args) < len(typing.get_args(annotation))
        annotation = args[0] if len(args) == 1 else Any
    origin = typing.get_origin(annotation)
    if annotation in _SCALAR_KINDS:
        return _SCALAR_KINDS[annotation], nullable
    if origin in (tuple, list):
        item = typing.get_args(annotation)[0]
        return (f"list[{_SCALAR_KINDS[item]}]" if item in _SCALAR_KINDS else "any"), nullable
    if origin in (dict, collections.abc.Mapping) or annotation in (dict, collections.abc.Mapping):
        return "mapping", nullable
    return "any", nullable


def settings_from(cls: type, section: Mapping[str, Any], /) -> Any:
    """The settings dataclass ``cls`` from a checked config section (lists become tuples where the
    field is a tuple; nested sections become their dataclasses, and so do the mappings of a list
    whose field is a tuple of settings dataclasses, ``tuple[Plate, ...]``)."""
    hints = typing.get_type_hints(cls)
    values = {}
    for f in dataclasses.fields(cls):
        if f.name not in section:
            continue
        value = section[f.name]
        if "section" in f.metadata:
            value = settings_from(f.metadata["section"], value)
        elif isinstance(value, list) and _is_tuple(hints[f.name]):
            item = _tuple_item(hints[f.name])
            value = tuple(settings_from(item, v) if _is_settings(item) and isinstance(v, Mapping) else v
                          for v in value)
        values[f.name] = value
    return cls(**values)


def _is_settings(item: Any) -> bool:
    return isinstance(item, type) and dataclasses.is_dataclass(item)


def _tuple_item(annotation: Any) -> Any:
    """The item type of the tuple in ``annotation`` (``tuple[X, ...]``, possibly ``| None``), or None."""
    if typing.get_origin(annotation) in (Union, types.UnionType):
        items = [_tuple_item(a) for a in typing.get_args(annotation)]
        return next((i for i in items if i is not None), None)
    return typing.get_args(annotation)[0] if typing.get_origin(annotation) is tuple else None


def _is_tuple(annotation: Any) -> bool:
    if typing.get_origin(annotation) in (Union, types.UnionType):
        return any(_is_tuple(a) for a in typing.get_args(annotation))
    return typing.get_origin(annotation) is tuple


def settings_as_section(settings: Any, /) -> dict[str, Any]:
    """A settings dataclass as its config section (tuples as lists, nested sections as mappings)."""
    out = {}
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if dataclasses.is_dataclass(value):
            value = settings_as_section(value)
        elif isinstance(value, tuple):
            value = list(value)
        out[f.name] = value
    return out
