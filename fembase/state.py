"""Component state: what a checkpoint keeps of a stateful component, and how it is given back.

Every stateful component (a solver with a time history, the particle manager, the model's time
stepping, a postprocessor that remembers its first value, ...) implements :class:`Stateful`:

- :meth:`Stateful.state` returns a :class:`State`: its *fields* (DOLFINx Functions, which a
  checkpoint saves by owned dof with their coordinates) and its *scalars* (anything JSON can hold);
- :meth:`Stateful.restore` takes the saved scalars back and returns the Functions (the same names
  as :attr:`State.fields`) that the checkpoint then fills with the saved values, exactly or by
  coordinates. A component that must make a Function first (a history that did not exist yet)
  makes it there.

A checkpoint (``convection.io.checkpoint``) writes and reads these and nothing else of a component;
the mesh and the particle swarm, which must exist before the components are built, are its own
parts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

__all__ = ["State", "Stateful"]


@dataclass
class State:
    """What a checkpoint keeps of a component.

    Attributes:
        fields: Functions by name (a name may hold ``/``, e.g. ``"salt/T_old"``).
        scalars: JSON-able values by name.
    """

    fields: dict[str, Any] = field(default_factory=dict)
    scalars: dict[str, Any] = field(default_factory=dict)


@runtime_checkable
class Stateful(Protocol):
    """A component whose state a checkpoint keeps (see the module docstring)."""

    def state(self) -> State:
        """The fields and scalars that continue this component."""

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, Any]:
        """Take the saved ``scalars`` back; returns the Functions to be filled with the saved field
        values, by the names of :meth:`state`'s fields."""
