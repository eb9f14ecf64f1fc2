"""Which part of a false shadow start costs: its knots raised, or marked as objects.

``ab.py``'s fits with ``solve._raise_objects`` wrapped: ``MODE=raise_only`` keeps the raised
knots but marks none as objects or shadowed, ``MODE=mark_only`` marks them but raises none.
Run from the repository root:
``MODE=raise_only python docs/notes/2026-12-02-law-in-fit/variants.py sand 1 apl``.
"""

import os
import runpy
import sys

import numpy as np

import sonar_raster.inversion.surface.solve as S

MODE = os.environ["MODE"]
ORIGINAL = S._raise_objects


def raise_objects(problem):
    """The shadow start with one of its two parts left out."""
    raised = ORIGINAL(problem)
    if MODE == "raise_only":
        problem.objects = np.zeros_like(problem.objects)
        problem.shadowed = np.zeros_like(problem.shadowed)
    elif MODE == "mark_only":
        raised = np.zeros_like(raised)
    return raised


S._raise_objects = raise_objects
sys.argv = ["ab.py", *sys.argv[1:]]
runpy.run_path("docs/notes/2026-12-02-law-in-fit/ab.py", run_name="__main__")
