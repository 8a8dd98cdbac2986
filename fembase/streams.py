"""Counter-based random numbers keyed by cell geometry (rank-independent streams).

A stream is a 64-bit key (seed, generator-specific stream number and a hash of the cell's sorted
node coordinates); the i-th number of a stream is ``splitmix64`` of the key mixed with ``i``. The
same cell therefore draws the same numbers on any number of ranks and in any local order.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["cell_streams", "mix", "uniforms"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _splitmix64(z: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    with np.errstate(over="ignore"):
        z = z + _GOLDEN
        z = (z ^ (z >> np.uint64(30))) * _M1
        z = (z ^ (z >> np.uint64(27))) * _M2
        return z ^ (z >> np.uint64(31))


def mix(h: npt.ArrayLike, v: npt.ArrayLike) -> npt.NDArray[np.uint64]:
    """Hash of the pair ``(h, v)`` (broadcasting), uint64."""
    h = np.asarray(h).astype(np.uint64, copy=False)
    v = np.asarray(v).astype(np.uint64, copy=False)
    return _splitmix64(h ^ _splitmix64(v))


def cell_streams(keys: npt.NDArray[np.float64], seed: int, stream: int) -> npt.NDArray[np.uint64]:
    """One stream key per cell from its geometric key (rows of float64), shape=(m,), uint64."""
    bits = np.ascontiguousarray(keys, dtype=np.float64).view(np.uint64)
    h = np.full(bits.shape[0], np.uint64(seed & 0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
    h = mix(h, np.uint64(stream))
    for column in bits.T:
        h = mix(h, column)
    return h


def uniforms(streams: npt.NDArray[np.uint64], counters: npt.ArrayLike, size: int) -> npt.NDArray[np.float64]:
    """Uniform numbers in [0, 1): row i uses stream ``streams[i]`` at ``counters[i]``.

    Returns:
        shape=(m, size), float64, with 53 random bits each.
    """
    h = mix(streams, np.asarray(counters, dtype=np.int64).astype(np.uint64))
    out = np.empty((h.shape[0], size))
    for j in range(size):
        out[:, j] = (mix(h, np.uint64(j)) >> np.uint64(11)).astype(np.float64) * 2.0**-53
    return out
