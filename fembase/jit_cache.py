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
The ranks decide together whether to use their entries (one allreduce, as DOLFINx's own path
has): UFL's signature of the same form can differ between ranks (operands are ordered by object
counters, which differ where a rank made objects alone, e.g. a serial reference on rank 0), so a
rank-local hit could leave one rank out of the others' collective compile (found as a hang in the
tests). On a hit everywhere the compiled objects are handed out; otherwise every rank takes
DOLFINx's path and remembers the result.
"""

from __future__ import annotations

from typing import Any

import dolfinx.jit
import numpy as np
import ufl
from mpi4py import MPI

_ORIGINAL = dolfinx.jit.ffcx_jit
_CACHE: dict[tuple[Any, ...], Any] = {}


_ELEMENT_TYPES = tuple(t for t in (getattr(ufl, "FiniteElementBase", None), getattr(ufl, "AbstractFiniteElement", None))
                       if t is not None)


def _key(ufl_object: Any, options: str) -> tuple[Any, ...] | None:
    if isinstance(ufl_object, ufl.Form):
        return ("form", ufl_object.signature(), options)
    if _ELEMENT_TYPES and isinstance(ufl_object, _ELEMENT_TYPES):
        return ("element", repr(ufl_object), options)
    return None  # expressions: compiled rarely, passed through


def _cached_ffcx_jit(comm: Any, ufl_object: Any, *args: Any, **kwargs: Any) -> Any:
    """``dolfinx.jit.ffcx_jit`` with the in-process cache; the compiler options (their names differ
    between DOLFINx versions) are part of the key, as in FFCx's own cache."""
    options = repr([repr(sorted(a.items())) if isinstance(a, dict) else repr(a) for a in args]
                   + sorted((k, repr(sorted(v.items())) if isinstance(v, dict) else repr(v))
                            for k, v in kwargs.items()))
    key = _key(ufl_object, options)
    if key is not None:
        hit = key in _CACHE
        if comm.size > 1:
            everywhere = np.zeros(1, dtype=np.int32)
            comm.Allreduce(np.array([hit], dtype=np.int32), everywhere, op=MPI.MIN)
            hit = bool(everywhere[0])
        if hit:
            return _CACHE[key]
    result = _ORIGINAL(comm, ufl_object, *args, **kwargs)
    if key is not None:
        _CACHE[key] = result
    return result


def install() -> None:
    """Route ``dolfinx.jit.ffcx_jit`` through the in-process cache (idempotent)."""
    dolfinx.jit.ffcx_jit = _cached_ffcx_jit


def cached() -> int:
    """How many compiled forms and elements the process holds."""
    return len(_CACHE)
