"""Particles between ranks (seed paper section 2.4, between subdomains).

:mod:`.migration` (hand each particle to the rank owning its cell; lost-particle counts),
:mod:`.offers` (who keeps a particle no local cell contains), :mod:`.exchange` (the point-to-point
message patterns of float64 tables) and :mod:`.ghosts` (one layer of ghost particles along rank
boundaries, for the interpolators and the population control). Imports only :mod:`particles.storage`.
"""
