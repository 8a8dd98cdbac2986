"""Particle generators (seed paper section 2.2)."""
