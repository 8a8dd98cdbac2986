"""Named column ranges of a swarm's property table (:attr:`particles.storage.swarm.Swarm.properties`)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PropertyLayout", "PropertyLayouts"]


@dataclass(frozen=True)
class PropertyLayout:
    """Where a named property lives in the property table.

    Attributes:
        name: Property name.
        start: First column in :attr:`Swarm.properties`.
        size: Number of scalar columns (1 for a scalar, gdim for a vector, gdim**2 for a tensor).
    """

    name: str
    start: int
    size: int

    @property
    def columns(self) -> slice:
        return slice(self.start, self.start + self.size)


class PropertyLayouts:
    """The layouts of the properties of one table, by name, in the order they were added."""

    def __init__(self) -> None:
        self._by_name: dict[str, PropertyLayout] = {}

    @property
    def names(self) -> list[str]:
        return list(self._by_name)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def __getitem__(self, name: str) -> PropertyLayout:
        """The layout of ``name``; KeyError lists the known names."""
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"unknown particle property {name!r}; known: {sorted(self._by_name)}") from None

    def add(self, name: str, start: int, size: int) -> PropertyLayout:
        """Name ``size`` columns from ``start`` on (ValueError for a known name or size < 1)."""
        if name in self._by_name:
            raise ValueError(f"particle property {name!r} exists already")
        if size < 1:
            raise ValueError(f"property size must be >= 1, got {size}")
        self._by_name[name] = PropertyLayout(name, start, size)
        return self._by_name[name]

    def remove(self, name: str) -> PropertyLayout:
        """Forget ``name`` and move the later properties' columns down; returns its old layout."""
        lay = self[name]
        del self._by_name[name]
        for key, other in list(self._by_name.items()):
            if other.start > lay.start:
                self._by_name[key] = PropertyLayout(key, other.start - lay.size, other.size)
        return lay
