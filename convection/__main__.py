"""``python -m convection``: see :mod:`convection.app.cli`."""

import sys

from convection.app.cli import main

sys.exit(main())
