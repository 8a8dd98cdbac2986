"""Particles in files (seed paper section 2.8).

:mod:`.output` (the particle writers by config name: one parallel HDF5 file per output step and one
XDMF time series; mesh fields from particles) and :mod:`.swarm_checkpoint` (a swarm saved to one
parallel HDF5 file and restored on the same or another number of ranks).
"""
