"""Names a package re-exports from its modules, imported when first used (PEP 562).

Packages whose modules are heavy (DOLFINx, PETSc, MPI) but whose light parts must stay light — the
MPI launcher (:mod:`convection.launch`), the pictures (:mod:`convection.io.pictures`), the
config reference — re-export their public names through :func:`lazy_exports` instead of importing
every module in ``__init__``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def lazy_exports(package: str, exports: dict[str, str], /) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package`` that import ``exports`` (public name ->
    module name inside the package) on first use."""

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{module}"), name)

    def __dir__() -> list[str]:
        return sorted(exports)

    return __getattr__, __dir__
