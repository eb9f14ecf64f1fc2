"""Stress tests of numerical stability (issue 8, section 4), as hypothesis properties.

Every property draws random scenes (boxes on a plane, procedural seabeds), tracks and sonar
settings within the documented valid ranges and checks a truth that does not depend on the
code's own output: finiteness (GL, reference and coherent renderers, inversion, writers),
invariance under a rigid motion or a scaling of the whole survey, agreement of the GL image
with the numpy patch reference, convergence to and energy of the closed form for a flat
seabed, and the monotone objective of the inversion. Examples are derandomised (the same
inputs on every run, so CI is reproducible), there is no example database, and images stay
tiny (<= 64 pings x <= 512 bins) so the whole file runs in about a minute on two CPU cores
with llvmpipe.

Failures hypothesis found are written out as plain tests in ``tests/test_regressions.py``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace

import numpy as np
from conftest import box_from_bounds, rect_seabed
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st

from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.rendering.analytic import flat_seabed_profile
from sonar_raster.rendering.gl.raster import RasterSettings
from sonar_raster.scene import MeshPart, build_scene
from sonar_raster.scenes.seabed import make_seabed
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory, heading_axes


def stress(max_examples: int, gl: bool = False):
    """Derandomised, database-free, deadline-free settings (GL tests share a session fixture)."""
    checks = [HealthCheck.function_scoped_fixture, HealthCheck.too_slow] if gl else []
    return settings(
        derandomize=True,
        database=None,
        deadline=None,
        max_examples=max_examples,
        suppress_health_check=checks,
        print_blob=True,
    )


# --------------------------------------------------------------------------- surveys


@dataclass(frozen=True)
class Survey:
    """One random survey: scene parts (world metres), sonar and trajectory."""

    parts: tuple[MeshPart, ...]
    sonar: Sonar
    traj: Trajectory

    @property
    def scene(self):
        return build_scene(list(self.parts))

    def moved(self, point_map, heading_map=None, roll_sign=1.0, flip_faces=False) -> Survey:
        """The survey with every vertex and ping position mapped by ``point_map`` (n, 3),
        headings by ``heading_map``, roll times ``roll_sign``, faces maybe re-wound."""
        parts = tuple(
            MeshPart(
                point_map(p.vertices),
                p.faces[:, ::-1] if flip_faces else p.faces,
                p.reflectivity,
                p.name,
                p.is_seabed,
            )
            for p in self.parts
        )
        t = self.traj
        headings = t.headings if heading_map is None else heading_map(t.headings)
        traj = Trajectory(point_map(t.positions), headings, roll_sign * t.roll, t.pitch)
        return Survey(parts, self.sonar, traj)


BEAMS = st.one_of(
    st.just(BeamPattern.uniform()),
    st.floats(10.0, 120.0).map(BeamPattern.gaussian),
    st.tuples(st.floats(0.02, 0.2), st.sampled_from([100e3, 400e3])).map(
        lambda a: BeamPattern.sinc(*a)
    ),
)
SIDES = st.sampled_from([("port",), ("starboard",), ("port", "starboard")])


@st.composite
def sonars(draw, max_bins: int = 512, sides=SIDES, beams=BEAMS) -> Sonar:
    """Range 10-100 m, bins 0.02-0.5 m (at most ``max_bins`` of them), tilt 0-60°."""
    max_range = draw(st.floats(10.0, min(100.0, 0.5 * max_bins)))
    range_bin = draw(st.floats(max(0.02, max_range / (max_bins + 0.49)), 0.5))
    return Sonar(
        max_range=max_range,
        range_bin=range_bin,
        beam=draw(beams),
        tilt=math.radians(draw(st.floats(0.0, 60.0))),
        sides=draw(sides),
    )


TRACK_SHAPES = ("straight", "climb", "turn", "wobble", "crab")


@st.composite
def tracks(draw, sonar, max_pings=64, min_pings=1, alt_frac=None, shapes=TRACK_SHAPES):
    """A track starting at altitude 2-50 m (and <= ``alt_frac`` of the range) over z = 0.

    Heading 0-360°, 1-64 pings 0.05-1 m apart; the track is straight and level, or climbs or
    dives (slope up to 5 %), or turns (up to 2° per ping), or wobbles across track (up to a
    quarter of a range bin or of the spacing, so the renderer splits it into many segments), or
    crabs (heading up to 10° off the direction of travel). Roll is constant (up to 3°) or
    jitters per ping (up to 1°, which also splits the track); pitch is 0 or constant up to 3°.
    """
    top = 50.0 if alt_frac is None else max(2.0, min(50.0, alt_frac * sonar.max_range))
    altitude = draw(st.floats(2.0, top))
    heading = math.radians(draw(st.floats(0.0, 360.0, exclude_max=True)))
    count = draw(st.integers(min_pings, max_pings))
    spacing = draw(st.floats(0.05, 1.0))
    start = np.array([draw(st.floats(-20.0, 20.0)), draw(st.floats(-20.0, 20.0)), altitude])
    shape = draw(st.sampled_from(shapes))
    k = np.arange(count)
    headings = np.full(count, heading)
    if shape == "turn":
        headings = heading + math.radians(draw(st.floats(-2.0, 2.0))) * k
    steps = np.stack([np.sin(headings), np.cos(headings), np.zeros(count)], axis=1) * spacing
    positions = start + np.concatenate([np.zeros((1, 3)), np.cumsum(steps[:-1], axis=0)])
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    if shape == "climb":
        positions[:, 2] += draw(st.floats(-0.05, 0.05)) * spacing * k
    elif shape == "wobble":
        _, starboard = heading_axes(heading)
        amplitude = 0.25 * min(sonar.range_bin, spacing)
        positions += rng.uniform(-amplitude, amplitude, (count, 1)) * starboard
    elif shape == "crab":
        headings = headings + math.radians(draw(st.floats(-10.0, 10.0)))
    if draw(st.booleans()):
        roll = np.full(count, math.radians(draw(st.floats(-3.0, 3.0))))
    else:
        roll = np.radians(rng.uniform(-1.0, 1.0, count))
    pitch = 0.0 if shape == "straight" else math.radians(draw(st.floats(-3.0, 3.0)))
    return Trajectory(positions, headings, roll, pitch)


def _swath_box(sonar: Sonar, traj: Trajectory, margin: float = 1.1) -> tuple[float, ...]:
    """(x0, x1, y0, y1) of a world-aligned rectangle covering every ping's full range."""
    reach = margin * sonar.max_range + 1.0
    lo = traj.positions[:, :2].min(axis=0) - reach
    hi = traj.positions[:, :2].max(axis=0) + reach
    return (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))


