"""Texture variance and lag-1 correlation across track per band, from compare_real JSONs.

In normalised intensity ``I = T S`` (texture times speckle, unit means, independent), the
variance is ``(1 + v_T)(1 + v_S) − 1`` and the lag-1 covariance ``(1 + v_T ρ_T)(1 + v_S ρ_S) −
1``; the plane run (no relief, no K) gives the speckle's ``v_S`` (contrast²) and ``ρ_S`` per band,
each band's contrast and across-track length give the rest. Approximate: the contrast is a
median over 16 × 16 patches, the length a lag-1 correlation over the band.

Run from the repository root::

    python tools/compare_real.py --micro-relief off --json plane.json
    python tools/compare_real.py --json default.json
    python docs/notes/2026-11-27-cell-texture/texture_rho.py plane.json default.json
"""

import json
import math
import sys

BIN = 0.0293  # the file's slant-range bin, metres


def rho(sigma: float) -> float:
    """Lag-1 correlation of the Gaussian cell whose std is ``sigma`` metres (compare_real)."""
    return math.exp(-1.0 / (4.0 * (sigma / BIN) ** 2))


plane, *runs = sys.argv[1:]
speckle = json.load(open(plane))["bands"]
for path in runs:
    for band, ref in zip(json.load(open(path))["bands"], speckle, strict=True):
        vs, rs = ref["contrast_sim"] ** 2, rho(ref["across_sim"])
        out = []
        for who in ("real", "sim"):
            v = band[f"contrast_{who}"] ** 2
            vt = (1 + v) / (1 + vs) - 1
            rt = (rho(band[f"across_{who}"]) * v - vs * rs) / ((1 + vs * rs) * vt)
            out.append(f"{who} v_T {vt:.3f} rho_T {rt:.2f}")
        lo, hi = band["band_m"]
        print(f"{band['side']:9s} {lo:4.1f}-{hi:4.1f} m  " + " | ".join(out))
