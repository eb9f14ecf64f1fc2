"""Sensor presets: published figures of widely used side-scan sonars and one SAS.

Each :class:`SensorPreset` holds one sensor's figures with their units in the field names, the
addresses they were read from (``sources``), and the names of the fields whose value is *not*
published in those sources (``assumed``) — for those, ``notes`` says what was chosen and why.
:meth:`SensorPreset.sonar` and :meth:`SensorPreset.effects` turn a preset into what the renderer
and the effects chain take. ``docs/sensors.md`` is the same table for people.

Conventions: beam widths are one-way -3 dB full widths (what datasheets quote); ``tilt_deg`` is
the depression of the beam axis below the horizontal; the range resolution is ``c / 2B`` for a
bandwidth B (chirp or CW), else ``c τ / 2`` for a pulse length τ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..errors import SonarRasterError
from ..sonar import SIDES, BeamPattern, Sonar
from .chain import Effects

#: The real recording the Marine Sonic preset is checked against (tests read its header).
REAL_FILE = "data/xtf/scotsman-iver2.xtf (shared folder; OpenSidescan, MIT)"

_DATASONICS = "https://manualshive.com/en/manual/datasonics/sis-1500/3704941"
_EDGETECH_4200 = "https://www.easymanua.ls/edgetech/4200/manual?p=27"
_EDGETECH_4200_BROCHURE = (
    "https://github.com/nvs-vocabs/L22/files/4477717/"
    "Edgetech_4200_series_side_scan_sonar_brochure.pdf"
)
_KLEIN_3900_USGS = "https://pubs.usgs.gov/ds/739/Data_acquisition_SideScan_Cat.html"
_KLEIN_3900_MANUAL = "https://www.manualslib.com/manual/2010143/Klein-3900-Series.html?page=21"
_MARINE_SONIC_MANUAL = (
    "https://www.scribd.com/document/249959946/Towed-System-Operators-Manual-V1-1-0"
)
_JW_FISHERS_TILT = "https://manualshive.com/en/manual/jw-fishers/sss-100k-pc/2036653?page=72"
_GARMIN_SIDEVU = "https://github.com/rolker/unh_marine_autonomy/issues/185"
_HISAS_SENSOTEK = (
    "https://docplayer.net/21044661-Interferometric-synthetic-aperture-sonar-for-auv-based-"
    "mine-hunting-the-sensotek-project.html"
)


@dataclass(frozen=True, kw_only=True)
class SensorPreset:
    """One sensor's published figures, what was chosen where none is published, and sources.

    Attributes
    ----------
    name : str
        Preset key, lower-case with hyphens (e.g. ``"marine-sonic-600"``).
    maker, model : str
        Manufacturer and model.
    kind : {"side-scan", "sas"}
        Real-aperture side-scan or synthetic-aperture sonar.
    frequency_hz : float
        Centre frequency, Hz.
    bandwidth_hz : float or None
        Transmit bandwidth, Hz (chirp sweep, or the CW pulse's ≈ 1/τ).
    pulse_length_s : float or None
        Transmit pulse length, s, where known.
    pulse : {"cw", "chirp"}
        Pulse type.
    horizontal_beamwidth_deg : float or None
        One-way -3 dB along-track beam width, degrees (None for a SAS).
    vertical_beamwidth_deg : float
        One-way -3 dB across-track (elevation) beam width, degrees.
    tilt_deg : float
        Depression of the beam axis below the horizontal, degrees.
    max_ranges_m : tuple of float
        Selectable slant-range settings per side, metres; the first is the preset's default.
    range_bins : int or None
        Samples per side at the default range, where recorded or published.
    bits : {8, 12, 16}
        Bit depth of the recorded samples.
    tvg : {"log", "off"}
        Time-varied gain law applied by :meth:`effects`.
    tvg_log_coefficient : float
        N of the ``N log10 r + 2 α r`` TVG law.
    sas_resolution_m : float or None
        SAS along-track resolution, metres (None for a side-scan).
    array_length_m : float or None
        Physical receive array length, metres, where published.
    sound_speed_m_s : float
        Speed of sound the ranges refer to, m/s.
    far_snr_db : float
        Signal-to-noise ratio of a sandy seabed at the default range seen from an altitude of a
        tenth of it, dB: sets the receiver noise level :attr:`noise_db` (not published for any
        of these sensors; 10 dB is where operators set the range, the Marine Sonic's is fitted
        to the real file's far range).
    headroom_db : float
        Receiver gain setting: full scale this many dB (intensity) above the median sample, so
        the seabed sits there and bright targets clip. The real file's median sample is 8160 of
        32767 on the seabed: 12 dB (taken for every preset; not a published figure).
    volume_db : float
        Volume backscattering strength Sv of the water column, dB re 1 m⁻¹ (an environment
        figure, not the sensor's: -75 dB, mid coastal water at a few hundred kHz).
    downsample : {"off", "max", "mean"}
        How the recorder reduces its samples to the recorded bins (XTF ``DownsampleMethod``:
        2 = MAX, 4 = RMS); with "max" or "mean" the effects make speckle and noise on a
        sub-sample grid of half the range resolution (the intensity envelope's Nyquist
        spacing for a bandwidth ``1/τ`` or B) and reduce it per bin.
    sidelobe_db : float
        Two-way floor of the vertical beam relative to its peak, dB (its sidelobes): -40 dB
        (-20 dB one way, a line array's far sidelobes) for every preset; no datasheet gives
        it. Without it a 40-50° Gaussian beam tilted 10° returns nothing from the nadir
        (-62 dB there), so the first bottom return that side-scan records show, and the
        bottom tracker reads, was missing (the tracked altitude 0.1-1 m long).
    speckle_looks : float
        Looks per recorded sample (see :class:`~sonar_raster.Effects`); 1 for every preset
        (no datasheet gives it; the real file suggests about 2.5 together with a patchy-seabed
        texture, docs/notes/2026-11-24-backscatter.md, not adopted as a default).
    assumed : tuple of str
        Names of the fields above whose value is not published in ``sources`` (chosen).
    sources : tuple of str
        Where the published figures were read (addresses; the real file for the Marine Sonic).
    notes : str
        Which figure comes from which source, and what was chosen for the rest and why.
    """

    name: str
    maker: str
    model: str
    kind: str = "side-scan"
    frequency_hz: float
    bandwidth_hz: float | None = None
    pulse_length_s: float | None = None
    pulse: str
    horizontal_beamwidth_deg: float | None
    vertical_beamwidth_deg: float
    tilt_deg: float
    max_ranges_m: tuple[float, ...]
    range_bins: int | None = None
    bits: int
    tvg: str = "log"
    tvg_log_coefficient: float = 30.0
    sas_resolution_m: float | None = None
    array_length_m: float | None = None
    sound_speed_m_s: float = 1500.0
    far_snr_db: float = 10.0
    headroom_db: float = 12.0
    volume_db: float = -75.0
    sidelobe_db: float = -40.0
    downsample: str = "off"
    speckle_looks: float = 1.0
    assumed: tuple[str, ...]
    sources: tuple[str, ...]
    notes: str

    def __post_init__(self) -> None:
        if self.kind not in ("side-scan", "sas"):
            raise SonarRasterError(f"preset {self.name}: kind must be side-scan or sas")
        if (self.kind == "sas") != (self.horizontal_beamwidth_deg is None):
            raise SonarRasterError(
                f"preset {self.name}: a side-scan needs a horizontal beam width, a SAS none"
            )
        if self.kind == "sas" and not self.sas_resolution_m:
            raise SonarRasterError(f"preset {self.name}: a SAS needs sas_resolution_m")
        if self.bandwidth_hz is None and self.pulse_length_s is None:
            raise SonarRasterError(f"preset {self.name}: give a bandwidth or a pulse length")
        if not self.max_ranges_m:
            raise SonarRasterError(f"preset {self.name}: give at least one range setting")
        names = {f for f in self.__dataclass_fields__}
        unknown = set(self.assumed) - names
        if unknown:
            raise SonarRasterError(f"preset {self.name}: assumed names unknown fields {unknown}")

    @property
    def range_resolution_m(self) -> float:
        """Slant-range resolution, metres: ``c / 2B``, else ``c τ / 2``."""
        if self.bandwidth_hz is not None:
            return self.sound_speed_m_s / (2.0 * self.bandwidth_hz)
        assert self.pulse_length_s is not None
        return self.sound_speed_m_s * self.pulse_length_s / 2.0

    @property
    def wavelength_m(self) -> float:
        """Wavelength at the centre frequency, metres."""
        return self.sound_speed_m_s / self.frequency_hz

    @property
    def footprint_width_m(self) -> float:
        """Equivalent along-track width of the two-way footprint at the default range, metres.

        ``√(2π) σ`` of the Gaussian intensity kernel of full width ``β r / √2`` (side-scan) or
        δ (SAS), as the along-track stage of the effects blurs with it.
        """
        if self.kind == "sas":
            assert self.sas_resolution_m is not None
            fwhm = self.sas_resolution_m
        else:
            assert self.horizontal_beamwidth_deg is not None
            fwhm = math.radians(self.horizontal_beamwidth_deg) * self.max_ranges_m[0] / math.sqrt(2)
        return math.sqrt(2.0 * math.pi) * fwhm / (2.0 * math.sqrt(2.0 * math.log(2.0)))

    def far_echo_db(self) -> float:
        """Echo of a sandy seabed at the default range, altitude a tenth of it, dB re source.

        ``10 log10(R sin g · w · δr / cos g) − 40 log10 r − 2 α r``: the renderer's Lambert law
        ``R cos θ`` for the sand of :mod:`~sonar_raster.scenes.sediments` at grazing g, over the
        footprint width w (:attr:`footprint_width_m`) and one range bin δr, spread and absorbed
        (Francois-Garrison at 10 °C, 35 PSU) — the level the effects chain gives that pixel
        before noise and TVG.
        """
        from ..scenes.sediments import material_reflectivity

        r = self.max_ranges_m[0]
        grazing = math.asin(0.1)
        area = self.footprint_width_m * self.sonar().range_bin / math.cos(grazing)
        sigma = material_reflectivity("sand") * math.sin(grazing) * area
        alpha = Effects().alpha_db_m(self.frequency_hz)
        return 10.0 * math.log10(sigma) - 40.0 * math.log10(r) - 2.0 * alpha * r

    @property
    def noise_db(self) -> float:
        """Receiver noise level, dB re the source level (noise − directivity − source level).

        :meth:`far_echo_db` minus :attr:`far_snr_db`.
        """
        return self.far_echo_db() - self.far_snr_db

    def sonar(
        self,
        max_range: float | None = None,
        range_bin: float | None = None,
        sides: tuple[str, ...] = SIDES,
    ) -> Sonar:
        """The :class:`~sonar_raster.Sonar` of this sensor.

        Parameters
        ----------
        max_range : float, optional
            Slant range per side, metres; default the first of ``max_ranges_m``.
        range_bin : float, optional
            Bin size, metres; default ``max_range / range_bins`` where the sample count is
            known, else half the range resolution (two samples per resolution cell).
        sides : tuple of str
            Sides to image.

        Returns
        -------
        Sonar
            Frequency, range sampling, a Gaussian vertical beam whose two-way half-power width
            is the one-way width / √2 (floored at :attr:`sidelobe_db`), the tilt in radians
            and the sound speed.
        """
        rng = self.max_ranges_m[0] if max_range is None else float(max_range)
        if range_bin is None:
            if self.range_bins is not None:
                range_bin = rng / self.range_bins
            else:
                range_bin = self.range_resolution_m / 2.0
        beam = BeamPattern.gaussian(
            self.vertical_beamwidth_deg / math.sqrt(2.0), sidelobe_db=self.sidelobe_db
        )
        return Sonar(
            frequency_hz=self.frequency_hz,
            max_range=rng,
            range_bin=float(range_bin),
            beam=beam,
            tilt=math.radians(self.tilt_deg),
            sides=tuple(sides),
            sound_speed=self.sound_speed_m_s,
        )

    def effects(self) -> Effects:
        """Every effect this sensor has, as :class:`~sonar_raster.Effects`.

        Along-track beam (horizontal beam width, or the SAS resolution), water-column volume
        reverberation (:attr:`volume_db`), exponential speckle correlated over the range
        resolution cell (made on the recorder's sub-samples and reduced per bin when
        :attr:`downsample` is on), two-way spreading and absorption, receiver noise
        (:attr:`noise_db`), the TVG law, a full scale :attr:`headroom_db` above the median, and
        quantisation of the amplitude to the sensor's bit depth. ``sensor`` is the preset name.
        """
        sas = self.kind == "sas"
        return Effects(
            sensor=self.name,
            along_beam_deg=None if sas else self.horizontal_beamwidth_deg,
            sas_resolution_m=self.sas_resolution_m if sas else None,
            volume_db=self.volume_db,
            noise_db=round(self.noise_db, 2),
            speckle="exponential",
            speckle_looks=self.speckle_looks,
            downsample=self.downsample,
            sample_spacing_m=self.sample_spacing_m,
            range_resolution_m=self.range_resolution_m,
            spreading=True,
            absorption=True,
            tvg=self.tvg,
            tvg_log_coefficient=self.tvg_log_coefficient,
            bits=self.bits,
            headroom_db=self.headroom_db,
            quantise_amplitude=True,
        )

    @property
    def sample_spacing_m(self) -> float | None:
        """Recorder sample spacing before downsampling, metres: half the range resolution.

        None when the recorder keeps its samples (``downsample = "off"``).
        """
        return None if self.downsample == "off" else self.range_resolution_m / 2.0

    def table_row(self) -> dict[str, object]:
        """The preset as a flat mapping of field name to value (for listings and sidecars)."""
        row: dict[str, object] = {f: getattr(self, f) for f in self.__dataclass_fields__}
        row["range_resolution_m"] = self.range_resolution_m
        return row


_MS_RANGE = 29.983501434326172  # SlantRange of every ping in the real file (the 30 m setting)
_MS_BINS = 1024  # NumSamples per channel in the real file
_MS_CYCLES = 10  # CW pulse length in cycles (assumed; not published, not in the file)

PRESETS: dict[str, SensorPreset] = {
    p.name: p
    for p in (
        SensorPreset(
            name="edgetech-4200-100",
            maker="EdgeTech",
            model="4200-SP, 100 kHz channel of the 100/400 kHz towfish",
            frequency_hz=100e3,
            bandwidth_hz=10e3,
            pulse="chirp",
            horizontal_beamwidth_deg=1.5,
            vertical_beamwidth_deg=50.0,
            tilt_deg=10.0,
            max_ranges_m=(100.0, 200.0, 500.0),
            bits=16,
            assumed=(
                "sidelobe_db",
                "bandwidth_hz",
                "horizontal_beamwidth_deg",
                "vertical_beamwidth_deg",
                "tilt_deg",
                "max_ranges_m",
                "bits",
                "tvg",
            ),
            sources=(_EDGETECH_4200, _EDGETECH_4200_BROCHURE),
            notes=(
                "Published (hardware manual 0004842 rev N, §1.3.2.1): 100/400 kHz dual "
                "linear-FM chirp; the 100 m range setting is the one the manual quotes for the "
                "IHO/NOAA 3-pings-on-a-1-m-target rule. Not found in the sources reachable "
                "here: the sweep bandwidth, the beam widths, the tilt, the other range settings "
                "and the sample bit depth. Chosen: 10 kHz sweep (7.5 cm cells, a 10 % fractional "
                "bandwidth), 1.5° horizontal (= 0.886 λ/L for a 0.51 m array), 50° vertical, 10° "
                "tilt (the middle setting of the Datasonics SIS-1500 and the JW Fishers normal "
                "position), 16 bits, 30 log r TVG. Replace them when the datasheet is at hand."
            ),
        ),
        SensorPreset(
            name="datasonics-sis1500",
            maker="Datasonics (Benthos)",
            model="SIS-1500 Seafloor Imaging System, TTV-195 tow vehicle",
            frequency_hz=200e3,
            bandwidth_hz=20e3,
            pulse="chirp",
            horizontal_beamwidth_deg=1.0,
            vertical_beamwidth_deg=50.0,
            tilt_deg=10.0,
            max_ranges_m=(150.0,),
            bits=16,
            assumed=("sidelobe_db", "vertical_beamwidth_deg", "max_ranges_m", "tvg"),
            sources=(f"{_DATASONICS}?page=24", f"{_DATASONICS}?page=82"),
            notes=(
                "Published (System Manual, June 1998): chirp in the 190-210 kHz band (centre "
                "200 kHz, 20 kHz sweep: c/2B = 3.75 cm), one-way horizontal beam width 1° "
                "(p. 1-10); six-element line arrays, down-look angle adjustable 0°-20° in 10° "
                "steps (10° taken, the middle setting), 16-bit digitiser (p. 4-14). Not found: "
                "the vertical beam width (50° chosen, a typical side-scan fan), the range "
                "settings (150 m chosen) and the TVG law (30 log r + 2αr, the seabed law)."
            ),
        ),
        SensorPreset(
            name="klein-3900-445",
            maker="Klein (L3Harris)",
            model="3900, 445 kHz channel",
            frequency_hz=445e3,
            pulse_length_s=50e-6,
            pulse="cw",
            horizontal_beamwidth_deg=0.4,
            vertical_beamwidth_deg=40.0,
            tilt_deg=10.0,
            max_ranges_m=(75.0, 150.0),
            bits=16,
            assumed=(
                "sidelobe_db",
                "pulse_length_s",
                "horizontal_beamwidth_deg",
                "vertical_beamwidth_deg",
                "tilt_deg",
                "max_ranges_m",
                "bits",
                "tvg",
            ),
            sources=(_KLEIN_3900_USGS, _KLEIN_3900_MANUAL),
            notes=(
                "Published (USGS DS 739 survey description; Klein Series 3900 manual §1.4): "
                "dual-frequency 445/900 kHz single-beam side-scan, XTF output. Not found in the "
                "retrieved text: pulse length, beam widths, tilt, range settings, bit depth. "
                "Chosen: 50 µs CW pulse (3.75 cm cells), 0.4° horizontal (≈ 0.886 λ/L, L ≈ "
                "0.43 m), 40° vertical, 10° tilt, 75/150 m, 16 bits, 30 log r TVG."
            ),
        ),
        SensorPreset(
            name="marine-sonic-600",
            maker="Marine Sonic Technology",
            model="Sea Scan HDS 600 kHz (OceanServer Iver2 AUV)",
            frequency_hz=600e3,
            pulse_length_s=2.0 * (_MS_RANGE / _MS_BINS) / 1500.0,
            pulse="cw",
            horizontal_beamwidth_deg=0.3,
            vertical_beamwidth_deg=50.0,
            tilt_deg=10.0,
            max_ranges_m=(_MS_RANGE,),
            range_bins=_MS_BINS,
            bits=16,
            far_snr_db=11.0,
            assumed=(
                "sidelobe_db",
                "pulse_length_s",
                "horizontal_beamwidth_deg",
                "vertical_beamwidth_deg",
                "tilt_deg",
                "tvg",
                "far_snr_db",
                "headroom_db",
            ),
            sources=(REAL_FILE, _MARINE_SONIC_MANUAL),
            notes=(
                "From the real file's XTF headers (SonarName 'HDS', program 'SEASCAN' 3100): "
                "ChanInfo.Frequency and ping Frequency 600 kHz; SlantRange 29.98 m (the 30 m "
                "setting) with 1024 samples per side (2.93 cm bins); SoundVelocity 750 = half "
                "of 1500 m/s (2·SlantRange/TimeDuration = 1500); 2 bytes per sample, values "
                "0-32767 (16-bit words, 15 bits used; 16 taken, the nearest the effects offer). "
                "The file leaves BandWidth, BeamWidth, HorizBeamAngle and TiltAngle at 0 (not "
                "recorded) and no Marine Sonic datasheet figure was reachable here. Chosen: a CW "
                "pulse whose c τ / 2 equals one recorded sample (39.0 µs, 2.93 cm) — the "
                "recorder samples at about its resolution; 50° vertical beam, 10° tilt (JW "
                "Fishers' 600 kHz transducers sit 10° down); 30 log r TVG. Fitted to the file "
                "with tools/compare_real.py (docs/sensors.md): 0.3° horizontal (= 0.886 λ/L for "
                "a 0.42 m array; 0.5° gave along-track speckle cells 1.2-1.8 times the file's), "
                "far_snr_db 11 dB (the wreck shadow's 30 dB contrast), headroom 12 dB (median "
                "sample 8160 of 32767)."
            ),
        ),
        SensorPreset(
            name="klein-3900-900",
            maker="Klein (L3Harris)",
            model="3900, 900 kHz channel",
            frequency_hz=900e3,
            pulse_length_s=25e-6,
            pulse="cw",
            horizontal_beamwidth_deg=0.2,
            vertical_beamwidth_deg=40.0,
            tilt_deg=10.0,
            max_ranges_m=(50.0, 75.0),
            bits=16,
            assumed=(
                "sidelobe_db",
                "pulse_length_s",
                "horizontal_beamwidth_deg",
                "vertical_beamwidth_deg",
                "tilt_deg",
                "max_ranges_m",
                "bits",
                "tvg",
            ),
            sources=(_KLEIN_3900_USGS, _KLEIN_3900_MANUAL),
            notes=(
                "Published: the 900 kHz channel of the 445/900 kHz Klein 3900 (USGS DS 739). "
                "Chosen as for klein-3900-445, scaled to the frequency on the same array: 0.2° "
                "horizontal (half of 0.4° at twice the frequency), 25 µs CW pulse (1.9 cm), "
                "50/75 m ranges."
            ),
        ),
        SensorPreset(
            name="garmin-sidevu-1200",
            maker="Garmin",
            model="GT34UHD-TM transducer, SideVü channel (~1.2 MHz label)",
            frequency_hz=1.12e6,
            pulse_length_s=20e-6,
            pulse="cw",
            horizontal_beamwidth_deg=0.44,
            vertical_beamwidth_deg=55.0,
            tilt_deg=30.0,
            max_ranges_m=(38.1,),
            bits=16,
            assumed=("sidelobe_db", "pulse_length_s", "tilt_deg", "tvg"),
            sources=(_GARMIN_SIDEVU,),
            notes=(
                "Published (GT34UHD-TM spec sheet as quoted in the linked issue, a secondary "
                "source): SideVü band 1,060-1,170 kHz (centre ~1,120 kHz; '1,200' is a rounded "
                "label), beam 0.44° along × 55° across, 125 ft (38.1 m) per side; samples "
                "recorded as UINT16. Just above 1 MHz: the high end of the table. Not found: "
                "pulse length (20 µs CW chosen, 1.5 cm), tilt (30° chosen: a hull transducer "
                "looking to ~38 m from a few metres' depth) and TVG (30 log r)."
            ),
        ),
        SensorPreset(
            name="kongsberg-hisas-1030",
            maker="Kongsberg Maritime / FFI",
            model="HISAS 1030 interferometric SAS (HUGIN AUV)",
            kind="sas",
            frequency_hz=100e3,
            bandwidth_hz=25e3,
            pulse="chirp",
            horizontal_beamwidth_deg=None,
            vertical_beamwidth_deg=40.0,
            tilt_deg=10.0,
            max_ranges_m=(200.0,),
            bits=16,
            sas_resolution_m=0.03,
            assumed=(
                "sidelobe_db",
                "frequency_hz",
                "bandwidth_hz",
                "vertical_beamwidth_deg",
                "tilt_deg",
                "max_ranges_m",
                "bits",
                "tvg",
            ),
            sources=(_HISAS_SENSOTEK,),
            notes=(
                "Published (Hagen, Hansen, Gade, Hammerstad, 'Interferometric SAS for AUV based "
                "mine hunting: the SENSOTEK project', FFI and Kongsberg Simrad, 2001): the "
                "system that became HISAS 1030 is designed for 3 × 3 cm resolution in imagery "
                "and bathymetry and area coverage rates up to 800 m²/s. Not found in the text "
                "reachable here: the band, the beams, the tilt, the range, the bit depth. "
                "Chosen: 100 kHz centre with a 25 kHz sweep, so that c/2B = 3 cm matches the "
                "published across-track resolution; 200 m per side (800 m²/s at ~2 m/s over "
                "two sides); 40° vertical, 10° tilt, 16 bits, 30 log r TVG. The along-track "
                "resolution (3 cm) is range-independent, as for any SAS."
            ),
        ),
    )
}

# The recorder as the real file's headers describe it (DownsampleMethod 2 = MAX: each stored
# sample the largest of several finer ones, so a pulse shorter than a stored sample). The
# default since the seabed's micro-relief (scenes.seabed.micro_relief): with it, this recorder
# brings the file's speckle contrast and histogram closest (docs/sensors.md); over a flat
# seabed without texture the one-look "marine-sonic-600" measures closer.
PRESETS["marine-sonic-600-max"] = replace(
    PRESETS["marine-sonic-600"],
    name="marine-sonic-600-max",
    pulse_length_s=_MS_CYCLES / 600e3,
    downsample="max",
    notes=(
        "From the real file's XTF headers (SonarName 'HDS', program 'SEASCAN' 3100): "
        "ChanInfo.Frequency and ping Frequency 600 kHz; SlantRange 29.98 m (the 30 m "
        "setting) with 1024 samples per side (2.93 cm bins); SoundVelocity 750 = half of "
        "1500 m/s (2·SlantRange/TimeDuration = 1500); 2 bytes per sample, values 0-32767 "
        "(16-bit words, 15 bits used; 16 taken, the nearest the effects offer). The file "
        "leaves BandWidth, BeamWidth, HorizBeamAngle and TiltAngle at 0 (not recorded) and"
        " no Marine Sonic datasheet figure was reachable here. Chosen: a CW pulse of 10 "
        "cycles (16.7 µs, c τ / 2 = 1.25 cm; the file's ChanInfo leaves it out): the "
        "file's DownsampleMethod = 2 (XTF: MAX) says each 2.93 cm sample is the largest of"
        " several finer samples, so the pulse is shorter than a recorded sample "
        "(docs/notes/2026-11-24-realism-physics.md); 50° vertical beam, 10° tilt (JW "
        "Fishers' 600 kHz transducers sit 10° down); 30 log r TVG. Fitted to the file with"
        " tools/compare_real.py (docs/sensors.md): 0.3° horizontal (= 0.886 λ/L for a 0.42"
        " m array; 0.5° gave along-track speckle cells 1.2-1.8 times the file's), "
        "far_snr_db 11 dB (the wreck shadow's 30 dB contrast), headroom 12 dB (median "
        "sample 8160 of 32767)."
    ),
)


#: The sensor whose effects ``render`` and ``dataset`` apply when none is named (the real file's).
DEFAULT_SENSOR = "marine-sonic-600-max"


def list_presets() -> list[str]:
    """Names of the known sensor presets, sorted by centre frequency."""
    return sorted(PRESETS, key=lambda n: (PRESETS[n].frequency_hz, n))


def preset(name: str) -> SensorPreset:
    """The sensor preset called ``name``.

    Raises
    ------
    SonarRasterError
        For an unknown name; the message lists the known ones.
    """
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        raise SonarRasterError(
            f"unknown sensor preset {name!r}; known: {', '.join(list_presets())}"
        ) from None


def apply_sensor_preset(data: dict, where: str) -> dict:
    """A scene description with its ``[sonar] preset = "NAME"`` expanded (a hook of the loader).

    The preset's sonar fills the ``[sonar]`` keys the file leaves out (``frequency_hz``,
    ``max_range``, ``range_bin``, ``tilt_deg``, a Gaussian ``beam``, ``sound_speed``; the range
    bin follows a ``max_range`` the file gives), and ``[effects]`` gets ``sensor = "NAME"``
    unless it names one, so the preset's effects are the base its keys replace.

    Parameters
    ----------
    data : dict
        The parsed TOML document; left unchanged.
    where : str
        The file's name, for messages.

    Returns
    -------
    dict
        ``data`` itself when ``[sonar]`` names no preset, else an expanded copy.

    Raises
    ------
    SonarRasterError
        For a preset name that is not text or not known.
    """
    table = data.get("sonar")
    if not isinstance(table, dict) or "preset" not in table:
        return data
    table = dict(table)
    name = table.pop("preset")
    if not isinstance(name, str):
        raise SonarRasterError(f"{where} [sonar]: 'preset' must be a preset name, got {name!r}")
    try:
        p = preset(name)
    except SonarRasterError as exc:
        raise SonarRasterError(f"{where} [sonar]: {exc}") from None
    number = (int, float)
    max_range = table.get("max_range")
    range_bin = table.get("range_bin")
    sonar = p.sonar(
        max_range if isinstance(max_range, number) else None,
        range_bin if isinstance(range_bin, number) else None,
    )
    filled = {
        "frequency_hz": sonar.frequency_hz,
        "max_range": sonar.max_range,
        "range_bin": sonar.range_bin,
        "tilt_deg": p.tilt_deg,
        "beam": {"kind": "gaussian", "beamwidth_deg": p.vertical_beamwidth_deg / math.sqrt(2.0)},
        "sound_speed": p.sound_speed_m_s,
    }
    effects = data.get("effects", {})
    if not isinstance(effects, dict):
        return {**data, "sonar": {**filled, **table}}  # the loader reports the bad [effects]
    return {**data, "sonar": {**filled, **table}, "effects": {"sensor": name, **effects}}
