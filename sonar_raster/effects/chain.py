"""Sensor effects: turn the renderer's raw geometric image into what a sonar records.

The raw image (:class:`SonarImage`) holds, per ping strip and slant-range bin, the beam-weighted
backscattering area ``Σ Φ R cos θ dA`` in m² — the vertical beam pattern Φ is already in it.
:func:`apply_effects` runs the enabled stages in this fixed, physical order; a disabled stage
costs nothing, and with every stage off the input arrays come back untouched:

1. ``along_track`` — horizontal beam: each range column is blurred along pings by the two-way
   beam footprint, a Gaussian of full width ``β r / √2`` (side-scan; ``β`` the one-way -3 dB
   beam width, ``0.886 λ / L`` for an array of length L) or a constant δ (SAS). The kernel has
   unit peak: a point target keeps its level, a seabed returns the sum over its footprint.
2. ``nadir_gap`` — no returns from within ``nadir_gap_deg`` of the vertical below the sonar.
3. ``water_column`` — volume reverberation in the bins before each ping's first bottom return,
   which are exactly zero in the raw image: a constant level ``water_column_db`` (dB re 1 m²,
   raw units) and/or a volume backscattering strength ``volume_db`` = Sv (dB re 1 m⁻¹), whose
   raw value in a bin is the scattering cross-section of the water the bin holds,
   ``Sv · δr · r · Ψ · w(r)``: δr the bin, ``Ψ = ∫ Φ dα`` the two-way vertical beam integrated
   over depression angles (radians), ``w(r)`` the equivalent along-track width of the two-way
   footprint (``√(2π) σ Δy``; the ping spacing Δy without an along-track beam). After
   spreading it falls as ``r⁻³``, like the seabed it is compared with.
4. ``speckle`` — multiplicative unit-mean speckle, exponential or K-distributed, correlated at
   the resolution cell (along track: the footprint above; across: ``range_resolution_m``).
   With ``downsample`` ("max" or "mean", XTF DownsampleMethod MAX / RMS) the field is made on
   the recorder's sub-sample grid (``sample_spacing_m``) and each recorded bin keeps the
   largest or the mean of its sub-samples, K texture applied before that reduction.
5. ``spreading`` — two-way spherical spreading, intensity × ``r⁻⁴`` at the bin centre r (m).
   Convention: the raw image is an integrated scattering area σ (m²); after this stage a value
   is the echo intensity relative to the source level at 1 m, ``σ / r⁴`` (``TS - 40 log r``).
6. ``absorption`` — × ``10^(-2 α r / 10)``, α from Francois & Garrison (1982) for the sonar's
   frequency and the water's temperature, salinity, depth and pH (or given directly).
7. ``noise`` — additive receiver noise, exponentially distributed intensity of mean
   ``10^(noise_db / 10)`` in the image's units at this point (with spreading on: noise level
   minus source level, dB), independent per pixel; with ``downsample`` on, band-limited to the
   range resolution and reduced per bin like the speckle (same mean level).
8. ``tvg`` — time-varied gain ``× 10^(G(r) / 10)``, ``G = N log10 r + 2 α r`` (N = 40 undoes the
   spreading of a point target, 30 that of a seabed seen through a side-scan footprint that
   grows as r) or a user curve of (range m, gain dB) points, linearly interpolated.
9. ``gain`` — a fixed gain in dB.
10. ``saturate`` — values above the full-scale level clip to it. Full scale: ``saturation``;
    else ``headroom_db`` above the median positive value (a receiver gain that puts the seabed
    that far below full scale, as a recorder's operator does); else the image's largest value.
11. ``quantise`` — rounding to ``2**bits - 1`` steps of full scale, of the intensity or, with
    ``quantise_amplitude``, of its square root (the envelope a recorder digitises, so 16 bits
    span 96 dB of amplitude); values stay in image units. A
    positive value never rounds to code 0: it keeps at least one step (a receiver's noise floor
    sits above its converter's last bit), so shadows and the water column hold the noise floor,
    never exact zeros.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import integer, non_negative, number, positive
from ..errors import InputWarning, SonarRasterError, SonarRasterTypeError
from ..image import SonarImage
from ..sonar import SIDES
from ..trajectory import Trajectory

#: Stage names in the order they run.
STAGES = (
    "along_track",
    "nadir_gap",
    "water_column",
    "speckle",
    "spreading",
    "absorption",
    "noise",
    "tvg",
    "gain",
    "saturate",
    "quantise",
)
SPECKLE_KINDS = ("off", "exponential", "k")
DOWNSAMPLE_KINDS = ("off", "max", "mean")
TVG_KINDS = ("off", "log", "curve")
QUANTISE_BITS = (8, 12, 16)


#: Fields that are None (off) or a number > 0.
_POSITIVE_OR_NONE = (
    "along_beam_deg",
    "array_length_m",
    "sas_resolution_m",
    "ping_spacing_m",
    "saturation",
    "range_resolution_m",
    "sample_spacing_m",
)
#: Fields that are None or a finite number (their ranges are checked apart).
_NUMBER_OR_NONE = (
    "headroom_db",
    "nadir_gap_deg",
    "water_column_db",
    "volume_db",
    "noise_db",
    "absorption_db_m",
)
#: Fields that are always a finite number (k_shape > 0).
_NUMBERS = (
    "k_shape",
    "speckle_looks",
    "temperature_c",
    "salinity_psu",
    "depth_m",
    "ph",
    "tvg_log_coefficient",
    "gain_db",
)
#: Largest constant gain, dB (10^30 in intensity: float32 holds 3.4e38).
MAX_GAIN_DB = 300.0

_ALONG_MODES = ("along_beam_deg", "array_length_m", "sas_resolution_m")


def _is_real(value: Any) -> bool:
    """An int or a float already (text, bools and other types are not)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass(frozen=True)
