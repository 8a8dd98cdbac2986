"""A mesh that deforms during a run: the free surface (its load and stabilisation in the Stokes
equations, :mod:`convection.deform.surface`) and the motion of the mesh with it, the mesh velocity
and the cells' quality (:mod:`convection.deform.motion`)."""

from convection.deform.motion import FreeSurface, cell_quality
from convection.deform.surface import FreeSurfaceSettings, SurfaceTerms, check_free_surface, surface_terms

__all__ = ["FreeSurface", "FreeSurfaceSettings", "SurfaceTerms", "cell_quality", "check_free_surface", "surface_terms"]
