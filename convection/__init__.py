"""Boussinesq Stokes + temperature convection on DOLFINx with adaptive meshes.

The rooms, from the floor up (a room imports only from rooms below it, and from ``particles`` and
``fembase``):

=============== ==========================================================================
``schema``,     declared parameters and their checks; closed-form expressions of the
``expressions`` coordinates (the floor: no DOLFINx)
``geometry``    the domain (box, annulus, spherical shell): meshes, boundaries, plates
``physics``     the approximation, materials and viscosity laws
``solvers``     Stokes, transport, PETSc options, the time step
``adapt``       adaptivity, the mesh hierarchy, transfer of fields, repartitioning
``model``       the model: its components, stepped in time; material fractions
``postprocess`` statistics columns
``io``          fields, statistics files, checkpoints, pictures
``config``      the YAML front end: loading, checks, the reference
``app``         the command line, the builder of models from configs, the run loop
=============== ==========================================================================

The names most scripts need are here: :func:`load_config`, :func:`build_model`, :func:`run_config`
and :class:`Model` (imported when first used).
"""

from convection._lazy import lazy_exports

__all__ = ["Model", "build_model", "load_config", "run_config"]

__getattr__, __dir__ = lazy_exports(__name__, {"Model": "model", "build_model": "app.factory",
                                               "load_config": "config", "run_config": "app.factory"})
