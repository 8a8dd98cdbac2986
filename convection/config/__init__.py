"""The YAML front end: the schema of a run's config, loading with ``--set`` overrides, the checks
across keys, config files, and the generated config reference."""

from convection._lazy import lazy_exports

__all__ = ["SCHEMA", "ConfigError", "dump_config", "load_config", "parse_overrides"]

__getattr__, __dir__ = lazy_exports(__name__, {name: "loader" for name in __all__})
