"""The config checks of ``initial.from_run`` (``run --initial-from PATH``): the source run's
checkpoint exists and its domain is this run's (:mod:`convection.io.continuation` takes its
temperature)."""

from __future__ import annotations

from typing import Any

from convection.config.loader import config_domain
from convection.io.checkpoint import inspect_checkpoint
from convection.io.continuation import KEY, source_checkpoint
from convection.schema import ConfigError

__all__ = ["check_source"]

_SAME = (("mesh", "geometry"), ("mesh", "cell_type"), ("mesh", "lower"), ("mesh", "upper"))
"""The source's config values that must equal the new run's (besides the dimension)."""


def _extent(config: dict[str, Any], key: str) -> Any:
    mesh = config["mesh"]
    value = mesh.get(key)
    if value is None:  # a box's defaults: the unit square or cube
        return [0.0 if key == "lower" else 1.0] * len(mesh["cells"] or ())
    return [float(v) for v in value]


def check_source(config: dict[str, Any], /) -> None:
    """Check ``initial.from_run`` of a resolved config (nothing to do when it is null); reads the
    source's checkpoint (not collective).

    Raises:
        ConfigError: One line naming ``initial.from_run``: no checkpoint there, a damaged one, one
            without a temperature, or a domain the new run's is not.
    """
    source = config["initial"]["from_run"]
    if source is None:
        return
    path = source_checkpoint(source)
    if path is None:
        raise ConfigError(f"config key '{KEY}': '{source}' is neither a run folder with a checkpoint "
                          "(checkpoints/checkpoint_*) nor a checkpoint folder")
    saved = inspect_checkpoint(path)
    if isinstance(saved, str):
        raise ConfigError(f"config key '{KEY}': checkpoint {path}: {saved}")
    if config["adaptivity"]["enabled"]:
        raise ConfigError(f"config key '{KEY}': not with adaptivity.enabled (the initial mesh is adapted to "
                          "initial.temperature)")
    other = saved.config
    if config_domain(config).manifold() is not None:
        raise ConfigError(f"config key '{KEY}': only a domain meshed with straight cells continues another run "
                          f"(mesh.geometry {config['mesh']['geometry']} is curved)")
    if len(other["mesh"].get("cells") or ()) != len(config["mesh"]["cells"]):
        raise ConfigError(f"config key '{KEY}': the source {path} is a {len(other['mesh'].get('cells') or ())}D "
                          f"run, this one is {len(config['mesh']['cells'])}D")
    for section, key in _SAME:
        mine = _extent(config, key) if key in ("lower", "upper") else config[section][key]
        theirs = _extent(other, key) if key in ("lower", "upper") else other[section].get(key)
        if theirs != mine:
            raise ConfigError(f"config key '{KEY}': the source {path} has {section}.{key} = {theirs}, this run "
                              f"{mine}")
    if not other["energy"]["enabled"]:
        raise ConfigError(f"config key '{KEY}': the source {path} has no temperature (energy.enabled: false)")
