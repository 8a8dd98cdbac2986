"""Partition methods: owner ranks for items with cell and particle loads (seed paper section 2.4).

A partition method maps per-item data (a position, the mesh cells and the particles the item
carries) to an owner rank per item, balancing the load ``cells + W particles``. Registry
:data:`PARTITIONERS`:

- ``morton``: items sorted along a Morton (Z-order) curve of their positions, cut into contiguous
  blocks of equal load (:func:`block_owners`) — the space-filling-curve partition of p4est-based
  codes such as ASPECT;
- ``rcb``: recursive coordinate bisection; every cut (axis and position) minimises the worst
  imbalance of the cells, the particles and the load 1 + W n_particles on its two sides (a
  multi-constraint geometric partition: for an interface refined along one axis it cuts across the
  interface, so every rank gets its share of fine cells and of coarse, particle-rich cells).

Pure NumPy, serial: :mod:`particles.balance` calls them on one rank and distributes the mesh.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

__all__ = ["PARTITIONERS", "PartitionMethod", "block_owners", "morton_order", "morton_owners", "partition",
           "rcb_owners"]


def block_owners(weights: npt.NDArray[np.float64], nparts: int, /) -> npt.NDArray[np.int32]:
    """Owner of each item when the sequence is cut into ``nparts`` blocks of equal weight.

    Args:
        weights: Positive weights in curve order, shape=(n,).
        nparts: Number of blocks.

    Returns:
        Block index per item, shape=(n,), int32, non-decreasing.
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.size == 0:
        return np.zeros(0, dtype=np.int32)
    if np.any(w <= 0.0):
        raise ValueError("partition weights must be positive")
    centre = (np.cumsum(w) - 0.5 * w) / w.sum()  # each item goes where its weight's midpoint falls
    return np.minimum((centre * nparts).astype(np.int32), nparts - 1)


def morton_order(points: npt.NDArray[np.float64], /, *, bits: int = 16) -> npt.NDArray[np.int64]:
    """Indices sorting ``points`` (shape=(n, d)) along a Morton (Z-order) curve."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    q = ((p - lo) / np.where(hi > lo, hi - lo, 1.0) * (2**bits - 1)).astype(np.int64)
    key = np.zeros(p.shape[0], dtype=np.int64)
    for bit in range(bits):
        for axis in range(p.shape[1]):
            key |= ((q[:, axis] >> bit) & 1) << (bit * p.shape[1] + axis)
    return np.argsort(key, kind="stable")


class PartitionMethod(Protocol):
    """What every partition method takes; a method may take more keywords (``rcb_owners``: ``balance``, ``axes``),
    which :func:`partition` passes on as its ``options``."""

    def __call__(self, points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
                 particles: npt.NDArray[np.float64], nparts: int, /, *,
                 particle_weight: float) -> npt.NDArray[np.int32]: ...


def morton_owners(points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
                  particles: npt.NDArray[np.float64], nparts: int, /, *, particle_weight: float
                  ) -> npt.NDArray[np.int32]:
    """Contiguous blocks of equal load ``cells + W particles`` along a Morton curve.

    Args:
        points: Where each item is (e.g. a base cell's midpoint), shape=(n, d).
        cells: Mesh cells each item carries (>= 1), shape=(n,).
        particles: Particles each item carries, shape=(n,).
        nparts: Number of parts.
        particle_weight: W.

    Returns:
        Owner per item, shape=(n,), int32.
    """
    order = morton_order(points)
    owners = np.empty(points.shape[0], dtype=np.int32)
    owners[order] = block_owners((cells + particle_weight * particles)[order], nparts)
    return owners


_QUANTITIES = ("cells", "particles", "load")


def rcb_owners(points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
               particles: npt.NDArray[np.float64], nparts: int, /, *, particle_weight: float,
               balance: Sequence[str] = _QUANTITIES, axes: Sequence[int] | None = None) -> npt.NDArray[np.int32]:
    """Recursive coordinate bisection balancing cells, particles and the load ``cells + W particles``.

    Each part is split into ``k // 2`` and ``k - k // 2`` parts; of all cut positions along all axes
    the one with the smallest worst ratio (share / target share) of the ``balance`` quantities is
    taken (first axis on ties). Arguments and result as :func:`morton_owners`, and:

    Args:
        balance: Which of ``"cells"``, ``"particles"``, ``"load"`` every cut balances (default all
            three; ``("load",)`` when only the total work matters, e.g. particles far costlier
            than cells).
        axes: The coordinate axes cuts may be perpendicular to (default all), e.g. to keep cuts
            parallel to a dominant flow so that few particles cross them.
    """
    load = cells + particle_weight * particles
    if np.any(load <= 0.0):
        raise ValueError("partition loads must be positive")
    unknown = set(balance) - set(_QUANTITIES)
    if unknown or not balance:
        raise ValueError(f"balance must name some of {_QUANTITIES}, got {tuple(balance)}")
    quantities = [q for name, q in zip(_QUANTITIES, (cells, particles, load)) if name in balance]
    axes = tuple(range(points.shape[1])) if axes is None else tuple(int(a) for a in axes)
    if not axes or any(a < 0 or a >= points.shape[1] for a in axes):
        raise ValueError(f"axes must be a non-empty subset of 0..{points.shape[1] - 1}, got {axes}")
    owners = np.zeros(points.shape[0], dtype=np.int32)
    stack = [(np.arange(points.shape[0]), nparts, 0)]
    while stack:
        items, k, first = stack.pop()
        if k == 1 or items.size == 0:
            owners[items] = first
            continue
        k_left = k // 2
        fraction = k_left / k
        best: tuple[float, np.ndarray, np.ndarray] | None = None
        for axis in axes:
            order = items[np.argsort(points[items, axis], kind="stable")]
            # Worst ratio (share / target share) of the balanced quantities for every cut position.
            score = np.zeros(order.size + 1)
            for quantity in quantities:
                q = quantity[order]
                total = q.sum()
                if total <= 0:
                    continue
                left = np.concatenate(([0.0], np.cumsum(q))) / total
                score = np.maximum(score, np.maximum(left / fraction, (1.0 - left) / (1.0 - fraction)))
            cut = int(np.argmin(score[1:-1])) + 1 if order.size > 1 else order.size
            if best is None or score[cut] < best[0] - 1e-12:
                best = (float(score[cut]), order[:cut], order[cut:])
        assert best is not None
        stack.append((best[1], k_left, first))
        stack.append((best[2], k - k_left, first + k_left))
    return owners


PARTITIONERS: dict[str, PartitionMethod] = {"morton": morton_owners, "rcb": rcb_owners}
"""Partition methods by config name (``balance.method``)."""


def partition(method: str, points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
              particles: npt.NDArray[np.float64], nparts: int, /, *, particle_weight: float,
              **options: Any) -> npt.NDArray[np.int32]:
    """Owner per item by the named method (see :data:`PARTITIONERS`); ``options`` go to the method
    (e.g. ``balance``, ``axes`` of :func:`rcb_owners`)."""
    if method not in PARTITIONERS:
        raise ValueError(f"unknown partition method {method!r}; valid names: {sorted(PARTITIONERS)}")
    return PARTITIONERS[method](points, cells, particles, nparts, particle_weight=particle_weight, **options)
