"""An XDMF time series and the HDF5 data it refers to, checked before VTK reads them.

VTK's XdmfReader meets a damaged file with pages of libxml2, HDF5 and VTK messages and then an
empty data set (or a ``TypeError`` deep in pyvista). :class:`XdmfSeries` parses the series itself
(Python's XML parser) and, for the time steps that are to be read, checks that every HDF5 data
item exists, is readable and holds as many values as the XDMF says; what is wrong is one line
(:class:`RunFilesError`) naming the file.

The series is the layout this project writes (``convection.io.fields``, ``particles.io.output``): a
``Domain`` with one temporal ``Collection`` grid of ``Uniform`` grids, each with a ``Time`` and
``DataItem`` elements ``Format="HDF"`` whose text is ``FILE.h5:/dataset``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    import h5py

__all__ = ["RunFilesError", "XdmfSeries"]


class RunFilesError(OSError):
    """A file of a run folder is missing or damaged (one line naming it)."""


class _Item(NamedTuple):
    """An HDF5 data item of a grid: the file (relative to the XDMF file), the dataset, the value count."""

    file: str
    dataset: str
    size: int | None


class XdmfSeries:
    """The time steps of an XDMF temporal collection (parsed on construction).

    Args:
        path: The ``.xdmf`` file.

    Attributes:
        times: The written times, sorted, shape=(n,), float64.

    Raises:
        RunFilesError: The file is missing, is not XML, or holds no temporal collection.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise RunFilesError(f"{self.path} is missing" if not self.path.exists() else f"{self.path} is not a file")
        try:
            root = ET.parse(self.path).getroot()
        except ET.ParseError as err:
            raise RunFilesError(f"{self.path}: damaged XDMF ({err})") from None
        except OSError as err:
            raise RunFilesError(f"{self.path}: cannot be read ({err.strerror or err})") from None
        collection = root.find("./Domain/Grid[@GridType='Collection']")
        if root.tag != "Xdmf" or collection is None:
            raise RunFilesError(f"{self.path}: damaged XDMF (no time series: Xdmf/Domain/Grid collection)")
        self._grids: list[tuple[float, list[_Item]]] = []
        for grid in collection.findall("Grid"):
            self._grids.append((self._time(grid), self._items(grid)))
        self.times = np.sort(np.array([t for t, _ in self._grids], dtype=np.float64))

    def _time(self, grid: ET.Element) -> float:
        time = grid.find("Time")
        try:
            value = float(time.get("Value", "")) if time is not None else math.nan
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise RunFilesError(f"{self.path}: damaged XDMF (grid {grid.get('Name')!r} has no valid time)")
        return value

    def _items(self, grid: ET.Element) -> list[_Item]:
        items = []
        for item in grid.iter("DataItem"):
            if item.get("Format") != "HDF":
                continue
            file, _, dataset = (item.text or "").strip().partition(":")
            if not file or not dataset:
                raise RunFilesError(f"{self.path}: damaged XDMF (data item {item.text!r} is not FILE.h5:/dataset)")
            try:
                size = math.prod(int(d) for d in item.get("Dimensions", "").split()) if item.get("Dimensions") else None
            except ValueError:
                raise RunFilesError(f"{self.path}: damaged XDMF (dimensions {item.get('Dimensions')!r})") from None
            items.append(_Item(file, dataset, size))
        return items

    def check(self, t: float) -> None:
        """Check the HDF5 data of the grids written at time ``t`` (one of :attr:`times`, to round-off).

        Raises:
            RunFilesError: A file it refers to is missing or damaged, lacks the dataset, or the
                dataset has another number of values than the XDMF says.
        """
        import h5py

        for file, items in self._by_file(t).items():
            h5_path = self.path.parent / file
            if not h5_path.is_file():
                raise RunFilesError(f"{h5_path} is missing ({self.path.name} refers to it)")
            try:
                with h5py.File(h5_path, "r") as h5:
                    for item in items:
                        _check_dataset(h5, h5_path, item)
            except RunFilesError:
                raise
            except (OSError, KeyError, ValueError, TypeError) as err:
                raise RunFilesError(f"{h5_path}: damaged HDF5 file ({' '.join(str(err).split())})") from None

    def _by_file(self, t: float) -> dict[str, list[_Item]]:
        out: dict[str, list[_Item]] = {}
        for time, items in self._grids:
            if abs(time - t) <= 1e-12 * max(1.0, abs(t)):
                for item in items:
                    out.setdefault(item.file, []).append(item)
        return out


def _check_dataset(h5: h5py.File, h5_path: Path, item: _Item) -> None:
    import h5py

    dataset = h5.get(item.dataset)
    if not isinstance(dataset, h5py.Dataset):
        raise RunFilesError(f"{h5_path}: no dataset {item.dataset} (damaged, or not the file the XDMF refers to)")
    if item.size is not None and dataset.size != item.size:
        raise RunFilesError(f"{h5_path}: dataset {item.dataset} has {dataset.size} values, the XDMF says {item.size}")
