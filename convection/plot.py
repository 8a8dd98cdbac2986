"""``python -m convection.plot RUN_DIR ...``: pictures of a run folder (:mod:`convection.io.pictures`)."""

import sys

from convection.io.pictures import main

if __name__ == "__main__":
    sys.exit(main())
