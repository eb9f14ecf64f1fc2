"""``python -m sonar_raster``: the same as the ``sonar-raster`` command."""

import sys

from .cli import main

sys.exit(main())
