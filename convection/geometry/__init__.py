"""The geometry of a run: the domain (ASPECT's GeometryModel) — box, annulus, spherical shell,
sector — which alone knows its shape (boundaries, gravity, facets, meshes, manifold, probes);
boundary conditions by name; plate velocities. Nothing outside this package tests which geometry
a run has: it asks the domain."""

from convection.geometry.boundary import TemperatureBC, VelocityBC
from convection.geometry.box import BoxDomain, BoxSpec
from convection.geometry.domain import Domain, MeshSection
from convection.geometry.gravity import Gravity, RadialGravity, VerticalGravity
from convection.geometry.plates import Plate, PlateVelocity
from convection.geometry.registry import DOMAINS, domain_from_settings
from convection.geometry.sector import Sector, SectorSpec
from convection.geometry.shell import Annulus, ShellDomain, ShellSpec, SphericalShell, shell_domain

__all__ = ["DOMAINS", "Annulus", "BoxDomain", "BoxSpec", "Domain", "Gravity", "MeshSection", "Plate", "PlateVelocity",
           "RadialGravity", "Sector", "SectorSpec", "ShellDomain", "ShellSpec", "SphericalShell", "TemperatureBC",
           "VelocityBC", "VerticalGravity", "domain_from_settings", "shell_domain"]
