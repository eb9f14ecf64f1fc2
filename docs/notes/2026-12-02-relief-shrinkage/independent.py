"""The relief raw, Wiener-shrunk and shrunk by the default on the independent model's images.

``tools/bench_independent.py``'s render, CLI invert and score. One inversion per seabed; the
shrinkage is recorded where the fit applies it and each variant scored on the same products.
Usage: ``python independent.py SEABEDS LOOKS``, e.g. ``python independent.py
sand,mound,trench,rough,box 1``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_independent as bi  # noqa: E402

from sonar_raster.inversion.surface import solve  # noqa: E402

SEEN: dict[str, np.ndarray] = {}
SHRINK = solve.shrink_relief


def recorded(z, std, knot, dx, dy):
    """The fit's shrink, keeping each variant for scoring."""
    SEEN["raw"] = z.copy()
    SEEN["wiener"] = SHRINK(z, std, knot, dx, dy, 1.0)
    SEEN["default"] = SHRINK(z, std, knot, dx, dy)
    return SEEN["default"]


def main() -> None:
    """Print raw and shrunk scores per seabed."""
    solve.shrink_relief = recorded
    looks = float(sys.argv[2])
    for name in sys.argv[1].split(","):
        image = bi.render(name, looks)
        with tempfile.TemporaryDirectory() as tmp:
            products, _ = bi.invert(image, Path(tmp), False, "auto")
        if not SEEN:
            print(f"{name:8s} L={looks:g}: profiles (no surface fit)", flush=True)
            continue
        written = products["elevation"]
        row = [f"{name:8s} L={looks:g}"]
        for key in ("raw", "wiener", "default"):
            variant = dict(products, elevation=np.where(np.isfinite(written), SEEN[key], np.nan))
            s = bi.score(name, image, variant)
            row.append(f"{key} {s['fit']:.3f} corr {s['corr']:.2f} 1σ {s['coverage']:.2f}")
        print("  ".join(row) + f"  flat {s['flat']:.3f}", flush=True)
        SEEN.clear()


if __name__ == "__main__":
    main()
