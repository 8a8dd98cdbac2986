"""Let the C heap hand freed memory back to the system again after PETSc is loaded.

Debian's PETSc links SuperLU_DIST, whose library constructor runs, when PETSc is loaded, glibc's
``mallopt(M_MMAP_MAX, 0)`` and ``mallopt(M_TRIM_THRESHOLD, -1)``: from then on no allocation is
mapped on its own and the heap is never trimmed, so every byte a process has freed stays resident
(seen in ``objdump -d libsuperlu_dist.so.8``: the calls sit in its ``.init_array``). In a run that
is the temporaries of the set-up (DOLFINx's sparsity patterns, numpy copies of CSR arrays,
PETSc's products) and their fragments: on the 3D thick layer at 16^3 on 2 ranks (issue 50),
82 MB per rank of free heap after the model's set-up and 92 MB after the first Stokes solve, all
of it counted in the resident size (benchmarks/performance/log/2026-12-07_memory_reduction.md).

:func:`return_freed_memory` puts glibc's own settings back (blocks of 128 kB and more mapped on
their own, unmapped when freed; the heap's top trimmed beyond 128 kB of free space) and trims
once. It changes where the bytes live, not what is computed: the numbers of a run stay the same
to the bit. Elsewhere than glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["return_freed_memory"]

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_MMAP_MAX = -1, -3, -4
"""glibc's ``mallopt`` parameters (malloc.h)."""
_THRESHOLD = 128 * 1024
"""glibc's default mapping and trimming threshold [bytes]."""
_MMAP_MAX = 65536
"""glibc's default for the most blocks mapped at once."""


def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
    except OSError:
        return None
    return libc if libc is not None and hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None


def return_freed_memory() -> bool:
    """glibc's mapping and trimming thresholds back (see the module docstring), then one
    ``malloc_trim``. Idempotent, not collective; call after PETSc is loaded. Returns whether the
    C library took the settings (False elsewhere than glibc)."""
    libc = _libc()
    if libc is None:
        return False
    done = all(libc.mallopt(parameter, value) == 1 for parameter, value in (
        (_M_MMAP_MAX, _MMAP_MAX), (_M_MMAP_THRESHOLD, _THRESHOLD), (_M_TRIM_THRESHOLD, _THRESHOLD)))
    libc.malloc_trim(0)
    return done