class Effects:
    """Which sensor effects to apply, with their physical parameters (all off by default).

    Attributes
    ----------
    along_beam_deg : float, optional
        Side-scan horizontal beam width (one-way, -3 dB), degrees.
    array_length_m : float, optional
        Side-scan array length L, metres; the beam width is ``0.886 λ / L``.
    sas_resolution_m : float, optional
        SAS mode: constant along-track resolution (-3 dB width), metres.
    ping_spacing_m : float, optional
        Along-track distance between pings, metres; default: from the trajectory or metadata.
    nadir_gap_deg : float, optional
        Half-angle of the blind cone below the sonar, degrees from the vertical, in (0, 90).
    water_column_db : float, optional
        Water-column return level before the first bottom return, dB re 1 m² (raw units).
    volume_db : float, optional
        Volume backscattering strength Sv of the water before the first bottom return,
        dB re 1 m⁻¹ (about -90 to -60 at high frequency in coastal water).
    speckle : {"off", "exponential", "k"}
        Speckle statistics.
    k_shape : float
        Shape ν > 0 of the K-distribution (small: patchy; large: nearly exponential).
    speckle_looks : float
        Looks L ≥ 1 per sample: the speckle intensity has the one-point law of L-look speckle
        (gamma of shape L, contrast 1/√L), as when a recorder averages L independent samples
        into one; 1 is fully developed single-look speckle.
    range_resolution_m : float, optional
        Range resolution cell for speckle correlation, metres; default: one range bin.
    downsample : {"off", "max", "mean"}
        How the recorder turns the sub-samples of one recorded bin into its value (XTF
        ``DownsampleMethod``: 2 = MAX; 4 = RMS, the mean intensity): speckle and receiver
        noise are made on the sub-sample grid (``sample_spacing_m``) and reduced per bin
        (``speckle_looks`` and ``k_shape`` then apply to the sub-samples).
    sample_spacing_m : float, optional
        Spacing of the recorder's samples before downsampling, metres (slant range); a bin
        holds ``round(range_bin / sample_spacing_m)`` of them (at least 1).
    spreading : bool
        Apply two-way spherical spreading, ``r⁻⁴``.
    absorption : bool
        Apply two-way absorption, ``2 α r`` dB.
    temperature_c, salinity_psu, depth_m, ph : float
        Water properties for Francois-Garrison absorption (°C, PSU, metres, pH).
    absorption_db_m : float, optional
        α in dB/m, overriding Francois-Garrison.
    noise_db : float, optional
        Receiver noise mean level, dB in the image's units at the receiver.
    tvg : {"off", "log", "curve"}
        Time-varied gain law.
    tvg_log_coefficient : float
        N of ``N log10 r + 2 α r``.
    tvg_curve : tuple of (float, float)
        (slant range m, gain dB) points for ``tvg = "curve"``, range increasing.
    gain_db : float
        Fixed gain, dB.
    saturation : float, optional
        Full-scale level (image units after gain); larger values clip.
    bits : {8, 12, 16}, optional
        Quantise to this many bits of full scale.
    headroom_db : float, optional
        Full scale this many dB above the median positive intensity (when no ``saturation``
        is given); larger values clip.
    quantise_amplitude : bool
        Quantise the amplitude √I rather than the intensity.
    sensor : str, optional
        Name of the sensor preset these effects come from (a label, kept in the metadata; an
        unknown name is refused). In a table (:meth:`from_table`), ``sensor = NAME`` starts
        from that preset's effects and ``sensor = "ideal"`` from none.
    """

    along_beam_deg: float | None = None
    array_length_m: float | None = None
    sas_resolution_m: float | None = None
    ping_spacing_m: float | None = None
    nadir_gap_deg: float | None = None
    water_column_db: float | None = None
    volume_db: float | None = None
    speckle: str = "off"
    k_shape: float = 1.0
    speckle_looks: float = 1.0
    range_resolution_m: float | None = None
    downsample: str = "off"
    sample_spacing_m: float | None = None
    spreading: bool = False
    absorption: bool = False
    temperature_c: float = 10.0
    salinity_psu: float = 35.0
    depth_m: float = 10.0
    ph: float = 8.0
    absorption_db_m: float | None = None
    noise_db: float | None = None
    tvg: str = "off"
    tvg_log_coefficient: float = 30.0
    tvg_curve: tuple[tuple[float, float], ...] = field(default_factory=tuple)
    gain_db: float = 0.0
    saturation: float | None = None
    bits: int | None = None
    headroom_db: float | None = None
    quantise_amplitude: bool = False
    sensor: str | None = None

    def __post_init__(self) -> None:
        self._check_numbers()
        modes = [n for n in _ALONG_MODES if getattr(self, n)]
        if len(modes) > 1:
            raise SonarRasterError(
                f"effects: give only one of {', '.join(modes)} (side-scan beam or SAS resolution)"
            )
        if self.along_beam_deg is not None and self.along_beam_deg >= 180:
            raise SonarRasterError(
                f"effects: along_beam_deg must be below 180 degrees, got {self.along_beam_deg!r}"
            )
        if abs(self.gain_db) > MAX_GAIN_DB:
            raise SonarRasterError(
                f"effects: gain_db must be within ±{MAX_GAIN_DB:g} dB, got {self.gain_db!r}"
            )
        if self.nadir_gap_deg is not None and not 0 < self.nadir_gap_deg < 90:
            raise SonarRasterError(
                f"effects: nadir_gap_deg must be in (0, 90) degrees, got {self.nadir_gap_deg!r}"
            )
        if self.speckle not in SPECKLE_KINDS:
            raise SonarRasterError(
                f"effects: unknown speckle {self.speckle!r}; use {', '.join(SPECKLE_KINDS)}"
            )
        if self.downsample not in DOWNSAMPLE_KINDS:
            raise SonarRasterError(
                f"effects: unknown downsample {self.downsample!r}; "
                f"use {', '.join(DOWNSAMPLE_KINDS)}"
            )
        if self.downsample != "off" and self.sample_spacing_m is None:
            raise SonarRasterError(
                f"effects: downsample {self.downsample!r} needs the recorder's sample spacing: "
                "give sample_spacing_m (metres; on the command line add --sample-spacing M)"
            )
        if self.tvg not in TVG_KINDS:
            raise SonarRasterError(f"effects: unknown tvg {self.tvg!r}; use {', '.join(TVG_KINDS)}")
        self._check_curve()
        if self.bits is not None and self.bits not in QUANTISE_BITS:
            raise SonarRasterError(f"effects: bits must be 8, 12 or 16, got {self.bits!r}")
        if self.absorption or self.tvg == "log":
            self._check_water()
        if self.sensor is not None and not isinstance(self.sensor, str):
            raise SonarRasterError(f"effects: sensor must be a preset name, got {self.sensor!r}")
        if self.sensor is not None and self.sensor != IDEAL:
            from .presets import preset

            try:
                preset(self.sensor)
            except SonarRasterError as exc:
                raise SonarRasterError(f"effects: {exc}") from None

    def _check_numbers(self) -> None:
        """Every numeric field is an int or float (not text), finite, and in its range."""
        for name in (*_POSITIVE_OR_NONE, *_NUMBER_OR_NONE, *_NUMBERS):
            value = getattr(self, name)
            if value is None and name not in _NUMBERS:
                continue
            if not _is_real(value):
                raise SonarRasterError(f"effects: {name} must be a number, got {value!r}")
            check = positive if name in _POSITIVE_OR_NONE or name == "k_shape" else number
            check(f"effects: {name}", value)
        if self.speckle_looks < 1.0:
            raise SonarRasterError(
                f"effects: speckle_looks must be >= 1 (looks per sample), got {self.speckle_looks}"
            )
        if self.absorption_db_m is not None:
            non_negative("effects: absorption_db_m (dB/m)", self.absorption_db_m)

    @classmethod
    def from_table(
        cls,
        table: Mapping[str, Any],
        *,
        base: str | Path | None = None,
        where: str = "[effects]",
        defaults: Effects | None = None,
    ) -> Effects:
        """Effects from an ``[effects]`` table (a scene description, a dataset config).

        Parameters
        ----------
        table : mapping
            Field names of :class:`Effects` to values, as TOML gives them: numbers, strings,
            true/false. ``tvg_curve`` is a list of ``[range_m, gain_db]`` pairs or the name
            of a CSV file of them (:func:`load_tvg_curve`). ``sensor`` names a preset whose
            effects the other keys replace (``"ideal"``: no effects), instead of ``defaults``.
        base : str or Path, optional
            Folder a ``tvg_curve`` file name is relative to (default: the working folder).
        where : str
            Names the table in messages, e.g. ``"scene.toml [effects]"``.
        defaults : Effects, optional
            The effects whose fields the table replaces (default: every effect off).

        Returns
        -------
        Effects

        Raises
        ------
        SonarRasterError
            On an unknown key, a value of the wrong type or out of range, or an invalid
            combination (the message names the key).
        """
        unknown = sorted(set(table) - {f.name for f in fields(cls)})
        if unknown:
            raise SonarRasterError(f"{where}: unknown key(s) {', '.join(unknown)}")
        changes = dict(table)
        for key in ("spreading", "absorption", "quantise_amplitude"):
            if key in changes and not isinstance(changes[key], bool):
                raise SonarRasterError(
                    f"{where}: '{key}' must be true or false, got {changes[key]!r}"
                )
        bits = changes.get("bits")
        if bits is not None and not (isinstance(bits, int) and bits in QUANTISE_BITS):
            raise SonarRasterError(f"{where}: 'bits' must be 8, 12 or 16, got {bits!r}")
        if "tvg_curve" in changes:
            changes["tvg_curve"] = _table_curve(changes["tvg_curve"], base, where)
        if "sensor" in changes:
            defaults = _sensor_effects(changes.pop("sensor"), where)
        return replace(defaults, **changes) if defaults is not None else cls(**changes)

    def _check_curve(self) -> None:
        try:
            curve = np.asarray(self.tvg_curve, dtype=np.float64)
        except (TypeError, ValueError):  # ragged rows or text
            raise SonarRasterError(
                "effects: a TVG curve needs >= 2 rows of range_m, gain_db numbers"
            ) from None
        if self.tvg != "curve":
            if curve.size:
                raise SonarRasterError('effects: tvg_curve is given but tvg is not "curve"')
            return
        if curve.ndim != 2 or curve.shape[1] != 2 or len(curve) < 2:
            raise SonarRasterError("effects: a TVG curve needs >= 2 rows of range_m, gain_db")
        if not np.all(np.isfinite(curve)) or np.any(np.diff(curve[:, 0]) <= 0):
            raise SonarRasterError("effects: TVG curve ranges must be finite and increasing")
        object.__setattr__(self, "tvg_curve", tuple(map(tuple, curve.tolist())))

    def _check_water(self) -> None:
        if self.absorption_db_m is None:
            from .absorption import francois_garrison

            francois_garrison(
                1e5, self.temperature_c, self.salinity_psu, self.depth_m, self.ph
            )  # raises on out-of-range water properties

    @property
    def stages(self) -> tuple[str, ...]:
        """Names of the stages this configuration runs, in order."""
        on = {
            "along_track": bool(
                self.along_beam_deg or self.array_length_m or self.sas_resolution_m
            ),
            "nadir_gap": self.nadir_gap_deg is not None,
            "water_column": self.water_column_db is not None or self.volume_db is not None,
            "speckle": self.speckle != "off",
            "spreading": self.spreading,
            "absorption": self.absorption,
            "noise": self.noise_db is not None,
            "tvg": self.tvg != "off",
            "gain": self.gain_db != 0.0,
            "saturate": self.saturation is not None or self.headroom_db is not None,
            "quantise": self.bits is not None,
        }
        return tuple(name for name in STAGES if on[name])

    def alpha_db_m(self, frequency_hz: float) -> float:
        """One-way absorption coefficient α, dB/m, at ``frequency_hz``."""
        if self.absorption_db_m is not None:
            return float(self.absorption_db_m)
        from .absorption import francois_garrison

        return float(
            francois_garrison(
                frequency_hz, self.temperature_c, self.salinity_psu, self.depth_m, self.ph
            )
        )

    def changed(self) -> dict[str, Any]:
        """The fields that differ from the defaults (for metadata)."""
        base = Effects()
        return {
            f.name: getattr(self, f.name)
            for f in fields(self)
            if getattr(self, f.name) != getattr(base, f.name)
        }


