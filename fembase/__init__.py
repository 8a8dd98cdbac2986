"""The floor under :mod:`particles` and :mod:`convection`: finite-element tools that make sense in a
project without particles, on DOLFINx meshes and Functions.

=========================== ==============================================================================
module                      what
=========================== ==============================================================================
:mod:`fembase.geometry`     cell geometry (affine maps, adjacency, curvature), pull-back and point location
:mod:`fembase.adjacency`    the cells sharing a vertex or a facet with each cell
:mod:`fembase.location`     the point searches among a cell geometry's cells
:mod:`fembase.manifold`     curved annulus and spherical-shell meshes refined from a straight base
:mod:`fembase.shell_map`    the manifold's point map on its fitted base, and its inverse
:mod:`fembase.curved_mesh`  meshes whose geometry nodes a point map moves (P1 to P2 and back)
:mod:`fembase.entities`     the reference order of simplex edges, boundary entities of a mesh
:mod:`fembase.kernels`      compiled kernels: P1/P2 simplex evaluation, pull-back, location among candidates
:mod:`fembase.evaluation`   Functions and gradients at points given by cell and reference coordinates
:mod:`fembase.partition`    partition methods (rcb, morton) for cell and particle loads
:mod:`fembase.distribute`   mesh pieces, meshes created on chosen owners, reproducible meshes, fingerprints
:mod:`fembase.files`        parallel HDF5 datasets and atomically written text files
:mod:`fembase.streams`      counter-based random streams (the same numbers on any rank count)
:mod:`fembase.timing`       named wall-clock timers with max/mean over ranks
:mod:`fembase.jit_cache`    compiled forms and elements kept per process
=========================== ==============================================================================

``particles`` and ``convection`` both import from here; nothing here imports either of them.
"""
