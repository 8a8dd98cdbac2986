"""The particle systems of a config: one ``particles`` mapping, or a list of named systems.

A config carries particles in one of two forms::

    particles:                        # one system, named "particles" (files particles.xdmf, ...)
      generator: {name: random_uniform, particles_per_cell: 20}
      ...

    particles:                        # several systems, each with its own settings
      - name: dense                   # files particles_dense.xdmf, columns n_particles_dense, ...
        generator: {name: random_uniform, particles_per_cell: 20}
      - name: tracers
        generator: {name: random_uniform, num_particles: 500, seed: 3}
        output: {every_steps: 1, properties: [initial_position]}

Each list item has the keys of the single mapping (:class:`particles.settings.ParticleSettings`)
except ``enabled`` (a listed system is carried) plus its ``name`` (letters, digits and ``_``; it
names the system's files and statistics columns). ``composition.particle_system`` names the
system that carries the material fractions and the fields the viscosity laws read (the
*primary* one; default the first). ``--set particles.<name>.<key>=...`` (or
``particles.<index>.<key>``) overrides a listed system's key.

A resolved config keeps the form it was given in (a list of resolved sections, each with its
``name``, or the mapping); :func:`particle_sections` gives both as one mapping of sections by
name.
"""

from __future__ import annotations

import re
from typing import Any

from convection.model.composition import COMPOSITION_SOURCES
from convection.schema import ConfigError, section_schema, short_repr, validate
from particles.settings import ParticleSettings
from particles.systems import DEFAULT_SYSTEM

__all__ = ["MAX_PARTICLE_SYSTEMS", "carries_particles", "document_generators", "check_primary", "listed_systems",
           "override_target", "particle_sections", "primary_system", "resolve_systems"]

MAX_PARTICLE_SYSTEMS = 16
"""Most particle systems a config may list."""

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}")


def resolve_systems(document: dict[str, Any], /) -> list[dict[str, Any]] | None:
    """Validate a listed ``particles`` (a list of systems) and take it out of ``document``, whose
    other keys the schema then validates; None (``document`` untouched) for the mapping form.

    Raises:
        ConfigError: naming the key: an empty list, too many systems, an item that is not a
            mapping, a missing, malformed or repeated name, or a key of a system's section.
    """
    systems = document.get("particles")
    if not isinstance(systems, list):
        return None
    if not systems:
        raise ConfigError("config key 'particles': an empty list; list one or more systems ({name: ..., generator: "
                          "...}), or give one particles section")
    if len(systems) > MAX_PARTICLE_SYSTEMS:
        raise ConfigError(f"config key 'particles': {len(systems)} systems, at most {MAX_PARTICLE_SYSTEMS}")
    schema = section_schema(ParticleSettings)
    resolved: list[dict[str, Any]] = []
    for i, item in enumerate(systems):
        if not isinstance(item, dict):
            raise ConfigError(f"config key 'particles[{i}]': expected a system {{name: ..., generator: ..., ...}}, got "
                              f"{short_repr(item)}")
        name = item.get("name")
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise ConfigError(f"config key 'particles[{i}].name': expected a name of letters, digits and _ starting "
                              f"with a letter (it names the system's files and statistics columns), got "
                              f"{short_repr(name)}")
        if any(other["name"] == name for other in resolved):
            raise ConfigError(f"config key 'particles[{i}].name': {name!r} names two systems")
        body = {key: value for key, value in item.items() if key != "name"}
        resolved.append({"name": name, **validate(schema, body, prefix=f"particles.{name}.")})
    del document["particles"]
    return resolved


def listed_systems(config: dict[str, Any], /) -> bool:
    """Whether a resolved config lists its particle systems (the list form)."""
    return isinstance(config["particles"], list)


def particle_sections(config: dict[str, Any], /, *, carried: bool = True) -> dict[str, dict[str, Any]]:
    """The particle sections of a resolved config by system name, in order: the listed systems,
    or the one mapping under :data:`particles.systems.DEFAULT_SYSTEM` (with ``carried``: only if
    the run carries particles, see :func:`carries_particles`)."""
    section = config["particles"]
    if isinstance(section, list):
        return {system["name"]: system for system in section}
    if carried and not carries_particles(config):
        return {}
    return {DEFAULT_SYSTEM: section}


def carries_particles(config: dict[str, Any], /) -> bool:
    """Whether a run of a resolved config carries particles: a listed system always; one mapping
    when ``particles.enabled`` says so (null: when composition.source is particles)."""
    section = config["particles"]
    if isinstance(section, list):
        return True
    enabled = section["enabled"]
    carried = COMPOSITION_SOURCES[config["composition"]["source"]].carried_by_particles
    return carried if enabled is None else bool(enabled)


def primary_system(config: dict[str, Any], /) -> str | None:
    """The system whose fields the model reads (``composition.particle_system``, default the
    first); None without particles."""
    sections = particle_sections(config)
    if not sections:
        return None
    chosen = config["composition"]["particle_system"]
    return next(iter(sections)) if chosen is None else chosen


def check_primary(config: dict[str, Any], /) -> None:
    """``composition.particle_system`` names a system of the config.

    Raises:
        ConfigError: it names none of them (or the run carries no particles).
    """
    chosen = config["composition"]["particle_system"]
    if chosen is None:
        return
    names = list(particle_sections(config))
    if chosen not in names:
        where = f"the systems are {names}" if names else "the run carries no particles"
        raise ConfigError(f"config key 'composition.particle_system': {chosen!r} is not a particle system ({where})")


def override_target(node: list[Any], part: str, path: list[str]) -> Any:
    """The item of a list a ``--set`` path goes through: ``part`` is an index or a listed system's
    name.

    Raises:
        ConfigError: no such item.
    """
    if part.isdigit() and int(part) < len(node):
        return node[int(part)]
    for item in node:
        if isinstance(item, dict) and item.get("name") == part:
            return item
    raise ConfigError(f"--set {'.'.join(path)}: {part!r} is neither an index nor the name of an item of the list")


def document_generators(document: dict[str, Any], /) -> dict[str, dict[str, Any]]:
    """The generator mappings of a config document as written (not resolved) by the ``--set``
    prefix of each system's section: ``{"particles": ...}`` or ``{"particles.<name>": ...}`` for
    listed systems (e.g. to cap the particle counts of a shipped config for a small run)."""
    section = document.get("particles") or {}
    items = [(f"particles.{s.get('name')}", s) for s in section if isinstance(s, dict)] if isinstance(section, list) \
        else [("particles", section)] if isinstance(section, dict) else []
    return {prefix: s.get("generator") or {} for prefix, s in items if isinstance(s.get("generator") or {}, dict)}
