"""Reflectivity, beam profile and elevation of the seabed from one side of a sonar image.

The slant-range image is resampled to ground range over a flat seabed at the altitude of the
first bottom return (for the initial R and Φ and the shadow ties), then the Lambertian model
(:mod:`sonar_raster.inversion.model`, seed Eqs. 12–14 with K absorbed into Φ), which places each
ground cell's return at its own slant range, is fitted to the slant-range image by least
squares (Eq. 16) with EM iterations (:mod:`sonar_raster.inversion.em`) on a three-level pyramid,
Φ constrained to be equal at equal depression angle (Eq. 21) and reflectivity in shadows tied
to the nearest lit cell (:mod:`sonar_raster.inversion.priors`). Each finer level keeps the
lowest-energy of three starts (see :func:`_solve`).

Z is the elevation relative to the transducer in metres, negative below it. The result also
carries the image reprojected to ground range at the recovered Z and the evenly illuminated
image of seed Eq. 22 (:mod:`.products`); :mod:`.write` writes
them with a textured mesh (:mod:`sonar_raster.meshio.export`) and preview renders
(:mod:`sonar_raster.rendering.gl.preview`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._checks import integer, positive
from ..errors import SonarRasterError
from ..image import SonarImage
from . import pyramid
from .bottom import track_side
from .em import Problem, Steps, iterate
from .ground import check_slant, ground_axis, ground_to_slant, slant_to_ground
from .model import Geometry
from .priors import angle_bins, estimate_looks, nearest_lit, profile_median, shadows

__all__ = [
    "BeamProfile",
    "Inversion",
    "ground_to_slant",
    "invert",
    "slant_to_ground",
    "Steps",
]

#: Initial reflectivity (seed: "typically 0.9").
INITIAL_REFLECTIVITY = 0.9
#: Weight of the reflectivity roughness ``Σ (ΔR)²`` against the data term, in units of the
#: mean squared data per ground cell over the mean R².
REFLECTIVITY_SMOOTHING = 10.0
#: Weight of the beam-profile curvature ``Σ (Δ²Φ)²`` in the same units (per ping).
BEAM_SMOOTHING = 100.0
#: ε of the edge-preserving reflectivity roughness, as a fraction of the initial mean R
#: (0: quadratic). Jumps in R much larger than ε (patches of another material) cost
#: ``2ε |ΔR|`` instead of ``ΔR²``, so they stay in R instead of turning into relief.
REFLECTIVITY_EDGE = 0.0
#: Ground cells whose slant range at the altitude lies within this many bins of the last fitted
#: bin get no estimate (NaN): their returns and their slope neighbours' fall partly outside the
#: data (measurements: docs/inversion.md).
EDGE_BINS = 6
#: Points each ground cell's return is spread over along its tangent plane (see
#: :mod:`sonar_raster.inversion.model`); more points model a flat seabed more exactly but did
#: not invert better (docs/inversion.md), so 1.
SUBSAMPLES = 1
#: Standard deviations of the seabed's relief about the flat seabed at the altitude (metres) and
#: of its slopes assumed by the priors on a speckled image (``looks`` of :func:`invert`).
RELIEF_STD = 0.1
SLOPE_STD = 0.2
#: σ of the flat-seabed prior's low-pass (``flat_prior`` of :func:`invert`), as a fraction of
#: the median altitude (2 m at 10 m).
FLAT_PRIOR_SCALE = 0.2


@dataclass(frozen=True)
class BeamProfile:
    """A sensor's recovered beam profile Φ against depression angle.

    Attributes
    ----------
    depression : ndarray, shape (n,)
        Depression angles below the horizontal, radians.
    gain : ndarray, shape (n,)
        Φ at those angles, in the units of the ground-range image (intensity per metre of
        ground range per unit reflectivity).
    """

    depression: np.ndarray
    gain: np.ndarray

    def __post_init__(self) -> None:
        dep = np.asarray(self.depression, dtype=np.float64)
        gain = np.asarray(self.gain, dtype=np.float64)
        if dep.ndim != 1 or dep.shape != gain.shape or dep.size < 2:
            raise SonarRasterError(
                f"a beam profile needs depression and gain as two equal 1-D lists of >= 2 "
                f"values, got shapes {dep.shape} and {gain.shape}"
            )
        object.__setattr__(self, "depression", dep)  # arrays, whatever the caller gave
        object.__setattr__(self, "gain", gain)

    def __call__(self, depression: np.ndarray) -> np.ndarray:
        """Φ at the given depression angles (linear interpolation, held at the ends)."""
        order = np.argsort(self.depression)
        return np.interp(depression, self.depression[order], self.gain[order])

    def save(self, path: str | os.PathLike) -> None:
        """Write the profile as JSON (``depression_rad``, ``gain``)."""
        doc = {"depression_rad": self.depression.tolist(), "gain": self.gain.tolist()}
        Path(path).write_text(json.dumps(doc, indent=1))

    @classmethod
    def load(cls, path: str | os.PathLike) -> BeamProfile:
        """Read a profile written by :meth:`save`.

        ``path`` may also be a folder holding one ``beam_profile.json`` (an output folder).
        """
        path = Path(path)
        if path.is_dir():
            if not (path / "beam_profile.json").is_file():
                raise SonarRasterError(
                    f"{path} holds no beam_profile.json (an invert output folder has one per "
                    "side); give that file or folder"
                )
            path = path / "beam_profile.json"
        try:
            doc = json.loads(path.read_text())
            profile = cls(doc["depression_rad"], doc["gain"])  # SonarRasterError: a ValueError
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise SonarRasterError(f"cannot read beam profile {path}: {exc}") from None
        return profile.checked(f"beam profile {path}")

    def checked(self, where: str = "the beam profile") -> BeamProfile:
        """The profile itself if its values are finite and its gain >= 0, else one line.

        What a profile from a file or a user must be; ``where`` names it in the message.
        """
        if not (np.all(np.isfinite(self.depression)) and np.all(np.isfinite(self.gain))):
            raise SonarRasterError(f"{where} holds NaN or infinite values")
        if np.any(self.gain < 0):
            raise SonarRasterError(f"{where}: its gain must be >= 0")
        return self


def load_beams(path: str | os.PathLike) -> BeamProfile | dict[str, BeamProfile]:
    """A calibrated beam for the surface fit: one profile for every side, or one per side.

    A file is a ``beam_profile.json``; a folder is an earlier ``invert`` run's output, whose
    ``SIDE/beam_profile.json`` (``line_1/SIDE/`` for survey lines) or single
    ``beam_profile.json`` is read.
    """
    where = Path(path)
    found = {}
    for side in ("port", "starboard") if where.is_dir() else ():
        for folder in (where / side, where / "line_1" / side):
            if (folder / "beam_profile.json").is_file():
                found[side] = BeamProfile.load(folder / "beam_profile.json")
                break
    return found or BeamProfile.load(where)


@dataclass(frozen=True)
class Inversion:
    """Result of :func:`invert`; maps are (pings, ground cells), NaN where no estimate.

    Attributes
    ----------
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres.
    altitude : ndarray, shape (pings,)
        Altitude per ping used for the ground-range conversion, metres.
    ground : ndarray
        The image in ground range, intensity per metre of ground range.
    reflectivity, beam, elevation : ndarray
        R, Φ and Z (metres relative to the transducer, negative below).
    profile : BeamProfile
        Φ against depression angle at the finest level.
    energies : list of list of float
        E per iteration for each level, coarsest first (the start kept at that level).
    reprojected : ndarray or None
        The image in ground range at the recovered elevation, intensity per metre of ground
        range (see :func:`sonar_raster.inversion.products.reproject`).
    even : ndarray or None
        The evenly illuminated ground-range image of seed Eq. 22, ``reprojected / (Φ cos⟨θ⟩)``
        (see :mod:`sonar_raster.inversion.products`).
    ping_spacing : float
        Along-track distance between pings used for the along-track slopes, metres.
    runs : list of dict
        Per level, coarsest first: ``factor``, ``pings``, ``cells``, ``kept`` (the start kept)
        and ``starts``, one dict per start with ``start``, ``iterations``, ``energy`` (final E)
        and ``stopped`` (``"tol"``, ``"stalled"`` or ``"max_iter"``).
    settings : dict
        The options the inversion ran with: ``method`` (``"profiles"``, or ``"surface"`` for
        the surface fit's results, whose other keys are its own), ``levels``, ``max_iter``, ``tol``,
        ``flat_prior``, ``looks`` (the number used, None without priors), ``relief_std``,
        ``slope_std``, ``calibrated`` (Φ fixed from a profile) and ``altitude`` (``"given"`` or
        ``"first return"``).
    elevation_std : ndarray or None
        Standard deviation of Z per cell, metres, where the method estimates it (the surface
        fit, :func:`sonar_raster.inversion.surface.invert_line`).
    """

    x: np.ndarray
    altitude: np.ndarray
    ground: np.ndarray
    reflectivity: np.ndarray
    beam: np.ndarray
    elevation: np.ndarray
    profile: BeamProfile
    energies: list[list[float]] = field(default_factory=list)
    reprojected: np.ndarray | None = None
    even: np.ndarray | None = None
    ping_spacing: float = math.nan
    runs: list[dict] = field(default_factory=list)
    settings: dict = field(default_factory=dict)
    elevation_std: np.ndarray | None = None

    @property
    def iterations(self) -> int:
        """Accepted EM iterations summed over the levels."""
        return sum(len(e) - 1 for e in self.energies)


def _flat_cos(level: pyramid.Level) -> np.ndarray:
    x, h = level.geom.x[None, :], level.altitude[:, None]
    return h / np.sqrt(x * x + h * h)


def _initial_beam(level: pyramid.Level, bins: np.ndarray, reflectivity: float) -> np.ndarray:
    ratio = level.image / (reflectivity * _flat_cos(level))
    return profile_median(ratio, level.weight, bins, level.image.shape[1])


def _initial_reflectivity(level: pyramid.Level, phi_cells: np.ndarray, beam) -> float:
    """0.9 (seed), or with a calibrated beam the median of ``I / (Φ cos θ_flat)``."""
    if beam is None:
        return INITIAL_REFLECTIVITY
    model = phi_cells * _flat_cos(level)
    keep = (level.weight > 0) & (model > 0)
    if not keep.any():
        return INITIAL_REFLECTIVITY
    return float(np.median(level.image[keep] / model[keep]))


def _ties(level: pyramid.Level, phi_cells: np.ndarray) -> np.ndarray:
    model = phi_cells * _flat_cos(level)
    normalised = np.where(model > 0, level.image / np.where(model > 0, model, 1.0), 0.0)
    return nearest_lit(shadows(normalised, level.weight))


@dataclass
class _State:
    r: np.ndarray
    phi: np.ndarray
    z: np.ndarray
    centres: np.ndarray


def _start(level: pyramid.Level, bins: np.ndarray, centres: np.ndarray, prev, coarse, beam):
    if beam is not None:
        phi = beam(centres)
    elif prev is None:
        phi = _initial_beam(level, bins, INITIAL_REFLECTIVITY)
    else:
        order = np.argsort(prev.centres)
        phi = np.interp(centres, prev.centres[order], prev.phi[order])
    if prev is None:
        r = np.full(level.image.shape, _initial_reflectivity(level, phi[bins], beam))
        z = np.repeat(-level.altitude[:, None], level.image.shape[1], axis=1)
    else:
        r = pyramid.upsample(prev.r, coarse, level)
        z = pyramid.upsample(prev.z, coarse, level)
    return _State(r, phi, z, centres)


def _check(slant: np.ndarray, range_bin: float, levels: int) -> np.ndarray:
    if isinstance(slant, (dict, SonarImage)):
        raise SonarRasterError(
            "invert takes one side's (pings, bins) array, e.g. image.sides['starboard']; "
            "for both sides at once use the surface fit (sonar_raster.inversion.surface)"
        )
    integer("levels", levels)
    positive("range_bin (metres)", range_bin)
    return check_slant(slant, range_bin, min_pings=2)


def _altitudes(slant: np.ndarray, range_bin: float, altitude, looks: float | None) -> np.ndarray:
    if altitude is None:
        # the tracker averages pings by the image's looks (estimated if the priors are off)
        return track_side(slant, range_bin, looks=looks).altitude
    alt = np.broadcast_to(np.asarray(altitude, dtype=np.float64), (slant.shape[0],)).copy()
    if not (np.all(np.isfinite(alt)) and np.all(alt > 0)):
        raise SonarRasterError("altitude must be > 0 metres")
    return alt


def invert(
    slant: np.ndarray,
    range_bin: float,
    *,
    altitude: float | np.ndarray | None = None,
    ping_spacing: float | None = None,
    ground_bin: float | None = None,
    levels: int = 3,
    max_iter: int = 300,
    tol: float = 1e-2,
    beam: BeamProfile | str | os.PathLike | None = None,
    steps: Steps | None = None,
    flat_prior: float = 0.0,
    looks: float | str | None = "auto",
    relief_std: float = RELIEF_STD,
    slope_std: float = SLOPE_STD,
    progress: bool = False,
) -> Inversion:
    """Recover reflectivity R, beam profile Φ and elevation Z from one side of an image.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Linear intensity, >= 0; columns are slant-range bins from range 0 outward.
    range_bin : float
        Slant-range bin size, metres.
    altitude : float or ndarray of shape (pings,), optional
        Sonar altitude, metres; by default from the first bottom return of each ping.
    ping_spacing : float, optional
        Along-track distance between pings, metres (default: the ground bin).
    ground_bin : float, optional
        Ground-range cell size, metres, at most ``range_bin`` (default: ``range_bin``). Each
        cell's return is placed at one range and split between the two nearest bins, so cells
        longer than a bin in range would alias; they are refused.
    levels : int
        Pyramid levels (each halves both axes).
    max_iter : int
        Most EM iterations per level.
    tol : float
        Each start of a level stops when an iteration lowers E by less than ``tol * E``. E has
        near-flat directions (absolute level, tilt, Φ against relief) that long runs drift
        along, so the default 1e-2 also regularises (run time against error:
        docs/inversion.md).
    beam : BeamProfile or path, optional
        Calibrated mode: Φ fixed from this profile (or a ``beam_profile.json``, or an output
        folder holding one); only R and Z are estimated.
    steps : Steps, optional
        Relative step weights of R, Φ, Z (default all 1).
    flat_prior : float
        Weight of a prior that the seabed is flat at the altitude on scales above
        ``FLAT_PRIOR_SCALE`` × the altitude (2 m at 10 m): ``Σ (G (Z − Z_flat))²``, ``G`` a
        Gaussian low-pass, a deviation of one range bin costing ``flat_prior`` times the mean
        squared data of a ground cell. 0 (default) leaves it out. The image hardly fixes a
        broad bending of Z (R and Φ absorb it; docs/inversion.md derives why), and the prior
        holds it at the altitude's flat seabed. For broadly flat seabeds with small relief and
        a trusted ``altitude``; it flattens relief broader than the low-pass.
    looks : float, "auto" or None
        Speckle looks L of the image: each bin's intensity is taken to vary about the model
        with variance ``Î² / L``, and two priors on Z join the fit with weights of that noise
        variance over the assumed variance of the relief (``relief_std``, about the flat
        seabed at the altitude) and of the slopes (``slope_std``, across and along track):
        the MAP estimate under Gaussian noise, relief and slopes. ``"auto"`` (default) estimates
        L from neighbouring pings (:func:`sonar_raster.inversion.priors.estimate_looks`, at
        least 1); None leaves the priors out, for noise-free images (on a speckled image
        speckle then turns into relief).
    relief_std, slope_std : float
        Standard deviations assumed by those priors: relief in metres, slopes as rise over
        run.
    progress : bool
        Show a progress bar per level.

    Returns
    -------
    Inversion

    Raises
    ------
    SonarRasterError
        For an empty, non-finite or negative image, or bad sizes.
    """
    original = _check(slant, range_bin, levels)
    if isinstance(beam, (str, os.PathLike)):
        beam = BeamProfile.load(beam)
    if beam is not None:
        if not isinstance(beam, BeamProfile):
            raise SonarRasterError(
                f"beam must be a BeamProfile or the path of a beam_profile.json, got "
                f"{type(beam).__name__}"
            )
        beam.checked()
    integer("max_iter", max_iter)
    positive("tol", tol)
    if ping_spacing is not None:
        positive("ping_spacing (metres)", ping_spacing)
    if not (math.isfinite(flat_prior) and flat_prior >= 0):
        raise SonarRasterError(f"flat prior must be a number >= 0, got {flat_prior!r}")
    for name, value in (("relief_std", relief_std), ("slope_std", slope_std)):
        if not (isinstance(value, (int, float)) and 0 < value < math.inf):
            raise SonarRasterError(f"{name} must be a number > 0, got {value!r}")
    # Fit a copy scaled by a power of two (exact) to order one, so no weight or Gauss-Newton
    # matrix under- or overflows whatever the image's units; Φ takes the scale back at the end.
    scale = _power_of_two_scale(original)
    image = original / scale
    if beam is not None:
        beam = BeamProfile(beam.depression, beam.gain / scale)
    noise_looks = _looks(looks, image)
    alt = _altitudes(image, range_bin, altitude, noise_looks)
    dx = float(ground_bin or range_bin)
    if not (math.isfinite(dx) and 0 < dx <= range_bin * (1 + 1e-9)):
        raise SonarRasterError(
            f"ground bin must be > 0 and at most the range bin ({range_bin:g} m), got {dx:g}: "
            "larger ground cells alias in the model"
        )
    x = ground_axis(alt, range_bin, image.shape[1], dx)
    ground, valid = slant_to_ground(image, range_bin, alt, x)
    spacing = float(ping_spacing or dx)
    geom = Geometry(x, dx, spacing, float(range_bin), image.shape[1], SUBSAMPLES)
    chain = pyramid.build(ground, valid, image / range_bin, alt, geom, levels)
    steps = steps or Steps()
    if beam is not None:
        steps = Steps(steps.r, 0.0, steps.z)
    opts = _Options(
        beam,
        steps,
        max_iter,
        tol,
        progress,
        flat_prior,
        noise_looks,
        relief_std,
        slope_std,
    )
    state, coarse, energies, runs = None, None, [], []
    for k, level in enumerate(chain):
        label = f"level {k + 1}/{len(chain)} (1/{level.factor} res.)"
        state, e, run = _solve(level, state, coarse, opts, label)
        energies.append(e)
        runs.append(run)
        coarse = level
    inv = _rescaled(_result(chain[-1], state, ground, valid, energies), scale)
    if not np.any(np.isfinite(inv.elevation)):
        pings, bins = image.shape
        raise SonarRasterError(
            f"no ground cell could be fitted in {pings} pings x {bins} bins (altitude "
            f"{np.nanmedian(alt):.3g} m, range {bins * range_bin:.3g} m): give the image as "
            "(pings, slant-range bins) with its range bin, reaching well past the first return"
        )
    settings = {
        "method": "profiles",
        "levels": len(chain),
        "max_iter": max_iter,
        "tol": tol,
        "flat_prior": flat_prior,
        "looks": opts.looks if opts.looks is not None and math.isfinite(opts.looks) else None,
        "relief_std": relief_std,
        "slope_std": slope_std,
        "calibrated": beam is not None,
        "altitude": "first return" if altitude is None else "given",
    }
    return _with_products(inv, original, range_bin, geom.dy, runs, settings)


def _power_of_two_scale(image: np.ndarray) -> float:
    """2**k nearest the image's largest value (1 for an all-zero image)."""
    top = float(image.max(initial=0.0))
    return 2.0 ** round(math.log2(top)) if top > 0 else 1.0


def _rescaled(inv: Inversion, scale: float) -> Inversion:
    """Undo the fitting scale: the image and Φ carry it, R and Z do not; E goes as its square."""
    from dataclasses import replace

    if scale == 1.0:
        return inv
    profile = BeamProfile(inv.profile.depression, inv.profile.gain * scale)
    energies = [[e * scale * scale for e in level] for level in inv.energies]
    return replace(
        inv, ground=inv.ground * scale, beam=inv.beam * scale, profile=profile, energies=energies
    )


def _with_products(
    inv: Inversion, image: np.ndarray, range_bin: float, dy: float, runs, settings: dict
) -> Inversion:
    from dataclasses import replace

    from .products import even_illumination, reproject

    ground = reproject(image, range_bin, inv.x, inv.elevation)
    even = even_illumination(ground, inv.beam, inv.x, inv.elevation)
    return replace(
        inv, reprojected=ground, even=even, ping_spacing=dy, runs=runs, settings=settings
    )


def _data_scale(level: pyramid.Level, r: np.ndarray) -> float:
    """Mean ``w I²`` per ground cell over R², the unit of the roughness weight."""
    scale = float(np.sum(level.slant_weight * level.slant**2)) / max(level.image.size, 1)
    r2 = float(np.mean(r * r))
    return scale / r2 if r2 > 0 else 0.0


@dataclass(frozen=True)
class _Options:
    """How every level is fitted (see :func:`invert`); ``looks`` resolved to a number or None."""

    beam: BeamProfile | None
    steps: Steps
    max_iter: int
    tol: float
    progress: bool
    flat_prior: float
    looks: float | None
    relief_std: float
    slope_std: float

    def noise_priors(self, level: pyramid.Level) -> tuple[float, float]:
        """Weights of the relief and slope priors at ``level``: σ² / a² and σ² / s².

        With L-look speckle a bin's intensity has variance ``Î² / L`` and ``E[I²] = Î² (1 +
        1/L)``; pooling ``f × f`` bins at a coarser level divides the variance by ``f²``.
        Under Gaussian noise of the mean variance σ², Gaussian relief of std ``a`` and slopes of
        std ``s``, the MAP estimate minimises
        ``Σ (I − Î)² + σ²/a² Σ (Z − Z_flat)² + σ²/s² Σ |∇Z|²``.
        """
        keep = level.slant_weight > 0
        if self.looks is None or not math.isfinite(self.looks) or not keep.any():
            return 0.0, 0.0
        mean_square = float(np.mean(level.slant[keep] ** 2))
        variance = mean_square / (self.looks * level.factor**2 + 1.0)
        return variance / self.relief_std**2, variance / self.slope_std**2


def _looks(looks: float | str | None, image: np.ndarray) -> float | None:
    """``looks`` of :func:`invert` as a number (estimated for ``"auto"``) or None (no priors)."""
    if looks is None:
        return None
    if isinstance(looks, str):
        if looks != "auto":
            raise SonarRasterError(f"looks must be a number > 0, 'auto' or None, got {looks!r}")
        # Single look is the noisiest fully developed speckle; a lower estimate comes from
        # relief or texture that changes between pings (or pings that share no seabed).
        return max(estimate_looks(image, np.ones_like(image)), 1.0)
    if not (isinstance(looks, (int, float)) and looks > 0):
        raise SonarRasterError(f"looks must be a number > 0, 'auto' or None, got {looks!r}")
    return float(looks)


def _solve(level, prev, coarse, opts: _Options, label):
    """Fit one level; below the coarsest, from three starts, keeping the lowest final E.

    The starts are the coarser level's R, Φ and Z; its R and Φ over the flat seabed at the
    detected altitude; and a fresh start as at the coarsest level. The coarse levels alias
    relief finer than a few of their cells, and their Z can trap the finer level.
    """
    bins, centres = angle_bins(level.geom.x, level.altitude)
    st = _start(level, bins, centres, prev, coarse, opts.beam)
    tie = _ties(level, st.phi[bins])
    smooth = REFLECTIVITY_SMOOTHING * _data_scale(level, st.r)
    scale = _data_scale(level, st.r) * float(np.mean(st.r * st.r))
    phi2 = float(np.mean(st.phi**2)) or 1.0
    smooth_phi = BEAM_SMOOTHING * scale * level.image.shape[0] / phi2
    edge = REFLECTIVITY_EDGE * float(np.mean(st.r))
    unit = level.geom.range_bin / level.factor  # the image's range bin
    sigma = FLAT_PRIOR_SCALE * float(np.median(level.altitude))
    prob = Problem(
        level.slant,
        level.slant_weight,
        level.geom,
        bins,
        tie,
        smooth,
        smooth_phi,
        edge,
        opts.flat_prior * scale / unit**2,
        (sigma / level.geom.dy, sigma / level.geom.dx),
        np.repeat(-level.altitude[:, None], level.image.shape[1], axis=1),
        *opts.noise_priors(level),
    )
    runs = [("coarser", st)]
    if prev is not None:
        fresh = _start(level, bins, centres, None, None, opts.beam)
        runs.append(("coarser R, Φ; flat Z", _State(st.r, st.phi, fresh.z, centres)))
        runs.append(("fresh", fresh))
    bar = None
    if opts.progress:
        from tqdm import tqdm

        # over the starts' iteration budget (max_iter each); a start that converges early
        # gives its unused budget back at once, so the bar ends at 100 % with the level and its
        # time left is an upper bound; the iterations actually run are in the postfix
        fmt = "{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]"
        bar = tqdm(total=opts.max_iter * len(runs), desc=label, bar_format=fmt, leave=True)
    tick = bar.update if bar is not None else None
    best: tuple | None = None
    kept, report, ran = "", [], 0
    for k, (name, s0) in enumerate(runs):
        if bar is not None:
            bar.set_postfix_str(f"start {k + 1}/{len(runs)}", refresh=False)
            budget_end = bar.n + opts.max_iter
        out = iterate(
            prob,
            s0.r.ravel(),
            s0.phi,
            s0.z,
            steps=opts.steps,
            max_iter=opts.max_iter,
            tol=opts.tol,
            tick=tick,
        )
        report.append(
            {"start": name, "iterations": len(out[3]) - 1, "energy": out[3][-1], "stopped": out[4]}
        )
        ran += len(out[3]) - 1
        if bar is not None:
            bar.set_postfix_str(f"start {k + 1}/{len(runs)}, {ran} iterations", refresh=False)
            bar.update(max(0, budget_end - bar.n))
        if best is None or out[3][-1] < best[3][-1]:
            best, kept = out, name
    assert best is not None  # runs is never empty
    r, phi, z, e, _ = best
    if bar is not None:
        bar.close()
    r_cells, _ = prob.cells(r, phi)
    pings, cells = level.image.shape
    run = {"factor": level.factor, "pings": pings, "cells": cells, "kept": kept, "starts": report}
    return _State(r_cells, phi, z, centres), e, run


def _beyond_data(level: pyramid.Level) -> np.ndarray:
    """Cells within ``EDGE_BINS`` of the last fitted slant bin of their ping, (pings, cells)."""
    last = level.slant_weight.shape[1] - 1 - np.argmax(level.slant_weight[:, ::-1] > 0, axis=1)
    end = (last + 0.5 - EDGE_BINS) * level.geom.range_bin
    rho = np.hypot(level.geom.x[None, :], level.altitude[:, None])
    return rho > end[:, None]


def _result(level, st, ground, valid, energies) -> Inversion:
    missing = ~valid | _beyond_data(level)
    bins, centres = angle_bins(level.geom.x, level.altitude)
    return Inversion(
        x=level.geom.x,
        altitude=level.altitude,
        ground=np.where(missing, np.nan, ground),
        reflectivity=np.where(missing, np.nan, st.r),
        beam=np.where(missing, np.nan, st.phi[bins]),
        elevation=np.where(missing, np.nan, st.z),
        profile=BeamProfile(centres, st.phi.copy()),
        energies=energies,
    )