COVERING = ("plane", "rough", "ripples", "bumpy")


@st.composite
def seabeds(draw, sonar: Sonar, traj: Trajectory, kinds=COVERING) -> list[MeshPart]:
    """A plane, or a rough, rippled or bumpy seabed (mean z = 0) covering the swath.

    Heightfield cells are 1/120 of the longer side (at most ~120 x 120 cells, ~29 k triangles).
    "patch" is a plane covering a random part of the swath (or none of it); "none" no seabed.
    """
    x0, x1, y0, y1 = _swath_box(sonar, traj)
    refl = draw(st.floats(0.05, 1.0))
    kind = draw(st.sampled_from(kinds))
    if kind == "none":
        return []
    if kind == "plane":
        return [rect_seabed(x0, x1, y0, y1, 0.0, refl)]
    if kind == "patch":
        u = sorted(draw(st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0))))
        v = sorted(draw(st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0))))
        assume(u[1] - u[0] > 0.01 and v[1] - v[0] > 0.01)
        xs = [x0 + (x1 - x0) * f for f in u]
        ys = [y0 + (y1 - y0) * f for f in v]
        return [rect_seabed(xs[0], xs[1], ys[0], ys[1], draw(st.floats(-5.0, 1.0)), refl)]
    size = (x1 - x0, y1 - y0)
    res = max(size) / 120.0
    common = {
        "size": size,
        "center": (0.5 * (x0 + x1), 0.5 * (y0 + y1)),
        "resolution": res,
        "seed": draw(st.integers(0, 2**31 - 1)),
    }
    if kind == "rough":
        params = {"rms_height": draw(st.floats(0.01, 0.5)), "correlation_length": 10 * res}
    elif kind == "ripples":
        params = {
            "wavelength": draw(st.floats(4.0, 12.0)) * res,
            "amplitude": draw(st.floats(0.01, 0.3)) * res,
            "direction_deg": draw(st.floats(0.0, 360.0)),
        }
    else:
        params = {
            "bump_height": draw(st.floats(0.05, 1.0)),
            "bump_width": draw(st.floats(1.0, 4.0)) * res,
            "density": draw(st.floats(20.0, 200.0)) / (size[0] * size[1]),
        }
    return [make_seabed(kind, **common, **params).mesh(refl)]


@st.composite
def boxes(draw, sonar: Sonar, traj: Trajectory, max_boxes: int = 3, tall=0.9) -> list[MeshPart]:
    """0-3 world-aligned boxes standing on the seabed inside the swath, at most ``tall``
    times the altitude (or 6 m) high: with ``tall`` > 1 they may rise above the sonar."""
    out = []
    seg = traj.segments(sonar.range_bin / 4.0)[0]
    altitude = float(traj.positions[0, 2])
    for k in range(draw(st.integers(0, max_boxes))):
        t = draw(st.floats(-5.0, float(np.ptp(traj.positions[:, :2], axis=0).max()) + 5.0))
        across = draw(st.floats(-sonar.max_range, sonar.max_range))
        centre = seg.origin[:2] + t * seg.along[:2] + across * seg.starboard[:2]
        half = np.array([draw(st.floats(0.1, 3.0)), draw(st.floats(0.1, 3.0))])
        top = draw(st.floats(0.1, tall)) * min(altitude, 6.0)
        lo = [centre[0] - half[0], centre[1] - half[1], -0.5]
        hi = [centre[0] + half[0], centre[1] + half[1], top]
        out.append(box_from_bounds([lo, hi], draw(st.floats(0.05, 1.0)), f"box{k}"))
    return out


