"""The sections of a run configuration that no room below ``config/`` owns (``initial``, whose
expressions several components read), and the typed forms of the sections a geometry reads
(``mesh``, ``boundary``) made from a resolved config."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from convection.geometry.boundary import BoundarySettings
from convection.geometry.domain import MeshSection
from convection.geometry.registry import DOMAINS
from convection.schema import MAX_ENTRIES, param, settings_from

__all__ = ["InitialSettings", "boundary_settings", "mesh_section"]


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


def boundary_settings(section: Mapping[str, Any], /) -> BoundarySettings:
    """The typed ``boundary`` section of a resolved config (its geometry's boundaries only)."""
    return BoundarySettings(MappingProxyType(dict(section["velocity"])), MappingProxyType(dict(section["temperature"])))
