"""Scalable particle-in-cell methods on DOLFINx meshes (after Gassmoeller et al., ASPECT).

The rooms, from the floor up (a room imports only from rooms above it in this table, and from
``fembase``):

================= ================================================================================
room              what it owns
================= ================================================================================
``storage``       the Swarm: per-particle rows sorted by cell, the property layout, the row kernels
``parallel``      particles between ranks: migration, the offer rounds, message patterns, ghosts
``relocation``    the cells of particles after a move, on a moved mesh and on a new mesh
``advection``     Runge-Kutta integrators (registry), their stages, the velocity at the particles
``generation``    generators (registry), one module each
``properties``    particle properties (registry), one module each
``interpolation`` particle-to-mesh interpolators (registry), empty-cell filling, tracked fields
``population``    particles per cell: count and density control, sub-cells, distribution score
``io``            particle output (writers by config name) and the swarm checkpoint
================= ================================================================================

The public faces stay here: :mod:`particles.manager` (``ParticleManager``, the particle world of
one run), :mod:`particles.systems` (several particle systems in one run), :mod:`particles.settings`
(the parameters of a particle system) and :mod:`particles.balance` (``rebalance``: repartition a
swarm's mesh by particle load, for particle users outside the convection runs).

`particles` never imports `convection`; it works on DOLFINx meshes and Functions.
"""

from particles.storage.swarm import PropertyLayout, Swarm

__all__ = ["PropertyLayout", "Swarm"]