@st.composite
def surveys(draw, max_bins=512, max_pings=64, min_pings=1, alt_frac=None, beams=BEAMS, **scene):
    """A random survey: sonar, track, seabed and boxes (``scene``: ``kinds`` and ``tall``)."""
    kinds, tall = scene.get("kinds", COVERING), scene.get("tall", 0.9)
    sonar = draw(sonars(max_bins=max_bins, beams=beams))
    traj = draw(tracks(sonar, max_pings=max_pings, min_pings=min_pings, alt_frac=alt_frac))
    parts = [*draw(seabeds(sonar, traj, kinds)), *draw(boxes(sonar, traj, tall=tall))]
    assume(parts)
    return Survey(tuple(parts), sonar, traj)


#: Any valid survey: partial or no seabed, boxes rising above the sonar, any altitude.
ANY_SURVEY = {"kinds": (*COVERING, "patch", "none"), "tall": 1.5}


def rel_l1(a: dict[str, np.ndarray], b: dict[str, np.ndarray], pairs=None) -> float:
    """Σ|a − b| / Σ|b| over the side pairs (a side name, b side name), in float64.

    ``b`` must hold some energy: an invariance between two black images proves nothing.
    """
    pairs = pairs or [(s, s) for s in b]
    num = sum(float(np.abs(a[p].astype(np.float64) - b[q]).sum()) for p, q in pairs)
    den = sum(float(np.abs(b[q].astype(np.float64)).sum()) for _, q in pairs)
    assert den > 0, "the reference image is black"
    return num / den


def assert_finite_image(image: SonarImage, survey_or_sonar, pings: int) -> None:
    sonar = getattr(survey_or_sonar, "sonar", survey_or_sonar)
    assert set(image.sides) == set(sonar.sides)
    for side, a in image.sides.items():
        assert a.shape == (pings, sonar.n_bins), side
        assert np.all(np.isfinite(a)), f"{side}: {np.count_nonzero(~np.isfinite(a))} non-finite"
        assert np.all(a >= 0), f"{side}: negative intensity {a.min()}"


def _render(gl, survey: Survey, **kw) -> SonarImage:
    return gl.render(survey.scene, survey.sonar, survey.traj, **kw)


def _render_lit(gl, survey: Survey) -> SonarImage:
    """Render, rejecting the example when the image is black (e.g. a narrow beam that misses
    the seabed: Φ < 1e-30 everywhere): an invariance between black images proves nothing."""
    image = _render(gl, survey)
    assume(any(float(a.max()) > 0 for a in image.sides.values()))
    return image


# --------------------------------------------------------------------------- no NaN or inf


@stress(150, gl=True)
@given(survey=surveys(**ANY_SURVEY))
def test_gl_images_are_finite(gl, survey):
    image = _render(gl, survey)
    assert_finite_image(image, survey, survey.traj.n_pings)


@stress(30, gl=True)
@given(survey=surveys(max_bins=256, max_pings=16, **ANY_SURVEY), data=st.data())
def test_gl_labels_and_oversampling_are_finite(gl, survey, data):
    """Other sampling settings: no NaN, labels only name objects of the scene, and asking for
    labels does not change the intensities."""
    gl.settings = RasterSettings(
        oversample=data.draw(st.floats(0.25, 8.0)),
        along_samples=data.draw(st.integers(1, 4)),
        split=data.draw(st.sampled_from(["footprint", "nearest", "linear"])),
    )
    try:
        image = _render(gl, survey, labels=True)
        plain = _render(gl, survey)
    finally:
        gl.settings = RasterSettings()
    assert_finite_image(image, survey, survey.traj.n_pings)
    for side in image.sides:
        assert np.array_equal(image.sides[side], plain.sides[side]), side
    assert image.labels is not None
    for side, lab in image.labels.items():
        assert lab.max() <= len(survey.parts), side
        assert np.all(lab[image.sides[side] > 0] > 0), f"{side}: a lit cell has no label"


@stress(15)
@given(survey=surveys(max_bins=96, max_pings=6, **ANY_SURVEY))
def test_reference_images_are_finite(survey):
    from sonar_raster.rendering.reference import render_reference

    with np.errstate(over="raise", invalid="raise", divide="raise"):
        image = render_reference(survey.scene, survey.sonar, survey.traj)
    assert_finite_image(image, survey, survey.traj.n_pings)


