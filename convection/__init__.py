"""Boussinesq Stokes + temperature convection on DOLFINx with adaptive meshes.

The rooms, from the floor up (a room imports only from rooms below it, and from ``particles`` and
``fembase``):

================ =========================================================================
``schema``       declared parameters (settings dataclasses) and the checks of config values
``expressions``  closed-form expressions of the coordinates
``launch``       the MPI launcher of this Python (light: starts no MPI)
``geometry``     the domain (box, annulus, spherical shell, sector): meshes, boundaries, plates
``physics``      the approximation, materials and viscosity laws
``solvers``      Stokes, transport, PETSc options, the time step
``adapt``        adaptivity, the mesh hierarchy, transfer of fields, repartitioning
``model``        the model: its components, stepped in time; material fractions
``postprocess``  statistics columns
``io``           fields, statistics files, checkpoints, the run folder, pictures
``run``          the run loop: steps with statistics, output, progress and stops
``config``       the YAML front end: loading, checks, the reference
``app``          the command line and the builder of models from configs
================ =========================================================================

The first three are the floor (no DOLFINx).
The names most scripts need are here: :func:`load_config`, :func:`build_model`, :func:`run_config`
and :class:`Model` (imported when first used).
"""

from convection._lazy import lazy_exports

__all__ = ["Model", "build_model", "load_config", "run_config"]

__getattr__, __dir__ = lazy_exports(__name__, {"Model": "model", "build_model": "app.factory",
                                               "load_config": "config", "run_config": "app.factory"})
