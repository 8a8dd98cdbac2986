"""The one XDMF time-series writer: a Temporal collection of Uniform grids in one ``.xdmf`` file.

Both the field output (:mod:`convection.io.fields`: each time on the mesh of its time) and the
particle output (:mod:`particles.io.output`: each step a Polyvertex grid) keep their series with an
:class:`XdmfSeries`: grids by a key (the time or the step), read back from an existing file when a
run continues, and the file rewritten atomically by rank 0 after every output
(:func:`fembase.files.atomic_write_text`), so ParaView (or ``pyvista.get_reader``) opens the whole
run, also while it goes on.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from collections.abc import Callable
from typing import Any

import h5py
import numpy as np

from fembase.files import atomic_write_text

__all__ = ["XdmfSeries", "data_item", "declare_types", "grid_time"]


class XdmfSeries:
    """A time series of grids written to ``path`` (rank 0 only; not collective).

    Args:
        path: The series file (``.xdmf``).
        name: The collection's name.
    """

    def __init__(self, path: str | Path, name: str, /) -> None:
        self.path = Path(path)
        self.name = name
        self.grids: list[tuple[Any, ET.Element]] = []

    def load(self, key: Callable[[ET.Element], Any | None], /, *, strict: bool = True) -> None:
        """Add the Uniform grids of an existing series file (a continued run), each under
        ``key(grid)``; grids whose key is None are left out. A missing file adds nothing; a damaged
        one raises ``xml.etree.ElementTree.ParseError`` (``strict``) or adds nothing."""
        if not self.path.exists():
            return
        try:
            root = ET.parse(self.path).getroot()
        except ET.ParseError:
            if strict:
                raise
            return
        for grid in root.iter("Grid"):
            if grid.get("GridType") == "Uniform":
                value = key(grid)
                if value is not None:
                    self.grids.append((value, grid))

    def keep(self, predicate: Callable[[Any], bool], /) -> None:
        """Keep only the grids whose key ``predicate`` accepts."""
        self.grids = [(k, g) for k, g in self.grids if predicate(k)]

    def append(self, key: Any, grid: ET.Element, /) -> None:
        """Add ``grid`` at the end of the series under ``key``."""
        self.grids.append((key, grid))

    def text(self) -> str:
        """The series file's text."""
        root = ET.Element("Xdmf", Version="3.0")
        domain = ET.SubElement(root, "Domain")
        series = ET.SubElement(domain, "Grid", Name=self.name, GridType="Collection", CollectionType="Temporal")
        series.extend(g for _, g in self.grids)
        ET.indent(root)
        return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"

    def write(self) -> None:
        """Write the series file atomically."""
        atomic_write_text(self.path, self.text())


def grid_time(grid: ET.Element, /) -> float | None:
    """The time of a Uniform grid (its ``Time`` value), or None."""
    time = grid.find("Time")
    return None if time is None else float(time.attrib["Value"])


def data_item(h5name: str, dataset: str, shape: tuple[int, ...], dtype: np.dtype, /) -> ET.Element:
    """An HDF ``DataItem`` naming ``h5name:/dataset`` with its shape and number type."""
    kind = "Float" if dtype.kind == "f" else ("UInt" if dtype.kind == "u" else "Int")
    item = ET.Element("DataItem", Dimensions=" ".join(str(d) for d in shape), NumberType=kind,
                      Precision=str(dtype.itemsize), Format="HDF")
    item.text = f"{h5name}:/{dataset}"
    return item


def declare_types(grid: ET.Element, directory: Path, /) -> None:
    """Give every HDF DataItem of ``grid`` the NumberType and Precision of its dataset.

    DOLFINx leaves them out, and XDMF readers then assume 4-byte floats (VTK converts the
    doubles to float32 on reading); the datasets' own types keep the values exact.
    """
    items = [item for item in grid.iter("DataItem") if item.get("Format") == "HDF" and item.text]
    files: dict[str, list[tuple[ET.Element, str]]] = {}
    for item in items:
        h5name, _, dataset = (item.text or "").strip().partition(":")
        files.setdefault(h5name, []).append((item, dataset))
    for h5name, entries in files.items():
        with h5py.File(directory / h5name, "r") as h5:
            for item, dataset in entries:
                dtype = h5[dataset].dtype
                kind = {"f": "Float", "i": "Int", "u": "UInt"}.get(dtype.kind)
                if kind is not None:
                    item.set("NumberType", kind)
                    item.set("Precision", str(dtype.itemsize))