@stress(6)
@given(
    freq=st.floats(10e3, 30e3),
    max_range=st.floats(8.0, 14.0),
    altitude=st.floats(2.0, 6.0),
    heading=st.floats(0.0, 360.0),
    sides=SIDES,
    kind=st.sampled_from(["plane", "rough"]),
    with_box=st.booleans(),
    seed=st.integers(0, 2**31 - 1),
)
def test_coherent_images_are_finite(
    freq, max_range, altitude, heading, sides, kind, with_box, seed
):
    """The coherent model on a small patch (few scatterers at 10-30 kHz, λ/1 spacing)."""
    from sonar_raster.rendering.coherent.model import render_coherent, to_raster_units

    sonar = Sonar(
        frequency_hz=freq,
        max_range=max_range,
        range_bin=0.1,
        beam=BeamPattern.gaussian(50.0),
        tilt=math.radians(25.0),
        sides=sides,
    )
    traj = Trajectory.straight((0.0, 0.0, altitude), heading, 0.2, 4)
    along, starboard = heading_axes(math.radians(heading))
    # an 8 m x 8 m seabed patch abeam on each side, plus maybe a box on it
    parts = []
    for sign in (-1.0, 1.0):
        c = sign * 6.0 * starboard + 0.3 * along
        if kind == "plane":
            parts.append(rect_seabed(c[0] - 4, c[0] + 4, c[1] - 4, c[1] + 4, 0.0, 0.7))
        else:
            hf = make_seabed(
                "rough", size=8.0, center=(c[0], c[1]), resolution=0.25, rms_height=0.05, seed=seed
            )
            parts.append(hf.mesh(0.7))
    if with_box:
        c = 5.0 * starboard
        parts.append(
            box_from_bounds([[c[0] - 0.3, c[1] - 0.3, 0.0], [c[0] + 0.3, c[1] + 0.3, 0.5]])
        )
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        image = render_coherent(build_scene(parts), sonar, traj, spacing_wavelengths=1.0, seed=seed)
        assert_finite_image(image, sonar, traj.n_pings)
        assert image.metadata["n_visible"] > 0  # the patches lie inside the range
        assert_finite_image(to_raster_units(image), sonar, traj.n_pings)


# --------------------------------------------------------------------------- invariances
#
# Tolerances (relative L1 over both images, Σ|a − b| / Σ|b|):
# - Translation. Scene and track are shifted in float64: an offset of up to 1e6 m adds an error
#   of at most 1e6 * 2^-52 ≈ 2e-10 m to each coordinate. The renderer subtracts the first ping's
#   position (float64) before converting to float32, and after that shift coordinates are below
#   ~250 m, where the float32 spacing is 2^-16 ≈ 1.5e-5 m: a 2e-10 m error changes the float32
#   value only when the coordinate lies within 2e-10 m of a rounding midpoint (a chance of
#   ~3e-5 per coordinate), and then by one ulp. The images are therefore bit-identical or differ
#   in a handful of samples by ~1 ulp / range bin: we allow 1e-6 (measured: <= 1.5e-10 over
#   100 examples).
# - Rotation, mirror and scaling re-round every float32 coordinate: vertices, the track's axes
#   and so every ray's range move by up to ~1 ulp ≈ 1.5e-5 m, i.e. <= 1.5e-5 / 0.02 = 7.5e-4
#   of the smallest bin. Where the image is smooth the moves cancel between neighbouring bins;
#   what remains comes from bin-scale edges (nadir, shadows, object edges) and from rays that
#   graze an object's edge and switch to the background (one whole sample, ~1e-4 of a row). The
#   segmentation of a curved track may also change where a ping sits exactly on the tolerance.
#   We allow 5e-4 (measured over 100-300 examples each: typically 1e-5, worst 2.0e-4).

TRANSLATE_TOL = 1e-6
MOTION_TOL = 5e-4


@stress(50, gl=True)
@given(
    survey=surveys(max_bins=256, max_pings=32, alt_frac=0.8),
    offset=st.tuples(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)),
)
def test_translation_invariance(gl, survey, offset):
    """Moving scene and track by up to 1e6 m along each axis changes nothing."""
    off = np.asarray(offset)
    base = _render_lit(gl, survey)
    moved = _render(gl, survey.moved(lambda p: p + off))
    err = rel_l1(moved.sides, base.sides)
    note(f"rel L1 {err:.3g}")
    assert err <= TRANSLATE_TOL


def _rotation(angle: float, pivot: np.ndarray):
    """Compass rotation by ``angle`` (clockwise seen from above) about the vertical at pivot."""
    c, s = math.cos(angle), math.sin(angle)
    m = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return lambda p: (p - pivot) @ m.T + pivot


@stress(50, gl=True)
@given(survey=surveys(max_bins=256, max_pings=32, alt_frac=0.8), turn=st.floats(1.0, 359.0))
def test_heading_rotation_invariance(gl, survey, turn):
    """Rotating scene and track together about the vertical gives the same image."""
    angle = math.radians(turn)
    pivot = survey.traj.positions[0] * [1.0, 1.0, 0.0]
    rotate = _rotation(angle, pivot)
    rotated = survey.moved(rotate, heading_map=lambda h: h + angle)
    # the rotation maps the heading axes onto the new heading's axes (checks the convention)
    h = float(survey.traj.headings[0])
    for old, new in zip(heading_axes(h), heading_axes(h + angle), strict=True):
        assert np.allclose(rotate(pivot + old[None, :])[0] - pivot, new, atol=1e-12)
    base = _render_lit(gl, survey)
    turned = _render(gl, rotated)
    err = rel_l1(turned.sides, base.sides)
    note(f"draws {base.metadata['draws']} and {turned.metadata['draws']}, rel L1 {err:.3g}")
    assert err <= MOTION_TOL


