"""Clean mounds, beam calibrated, R held, no line prior: flat against true start, and a scan.

The objective is also evaluated along the straight path from a flat seabed to the truth.

Usage (from the repository root)::

    python docs/notes/2026-11-29-mound-path/path.py [SEABED [LOOKS]]

The beam profile of each side is fitted on a flat seabed's line first (the bench's
``--beam calibrated``). R is held by a roughness weight of 1000 (the truth's R is uniform), and
the calibrated line-profile prior is off, so that what is left between the fit and the truth
is the path the Gauss-Newton steps take. Printed per start: the score, the final E per level,
per side the RMS of the error's along-track mean and of the rest (cm) and the highest point
(fit, truth, m); then, in the true start's final problem, E at Z = flat + s × relief with R
and Φ held at the true start's, and with them refitted (40 L-BFGS iterations), relative to
the true start's E.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "2026-11-29-objective-vs-truth"))

import bench_bathymetry as bench  # noqa: E402
from true_start import true_start  # noqa: E402

import sonar_raster.inversion.surface.problem as P  # noqa: E402
import sonar_raster.inversion.surface.solve as S  # noqa: E402
from sonar_raster.inversion.bottom import track_bottom  # noqa: E402


def main() -> None:
    """Both starts, then the scan."""
    name = sys.argv[1] if len(sys.argv) > 1 else "mounds"
    looks = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    profiles = bench.calibrate(200, looks, 1, 0.4)
    field, tracks, images = bench.render(name, 200, looks, 1)
    baselines = [track_bottom(sides, bench.BIN).altitude for sides in images]
    P.REFLECTIVITY_WEIGHT, S.CALIBRATED_LINE_WEIGHT = 1000.0, 0.0
    captured: dict = {}
    results, flat_start = S._results, S._start

    def keep(full, params, *args, **kwargs):
        captured["problem"], captured["p"] = full, params.copy()
        return results(full, params, *args, **kwargs)

    S._results = keep
    truth = functools.partial(true_start, field=field)
    for tag, start in (("flat", flat_start), ("true", truth)):
        S._start = start
        S.SHADOW_START_BINS = None if tag == "true" else S.SHADOW_START_BINS
        fits = bench.fit(tracks, images, True, beam=profiles)
        rel, flat, _, _ = bench.score(field, fits, baselines)
        print(f"{tag} start: {rel:.3f} (flat {flat:.3f}), E {fits[0].energies}")
        for side, parts in _decompose(field, fits[0]).items():
            print(f"  {side}: along-track mean {parts[0]:.1f} cm, rest {parts[1]:.1f} cm, "
                  f"highest {parts[2]:.2f} m (truth {parts[3]:.2f} m)")  # fmt: skip
    problem, p0 = captured["problem"], captured["p"]
    ky, kx = problem.grid.knots("z")
    yy, xx = np.meshgrid(ky, kx, indexing="ij")
    relief = field.height_at(xx, yy).ravel()
    flat_part = p0[: problem.nz] - relief
    free = np.zeros(problem.size, bool)
    free[problem.nz :] = True
    e0 = problem(p0)[0]
    for s in (0.0, 0.2, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1):
        p = p0.copy()
        p[: problem.nz] = flat_part + s * relief
        held = problem(p)[0] - e0
        refitted = S._minimise(problem, p, 40, free)[1] - e0
        print(f"s {s:.1f}: E {held:+10.1f} (R, Φ held), {refitted:+10.1f} (refitted)")


def _decompose(field, fit) -> dict[str, tuple[float, float, float, float]]:
    x = fit.x
    keep = (x > 1.0) & (x < x[-1] - 2.0)
    out = {}
    for side in fit.elevation:
        where = fit.position[side][:, keep]
        truth = field.height_at(where[..., 0], where[..., 1]) - bench.ALT
        error = fit.elevation[side][:, keep] - truth
        column = error.mean(axis=0, keepdims=True)
        out[side] = (
            100 * float(np.sqrt(np.mean(column**2))),
            100 * float(np.sqrt(np.mean((error - column) ** 2))),
            float(fit.elevation[side][:, keep].max() + bench.ALT),
            float(truth.max() + bench.ALT),
        )
    return out


if __name__ == "__main__":
    main()
