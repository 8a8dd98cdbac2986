"""Registries mapping lowercase config names to implementation classes (one per role).

Each implementation class carries ``name`` and ``description`` class attributes and is a frozen
dataclass of its parameters; a registry is a plain ``dict[name, class]``.
"""

from __future__ import annotations

from typing import Any, Mapping

__all__ = ["create", "describe"]


def describe(registry: Mapping[str, type], /) -> dict[str, str]:
    """One-line description of every registered implementation, by name."""
    return {name: cls.description for name, cls in registry.items()}


def create(registry: Mapping[str, type], role: str, name: str, parameters: Mapping[str, Any], /) -> Any:
    """Build the implementation registered as ``name`` with ``parameters``.

    Raises:
        ValueError: Unknown name; the message lists the valid names of this ``role``.
    """
    try:
        cls = registry[name]
    except KeyError:
        raise ValueError(f"unknown particle {role} {name!r}; valid: {sorted(registry)}") from None
    return cls(**parameters)
