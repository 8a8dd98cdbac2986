"""Boussinesq Stokes + temperature convection on DOLFINx with adaptive meshes."""
