"""One registry per plugin role, mapping lowercase config names to implementations (the particle
roles of :mod:`particles` and the roles of :mod:`convection`: domains, viscosity laws,
postprocessors, writers, ...).

Every entry carries ``name`` and ``description`` attributes: an implementation class (a frozen
dataclass of its parameters, with class attributes) or a ready object such as a Butcher tableau.
A :class:`Registry` is a ``dict[name, entry]`` that also knows its role, so ``name in REGISTRY``,
``sorted(REGISTRY)`` and ``REGISTRY[name]`` work as on a plain dict, and an unknown name is an
error naming the role and listing the valid names::

    GENERATORS = Registry("particle generator", (RandomUniform, BoxLattice))
    GENERATORS.create("random_uniform", num_particles=5, seed=1)  # == RandomUniform(5, seed=1)
    GENERATORS.create("random")  # ValueError: unknown particle generator 'random'; valid: [...]

The one shape of a plugin (:class:`Plugin`): a ``Settings`` dataclass (its parameters, declared with
:func:`fembase.params.param`) and a classmethod ``build(settings, context)``, where ``context``
holds what the family's implementations are made from (the mesh, the materials, ...);
:meth:`Registry.build` makes the one registered under a name. Families whose entries are ready
objects (Butcher tableaux, mixing rules, linear-solver setups) register those and are asked, not built.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, ClassVar, Generic, Protocol, TypeVar

__all__ = ["Plugin", "Registry"]

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
