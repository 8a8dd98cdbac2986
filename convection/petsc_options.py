"""Per-object PETSc options that leave the global options database when the object goes away.

Each solver uses its own options prefix so several solvers can coexist with different settings.
PETSc's options database is global and limited (512 entries by default): a run that rebuilds its
solvers after every mesh adaptation would exhaust it, so the entries are removed again when the
solver that set them is garbage collected. :func:`destroy_petsc_objects` frees solvers
explicitly, at the same point on every rank.
"""

from __future__ import annotations

import weakref
from typing import Any, Mapping, Sequence

from petsc4py import PETSc

__all__ = ["set_owned_options"]


def _clear(prefix: str, keys: list[str]) -> None:
    opts = PETSc.Options()
    for key in keys:
        opts.delValue(prefix + key)


def set_owned_options(owner: object, prefix: str, options: Mapping[str, Any], /) -> None:
    """Set ``prefix + key = value`` for every option; remove them when ``owner`` is collected."""
    opts = PETSc.Options()
    for key, value in options.items():
        opts[prefix + key] = value
    weakref.finalize(owner, _clear, prefix, list(options))


def destroy_petsc_objects(owner: object, names: Sequence[str], /) -> None:
    """Destroy the PETSc objects held in ``owner``'s attributes ``names`` and set them to None.

    Collective: call on every rank at the same point. Destroying some parallel objects
    communicates (a MUMPS factorisation, for one); left to Python's garbage collector, which runs
    at different times on different ranks, that can deadlock a run that replaces its solvers
    (adaptivity, load balancing).
    """
    for name in names:
        obj = getattr(owner, name, None)
        if obj is not None:
            obj.destroy()
            setattr(owner, name, None)
