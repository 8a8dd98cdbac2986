"""``python -m convection.io.pictures RUN_DIR ...``: as ``python -m convection.plot``."""

import sys

from convection.io.pictures.cli import main

if __name__ == "__main__":
    sys.exit(main())
