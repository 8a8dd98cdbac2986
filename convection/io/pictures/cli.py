"""Pictures of a run folder: summary.png, then the snapshots (python -m convection.plot RUN_DIR).

A missing or damaged run file is one line ``error: ...`` and exit code 1; an unknown field,
particle property or particle system exit code 2."""

from __future__ import annotations

import argparse
import sys

from convection.io.pictures.run_files import check_run_folder, field_files
from convection.io.pictures.snapshots import plot_snapshots
from convection.io.pictures.summary import plot_run
from convection.io.statistics import StatisticsFileError

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m convection.plot", description=__doc__.split("\n")[0])
    parser.add_argument("directory", help="run directory")
    parser.add_argument("--png", default=None, help="summary picture (default RUN_DIR/summary.png)")
    parser.add_argument("--times", type=float, nargs="+", default=None, metavar="T",
                        help="snapshot times, each snapped to the nearest written time "
                             "(default: first, middle and last)")
    parser.add_argument("--field", default=None,
                        help="field of the composition snapshots (default: material, else composition, else "
                             "the first other scalar field)")
    parser.add_argument("--particle-property", default=None, metavar="NAME",
                        help="particle property that colours the particles (default: black particles)")
    parser.add_argument("--particle-radius", type=float, default=None, metavar="R",
                        help="spherical shells: draw only particles within R of the centre (default: all of the "
                             "northern hemisphere)")
    parser.add_argument("--particle-system", default=None, metavar="NAME",
                        help="of a run with several particle systems: the one drawn (default: the first that "
                             "wrote output, by name)")
    parser.add_argument("--snapshots", default=None, metavar="DIR",
                        help="folder of the snapshot pictures (default RUN_DIR/snapshots)")
    args = parser.parse_args(argv)
    try:
        _draw(args)
    except (StatisticsFileError, OSError) as exc:  # RunFilesError, and e.g. a picture that cannot be written
        return _error(exc, 1)
    except ValueError as exc:  # an unknown --field or --particle-property
        return _error(exc, 2)
    return 0


def _draw(args: argparse.Namespace) -> None:
    """What ``main`` draws: the summary, then the snapshots (or one line saying why none)."""
    directory = check_run_folder(args.directory)
    print(plot_run(directory, args.png, log=print))
    if not (directory / "fields.xdmf").exists() and not field_files(directory):
        print(f"{directory}: no field output (fields.xdmf, fields_NNN.h5): summary without the temperature, "
              "no snapshots")
        return
    paths = plot_snapshots(directory, args.times, args.field, args.particle_property,
                           particle_radius=args.particle_radius, particle_system=args.particle_system,
                           out_dir=args.snapshots)
    for path in paths:
        print(path)


def _error(exc: BaseException, code: int) -> int:
    print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
