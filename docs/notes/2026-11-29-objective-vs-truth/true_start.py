"""The bench's one-line fit started from the true seabed against the usual flat start.

Usage (from the repository root)::

    python docs/notes/2026-11-29-objective-vs-truth/true_start.py SEABED LOOKS [M:NAME=VALUE]

SEABED is one of tools/bench_bathymetry.py's (sand, mounds, ...), LOOKS 1 (single look) or 0
(clean). Both fits run on the same render and speckle draw; each prints its score (Z RMSE /
relief std), and the objective's terms of both parameter vectors are evaluated in the flat
start's final problem (its anchor offset), so the two minima can be compared term by term.
M is S (``surface.solve``) or P (``surface.problem``), e.g. ``P:LINE_PROFILE_WEIGHT=0.01``.
The true start sets the Z knots to the true heights at the knots (then Φ alone is fitted, as
the flat start does) and leaves out the shadow start (``SHADOW_START_BINS = None``).
"""

from __future__ import annotations

import functools
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))

import bench_bathymetry as bench  # noqa: E402

import sonar_raster.inversion.surface.problem as P  # noqa: E402
import sonar_raster.inversion.surface.solve as S  # noqa: E402
from sonar_raster.inversion.bottom import track_bottom  # noqa: E402


def main() -> None:
    """Both fits, their scores and their terms."""
    name, looks = sys.argv[1], float(sys.argv[2])
    for arg in sys.argv[3:]:
        module, setting = arg.split(":")
        key, value = setting.split("=")
        number = None if value == "None" else (int(value) if value.isdigit() else float(value))
        setattr({"S": S, "P": P}[module], key, number)
    field, tracks, images = bench.render(name, 200, looks, 1)
    baselines = [track_bottom(sides, bench.BIN).altitude for sides in images]
    captured: dict = {}
    results, flat_start, shadow_start = S._results, S._start, S.SHADOW_START_BINS

    def keep(full, params, *args, **kwargs):
        captured["problem"], captured["p"] = full, params.copy()
        return results(full, params, *args, **kwargs)

    S._results = keep
    runs = {}
    truth = functools.partial(true_start, field=field)
    for tag, start, shadows in (("flat", flat_start, shadow_start), ("true", truth, None)):
        S._start, S.SHADOW_START_BINS = start, shadows
        fits = bench.fit(tracks, images, True)
        rel, flat, corr, coverage = bench.score(field, fits, baselines)
        runs[tag] = (captured["problem"], captured["p"])
        print(f"{name} looks {looks:g} {tag} start: {rel:.3f} (flat {flat:.3f}), corr {corr:.2f}, "
              f"1σ {coverage:.2f}, E {fits[0].energies}")  # fmt: skip
    problem = runs["flat"][0]
    a, b = terms(problem, runs["flat"][1]), terms(problem, runs["true"][1])
    for key in a:
        print(f"{key:12s} flat start {a[key]:14.1f}  true start {b[key]:14.1f}  "
              f"difference {b[key] - a[key]:+9.1f}")  # fmt: skip


def true_start(problem, field):
    """The problem's parameters at the true seabed: Z knots at its heights, R at 1.

    Φ alone is then fitted (60 L-BFGS iterations), as the flat start fits it.
    """
    p = np.zeros(problem.size)
    ky, kx = problem.grid.knots("z")
    yy, xx = np.meshgrid(ky, kx, indexing="ij")  # the frame is the first line's: x east
    p[: problem.nz] = (field.height_at(xx, yy) - bench.ALT).ravel()
    for side in problem.grid.sides:
        data = np.concatenate([v.image[v.mask] for v in problem.views if v.side == side])
        p[problem.phi_slice(side)] = math.log(max(float(np.mean(data)), 1e-30))
    free = np.zeros(problem.size, bool)
    free[problem.nz + problem.nr :] = True
    p[:], _, _ = S._minimise(problem, p, 60, free)
    return p


def terms(problem, p) -> dict[str, float]:
    """The objective's terms at ``p`` (nats)."""
    zc, rc, lphi = problem.split(p)
    data = 0.0
    for view in problem.views:
        z, r, beam = problem.fields(p, view)
        data += P.view_objective(view, r, beam.phi, z)[0]
    out = {"data": data}
    for axis, w, key in ((0, problem.w_z_along, "Z along"), (1, problem.w_z, "Z across")):
        out[key] = P.second_difference(zc, axis, problem.grid.z_spacing, w)[0]
    relief = problem.relief_weights()
    out["relief"] = 0.0 if relief is None else float(np.sum(relief * (zc - problem.flat) ** 2))
    out["line"] = P.line_profile(problem, (zc - problem.flat).ravel())[0]
    out["anchor"] = problem._anchor(zc)[0]
    out["R edges"] = sum(
        P.charbonnier(rc, axis, P.REFLECTIVITY_EDGE, problem.w_r)[0] for axis in (0, 1)
    )
    out["R and Φ"] = problem.reflectivity_beam_priors(rc, lphi, np.zeros_like(p))
    out["total"] = problem(p)[0]
    return out


if __name__ == "__main__":
    main()
