"""The config reference, generated from the schema and the plugin registries.

``python -m convection schema`` prints it; ``docs/config-reference.md`` is that output (a test
fails when they differ, so the reference cannot fall behind the code). Two renderings:

- :func:`render_markdown`: every section and key of :data:`convection.config.loader.SCHEMA` with type,
  default, allowed values and help; every name a registry offers, with its one-line description;
  every plugin's parameters from its dataclass (particle generators, properties and interpolators,
  viscosity laws) with type, default and the help declared with the field;
- :func:`render_yaml`: a YAML document holding every key at its default, help and allowed values
  as comments (``null  # required`` where the user must give a value) — a config to start from.

Nothing here reads a config or needs MPI: the reference is the same on every machine.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
from dataclasses import dataclass
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import yaml

from convection.config.loader import SCHEMA
from convection.geometry.registry import DOMAINS
from convection.schema import REQUIRED, Field, Names

if TYPE_CHECKING:
    from particles.properties import ParticleProperty

__all__ = ["KeyDoc", "Parameter", "PluginRole", "plugin_roles", "render_markdown", "render_yaml", "schema_keys"]

"""Boundary names of an annulus/spherical shell (commented out in the YAML form, whose mesh is a box)."""
MATERIAL = "<material>"
"""Placeholder of a free mapping key (a material's name) in dotted keys."""


@dataclass(frozen=True)
class KeyDoc:
    """One leaf of the schema, flattened: dotted ``key`` and its :class:`~convection.schema.Field`."""

    key: str
    field: Field

    @property
    def required(self) -> bool:
        return self.field.default is REQUIRED

    def type_text(self) -> str:
        kind = self.field.kind
        if self.field.length:
            kind += f" (length {' or '.join(map(str, self.field.length))})"
        return kind + (" or null" if self.field.nullable else "")

    def default_text(self) -> str:
        return "required" if self.required else _value(self.field.default)

    def bounds_text(self) -> str:
        f = self.field
        parts = [f">= {f.minimum:g}" if f.minimum is not None else "",
                 f"> {f.exclusive_minimum:g}" if f.exclusive_minimum is not None else "",
                 f"<= {f.maximum:g}" if f.maximum is not None else "",
                 f"< {f.exclusive_maximum:g}" if f.exclusive_maximum is not None else "",
                 f"at most {f.max_items} entries" if f.max_items is not None else ""]
        return ", ".join(p for p in parts if p)


@dataclass(frozen=True)
class Parameter:
    """A plugin parameter: ``name``, type text, default text (``required`` when it has none), help."""

    name: str
    type: str
    default: str
    help: str


@dataclass(frozen=True)
class PluginRole:
    """One plugin registry: its title, the config keys that choose from it, and its entries as
    ``{name: (description, parameters)}``."""

    title: str
    keys: tuple[str, ...]
    entries: dict[str, tuple[str, list[Parameter]]]
    note: str = ""


def schema_keys(schema: Mapping[str, Any] = SCHEMA, prefix: str = "") -> Iterator[KeyDoc]:
    """Every leaf of ``schema`` in order, as dotted keys (a mapping of named items, such as
    ``materials``, also yields ``materials.<material>.KEY`` for each item key; others ``<name>``)."""
    for name, node in schema.items():
        key = f"{prefix}{name}"
        if isinstance(node, Field):
            yield KeyDoc(key, node)
            if node.items:
                yield from schema_keys(node.items, f"{key}.{MATERIAL if name == 'materials' else '<name>'}.")
        else:
            yield from schema_keys(node, f"{key}.")


def _value(value: Any) -> str:
    """A default as YAML flow text (``null``, ``[32, 32]``, ``{name: cell_average, ...}``), as PyYAML
    reads it back (``1.0e-06``, not ``1e-06``, which it reads as text)."""
    if isinstance(value, tuple):
        value = list(value)
    text = yaml.safe_dump(value, default_flow_style=True, sort_keys=False, width=10**6)
    return text.removesuffix("\n").removesuffix("\n...")


def _describe(entry: Any) -> str:
    """One line describing a registry entry: a text, an object's ``description``, or the first
    line of a function's docstring."""
    if isinstance(entry, str):
        return entry
    description = getattr(entry, "description", None)
    if isinstance(description, str):
        return description
    doc = inspect.getdoc(entry) or ""
    return doc.split("\n\n")[0].replace("\n", " ").replace("``", "`")


def _dataclass_parameters(cls: type, *, skip: tuple[str, ...] = ()) -> list[Parameter]:
    """The init parameters of a dataclass plugin (its ``Settings``): name, type, default, help and
    checks, as declared with the field by :func:`fembase.params.param`."""
    out = []
    for f in dataclasses.fields(cls):
        if not f.init or f.name in skip or f.name.startswith("_"):
            continue
        if f.default is not dataclasses.MISSING:
            default = _value(f.default)
        elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
            default = _value(f.default_factory())  # type: ignore[misc]
        else:
            default = "required"
        spec = f.metadata.get("schema", {})
        kind = spec.get("kind") or (f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type)))
        help_text = spec.get("help", "")
        checks = [f"{text} {spec[key]:g}" for key, text in (("minimum", ">="), ("exclusive_minimum", ">"),
                                                              ("maximum", "<="), ("exclusive_maximum", "<"))
                  if isinstance(spec.get(key), (int, float))]
        choices = spec.get("choices")
        if choices:
            checks.append("one of " + ", ".join(map(str, choices() if callable(choices) else choices)))
        if checks:
            help_text = (help_text + " " if help_text else "") + f"({'; '.join(checks)})"
        out.append(Parameter(f.name, str(kind), default, help_text))
    return out


