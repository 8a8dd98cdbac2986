"""Explicit Runge-Kutta advection of particles and of the properties that obey an ODE (seed paper
section 2.3), with the integrators' registry.

:mod:`.integrators` (the Butcher tableaus by config name, ``INTEGRATORS``, and ``ParticleODE``),
:mod:`.advector` (``Advector``: one step, its stage positions relocated and migrated),
:mod:`.stages` (the integrated state and the stage slopes kept in the swarm's stage table) and
:mod:`.velocity` (the velocity linear in time between two Functions, at the particles). The names
most callers need are here.
"""

from particles.advection.advector import AdvectionStats, Advector
from particles.advection.integrators import INTEGRATORS, ButcherTableau, ParticleODE, get_integrator

__all__ = ["AdvectionStats", "Advector", "ButcherTableau", "INTEGRATORS", "ParticleODE", "get_integrator"]
