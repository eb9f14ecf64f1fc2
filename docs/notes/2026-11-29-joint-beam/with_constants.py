"""``sonar-raster invert`` with module constants of the package set first (one-off variants).

Run: ``python docs/notes/2026-11-29-joint-beam/with_constants.py OUT
sonar_raster.inversion.surface.solve:JOINT_BEAM=False -- d.exr`` (each ``module:NAME=VALUE``
evaluated as a Python literal; what follows ``--`` goes to ``invert``, with ``-o OUT -q``).
Score with ``docs/notes/2026-11-29-first-return/default_render_bands.py OUT``.
"""

import ast
import importlib
import sys

from sonar_raster.cli import app

out = sys.argv[1]
split = sys.argv.index("--")
for spec in sys.argv[2:split]:
    module, setting = spec.split(":")
    name, value = setting.split("=")
    setattr(importlib.import_module(module), name, ast.literal_eval(value))
    print(f"set {module}.{name} = {value}")
sys.exit(app.main(["invert", *sys.argv[split + 1 :], "-o", out, "-q"]))