IDEAL = "ideal"


def _sensor_effects(name: Any, where: str) -> Effects:
    """The effects a table's ``sensor = NAME`` starts from (``"ideal"``: none)."""
    if name == IDEAL:
        return Effects()
    if not isinstance(name, str):
        raise SonarRasterError(f"{where}: 'sensor' must be a preset name, got {name!r}")
    from .presets import preset

    try:
        return preset(name).effects()
    except SonarRasterError as exc:
        raise SonarRasterError(f"{where}: {exc}") from None


def load_tvg_curve(path: str) -> tuple[tuple[float, float], ...]:
    """Read a TVG curve CSV of ``range_m, gain_db`` rows (a header line is allowed).

    Raises
    ------
    SonarRasterError
        If the file cannot be read or is not two numeric columns.
    """
    try:
        with open(path, encoding="utf-8") as fh:
            first = fh.readline()
        try:
            [float(x) for x in first.split(",")]
            skip = 0
        except ValueError:
            skip = 1
        data = np.loadtxt(path, delimiter=",", ndmin=2, comments="#", skiprows=skip)
    except (OSError, ValueError) as exc:
        raise SonarRasterError(f"cannot read TVG curve {path}: {exc}") from None
    if data.shape[1] != 2:
        raise SonarRasterError(f"{path}: a TVG curve has two columns, range_m,gain_db")
    return tuple((float(r), float(g)) for r, g in data)


