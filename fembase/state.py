"""Component state: what a checkpoint keeps of a stateful component, and how it is given back.

Every stateful component (a solver with a time history, the particle manager, the model's time
stepping, a postprocessor that remembers its first value, ...) implements :class:`Stateful`:

- :meth:`Stateful.state` returns a :class:`State`: its *fields* (DOLFINx Functions, which a
  checkpoint saves by owned dof with their coordinates) and its *scalars* (anything JSON can hold);
- :meth:`Stateful.restore` takes the saved scalars back and returns the Functions (the same names
  as :attr:`State.fields`) that the checkpoint then fills with the saved values, exactly or by
  coordinates. A component that must make a Function first (a history that did not exist yet)
  makes it there;
- :meth:`Stateful.restored` is called once every component's Functions are filled.

:class:`Stateful` is also a no-op base to inherit: a component overrides what it keeps.

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
    """A component whose state a checkpoint keeps (see the module docstring).

    Also a no-op base: a class that names it (``class Solver(Stateful):``) inherits an empty
    :meth:`state`, a :meth:`restore` that fills nothing and a :meth:`restored` that does nothing, and
    overrides what it keeps. The checkpoint calls :meth:`restored` of every component.
    """

    def state(self) -> State:
        """The fields and scalars that continue this component (default: nothing)."""
        return State()

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, Any]:
        """Take the saved ``scalars`` back; returns the Functions to be filled with the saved field
        values, by the names of :meth:`state`'s fields (default: none)."""
        return {}

    def restored(self) -> None:
        """The Functions of :meth:`restore` are filled (on every component): finish the restore,
        e.g. move the mesh's nodes to the filled coordinates (default: nothing to do)."""
        return None
