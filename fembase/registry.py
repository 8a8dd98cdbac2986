"""One registry per plugin role, mapping lowercase config names to implementations (the particle
roles of :mod:`particles` and the roles of :mod:`convection`: domains, viscosity laws,
postprocessors, writers, ...).

Every entry carries ``name`` and ``description`` attributes: an implementation class (with its
``Settings``, or still a frozen dataclass of its parameters) or a ready object such as a Butcher
tableau.
A :class:`Registry` is a ``dict[name, entry]`` that also knows its role, so ``name in REGISTRY``,
``sorted(REGISTRY)`` and ``REGISTRY[name]`` work as on a plain dict, and an unknown name is an
error naming the role and listing the valid names::

    GENERATORS = Registry("particle generator", (RandomUniform, BoxLattice))
    GENERATORS.build("random_uniform", RandomUniform.Settings(num_particles=5, seed=1), context)
    GENERATORS.lookup("random")  # ValueError: unknown particle generator 'random'; valid: [...]

The one shape of a plugin (:class:`Plugin`): a ``Settings`` dataclass (its parameters, declared with
:func:`fembase.params.param`) and a classmethod ``build(settings, context)``, where ``context``
holds what the family's implementations are made from (the mesh, the materials, ...);
:meth:`Registry.build` makes the one registered under a name. Families whose entries are ready
objects (Butcher tableaux, mixing rules, linear-solver setups) register those and are asked, not built.
:class:`Configured` is the base of a plugin that keeps its settings and needs nothing else to be made.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any, ClassVar, Generic, Protocol, TypeVar

__all__ = ["Configured", "Plugin", "Registry"]

E = TypeVar("E")
T = TypeVar("T")


class Plugin(Protocol):
    """The one shape of a plugin: a name, a one-line description, its settings and how it is built.

    Attributes:
        name: The lowercase config name.
        description: One line for listings and the config reference.
        Settings: The frozen dataclass of its parameters (fields made by :func:`fembase.params.param`).
    """

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]

    @classmethod
    def build(cls, settings: Any, context: Any, /) -> Any:
        """The implementation for ``settings`` (a ``Settings``) in ``context`` (what the family's
        implementations are made from)."""


class Configured:
    """Base of a :class:`Plugin` that keeps its settings: ``self.settings``, compared and shown by
    them. ``build(settings, context)`` is ``cls(settings)``; a plugin whose settings hold what the
    context turns into something else (a text made a function, a count per cell made a total)
    overrides :meth:`build` and makes the settings it keeps.

    Args:
        settings: Its ``Settings`` (None: the defaults).
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    Settings: ClassVar[type]

    def __init__(self, settings: Any = None, /) -> None:
        self.settings = self.Settings() if settings is None else settings
        if not isinstance(self.settings, self.Settings):
            raise TypeError(f"{type(self).__name__} takes a {type(self).__name__}.Settings, got "
                            f"{type(self.settings).__name__}")

    @classmethod
    def build(cls, settings: Any, context: Any, /) -> Any:
        """The plugin of ``settings``; ``context`` is not needed."""
        return cls(settings)

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.settings == self.settings  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash((type(self), self.settings))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.settings!r})"


class Registry(dict[str, E], Generic[E]):
    """Implementations of one role by their lowercase config name.

    Args:
        role: What the entries are, as error messages say it ("particle generator", "domain", ...).
        entries: Objects with ``name`` and ``description`` attributes, registered in order.

    Raises:
        ValueError: Two entries with the same name, or a name that is not lowercase.
    """

    def __init__(self, role: str, entries: Iterable[E] = (), /) -> None:
        super().__init__()
        self.role = role
        for entry in entries:
            self.register(entry)

    def register(self, entry: E, /) -> E:
        """Add ``entry`` under ``entry.name`` and return it (usable as a class decorator)."""
        name = entry.name  # type: ignore[attr-defined]
        if name != name.lower():
            raise ValueError(f"{self.role} name {name!r} is not lowercase")
        if name in self:
            raise ValueError(f"{self.role} {name!r} is registered twice")
        self[name] = entry
        return entry

    def lookup(self, name: str, /) -> E:
        """The entry registered as ``name``.

        Raises:
            ValueError: Unknown name; the message names the role and lists the valid names.
        """
        try:
            return self[name]
        except KeyError:
            raise ValueError(f"unknown {self.role} {name!r}; valid: {sorted(self)}") from None

    def create(self: Registry[type[T]], name: str, /, **parameters: Any) -> T:
        """The implementation registered as ``name``, built with ``parameters``.

        Raises:
            ValueError: Unknown name (the message lists the valid names), or invalid parameters.
        """
        return self.lookup(name)(**parameters)

    def settings(self, name: str, /, **parameters: Any) -> Any:
        """The ``Settings`` of the :class:`Plugin` registered as ``name``, made of ``parameters``.

        Raises:
            ValueError: Unknown name (the message lists the valid names), a parameter the plugin does
                not have or a required one missing (the message names it), or a value its
                ``Settings`` refuses.
        """
        cls = self.lookup(name).Settings  # type: ignore[attr-defined]
        fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
        unknown = sorted(set(parameters) - set(fields))
        if unknown:
            raise ValueError(f"{self.role} {name!r} has no parameter {unknown[0]!r}; its parameters: {sorted(fields)}")
        missing = [key for key, f in fields.items() if key not in parameters and f.default is dataclasses.MISSING
                   and f.default_factory is dataclasses.MISSING]
        if missing:
            raise ValueError(f"{self.role} {name!r} needs the parameter {missing[0]!r}")
        return cls(**parameters)

    def build(self, name: str, settings: Any, context: Any, /) -> Any:
        """The :class:`Plugin` registered as ``name`` built by its ``build(settings, context)``.

        Raises:
            ValueError: Unknown name (the message lists the valid names).
        """
        return self.lookup(name).build(settings, context)  # type: ignore[attr-defined]

    def describe(self) -> dict[str, str]:
        """One-line description of every registered implementation, by name."""
        return {name: entry.description for name, entry in self.items()}  # type: ignore[attr-defined]

    def __repr__(self) -> str:
        return f"Registry({self.role!r}, {sorted(self)})"
