"""One seabed surface fitted to every ping of one or several lines.

Both sides, shadows and a speckle likelihood.

The per-ping solver (:mod:`..em`) gives each ping its own elevation profile, so each profile is
fitted from its own speckle (one datum per cell for two unknowns). Here the unknowns are shared
by many pings and bins instead:

* ``Z`` is one smooth surface, a tensor cubic B-spline in a plane frame along the first line
  (:mod:`.layout`), knots a few resolution cells apart, so both sides, the nadir and every
  overlapping line share it;
* ``log R`` is a tensor B-spline too, with an edge-preserving (Charbonnier) roughness: a jump
  between two sediments costs in proportion to its size, so it stays in R, while a ripple's
  repeated shading costs R far more than it costs Z;
* ``log Φ`` is a profile over depression angle per side, shared by every ping of every line,
  evaluated at each cell's own angle ``atan2(−Z, x)``;
* each line's first bottom return anchors Z at its nadir.

The objective (:mod:`.problem`) is the L-look Gamma likelihood of the image model with soft
cast shadows plus the priors; Gauss-Newton steps on the Z knots alternate with L-BFGS on R and
Φ, coarse to fine, and a Laplace approximation gives Z's standard deviation (:mod:`.solve`).
"""

from .invert import invert_line, invert_lines
from .layout import Line
from .solve import SurfaceFit, fit_lines, fit_surface

__all__ = ["Line", "SurfaceFit", "fit_lines", "fit_surface", "invert_line", "invert_lines"]