@stress(40, gl=True)
@given(survey=surveys(max_bins=256, max_pings=32, alt_frac=0.8))
def test_mirror_swaps_port_and_starboard(gl, survey):
    """Mirroring scene and track across a vertical plane along the track swaps the sides.

    The plane holds the first ping and its heading; headings reflect (h → 2 h0 − h), roll is
    negated (starboard down becomes port down) and faces are re-wound so normals stay outward.
    """
    survey = Survey(survey.parts, replace(survey.sonar, sides=("port", "starboard")), survey.traj)
    h0 = float(survey.traj.headings[0])
    p0 = survey.traj.positions[0]
    _, s = heading_axes(h0)

    def mirror(p: np.ndarray) -> np.ndarray:
        return p - 2.0 * ((p - p0) @ s)[:, None] * s

    flipped = survey.moved(mirror, lambda h: 2.0 * h0 - h, roll_sign=-1.0, flip_faces=True)
    base = _render_lit(gl, survey)
    mirrored = _render(gl, flipped)
    err = rel_l1(mirrored.sides, base.sides, [("port", "starboard"), ("starboard", "port")])
    note(f"rel L1 {err:.3g}")
    assert err <= MOTION_TOL


@stress(50, gl=True)
@given(
    survey=surveys(max_bins=256, max_pings=32, min_pings=2, alt_frac=0.8),
    k=st.integers(-2, 1),
    u=st.floats(1.01, 1.99),
)
def test_scaling_scales_image_by_s_squared(gl, survey, k, u):
    """Scene, ranges, bins and ping spacing times s: the image (an area, m²) times s².

    s = 2^k · u is in [0.25, 4), u in [1.01, 1.99] not a power of two, so coordinates re-round.
    At least two pings: a lone ping integrates a fixed 1 m along track (see Segment.width).
    """
    s = 2.0**k * u
    sonar = survey.sonar
    scaled = survey.moved(lambda p: p * s)
    scaled = Survey(
        scaled.parts,
        replace(sonar, max_range=sonar.max_range * s, range_bin=sonar.range_bin * s),
        scaled.traj,
    )
    assume(scaled.sonar.n_bins == sonar.n_bins)  # round(r_max / bin) may flip at .5
    base = _render_lit(gl, survey)
    big = _render(gl, scaled)
    err = rel_l1({k_: v / s**2 for k_, v in big.sides.items()}, base.sides)
    note(f"rel L1 {err:.3g}")
    assert err <= MOTION_TOL


# --------------------------------------------------------------------------- two renderers

SMOOTH_BEAMS = st.one_of(
    st.just(BeamPattern.uniform()), st.floats(30.0, 120.0).map(BeamPattern.gaussian)
)
#: Rays and patches (a quarter bin) discretise differently where the image has a step: nadir,
#: box edges, shadow ends (in range, up to ~one bin of the row each) and object edges along
#: track, where one row of rays stands for 1/along_samples of the ping's width (first order:
#: a box exactly one ping wide, turned 3° off the track, is off by 6 % with 2 rows per ping,
#: 2 % with 16 and 0.7 % with 32). With 4 columns per bin and 16 rows per ping: measured worst
#: 2.2 % over 60 examples (90th percentile 1 %). An object passing within two bins under the
#: sonar is first order at nadir, where a ray bundle's range spread is widest: a box top 2 bins
#: (1 m at 0.5 m bins) under the sonar differed by 5.6 %, and 3 bins by 5.26-5.31 % (pinned as
#: the strict xfail test_regressions.py::test_box_top_three_bins_under_a_single_ping; hypothesis
#: kept drawing that boundary), so object tops keep 4 bins until nadir sampling is refined.
RENDERERS_TOL = 0.05
NADIR_CLEARANCE_BINS = 4.0


def _under_the_track(survey: Survey) -> bool:
    """Whether an object's footprint (grown by a range bin) holds a ping's nadir point.

    A bright object straight under the track differs from the reference by 5.1-5.3 % whatever
    its clearance (4 to 7 bins measured on the case pinned as
    test_regressions.py::test_bright_box_under_the_track), above RENDERERS_TOL: a known
    accuracy gap, kept out of this test's domain and pinned there instead.
    """
    grow = survey.sonar.range_bin
    xy = survey.traj.positions[:, :2]
    for part in survey.parts:
        if part.is_seabed:
            continue
        lo, hi = part.vertices[:, :2].min(axis=0) - grow, part.vertices[:, :2].max(axis=0) + grow
        if np.any(np.all((xy >= lo) & (xy <= hi), axis=1)):
            return True
    return False


