"""The application: the command line (``python -m convection``), the builder of a model from a
config, the run loop with its outputs, the run folder's lock, the progress display and the MPI
launcher. Names are imported when first used (the launcher must not start MPI)."""

from convection._lazy import lazy_exports

__all__ = ["build_model", "main", "run", "run_config"]

__getattr__, __dir__ = lazy_exports(__name__, {"build_model": "factory", "run_config": "factory", "main": "cli",
                                               "run": "loop"})
