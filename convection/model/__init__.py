"""The model: its components (flow, temperature, material fractions, particles, adaptivity,
balancing), advanced one time step at a time, and the fields derived from its rheology."""

from convection.model.composition import (
    COMPOSITION_SOURCES, CompositionSource, FieldComposition, ParticleComposition, StaticComposition,
)
from convection.model.model import Model, StepReport

__all__ = ["COMPOSITION_SOURCES", "CompositionSource", "FieldComposition", "Model", "ParticleComposition",
           "StaticComposition", "StepReport"]