@stress(30, gl=True)
@given(survey=surveys(max_bins=128, max_pings=4, alt_frac=0.8, beams=SMOOTH_BEAMS))
def test_gl_agrees_with_the_reference(gl, survey):
    """The GL image and the numpy patch reference (an independent discretisation) agree."""
    from sonar_raster.rendering.reference import render_reference

    tops = [float(p.vertices[:, 2].max()) for p in survey.parts if not p.is_seabed]
    clearance = float(survey.traj.positions[:, 2].min()) - max(tops, default=-np.inf)
    assume(clearance >= NADIR_CLEARANCE_BINS * survey.sonar.range_bin)
    assume(not _under_the_track(survey))

    ref = render_reference(survey.scene, survey.sonar, survey.traj)
    assume(any(float(a.max()) > 0 for a in ref.sides.values()))
    gl.settings = RasterSettings(oversample=4.0, along_samples=16)
    try:
        image = _render(gl, survey)
    finally:
        gl.settings = RasterSettings()
    err = rel_l1(image.sides, ref.sides)
    note(f"rel L1 {err:.3g}")
    assert err <= RENDERERS_TOL


# --------------------------------------------------------------------------- flat seabed


#: Smooth beams only: a sinc⁴ beam's lobes (λ / L wide) can be narrower than the renderer's
#: columns near nadir, where sampling Φ at column centres misses the lobes' shape
#: (tests/test_regressions.py::test_sidelobe_lit_flat_seabed_energy).
ENERGY_BEAMS = st.one_of(
    st.just(BeamPattern.uniform()), st.floats(10.0, 120.0).map(BeamPattern.gaussian)
)


@st.composite
def flat_surveys(draw, max_bins: int = 512):
    """A flat plane covering the swath, a level track with constant roll and >= 2 pings."""
    sonar = draw(sonars(max_bins=max_bins, beams=ENERGY_BEAMS))
    traj = draw(tracks(sonar, max_pings=8, min_pings=2, alt_frac=0.8, shapes=("straight",)))
    if not sonar.beam.is_uniform:
        # Near nadir a look-angle column spans degrees, and Φ at its centre (a midpoint rule)
        # misses a steep flank: 0.23 % low for a 10° beam 4 bins above the seabed (see
        # test_regressions.py::test_sidelobe_lit_flat_seabed_energy); keep 10 bins of altitude.
        assume(traj.positions[0, 2] >= 10.0 * sonar.range_bin)
    roll = math.radians(draw(st.floats(-3.0, 3.0)))
    traj = Trajectory(traj.positions, traj.headings, np.full(traj.n_pings, roll))
    x0, x1, y0, y1 = _swath_box(sonar, traj)
    refl = draw(st.floats(0.05, 1.0))
    return Survey((rect_seabed(x0, x1, y0, y1, 0.0, refl),), sonar, traj)


def _flat_profile(survey: Survey, side: str) -> np.ndarray:
    t = survey.traj
    spacing = float(np.linalg.norm(t.positions[1] - t.positions[0]))
    refl = float(survey.parts[0].reflectivity)
    return flat_seabed_profile(
        survey.sonar, float(t.positions[0, 2]), refl, spacing, side=side, roll=float(t.roll[0])
    )


OVERSAMPLES = (0.5, 1.0, 2.0, 4.0, 8.0)
#: Error differences below this are noise: float32 ranges and weights and fixed-point sums
#: leave a floor of ~1e-5 (measured 3e-6 to 6e-5 at 8 columns per bin, where the error
#: stops halving).
CONVERGENCE_NOISE = 2e-5


@stress(30, gl=True)
@given(survey=flat_surveys(max_bins=384))
def test_error_against_closed_form_decreases_with_oversampling(gl, survey):
    """Relative L1 error against the analytic flat-seabed profile, beyond the first bins
    after nadir, does not grow (within noise) as look-angle samples per bin increase."""
    sonar, alt = survey.sonar, float(survey.traj.positions[0, 2])
    first = int(math.ceil(alt / sonar.range_bin)) + 1
    errors = []
    for oversample in OVERSAMPLES:
        gl.settings = RasterSettings(oversample=oversample)
        try:
            image = _render(gl, survey)
        finally:
            gl.settings = RasterSettings()
        num = den = 0.0
        for side in sonar.sides:
            expected = _flat_profile(survey, side)[first:]
            got = image.sides[side][:, first:].astype(np.float64)
            num += float(np.abs(got - expected).sum())
            den += float(expected.sum()) * len(got)
        errors.append(num / den)
    note(f"errors {errors}")
    for coarse, fine in zip(errors, errors[1:], strict=False):
        assert fine <= coarse * 1.05 + CONVERGENCE_NOISE, errors
    # and it does fall, about second order: 16 times the samples divide the error by >= 10
    # (measured: 31 to 450 over 60 examples), down to the noise
    assert errors[-1] <= max(errors[0] / 10, 2 * CONVERGENCE_NOISE), errors


