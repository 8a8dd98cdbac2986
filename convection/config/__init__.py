"""The YAML front end: the schema of a run's config, loading with ``--set`` overrides, the checks
across keys, config files, the generated config reference, and the typed tree a run is built from
(:class:`~convection.config.settings.RunSettings`, made once after loading by
:func:`~convection.config.settings.run_settings`)."""

from convection._lazy import lazy_exports

__all__ = ["SCHEMA", "ConfigError", "RunSettings", "dump_config", "load_config", "parse_overrides", "run_settings"]

__getattr__, __dir__ = lazy_exports(__name__, {**{name: "loader" for name in __all__ if name not in
                                                  ("RunSettings", "run_settings")},
                                               "RunSettings": "settings", "run_settings": "settings"})
