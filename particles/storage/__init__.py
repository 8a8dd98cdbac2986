"""Where the particles of one rank live (seed paper section 2.1).

:mod:`.swarm` (the :class:`~particles.storage.swarm.Swarm`: ids, positions, reference positions,
cells, property and stage tables, sorted by owned cell with CSR offsets), :mod:`.rows` (its buffers
with spare rows), :mod:`.cell_order` (the counting sort by cell), :mod:`.property_layout` (named
column ranges of the property table) and :mod:`.row_kernels` (the compiled loops that count, sort,
gather, scatter, pack and append rows). Nothing here imports another room of :mod:`particles`.
"""
