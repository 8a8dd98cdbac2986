"""The floor under :mod:`particles` and :mod:`convection`: finite-element tools that make sense in a
project without particles, on DOLFINx meshes and Functions.

=========================== ==============================================================================
module                      what
=========================== ==============================================================================
:mod:`fembase.geometry`     cell geometry (affine maps, adjacency, curvature), pull-back and point location
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