def _table_curve(value: Any, base: str | Path | None, where: str) -> Any:
    """A table's ``tvg_curve``: a CSV file name (read) or a list of [range_m, gain_db] pairs."""
    if isinstance(value, str):
        return load_tvg_curve(value if base is None else str(Path(base) / value))
    rows = value if isinstance(value, (list, tuple)) else None
    if rows is None or not all(_is_pair(row) for row in rows):
        raise SonarRasterError(
            f"{where}: 'tvg_curve' must be a CSV file name or a list of [range_m, gain_db] "
            f"pairs of numbers, got {value!r}"
        )
    return tuple(tuple(row) for row in rows)


def _is_pair(row: Any) -> bool:
    return isinstance(row, (list, tuple)) and len(row) == 2 and all(map(_is_real, row))


@dataclass
class _Context:
    """What the stages of one side share."""

    range_bin: float
    ranges: np.ndarray  # (bins,) bin-centre slant ranges, metres
    first: np.ndarray  # (pings,) index of the first bin with a return, n_bins if none
    sigma_along: np.ndarray  # (bins,) two-way intensity kernel σ, pings (zeros: none)
    rng: np.random.Generator
    alpha: float
    full_scale: float
    ping_spacing: float = 0.0  # metres (0: unknown; the volume level then needs the beam)
    beam_integral: float = 0.0  # Ψ = ∫ Φ dα over depression angles, radians


