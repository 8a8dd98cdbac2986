"""Pictures of a run: ``python -m convection.plot RUN_DIR [--png FILE] [--times T ...]``.

``summary.png`` (matplotlib): the final temperature (or, without an energy equation, the material
field) with the mesh, read from the last field file (``fields_NNN.h5`` written by
:mod:`convection.io.fields`; of a 3D box its side y = (smallest y)), and one panel for each of
vrms, the Nusselt number, the topography and the cell count over time that the run measured, from
``statistics.csv`` (``statistics_physical.csv`` in a model's units). No panel is left empty.

``snapshots/*.png`` (pyvista, rendered off-screen): at chosen times of ``fields.xdmf`` (default: the
first, middle and last written time; a requested time snaps to the nearest written one),

- the material field (``material``, else ``composition``, else the first other scalar field that is
  not temperature, pressure or velocity; or ``--field NAME``) with the particles of
  ``particles.xdmf`` on top (the written particle time nearest to the field time; coloured by
  ``--particle-property NAME``, else black);
- the viscosity per cell (a logarithmic scale where it spans a decade or more), where the run wrote
  one that varies;
- the temperature with the mesh edges (skipped, with a message, where it is constant, e.g. Ra = 0).

Each has axes x and z (the vertical coordinate) and colour bars below it; tick numbers are plain
(``0.2``, ``1573``; a power of ten goes into the label, never an offset). A run in physical units
(``fields_units.json``) gets its times, coordinates (``x [km]``), units and colour-bar titles in
those units.

2D meshes are seen from +z. 3D meshes are cut by the vertical plane y = (centre of the domain): the
picture is that x-z section seen from -y, with the particles within one typical cell size of the
plane. A 3D box also gets a perspective ``volume_*.png``: three orthogonal slices through the
centre (x-y shows the planform) coloured by the temperature (the material field where the
temperature is constant), the isosurface of the material field at the middle of its range
(without one, of the temperature), and axes x, y, z in the output's units.

A spherical shell (3D, hollow around the origin) also gets a perspective ``shell_*.png`` (the seed
paper's picture of section 4.2): the temperature on the equatorial plane z = 0, the core as a grey
sphere, and the particles of the northern hemisphere (within ``--particle-radius``
of the centre if given) as points coloured by ``--particle-property`` (default ``displacement`` when
the particles carry it).

A missing or damaged file of the run folder (the folder itself, ``statistics.csv``, a field or
particle file) stops ``python -m convection.plot`` with one line ``error: ...`` naming it, exit
code 1 (:class:`convection.io.xdmf_check.RunFilesError`; an XDMF series and the HDF5 data of the
times drawn are checked before VTK reads them). A run without field output (statistics only)
gets its curves, and one line saying what was skipped. A ``statistics.csv`` whose last line was
cut off (a run killed while writing it) is read without that line.

The package, one module per concept:

- :mod:`~convection.io.pictures.run_files`: reading a run folder (statistics, field files, units,
  particle series);
- :mod:`~convection.io.pictures.labels`: titles, axis labels and tick numbers in the output's units;
- :mod:`~convection.io.pictures.summary`: ``summary.png``;
- :mod:`~convection.io.pictures.series`: the XDMF series read with VTK;
- :mod:`~convection.io.pictures.sections`: the flat pictures (2D domains, sections of 3D ones);
- :mod:`~convection.io.pictures.shell`: the spherical shell in perspective;
- :mod:`~convection.io.pictures.volume`: a 3D box in perspective (slices and an isosurface);
- :mod:`~convection.io.pictures.snapshots`: which pictures each time gets;
- :mod:`~convection.io.pictures.cli`: ``python -m convection.plot``.
"""

from convection.io.pictures.cli import main
from convection.io.pictures.run_files import (RunFilesError, check_run_folder, field_files, field_units,
                                              particle_series, read_last_field, read_statistics)
from convection.io.pictures.series import import_pyvista, snapshot_times
from convection.io.pictures.snapshots import plot_snapshots
from convection.io.pictures.summary import plot_run

__all__ = ["RunFilesError", "read_statistics", "read_last_field", "field_units", "plot_run", "import_pyvista",
           "snapshot_times", "plot_snapshots", "particle_series", "field_files", "check_run_folder", "main"]
