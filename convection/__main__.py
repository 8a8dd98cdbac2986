"""``python -m convection``: see :mod:`convection.cli`."""

import sys

from convection.cli import main

sys.exit(main())