#: Tolerances of the flat-seabed energy test. The closed form is exact (agrees with
#: analytic.flat_seabed_profile summed to 3e-16). With a uniform beam the renderer's error is its
#: geometric discretisation (second order in the column width) plus float32 rounding: measured
#: worst 1.3e-5 over 120 examples; 1.25e-4 on 0.5 m bins 14 bins above the seabed with 1 m
#: between pings (found by a full-suite run), allowed 3e-4. A Gaussian beam adds the midpoint
#: rule of Φ sampled at column centres, largest where the seabed sits in the beam's steep
#: flank: measured worst 2.3e-4 over 180 examples with the seabed lit above -30 dB, allowed 1e-3.
ENERGY_RTOL = {"uniform": 3e-4, "beam": 1e-3}


def _closed_form_total(sonar: Sonar, alt: float, refl: float, width: float, axis: float) -> float:
    """∫ R Φ(α − axis) h / sin α dα · w from the farthest depression asin(h / r_max) to nadir.

    The flat-seabed energy in a ping: a ray bundle of angular width dα and along-track width
    dy carries R Φ r dα dy (Lambert), r = h / sin α on the plane z = 0. A uniform beam has the
    closed form ∫ dα / sin α = ln tan(α / 2); a tabulated beam is linear between its nodes, so
    each piece between nodes is integrated by 16-point Gauss-Legendre (1/sin α is smooth there).
    """
    lo = math.asin(min(1.0, alt / (sonar.n_bins * sonar.range_bin)))
    if sonar.beam.is_uniform:
        return refl * width * alt * -math.log(math.tan(lo / 2))
    nodes = sonar.beam.angles + axis
    edges = np.concatenate(
        [[lo], np.sort(nodes[(nodes > lo) & (nodes < math.pi / 2)]), [math.pi / 2]]
    )
    x, w = np.polynomial.legendre.leggauss(16)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    alpha = mid[:, None] + half[:, None] * x
    total = float(np.sum(half * ((sonar.beam(alpha - axis) / np.sin(alpha)) @ w)))
    return refl * width * alt * total


@stress(150, gl=True)
@given(survey=flat_surveys())
def test_flat_seabed_energy_matches_the_closed_form_integral(gl, survey):
    """Σ over bins of a flat seabed's image equals R w h ∫ Φ(α − axis) / sin α dα."""
    image = _render(gl, survey)
    t, sonar = survey.traj, survey.sonar
    alt = float(t.positions[0, 2])
    width = float(np.linalg.norm(t.positions[1] - t.positions[0]))
    refl = float(survey.parts[0].reflectivity)
    roll = float(t.roll[0])
    for side in sonar.sides:
        axis = sonar.tilt + roll if side == "starboard" else sonar.tilt - roll
        expected = _closed_form_total(sonar, alt, refl, width, axis)
        # The seabed must be inside the beam: lit at > -30 dB of a unit beam on average. In a
        # beam's deep tail Φ falls by orders of magnitude across one column and the midpoint
        # rule fails (0.8 % at -60 dB; the fix is the one of test_sidelobe_lit_flat_seabed_energy),
        # and below -90 dB the fixed-point sums (2^30 steps) round the weights to 0.
        unit_beam = _closed_form_total(
            replace(sonar, beam=BeamPattern.uniform()), alt, refl, width, 0
        )
        assume(expected > 1e-3 * unit_beam)
        totals = image.sides[side].astype(np.float64).sum(axis=1)
        note(f"energy {side}: {np.abs(totals / expected - 1).max() if expected else totals.max()}")
        rtol = ENERGY_RTOL["uniform" if sonar.beam.is_uniform else "beam"]
        np.testing.assert_allclose(totals, expected, rtol=rtol)


# --------------------------------------------------------------------------- inversion

IMAGE_KINDS = ("zeros", "noise", "seabed", "saturated", "black_water", "spikes", "constant")


def _flat_like(rng, pings: int, bins: int, range_bin: float, alt: float) -> np.ndarray:
    """A speckled flat-seabed image: R w h / sqrt(r² − h²) per metre of range, times speckle."""
    r = (np.arange(bins) + 0.5) * range_bin
    g = np.where(r > alt, alt / np.sqrt(np.maximum(r * r - alt * alt, 1e-12)), 0.0)
    g = np.minimum(g, g[r > alt][0] if np.any(r > alt) else 0.0) * range_bin
    return g * rng.exponential(1.0, (pings, bins))


@st.composite
def hostile_images(draw):
    """(image, range_bin, altitude): valid images (finite, >= 0), friendly to hostile.

    Kinds: all zeros, constant, uniform noise, a speckled flat seabed, the same saturated (clipped
    at a percentile), with a black near half (water column), or a few isolated spikes; scaled by
    10^-38 .. 10^38.
    """
    pings = draw(st.integers(2, 16))
    bins = draw(st.integers(64, 256))
    range_bin = draw(st.sampled_from([0.02, 0.05, 0.1, 0.25]))
    alt = draw(st.floats(0.1, 0.7)) * bins * range_bin
    kind = draw(st.sampled_from(IMAGE_KINDS))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    # any level a float32 image file can hold (beyond it: tests/test_regressions.py)
    amp = 10.0 ** draw(st.floats(-38.0, 38.0))
    base = _flat_like(rng, pings, bins, range_bin, alt)
    if kind == "zeros":
        img = np.zeros((pings, bins))
    elif kind == "constant":
        img = np.ones((pings, bins))
    elif kind == "noise":
        img = rng.uniform(0.0, 1.0, (pings, bins))
    elif kind == "seabed":
        img = base
    elif kind == "saturated":
        img = np.minimum(base, np.percentile(base, draw(st.floats(10.0, 95.0))))
    elif kind == "black_water":
        img = base.copy()
        img[:, : int(0.5 * bins)] = 0.0
    else:
        img = np.zeros((pings, bins))
        n = draw(st.integers(1, 20))
        img[rng.integers(0, pings, n), rng.integers(0, bins, n)] = rng.uniform(0.5, 1.0, n)
    return amp * img, range_bin, alt


