"""Field and particle series (Temporal XDMF) read with VTK's XdmfReader, as ParaView reads them,
and what a picture takes from the data sets: the material field, values, colour ranges."""

from __future__ import annotations

import ctypes
import os
import sys
import warnings
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING
from collections.abc import Sequence

import numpy as np

from convection.io.pictures.run_files import MATERIAL_FIELDS, NON_MATERIAL_FIELDS
from convection.io.xdmf_check import RunFilesError, XdmfSeries

if TYPE_CHECKING:
    import pyvista as pv

__all__ = ["Series", "clim", "field_values", "import_pyvista", "is_constant", "material_field", "positive",
           "read_particles", "scalar_names", "snapshot_times"]


# std::__detail::_Scanner<char>::_M_scan_normal(), one of the std::regex internals that a C++ library
# instantiates and exports: the symbol that shows whose copy of std::regex the global scope holds.
_REGEX_SYMBOL = "_ZNSt8__detail8_ScannerIcE14_M_scan_normalEv"
_loaded_here: list[bool] = []  # [True] once import_pyvista has loaded VTK


def import_pyvista() -> ModuleType:
    """pyvista, with VTK's libraries loaded so that they render also in a process that uses DOLFINx.

    ``import dolfinx`` (Debian 12's DOLFINx 0.5) sets the dlopen flags to ``RTLD_NOW | RTLD_GLOBAL``
    and leaves them so, which puts libdolfinx's C++ template instantiations (``std::regex``
    internals built with the new ``std::string`` ABI) in the global symbol scope. VTK's wheels are
    built with the old ``std::string`` ABI; a VTK library loaded after DOLFINx resolves its own
    ``std::__detail::_Scanner<char>`` calls to libdolfinx's copies, which write a 32-byte string
    where VTK's ``std::regex`` compiler reads an 8-byte one: the first scalar bar
    (``vtkScalarBarActor::LayoutTicks`` -> ``vtk::is_printf_format``) throws ``std::bad_alloc``
    from ``std::string::_S_create``, uncaught, and the process aborts (SIGABRT). Restoring the dlopen
    flags does not help (libdolfinx stays global); loaded with ``RTLD_DEEPBIND``, each VTK library
    finds its own symbols first. All VTK modules are loaded at once, so no module that pyvista
    loads later on demand binds the wrong way.

    So use this instead of ``import pyvista`` wherever DOLFINx may have been imported first: a plain
    ``import pyvista`` after ``import dolfinx`` is the state that aborted the serial test process
    at a picture test (2026-12-07: two tests read fields with ``pytest.importorskip("pyvista")``).
    VTK loaded that way cannot be loaded again; it is refused with a RuntimeError here, before
    it aborts the process. VTK loaded before DOLFINx binds to itself and is used as it is.

    Raises:
        RuntimeError: VTK was loaded without this function after a library that put its
            ``std::regex`` internals in the global symbol scope (e.g. ``import dolfinx``).
    """
    if "vtkmodules.vtkCommonCore" in sys.modules and not _loaded_here:
        _refuse_vtk_bound_elsewhere()
    if "pyvista" in sys.modules and _loaded_here:
        return sys.modules["pyvista"]
    flags = sys.getdlopenflags()
    sys.setdlopenflags(os.RTLD_NOW | os.RTLD_DEEPBIND)
    try:
        import vtkmodules.all  # noqa: F401 - loads every VTK library under these flags

        import pyvista
        import pyvista.plotting  # noqa: F401
    finally:
        sys.setdlopenflags(flags)
    _loaded_here[:] = [True]
    return pyvista


def _refuse_vtk_bound_elsewhere() -> None:
    """Raise if VTK's core library was loaded after the library whose ``std::regex`` internals the
    global symbol scope holds (see :func:`import_pyvista`): the order of the dynamic linker's list
    of loaded objects, which is the load order."""
    if not sys.platform.startswith("linux"):
        return
    scope = ctypes.CDLL(None)  # dlopen(NULL): the global symbol scope
    try:
        address = ctypes.cast(getattr(scope, _REGEX_SYMBOL), ctypes.c_void_p).value
    except AttributeError:
        return  # no global std::regex internals: VTK bound to its own

    class DlInfo(ctypes.Structure):
        _fields_ = [("fname", ctypes.c_char_p), ("fbase", ctypes.c_void_p), ("sname", ctypes.c_char_p),
                    ("saddr", ctypes.c_void_p)]

    class PhdrInfo(ctypes.Structure):  # the leading fields of struct dl_phdr_info
        _fields_ = [("addr", ctypes.c_void_p), ("name", ctypes.c_char_p)]

    info = DlInfo()
    scope.dladdr(ctypes.c_void_p(address), ctypes.byref(info))
    owner = os.path.realpath(info.fname.decode()) if info.fname else ""
    loaded: list[str] = []

    @ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(PhdrInfo), ctypes.c_size_t, ctypes.c_void_p)
    def collect(phdr, size, data):
        loaded.append(os.path.realpath(phdr.contents.name.decode()) if phdr.contents.name else "")
        return 0

    scope.dl_iterate_phdr(collect, None)
    vtk = [i for i, name in enumerate(loaded) if os.path.basename(name).startswith("libvtkCommonCore")]
    if owner and owner in loaded and "vtkmodules" not in owner and vtk and loaded.index(owner) < vtk[0]:
        raise RuntimeError(f"VTK was loaded (a plain `import pyvista` or `import vtk`) after {owner} had put its "
                           "std::regex internals in the global symbol scope (`import dolfinx` does): its scalar "
                           "bars would abort the process; import pyvista with "
                           "convection.io.pictures.import_pyvista() instead")


