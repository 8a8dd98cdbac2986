"""Scalable particle-in-cell methods on DOLFINx meshes (after Gassmoeller et al., ASPECT).

`particles` never imports `convection`; it works on DOLFINx meshes and Functions.
"""

from particles.swarm import PropertyLayout, Swarm

__all__ = ["PropertyLayout", "Swarm"]
