"""How many particles each cell has, and how evenly they spread in it.

:mod:`.control` (``PopulationControl``: particles per cell kept between two bounds, the ``count``
and ``density`` methods, new particles' properties), :mod:`.density` (kernel density estimates and
the density-based choice of the particles to remove and the points to add), :mod:`.subcells`
(equal-volume sub-cells of a reference cell) and :mod:`.distribution` (ASPECT's particle
distribution score).
"""