class Series:
    """A Temporal XDMF collection read with VTK's XdmfReader, as ParaView reads it.

    Args:
        path: The ``.xdmf`` file.
    """

    def __init__(self, path: Path) -> None:
        self.series = XdmfSeries(path)  # checks the XML before VTK's parser sees it
        pv = import_pyvista()
        self.path = path
        self.reader = pv.get_reader(str(path))
        self.times = np.sort(np.asarray(self.reader.time_values, dtype=np.float64))

    def nearest(self, t: float) -> float:
        """The written time nearest to ``t``."""
        return float(self.times[np.argmin(np.abs(self.times - t))]) if self.times.size else float(t)

    def read(self, t: float) -> tuple[pv.DataSet, list[str]]:
        """The data set at written time ``t``, and the names of arrays VTK read with a wrong length.

        Arrays whose length matches neither the points nor the cells are dropped (VTK's reader
        reads e.g. an XDMF ``Matrix`` attribute as a single tuple).

        Raises:
            RunFilesError: An HDF5 file of that time is missing or damaged, or VTK read nothing.
        """
        pv = import_pyvista()
        self.series.check(t)
        if self.times.size:
            self.reader.set_active_time_value(t)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pyvista's InvalidMeshWarning: handled below
            data = self.reader.read()
            if isinstance(data, pv.MultiBlock):
                data = data.combine()
        if data.n_points == 0:
            raise RunFilesError(f"{self.path}: nothing could be read at t = {t:.6g} (damaged?)")
        dropped = []
        for arrays, size in ((data.point_data, data.n_points), (data.cell_data, data.n_cells)):
            for name in list(arrays.keys()):
                if arrays[name].shape[0] != size:
                    arrays.remove(name)
                    dropped.append(name)
        return data, dropped


def snapshot_times(available: Sequence[float], requested: Sequence[float] | None = None) -> list[float]:
    """The written times to draw: for each requested time the nearest available one.

    Args:
        available: Written times, shape=(n,).
        requested: Wanted times; default the first, middle and last available time.

    Returns:
        Sorted distinct times, each one of ``available``.
    """
    times = np.sort(np.asarray(available, dtype=np.float64))
    if times.size == 0:
        return []
    if requested is None:
        requested = [times[0], times[times.size // 2], times[-1]]
    return sorted({float(times[np.argmin(np.abs(times - t))]) for t in requested})


def scalar_names(data: pv.DataSet) -> list[str]:
    """Scalar (one-component) point and cell arrays of ``data``, in file order."""
    names = []
    for arrays in (data.cell_data, data.point_data):
        names += [n for n in arrays.keys() if arrays[n].ndim == 1 or arrays[n].shape[1] == 1]
    return names


def material_field(data: pv.DataSet, field: str | None) -> str | None:
    """The field of the composition picture (see the module docstring); None if there is none."""
    names = list(data.cell_data.keys()) + list(data.point_data.keys())
    if field is not None:
        if field not in names:
            raise ValueError(f"no field '{field}' in fields.xdmf; fields: {', '.join(names)}")
        return field
    scalars = scalar_names(data)
    for name in (*MATERIAL_FIELDS, *(n for n in scalars if n not in NON_MATERIAL_FIELDS)):
        if name in scalars:
            return name
    return None


def field_values(data: pv.DataSet, name: str) -> np.ndarray:
    values = data.cell_data[name] if name in data.cell_data.keys() else data.point_data[name]
    return np.linalg.norm(values, axis=1) if values.ndim > 1 and values.shape[1] > 1 else values.reshape(-1)


def clim(values: np.ndarray) -> tuple[float, float]:
    """Colour range of ``values``; an end within round-off of zero becomes zero (no "-5.55e-17")."""
    lo, hi = float(np.min(values)), float(np.max(values))
    if hi <= lo:
        return lo - 0.5, hi + 0.5
    lo, hi = (0.0 if abs(v) <= 1e-9 * (hi - lo) else v for v in (lo, hi))
    return lo, hi


def is_constant(values: np.ndarray) -> bool:
    lo, hi = float(np.min(values)), float(np.max(values))
    return hi - lo <= 1e-12 * max(1.0, abs(lo), abs(hi))


def positive(values: np.ndarray) -> np.ndarray:
    """The values, with non-positive or non-finite ones raised to the smallest positive one (a
    logarithmic colour scale)."""
    good = np.isfinite(values) & (values > 0.0)
    floor = float(values[good].min()) if good.any() else 1.0
    return np.where(good, values, floor)


def read_particles(particles: Series, t: float, particle_property: str | None) -> tuple[pv.DataSet, float]:
    """The particles written nearest to ``t`` and their time; ``particle_property`` must exist.

    Raises:
        ValueError: No such particle property (the message lists those there are).
    """
    tp = particles.nearest(t)
    cloud, dropped = particles.read(tp)
    if particle_property is not None and particle_property not in cloud.point_data.keys():
        known = [n for n in cloud.point_data.keys()]
        unread = f" (VTK could not read: {', '.join(dropped)})" if dropped else ""
        raise ValueError(f"no particle property '{particle_property}' in {particles.path.name}; "
                         f"properties: {', '.join(known)}{unread}")
    return cloud, tp