def _settings_parameters(plugin: Any) -> list[Parameter]:
    """The parameters of a plugin of the one shape: its ``Settings``' fields."""
    return _dataclass_parameters(plugin.Settings)


def _property_parameters(cls: type[ParticleProperty]) -> list[Parameter]:
    """A particle property's parameters (its ``Settings``), its update policies with their allowed
    values and this property's defaults."""
    from particles.properties import NEW_PARTICLE_POLICIES, UPDATE_POLICIES

    policies = {"update": ("when the value is recomputed", UPDATE_POLICIES, cls.default_update),
                "new_particles": ("what particles added later (population control) get", NEW_PARTICLE_POLICIES,
                                  cls.default_new_particles)}
    out = []
    for p in _dataclass_parameters(cls.Settings):
        if p.name in policies:
            text, allowed, default = policies[p.name]
            p = Parameter(p.name, "str or null", "null", f"{text}: one of {', '.join(allowed)} (null: {default})")
        out.append(p)
    return out


def plugin_roles() -> list[PluginRole]:
    """The plugin registries a config chooses from, each entry with its parameters."""
    from convection.physics.rheology import COMBINATIONS, STRAIN_RATE_MEASURES, VISCOSITY_LAWS, LawSettings
    from particles.generation import GENERATORS
    from particles.interpolation import INTERPOLATORS
    from particles.properties import PROPERTIES

    def role(title: str, keys: tuple[str, ...], registry: Mapping[str, Any],
             parameters: Callable[[Any], list[Parameter]], note: str = "") -> PluginRole:
        return PluginRole(title, keys, {name: (_describe(entry), parameters(entry)) for name, entry in
                                        registry.items()}, note)

    bounds = _dataclass_parameters(LawSettings, skip=("name", "settings"))
    return [
        role("Particle generators", ("particles.generator",), GENERATORS, _settings_parameters,
             "`{name: <generator>, <parameter>: ...}`; `particles_per_cell: N` may replace `num_particles` "
             "(N times the global cell count). A `density` is an expression in x, y, z, r, phi, theta "
             "(0 outside, e.g. `\"r < r_inner + 0.15\"`)."),
        role("Particle properties", ("particles.properties",), PROPERTIES, _property_parameters,
             "each item a name or `{name: <property>, <parameter>: ...}`; `update` and `new_particles` "
             "override when a property is recomputed and how particles added later get their value."),
        role("Particle interpolators", ("particles.interpolator",), INTERPOLATORS, _settings_parameters,
             "`{name: <interpolator>, <parameter>: ...}`: how particle properties become mesh fields."),
        role("Viscosity laws", ("physics.viscosity.law", f"materials.{MATERIAL}.viscosity"), VISCOSITY_LAWS,
             lambda law: _dataclass_parameters(law.Settings) + bounds,
             "a positive number (constant viscosity) or `{name: <law>, <parameter>: ...}`; a parameter of kind "
             "`law`/`laws` is itself a law (or a list of laws); every law may add `min_viscosity` and "
             "`max_viscosity` (the result is clipped to them)."),
        role("Strain-rate measures of the yield laws", ("strain_rate (von_mises, drucker_prager)",),
             STRAIN_RATE_MEASURES, lambda entry: []),
        role("Visco-plastic combination rules", ("combination (viscoplastic)",), COMBINATIONS, lambda entry: []),
    ]


def _registry_choices() -> list[tuple[KeyDoc, dict[str, str]]]:
    """Schema keys whose allowed names come from a registry, with each name's description."""
    out: list[tuple[KeyDoc, dict[str, str]]] = []
    for doc in schema_keys():
        if isinstance(doc.field.choices, Names):
            registry = doc.field.choices.registry()
            out.append((doc, {name: _describe(registry[name]) + _columns(registry[name]) for name in registry}))
    return out


def _columns(entry: Any) -> str:
    """`` (columns `a`, `b`)`` of a postprocessor with fixed statistics columns, else ''."""
    columns = getattr(entry, "columns", None)
    if not isinstance(columns, tuple) or not columns:
        return ""
    return " (columns " + ", ".join(f"`{c}`" for c in columns) + ")"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _sections() -> list[tuple[str, list[KeyDoc]]]:
    """The schema's keys grouped by top-level section (top-level leaves under "general")."""
    groups: dict[str, list[KeyDoc]] = {}
    for doc in schema_keys():
        head = doc.key.split(".")[0]
        if isinstance(SCHEMA[head], Field) and not SCHEMA[head].items:
            head = "general"
        groups.setdefault(head, []).append(doc)
    return list(groups.items())


