"""Remember DOLFINx's just-in-time compiled forms and elements within the process.

Every ``FunctionSpace`` and every ``dolfinx.fem.form`` asks ``dolfinx.jit.ffcx_jit`` for its
compiled code. DOLFINx 0.5 finds it in FFCx's disk cache each time: it imports the module from a
directory that holds every form ever compiled (thousands of files after a few runs) and, on more
than one rank, lets rank 0 look first while the others wait (``mpi_jit_decorator``), then the
others. An adaptive run rebuilds its spaces and forms after every adaptation, so this fixed cost
recurs and does not shrink with more ranks (measured: van Keken 1a to t = 300, 644 look-ups,
0.59 s of an 8.9 s serial run).

:func:`install` wraps ``dolfinx.jit.ffcx_jit`` with a dictionary keyed by what FFCx's own cache
keys on (the form's signature, the element's representation, the compiler options), so a form or
element compiled once in the process is handed out again without touching the disk. The compiled
objects are immutable C structures; FFCx's disk cache hands out the same library for the same key.
An entry counts only for the processes that compiled it together: the key holds the ranks (in
``MPI.COMM_WORLD``) of the communicator it was compiled on. Creation is collective over that
communicator, so its ranks hit or miss together and DOLFINx's collective runs on every miss; a
form made by rank 0 alone (``MPI.COMM_SELF``) is not a hit for the same form made by all ranks
later, which would leave rank 0 out of the others' collective (found as a hang in the tests).
"""

from __future__ import annotations

from typing import Any

import dolfinx.jit
import ufl
from mpi4py import MPI

_ORIGINAL = dolfinx.jit.ffcx_jit
_CACHE: dict[tuple[Any, ...], Any] = {}


def _members(comm: MPI.Comm) -> tuple[int, ...]:
    """The ``MPI.COMM_WORLD`` ranks of the processes in ``comm`` (local: no communication)."""
    if comm.size == MPI.COMM_WORLD.size:
        return ("world",)  # every process (the usual case; no group translation needed)
    return tuple(MPI.Group.Translate_ranks(comm.group, list(range(comm.size)), MPI.COMM_WORLD.group))


def _key(comm: MPI.Comm, ufl_object: Any, options: dict[str, Any]) -> tuple[Any, ...] | None:
    if isinstance(ufl_object, ufl.Form):
        return ("form", _members(comm), ufl_object.signature(), repr(sorted(options.items())))
    if isinstance(ufl_object, ufl.FiniteElementBase):
        return ("element", _members(comm), repr(ufl_object), repr(sorted(options.items())))
    return None  # expressions: compiled rarely, passed through


def _cached_ffcx_jit(comm: Any, ufl_object: Any, form_compiler_params: dict | None = None,
                     jit_params: dict | None = None) -> Any:
    options = {"form_compiler_params": repr(sorted((form_compiler_params or {}).items())),
               "jit_params": repr(sorted((jit_params or {}).items()))}
    key = _key(comm, ufl_object, options)
    if key is not None and key in _CACHE:
        return _CACHE[key]
    result = _ORIGINAL(comm, ufl_object, form_compiler_params=form_compiler_params, jit_params=jit_params)
    if key is not None:
        _CACHE[key] = result
    return result


def install() -> None:
    """Route ``dolfinx.jit.ffcx_jit`` through the in-process cache (idempotent)."""
    dolfinx.jit.ffcx_jit = _cached_ffcx_jit


def cached() -> int:
    """How many compiled forms and elements the process holds."""
    return len(_CACHE)
