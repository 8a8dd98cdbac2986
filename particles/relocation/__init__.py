"""The cells of particles after they or the mesh moved (seed paper sections 2.4 and 2.5).

:mod:`.between_cells` (``relocate``: the old cell, the facet crossed, the vertex neighbours, then a
bounding-box search), :mod:`.affine_walk` (that walk compiled for affine simplices),
:mod:`.moving_mesh` (particles on a mesh whose nodes moved; the moving-boundary rule ``pull_in``)
and :mod:`.new_mesh` (particles onto a refined, coarsened or repartitioned mesh). Imports
:mod:`particles.storage` and :mod:`particles.parallel`.
"""
