"""Field output to XDMF (ParaView) on meshes that change with adaptivity.

XDMF ties a time series to one mesh, so each mesh gets its own file: ``fields_000.xdmf`` for the
first mesh, ``fields_001.xdmf`` after the first adaptation that changed the mesh, and so on (open
them together in ParaView). Higher-degree fields are interpolated to P1 at the vertices; DG0 fields
are written as cell data.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import dolfinx.fem
import dolfinx.io
import dolfinx.mesh

__all__ = ["FieldOutput"]


class FieldOutput:
    """Writes named Functions every call, starting a new file when the mesh changes (collective).

    Args:
        directory: Output folder.
        prefix: File name prefix.
    """

    def __init__(self, directory: str | Path, /, *, prefix: str = "fields") -> None:
        self.directory = Path(directory)
        self.prefix = prefix
        self.epoch = -1
        self._mesh: dolfinx.mesh.Mesh | None = None
        self._file: dolfinx.io.XDMFFile | None = None
        self._out: dict[str, dolfinx.fem.Function] = {}
        self.files: list[Path] = []

    def _open(self, mesh: dolfinx.mesh.Mesh) -> None:
        self.close()
        self.epoch += 1
        path = self.directory / f"{self.prefix}_{self.epoch:03d}.xdmf"
        self._file = dolfinx.io.XDMFFile(mesh.comm, str(path), "w")
        self._file.write_mesh(mesh)
        self._mesh = mesh
        self._out = {}
        self.files.append(path)

    def _output_function(self, name: str, f: dolfinx.fem.Function) -> dolfinx.fem.Function:
        out = self._out.get(name)
        if out is None:
            element = f.function_space.ufl_element()
            mesh = f.function_space.mesh
            if element.family() in ("Discontinuous Lagrange", "DG") and element.degree() == 0:
                space = dolfinx.fem.FunctionSpace(mesh, ("DG", 0)) if not f.ufl_shape else \
                    dolfinx.fem.VectorFunctionSpace(mesh, ("DG", 0))
            elif f.ufl_shape:
                space = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
            else:
                space = dolfinx.fem.FunctionSpace(mesh, ("Lagrange", 1))
            out = dolfinx.fem.Function(space, name=name)
            self._out[name] = out
        out.interpolate(f)
        return out

    def write(self, functions: Mapping[str, dolfinx.fem.Function], t: float) -> None:
        """Write every Function (all on one mesh) at time ``t``."""
        mesh = next(iter(functions.values())).function_space.mesh
        if mesh is not self._mesh:
            self._open(mesh)
        assert self._file is not None
        for name, f in functions.items():
            self._file.write_function(self._output_function(name, f), t)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
