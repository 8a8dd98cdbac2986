"""The geometry of a run: the domain (ASPECT's GeometryModel: box, annulus, spherical shell), its
meshes, its boundaries and the conditions on them by name, plate velocities and the probe points
that configs are checked at."""

from convection.geometry.boundary import TemperatureBC, VelocityBC
from convection.geometry.domain import BoxDomain, Domain, ShellDomain, domain_from_config
from convection.geometry.mesh import BoxSpec, MeshSpec, ShellSpec, create_mesh
from convection.geometry.plates import Plate, PlateVelocity

__all__ = ["BoxDomain", "BoxSpec", "Domain", "MeshSpec", "Plate", "PlateVelocity", "ShellDomain", "ShellSpec",
           "TemperatureBC", "VelocityBC", "create_mesh", "domain_from_config"]