@stress(40)
@given(case=hostile_images(), levels=st.integers(1, 3), given_alt=st.booleans())
def test_inversion_is_finite_and_monotone(case, levels, given_alt):
    from sonar_raster.inversion.solver import invert

    img, range_bin, alt = case
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            inv = invert(
                img, range_bin, altitude=alt if given_alt else None, levels=levels, max_iter=15
            )
    except SonarRasterError as exc:
        # The only refusals allowed for a valid image: no bottom return to find, or an image
        # too small for the ground grid (a one-line, actionable error, not a crash).
        assert "bottom return" in str(exc) or "ground cells" in str(exc), exc
        assume(False)
        return
    ok = np.isfinite(inv.elevation)
    for name in ("reflectivity", "beam", "elevation", "ground"):
        arr = getattr(inv, name)
        assert np.array_equal(np.isfinite(arr), ok), f"{name}: NaN outside the no-estimate cells"
    assert np.all(np.isfinite(inv.altitude)) and np.all(inv.altitude > 0)
    assert np.all(np.isfinite(inv.profile.gain)) and np.all(np.isfinite(inv.profile.depression))
    assert np.all(inv.reflectivity[ok] >= 0) and np.all(inv.beam[ok] >= 0)
    for level in inv.energies:
        e = np.asarray(level)
        assert np.all(np.isfinite(e)) and np.all(e >= 0)
        # never increases by more than float noise (E is a sum of squares in float64)
        assert np.all(np.diff(e) <= 1e-12 * e[0]), e


# --------------------------------------------------------------------------- writers


@st.composite
def raw_images(draw) -> SonarImage:
    """Finite, non-negative float32 images: zeros, denormals, huge values, single spikes."""
    pings, bins = draw(st.integers(1, 64)), draw(st.integers(1, 512))
    sides = draw(SIDES)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kind = draw(st.sampled_from(["zeros", "uniform", "lognormal", "spike", "extremes"]))
    out = {}
    for side in sides:
        if kind == "zeros":
            a = np.zeros((pings, bins))
        elif kind == "uniform":
            a = rng.uniform(0.0, 10.0 ** draw(st.floats(-30.0, 30.0)), (pings, bins))
        elif kind == "lognormal":
            a = rng.lognormal(0.0, draw(st.floats(0.1, 20.0)), (pings, bins))
        elif kind == "spike":
            a = np.zeros((pings, bins))
            a[rng.integers(pings), rng.integers(bins)] = 10.0 ** draw(st.floats(-40.0, 38.0))
        else:
            choices = np.array([0.0, 1e-45, 1.2e-38, 1.0, 3.0e38])
            a = rng.choice(choices, (pings, bins))
        out[side] = np.minimum(a, np.finfo(np.float32).max).astype(np.float32)
    range_bin = draw(st.floats(0.01, 0.5))
    return SonarImage(out, Sonar(max_range=bins * range_bin, range_bin=range_bin, sides=sides))


def _strict_json(path) -> object:
    def bad(name):
        raise AssertionError(f"{path.name} holds {name}")

    return json.loads(path.read_text(), parse_constant=bad)


@stress(100)
@given(image=raw_images(), bit_depth=st.sampled_from([8, 16]))
def test_writers_round_trip_finite(tmp_path_factory, image, bit_depth):
    from sonar_raster.io import images as io

    tmp = tmp_path_factory.mktemp("w")
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        exr = io.write_image(image, tmp / "a.exr")
        png = io.write_image(image, tmp / "a.png", bit_depth=bit_depth)
    sides, _ = io.read_exr(exr[0])
    assert set(sides) == set(image.sides)
    for side, a in image.sides.items():
        assert np.array_equal(sides[side], a), side  # linear EXR is bit exact, no NaN made
    pixels, spec = io.read_pixels(png[0])
    assert np.all(np.isfinite(pixels)) and pixels.min() >= 0.0 and pixels.max() <= 1.0
    assert pixels.shape[:2] == image.display().shape
    # zeros (shadow, water column) stay black; positive values are never brighter than full
    assert np.all(pixels[..., 0][image.display() == 0] == 0.0)
    for sidecar in (exr[1], png[1]):
        doc = _strict_json(sidecar)
        assert isinstance(doc, dict)
