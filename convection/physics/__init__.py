"""The physics: the Boussinesq approximation (buoyancy, viscosity, heating), materials and their
mixing, the viscosity laws (rheology) and the semi-implicit buoyancy."""

from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.physics.materials import Material, Materials
from convection.physics.rheology import VISCOSITY_LAWS, ViscosityLawBase, build_law

__all__ = ["VISCOSITY_LAWS", "BoussinesqApproximation", "Material", "Materials", "ViscosityLaw", "ViscosityLawBase",
           "build_law"]