Stage = Callable[[np.ndarray, Effects, _Context], np.ndarray]


def _along_track(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    from .along_track import blur_along_track

    return blur_along_track(data, ctx.sigma_along)


def _nadir_gap(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    assert fx.nadir_gap_deg is not None
    n_bins = data.shape[1]
    altitude = ctx.first * ctx.range_bin  # lower edge of the first bin with a return
    edge = np.ceil(altitude / math.cos(math.radians(fx.nadir_gap_deg)) / ctx.range_bin)
    k = np.arange(n_bins)
    blind = (k >= ctx.first[:, None]) & (k < edge[:, None])
    return np.where(blind, 0.0, data)


def _water_column(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    level = np.zeros(data.shape[1])
    if fx.water_column_db is not None:
        level += 10.0 ** (fx.water_column_db / 10.0)
    if fx.volume_db is not None:
        level += 10.0 ** (fx.volume_db / 10.0) * _volume_area(ctx)
    before = np.arange(data.shape[1]) < ctx.first[:, None]
    return data + np.where(before, level, 0.0)


def _volume_area(ctx: _Context) -> np.ndarray:
    """``δr · r · Ψ · w(r)`` per bin, m³: the water volume a bin holds, beam-weighted (m³)."""
    width = np.where(
        ctx.sigma_along > 0,
        math.sqrt(2.0 * math.pi) * ctx.sigma_along * ctx.ping_spacing,
        ctx.ping_spacing,
    )
    return ctx.range_bin * ctx.ranges * ctx.beam_integral * width


def subsamples_per_bin(fx: Effects, range_bin: float) -> int:
    """Recorder sub-samples per recorded bin (1 when ``downsample`` is off).

    ``round(range_bin / sample_spacing_m)``, at least 1.
    """
    if fx.downsample == "off" or fx.sample_spacing_m is None:
        return 1
    return max(1, round(range_bin / fx.sample_spacing_m))


def _recorded_field(
    shape: tuple[int, int],
    fx: Effects,
    ctx: _Context,
    sigma_along: np.ndarray,
    k_shape: float | None = None,
    looks: float = 1.0,
) -> np.ndarray | None:
    """Unit-mean speckle made on the recorder's sub-sample grid, reduced per bin.

    None when the recorder keeps one sample per bin.
    """
    from .along_track import FWHM_PER_SIGMA
    from .speckle import recorded_speckle_field

    n = subsamples_per_bin(fx, ctx.range_bin)
    if n == 1:
        return None
    cell = fx.range_resolution_m
    sigma_fine = 0.0 if cell is None else cell * n / (FWHM_PER_SIGMA * ctx.range_bin)
    entropy = np.random.SeedSequence(int(ctx.rng.integers(2**63)))
    return recorded_speckle_field(
        shape, entropy, sigma_along, sigma_fine, n, fx.downsample, k_shape, looks
    )


def _speckle(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    from .along_track import FWHM_PER_SIGMA
    from .speckle import speckle_field

    cell = fx.range_resolution_m
    sigma_range = 0.0 if cell is None else cell / (FWHM_PER_SIGMA * ctx.range_bin)
    nu = fx.k_shape if fx.speckle == "k" else None
    field = _recorded_field(data.shape, fx, ctx, ctx.sigma_along, nu, fx.speckle_looks)
    if field is None:
        field = speckle_field(
            data.shape, ctx.rng, ctx.sigma_along, sigma_range, nu, fx.speckle_looks
        )
    return data * field


def _spreading(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    return data * ctx.ranges**-4.0


def _absorption(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    return data * 10.0 ** (-2.0 * ctx.alpha * ctx.ranges / 10.0)


def _noise(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    assert fx.noise_db is not None
    level = 10.0 ** (fx.noise_db / 10.0)
    field = _recorded_field(data.shape, fx, ctx, np.zeros(data.shape[1]))
    if field is None:
        return data + ctx.rng.exponential(level, size=data.shape)
    return data + level * field  # band-limited noise through the same downsampling


def tvg_db(fx: Effects, ranges: np.ndarray, alpha_db_m: float) -> np.ndarray:
    """TVG gain in dB at slant ranges (metres), shape of ``ranges``."""
    if fx.tvg == "curve":
        curve = np.asarray(fx.tvg_curve, dtype=np.float64)
        return np.interp(ranges, curve[:, 0], curve[:, 1])
    return fx.tvg_log_coefficient * np.log10(ranges) + 2.0 * alpha_db_m * ranges


def _tvg(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    return data * 10.0 ** (tvg_db(fx, ctx.ranges, ctx.alpha) / 10.0)


def _gain(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    return data * 10.0 ** (fx.gain_db / 10.0)


def _saturate(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    return np.minimum(data, ctx.full_scale)


def _quantise(data: np.ndarray, fx: Effects, ctx: _Context) -> np.ndarray:
    assert fx.bits is not None
    levels = 2**fx.bits - 1
    power = 0.5 if fx.quantise_amplitude else 1.0
    step = ctx.full_scale**power / levels
    codes = np.round(np.clip(data, 0.0, ctx.full_scale) ** power / step)
    return (np.where(data > 0, np.maximum(codes, 1.0), codes) * step) ** (1.0 / power)


_FUNCTIONS: dict[str, Stage] = {
    "along_track": _along_track,
    "nadir_gap": _nadir_gap,
    "water_column": _water_column,
    "speckle": _speckle,
    "spreading": _spreading,
    "absorption": _absorption,
    "noise": _noise,
    "tvg": _tvg,
    "gain": _gain,
    "saturate": _saturate,
    "quantise": _quantise,
}


def _ping_spacing(
    fx: Effects, image: SonarImage, ping_spacing: float | None, trajectory: Any
) -> float:
    for value in (fx.ping_spacing_m, ping_spacing):
        if value is not None:
            return positive("ping spacing (metres)", value)
    if trajectory is not None:
        return float(trajectory.typical_spacing)
    stored: Any = image.metadata.get("ping_spacing_m")
    if _is_real(stored) and math.isfinite(stored) and stored > 0:
        return float(stored)
    raise SonarRasterError(
        "the along-track beam needs the ping spacing: give ping_spacing_m or the trajectory"
    )


def _along_sigma(
    fx: Effects, image: SonarImage, ping_spacing: float | None, trajectory: Any
) -> tuple[np.ndarray, float | None]:
    n_bins = image.shape[1]
    if "along_track" not in fx.stages:
        return np.zeros(n_bins), None
    from .along_track import LINE_APERTURE_WIDTH, kernel_sigma_pings

    sonar = image.sonar
    spacing = _ping_spacing(fx, image, ping_spacing, trajectory)
    beam = None
    if fx.along_beam_deg:
        beam = math.radians(fx.along_beam_deg)
    elif fx.array_length_m:
        beam = LINE_APERTURE_WIDTH * sonar.wavelength / fx.array_length_m
    sigma = kernel_sigma_pings(n_bins, sonar.range_bin, spacing, beam, fx.sas_resolution_m)
    return sigma, spacing


def _first_returns(side: np.ndarray) -> np.ndarray:
    """Index of the first bin with a nonzero return per ping; n_bins for an empty ping."""
    hit = side > 0
    return np.where(hit.any(axis=1), hit.argmax(axis=1), side.shape[1])


def _seed(seed: Any) -> int | None:
    """A seed of the random stages: None (fresh entropy) or a whole number >= 0."""
    return None if seed is None else integer("seed", seed, minimum=0)


def apply_effects(
    image: SonarImage,
    effects: Effects | None = None,
    *,
    seed: int | None = None,
    ping_spacing: float | None = None,
    trajectory: Any = None,
) -> SonarImage:
    """Apply the enabled sensor effects to a raw image.

    Parameters
    ----------
    image : SonarImage
        Raw image from a renderer: float (pings × bins) per side, bin k centred at slant range
        ``(k + 0.5) * sonar.range_bin``.
    effects : Effects, optional
        What to apply; None or ``Effects()`` applies nothing.
    seed : int, optional
        Seed of the random stages (speckle, noise). The same seed gives the same image; None
        draws fresh entropy, recorded in the metadata so the image can be reproduced.
    ping_spacing : float, optional
        Along-track distance between pings, metres (for the along-track beam), unless
        ``effects.ping_spacing_m`` is set; default: ``trajectory.typical_spacing``, then
        ``image.metadata["ping_spacing_m"]``.
    trajectory : Trajectory, optional
        The trajectory the image was rendered along (at least one pose per ping).

    Returns
    -------
    SonarImage
        float32 sides of the same shape. ``metadata["effects"]["stages"]`` lists the stages
        that ran; with none, the input arrays are returned as they are (no copy, no work).

    Raises
    ------
    SonarRasterError
        On an invalid image, a trajectory with fewer pings than the image, or a missing ping
        spacing for the along-track beam.

    Warns
    -----
    InputWarning
        When the image's metadata says a stage that would run was applied to it already.
    """
    fx = effects if effects is not None else Effects()
    if not isinstance(fx, Effects):
        raise SonarRasterError(
            f"effects must be an Effects (e.g. Effects(speckle='exponential') or a preset's "
            f".effects()), got {type(fx).__name__}"
        )
    if not isinstance(image, SonarImage):
        raise SonarRasterError(
            f"apply_effects takes a SonarImage (what render returns), got {type(image).__name__}"
        )
    _check_trajectory(trajectory, image)
    stages = fx.stages
    _warn_repeated(image, stages)
    if not stages:
        return SonarImage(
            dict(image.sides), image.sonar, {**image.metadata, "effects": {"stages": []}}
        )
    _check_image(image)
    sigma, spacing = _along_sigma(fx, image, ping_spacing, trajectory)
    sonar = image.sonar
    ranges = (np.arange(image.shape[1]) + 0.5) * sonar.range_bin
    alpha = (
        fx.alpha_db_m(sonar.frequency_hz) if ("absorption" in stages or fx.tvg == "log") else 0.0
    )
    entropy = np.random.SeedSequence(_seed(seed))
    children = entropy.spawn(len(SIDES))
    work = {name: np.asarray(a, dtype=np.float64) for name, a in image.sides.items()}
    need_first = "nadir_gap" in stages or "water_column" in stages
    volume = _volume_terms(fx, image, spacing, ping_spacing, trajectory)
    ctx = {
        name: _Context(
            sonar.range_bin,
            ranges,
            _first_returns(a) if need_first else np.empty(0, dtype=np.int64),
            sigma,
            np.random.default_rng(children[SIDES.index(name)] if name in SIDES else entropy),
            alpha,
            math.inf,
            *volume,
        )
        for name, a in work.items()
    }
    full_scale: float | None = None
    for stage in stages:
        if stage in ("saturate", "quantise") and full_scale is None:
            full_scale = _full_scale(fx, work)
            for c in ctx.values():
                c.full_scale = full_scale
        for name in work:
            work[name] = _FUNCTIONS[stage](work[name], fx, ctx[name])
    record = {
        "stages": list(stages),
        "seed": entropy.entropy,
        "settings": fx.changed(),
        "alpha_db_m": alpha,
        "ping_spacing_m": spacing,
        "full_scale": full_scale,
    }
    meta = {**image.metadata, "effects": record}
    if fx.sensor is not None:
        meta["sensor_preset"] = fx.sensor
    sides = {name: a.astype(np.float32) for name, a in work.items()}
    return SonarImage(sides, image.sonar, meta)


#: Along-track kernel σ (pings) covered by the halo a streamed block borrows from its neighbours.
HALO_SIGMAS = 6.0


def apply_effects_blocks(
    blocks: Iterable[SonarImage],
    effects: Effects,
    *,
    seed: int | None = None,
    ping_spacing: float,
) -> Iterator[SonarImage]:
    """Apply effects to consecutive blocks of pings as they come, one block behind.

    A long track streamed in blocks (:func:`sonar_raster.rendering.survey.render_survey`) gets
    the effects of :func:`apply_effects` without being held whole: each block is processed
    with a halo of ``HALO_SIGMAS`` along-track kernel widths of raw pings from the block
    before and the block after (so it is yielded when the next one has arrived), and cropped
    back. What joins exactly: the along-track beam (while the halo fits in the next block),
    the water column, nadir gap, spreading, absorption, TVG and gain, all per ping. What
    differs from one whole image: the random fields (speckle, noise) are drawn per block from
    the block's child of ``SeedSequence(seed)``, so their along-track correlation breaks
    at block edges, and the full scale of ``headroom_db`` is the first block's (later blocks
    clip and quantise at the same level).

    Parameters
    ----------
    blocks : iterable of SonarImage
        Raw images of consecutive pings in order (``metadata["first_ping"]`` as the renderer
        sets it), one shape of bins.
    effects : Effects
    seed : int, optional
        Seed of the random stages (None: fresh entropy); recorded in each block's metadata as
        ``effects.stream_seed``, which gives the same blocks again.
    ping_spacing : float
        Along-track distance between pings, metres.

    Yields
    ------
    SonarImage
        Each block with the effects applied, its metadata kept (``effects`` added).
    """
    entropy = np.random.SeedSequence(_seed(seed)).entropy
    fx, halo = effects, None
    tail: dict[str, np.ndarray] | None = None  # the raw pings before the held block
    held: SonarImage | None = None
    index = 0
    for block in blocks:
        if halo is None:
            sigma, _ = _along_sigma(fx, block, ping_spacing, None)
            halo = math.ceil(HALO_SIGMAS * float(np.max(sigma, initial=0.0)))
        if held is not None:
            out = _block_effects(held, tail, block, halo, fx, entropy, index, ping_spacing)
            fx = _fixed_scale(fx, out)
            tail = _tail(tail, held, halo)
            index += 1
            yield out
        held = block
    if held is not None:
        yield _block_effects(held, tail, None, halo or 0, fx, entropy, index, ping_spacing)


def _block_effects(
    held: SonarImage,
    before: dict[str, np.ndarray] | None,
    after: SonarImage | None,
    halo: int,
    fx: Effects,
    entropy: Any,
    index: int,
    ping_spacing: float,
) -> SonarImage:
    """``held`` with the effects applied over it and its halo, cropped back to its pings."""
    lead = 0 if before is None else len(next(iter(before.values())))
    sides = {}
    for name, values in held.sides.items():
        parts = [] if before is None else [before[name]]
        parts.append(np.asarray(values))
        if after is not None and halo > 0:
            parts.append(np.asarray(after.sides[name])[:halo])
        sides[name] = np.concatenate(parts)
    state = np.random.SeedSequence(entropy, spawn_key=(index,))  # the stream's block'th child
    block_seed = int(state.generate_state(1, np.uint64)[0])
    out = apply_effects(
        SonarImage(sides, held.sonar, held.metadata), fx, seed=block_seed, ping_spacing=ping_spacing
    )
    rows = slice(lead, lead + held.shape[0])
    meta = dict(out.metadata)
    meta["effects"] = {
        **meta["effects"],
        "block": index,
        "halo_pings": halo,
        "stream_seed": entropy,  # each block's seed derives from it and the block index
    }
    return SonarImage({n: a[rows] for n, a in out.sides.items()}, out.sonar, meta)


def _fixed_scale(fx: Effects, out: SonarImage) -> Effects:
    """Later blocks clip and quantise at the full scale the first block chose."""
    full = out.metadata["effects"].get("full_scale")
    if full is None or fx.saturation is not None:
        return fx
    return replace(fx, saturation=float(full), headroom_db=None)


def _tail(
    tail: dict[str, np.ndarray] | None, held: SonarImage, halo: int
) -> dict[str, np.ndarray] | None:
    """The last ``halo`` raw pings before the next block (None without a halo)."""
    if halo <= 0:
        return None
    joined = {
        n: np.asarray(v) if tail is None else np.concatenate([tail[n], np.asarray(v)])
        for n, v in held.sides.items()
    }
    return {n: v[-halo:] for n, v in joined.items()}


def _volume_terms(
    fx: Effects, image: SonarImage, spacing: float | None, ping_spacing: float | None, traj: Any
) -> tuple[float, float]:
    """(ping spacing m, Ψ = ∫ Φ dα rad) for the volume reverberation; zeros when it is off."""
    if fx.volume_db is None:
        return 0.0, 0.0
    if spacing is None:
        spacing = _ping_spacing(fx, image, ping_spacing, traj)
    alpha = np.linspace(-math.pi / 2.0, math.pi / 2.0, 4097)
    gain = image.sonar.gain(alpha)
    psi = float(np.sum(0.5 * (gain[1:] + gain[:-1]) * np.diff(alpha)))
    return spacing, psi


def _full_scale(fx: Effects, work: dict[str, np.ndarray]) -> float:
    if fx.saturation is not None:
        return float(fx.saturation)
    if fx.headroom_db is not None:
        values = np.concatenate([a[a > 0] for a in work.values()])
        if values.size:
            return float(np.median(values)) * 10.0 ** (fx.headroom_db / 10.0)
    top = max(float(np.max(a)) for a in work.values())
    return top if top > 0 else 1.0


def _check_trajectory(trajectory: Any, image: SonarImage) -> None:
    """Refuse a trajectory that is not one, or has fewer pings than the image."""
    if trajectory is None:
        return
    if not isinstance(trajectory, Trajectory):
        raise SonarRasterTypeError(
            "trajectory must be the Trajectory the image was rendered along (e.g. "
            f"load_scene(...).trajectory), got {type(trajectory).__name__}"
        )
    pings = image.shape[0] if image.sides else 0
    if trajectory.n_pings < pings:
        raise SonarRasterError(
            f"the trajectory has {trajectory.n_pings} pings, the image {pings}: give the "
            "trajectory the image was rendered along (or ping_spacing= in metres)"
        )


def _warn_repeated(image: SonarImage, stages: tuple[str, ...]) -> None:
    """Warn when the image's metadata says some of these stages were applied to it already."""
    record = image.metadata.get("effects")
    done = record.get("stages") if isinstance(record, Mapping) else None
    again = [s for s in stages if isinstance(done, (list, tuple)) and s in done]
    if again:
        warnings.warn(
            f"the image already has {', '.join(again)} applied (its metadata['effects'] says "
            "so): applying it again compounds it; apply effects once, to the raw image "
            "render returns",
            InputWarning,
            stacklevel=3,
        )


def _check_image(image: SonarImage) -> None:
    if not image.sides:
        raise SonarRasterError("the image has no sides; nothing to apply effects to")
    shapes = {np.shape(a) for a in image.sides.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2 or 0 in next(iter(shapes)):
        raise SonarRasterError(f"image sides must be non-empty 2-D arrays of one shape: {shapes}")
    for name, a in image.sides.items():
        if not np.all(np.isfinite(a)) or np.any(np.asarray(a) < 0):
            raise SonarRasterError(
                f"the {name} image has NaN, infinite or negative values; effects need I >= 0"
            )
