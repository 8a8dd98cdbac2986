"""The application: the command line (``python -m convection``), the builder of a model from a
config and its run. Names are imported when first used."""

from convection._lazy import lazy_exports

__all__ = ["build_model", "main", "run_config"]

__getattr__, __dir__ = lazy_exports(__name__, {"build_model": "factory", "run_config": "factory", "main": "cli"})