def render_markdown() -> str:
    """The config reference as Markdown (the content of ``docs/config-reference.md``)."""
    from convection.config import loader as config_module

    lines = ["# Config reference", "",
             "<!-- Generated by `python -m convection schema > docs/config-reference.md`; do not edit: "
             "tests/convection/config/test_reference.py fails when this file differs from the output. -->", "",
             "Every key a run configuration (YAML) may hold, with its type, default, allowed values and "
             "meaning, followed by the plugins a config chooses by name and their parameters. Keys are "
             "written dotted: `mesh.cells` is `cells:` inside `mesh:`; every key may also be set on the "
             "command line with `--set mesh.cells=[64,64]`. Only `physics.Ra`, `time.end`, "
             "`output.directory` and the mesh size (`mesh.cells`, or `mesh.resolution` for a shell) must "
             "be given. `python -m convection check CONFIG` prints a config with every default filled in; "
             "`python -m convection schema --format yaml` prints a config holding every key at its "
             "default.", ""]
    sections = next(part for part in (config_module.__doc__ or "").split("\n\n") if part.startswith("- "))
    lines += ["The sections:", "", re.sub(r":\w+:`([^`]+)`", r"`\1`", sections.replace("``", "`"))]
    lines += ["", "## Keys", ""]
    for head, docs in _sections():
        lines += [f"### `{head}`" if head != "general" else "### General", "",
                  "| key | type | default | allowed | meaning |", "|---|---|---|---|---|"]
        for doc in docs:
            allowed = doc.field.allowed()
            allowed_text = ", ".join(f"`{a}`" for a in allowed) if allowed else doc.bounds_text()
            if allowed and doc.bounds_text():
                allowed_text += "; " + doc.bounds_text()
            lines.append(f"| `{doc.key}` | {_cell(doc.type_text())} | `{_cell(doc.default_text())}` | "
                         f"{_cell(allowed_text)} | {_cell(doc.field.help)} |")
        lines.append("")
    lines += ["## Named choices", "",
              "Keys whose values are names from a registry of the code (the registry is the one list: "
              "a new implementation registered there appears here).", ""]
    for doc, names in _registry_choices():
        lines += [f"### `{doc.key}`", ""]
        lines += [f"- `{name}`: {text}" for name, text in names.items()]
        lines.append("")
    lines += ["## Plugins and their parameters", ""]
    for plugin in plugin_roles():
        lines += [f"### {plugin.title}", "", "Chosen by " + ", ".join(f"`{k}`" for k in plugin.keys) + "." +
                  (f" {plugin.note}" if plugin.note else ""), ""]
        for name, (description, parameters) in plugin.entries.items():
            lines += [f"#### `{name}`", "", description[:1].upper() + description[1:] + ".", ""]
            if parameters:
                lines += ["| parameter | type | default | meaning |", "|---|---|---|---|"]
                lines += [f"| `{p.name}` | {_cell(p.type)} | `{_cell(p.default)}` | {_cell(p.help)} |"
                          for p in parameters]
                lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def _other_geometry(path: str, name: str) -> bool:
    """Whether the key ``path + name`` belongs to a geometry other than the default box."""
    box = DOMAINS["box"]
    if path.startswith("boundary."):
        return name not in box.config_boundaries
    return path == "mesh." and name not in (*box.config_keys, "geometry", "max_cells")


def render_yaml() -> str:
    """Every key of the schema at its default, as a YAML document with help and allowed values as
    comments (required keys are ``null  # required: ...``)."""
    lines = ["# Every key of a run configuration at its default (python -m convection schema --format yaml).",
             "# Keys marked 'required' must be given; see docs/config-reference.md for the plugins' parameters.",
             "# The mesh keys and boundaries of the other geometries (annulus, spherical shell, sector) are commented",
             "# out: this is a box; for another geometry, uncomment its keys and boundaries and remove the box's."]

    def walk(schema: Mapping[str, Any], depth: int, path: str = "") -> None:
        pad = "  " * depth
        for name, node in schema.items():
            if isinstance(node, Field):
                off = "# " if _other_geometry(path, name) else ""
                doc = KeyDoc(name, node)
                value = "null" if doc.required else _value(node.default)
                notes = (["required"] if doc.required else []) + ([node.help] if node.help else [])
                allowed = node.allowed()
                if allowed:
                    notes.append("one of: " + ", ".join(allowed))
                elif doc.bounds_text():
                    notes.append(doc.bounds_text())
                comment = "  # " + "; ".join(notes) if notes else ""
                lines.append(f"{pad}{off}{name}: {value}{comment}")
            else:
                lines.append(f"{pad}{name}:")
                walk(node, depth + 1, f"{path}{name}.")

    walk(SCHEMA, 0)
    return "\n".join(lines) + "\n"
