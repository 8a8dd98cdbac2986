"""The sections of a run configuration that no room below ``config/`` owns (``initial``, whose
expressions several components read), and the typed forms of the sections a geometry reads
(``mesh``, ``boundary``) made from a resolved config."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from convection.geometry.boundary import (
    DEFAULT_TEMPERATURE, TEMPERATURE_BC_KINDS, VELOCITY_BC_KINDS, BoundarySettings, TemperatureBC, VelocityCondition,
)
from convection.geometry.domain import MeshSection
from convection.geometry.registry import DOMAINS
from convection.schema import MAX_ENTRIES, REQUIRED, param, section_schema, settings_from, short_repr, validate

__all__ = ["InitialSettings", "boundary_settings", "mesh_section", "temperature_condition", "velocity_condition"]


@dataclass(frozen=True)
class InitialSettings:
    """The ``initial`` config section: the initial condition."""

    temperature: str = param("1 - z", help="expression in x, y, z (z vertical), r, phi, theta")
    temperature_bounded: bool = param(False, help="set the initial temperature by its linear interpolant at the "
                                      "vertices, within the expression's values everywhere (P2 at every node "
                                      "overshoots a sharp anomaly by up to 1/8 of its jump between the nodes)")
    composition: str | None = param(None, help="expression in x, y, z (1 = dense/second material), or null for none")
    constants: Mapping[str, Any] = param({}, max_items=MAX_ENTRIES, help="named constants usable in the expressions")
    from_run: str | None = param(None, help="start from another run's temperature instead of initial.temperature: "
                                 "its run folder (newest checkpoint) or a checkpoint folder; interpolated onto this "
                                 "mesh, on any rank count (a box of the same extent; command line: run --initial-from "
                                 "PATH)")
    steady: bool = param(False, help="before the first step, solve the steady equations for flow and temperature "
                         "by Newton's method (from initial.temperature or initial.from_run, via the isoviscous flow "
                         "and a continuation in the viscosity contrast; boxes, Boussinesq, no composition); the "
                         "run then steps on from that state (docs/configs.md, 'Steady start')")


def mesh_section(section: Mapping[str, Any], /) -> MeshSection:
    """The typed ``mesh`` section of a resolved config: its geometry's keys as that geometry's
    :attr:`~convection.geometry.domain.Domain.Settings` (the other geometries' keys left out)."""
    geometry = section["geometry"]
    return MeshSection(geometry, settings_from(DOMAINS.lookup(geometry).Settings, section), section["max_cells"])


def velocity_condition(value: Any, /) -> VelocityCondition | None:
    """The typed velocity condition of a ``boundary.velocity.<side>`` value as written: a kind's
    name, or ``{kind: <name>, <entry>: ...}`` with the entries of the kind's ``Settings``
    (:class:`convection.geometry.boundary.VelocityKind`); None: traction free.

    Raises:
        ValueError: What is wrong, in the user's terms (the config check puts the key before it).
    """
    if value is None:
        return None
    name = value.get("kind") if isinstance(value, dict) else value
    if not isinstance(name, str) or name not in VELOCITY_BC_KINDS:
        raise ValueError(f"velocity condition {short_repr(value)} is not one of {list(VELOCITY_BC_KINDS)} "
                         "(or {kind: prescribed, value: [..]})")
    kind = VELOCITY_BC_KINDS[name]
    schema = section_schema(kind.Settings)
    if not isinstance(value, dict):
        if any(field.default is REQUIRED for field in schema.values()):
            raise ValueError(f"a {name} velocity needs the form {kind.form}")
        return VelocityCondition(name, kind.Settings())
    entries = {key: entry for key, entry in value.items() if key != "kind"}
    unknown = [key for key in entries if key not in schema]
    if unknown:
        raise ValueError(f"unknown entry {short_repr(unknown[0])}; allowed: {['kind', *sorted(schema)]}")
    return VelocityCondition(name, _settings(kind.Settings, entries))


def _settings(cls: type, entries: Mapping[str, Any], /) -> Any:
    """The kind's ``Settings`` ``cls`` of its ``entries`` as written: each entry's ``check`` first
    (a required entry that is missing: given None), in the user's terms (ValueError), then the
    schema's checks."""
    schema = section_schema(cls)
    for key, field in schema.items():
        if key in entries or field.default is REQUIRED:
            problem = field.check(entries.get(key)) if field.check is not None else None
            if problem:
                raise ValueError(problem)
    return settings_from(cls, validate(schema, entries))


def temperature_condition(value: Any, /) -> TemperatureBC:
    """The temperature condition of a ``boundary.temperature.<side>`` value as written: a kind's
    name, or ``{<name>: <its one entry>}`` (``{dirichlet: 1.0}``); None: insulating.

    Raises:
        ValueError: What is wrong, in the user's terms (the config check puts the key before it).
    """
    if value is None:
        return DEFAULT_TEMPERATURE
    name = next(iter(value)) if isinstance(value, dict) and len(value) == 1 else value
    kind = TEMPERATURE_BC_KINDS.get(name) if isinstance(name, str) else None
    entries = 0 if kind is None else len(section_schema(kind.Settings))
    if kind is None or entries != (0 if isinstance(value, str) else 1):
        raise ValueError(f"temperature condition {short_repr(value)} must be 'insulating' or {{dirichlet: <number>}}")
    written = {} if isinstance(value, str) else dict.fromkeys(section_schema(kind.Settings), value[name])
    return TEMPERATURE_BC_KINDS.build(name, _settings(kind.Settings, written), None)


def boundary_settings(section: Mapping[str, Any], /) -> BoundarySettings:
    """The typed ``boundary`` section of a resolved config (its geometry's boundaries only)."""
    velocity = {side: velocity_condition(value) for side, value in section["velocity"].items()}
    temperature = {side: temperature_condition(value) for side, value in section["temperature"].items()}
    return BoundarySettings(MappingProxyType(velocity), MappingProxyType(temperature))
