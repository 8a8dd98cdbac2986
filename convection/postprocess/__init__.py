"""Postprocessors: the columns of ``statistics.csv`` (each declares its columns and when it applies)
and the integrals they are made of (vrms, Nusselt numbers, temperature statistics)."""

from convection.postprocess.postprocessors import (
    POSTPROCESSORS, Postprocessor, PostprocessorContext, create_postprocessors,
)

__all__ = ["POSTPROCESSORS", "Postprocessor", "PostprocessorContext", "create_postprocessors"]
