"""Dataset configuration files (TOML): fixed values and distributions to draw samples from.

A value is a number, string or list (fixed), or a one-key table naming a distribution:
``{ uniform = [a, b] }``, ``{ loguniform = [a, b] }``, ``{ normal = [mean, std] }`` (optional
``min`` and ``max`` clip it), ``{ integers = [lo, hi] }`` (both included), ``{ poisson = mean }``
or ``{ choice = [v1, v2, ...] }`` (optional ``weights``). A list whose items are distributions
draws each item (e.g. a box's ``size``). The format is documented in docs/datasets.md.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import integer
from ..errors import SonarRasterError
from ..meshio.formats import MODEL_SUFFIXES, Y_UP_SUFFIXES
from ..scenes import seabed as _seabed
from ..scenes.objects import PRIMITIVES
from ..sonar import SIDES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

_DIST_KINDS = ("uniform", "loguniform", "normal", "integers", "poisson", "choice")
SEABED_KINDS = ("flat", "rough", "ripples", "bumpy")
_SEABED_FIXED = ("size", "center", "depth", "seed")  # set by the generator, not the config
BOX_MODES = ("highlight", "highlight+shadow")
FORMATS = ("png", "exr")


@dataclass(frozen=True)
class Dist:
    """A fixed value or a distribution; :meth:`draw` takes one value from a numpy Generator."""

    kind: str
    args: tuple = ()
    options: tuple = ()  # (key, value) pairs: min, max (normal), weights (choice)

    def draw(self, rng: np.random.Generator) -> Any:
        """One value: float, int, str or list (a fixed value costs no random draw)."""
        a, opts = self.args, dict(self.options)
        if self.kind == "fixed":
            return a[0]
        if self.kind == "vector":
            return [d.draw(rng) for d in a]
        if self.kind == "uniform":
            return float(rng.uniform(a[0], a[1]))
        if self.kind == "loguniform":
            return float(math.exp(rng.uniform(math.log(a[0]), math.log(a[1]))))
        if self.kind == "normal":
            value = float(rng.normal(a[0], a[1]))
            return float(np.clip(value, opts.get("min", -np.inf), opts.get("max", np.inf)))
        if self.kind == "integers":
            return int(rng.integers(a[0], a[1], endpoint=True))
        if self.kind == "poisson":
            return int(rng.poisson(a[0]))
        k = int(rng.choice(len(a), p=opts.get("weights")))
        return a[k]

    @property
    def bounds(self) -> tuple[float, float]:
        """Smallest and largest value it can take (numbers only; normal: its clip or ±inf)."""
        a, opts = self.args, dict(self.options)
        if self.kind == "fixed":
            return (float(a[0]), float(a[0]))
        if self.kind in ("uniform", "loguniform", "integers"):
            return (float(a[0]), float(a[1]))
        if self.kind == "normal":
            return (float(opts.get("min", -np.inf)), float(opts.get("max", np.inf)))
        if self.kind == "poisson":
            return (0.0, np.inf)
        return (float(min(a)), float(max(a)))


def parse_dist(value: Any, where: str) -> Dist:
    """Parse a fixed value or a distribution table (see the module docstring)."""
    if isinstance(value, bool) or isinstance(value, (int, float, str)):
        return Dist("fixed", (value,))
    if isinstance(value, list):
        if any(isinstance(v, dict) for v in value):
            return Dist("vector", tuple(parse_dist(v, where) for v in value))
        return Dist("fixed", (list(value),))
    if not isinstance(value, dict):
        raise SonarRasterError(f"{where}: expected a value or a distribution table")
    table = dict(value)
    kinds = [k for k in _DIST_KINDS if k in table]
    if len(kinds) != 1:
        raise SonarRasterError(
            f"{where}: a distribution table names exactly one of {', '.join(_DIST_KINDS)}"
        )
    kind = kinds[0]
    args = table.pop(kind)
    options: dict[str, Any] = {}
    if kind == "normal":
        for key in ("min", "max"):
            if key in table:
                options[key] = _number(table.pop(key), f"{where} {key}")
    if kind == "choice":
        if not isinstance(args, list) or not args:
            raise SonarRasterError(f"{where}: 'choice' needs a non-empty list")
        if "weights" in table:
            w = np.asarray(table.pop("weights"), dtype=np.float64)
            if w.shape != (len(args),) or not np.all(w >= 0) or not w.sum() > 0:
                raise SonarRasterError(f"{where}: 'weights' must be {len(args)} numbers >= 0")
            options["weights"] = tuple(w / w.sum())
        _no_leftovers(table, where)
        return Dist("choice", tuple(args), tuple(options.items()))
    _no_leftovers(table, where)
    if kind == "poisson":
        mean = _number(args, where)
        if mean < 0:
            raise SonarRasterError(f"{where}: 'poisson' mean must be >= 0")
        return Dist("poisson", (mean,))
    if not (isinstance(args, list) and len(args) == 2):
        raise SonarRasterError(f"{where}: '{kind}' needs a list of two numbers")
    lo, hi = (_number(x, where) for x in args)
    if kind == "integers":
        if lo != int(lo) or hi != int(hi) or lo > hi:
            raise SonarRasterError(f"{where}: 'integers' needs [lo, hi] integers with lo <= hi")
        return Dist("integers", (int(lo), int(hi)))
    if kind == "normal":
        if hi < 0:
            raise SonarRasterError(f"{where}: 'normal' standard deviation must be >= 0")
        return Dist("normal", (lo, hi), tuple(options.items()))
    if lo > hi or (kind == "loguniform" and lo <= 0):
        raise SonarRasterError(f"{where}: '{kind}' needs [a, b] with a <= b (and a > 0 for log)")
    return Dist(kind, (lo, hi))


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SonarRasterError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _no_leftovers(table: dict, where: str) -> None:
    if table:
        raise SonarRasterError(f"{where}: unknown key(s) {', '.join(sorted(table))}")


@dataclass(frozen=True)
class SeabedSpec:
    """One seabed kind to draw from, with its weight and its parameters' distributions."""

    kind: str
    weight: float
    reflectivity: Dist
    params: tuple[tuple[str, Dist], ...]
    micro_relief: Dist | None = None  # a sediment name (or a choice of them): its roughness
    material: Dist | None = None  # a sediment name (or a choice): its law and reflectivity
    scattering: str = "apl"  # the material's law: "apl" (APL-UW) or "lambert"


@dataclass(frozen=True)
class ObjectSpec:
    """One entry of the object library.

    ``primitive`` names a bundled shape (:mod:`sonar_raster.scenes.objects`); ``file`` a user mesh
    (resolved against the config's folder). ``params`` are the primitive's own parameters.
    """

    label: str
    primitive: str | None
    file: str | None
    up: str
    count: Dist
    reflectivity: Dist
    scale: Dist
    burial_fraction: Dist
    yaw_deg: Dist
    pitch_deg: Dist
    roll_deg: Dist
    params: tuple[tuple[str, Dist], ...]


@dataclass(frozen=True)
class BackgroundSpec:
    """``[background]``: real recordings whose windows replace the simulated seabed.

    Attributes
    ----------
    recordings : tuple of str
        XTF files (resolved against the config's folder).
    samples : str
        What their samples are: "auto", "amplitude" or "intensity".
    seabed_reflectivity : float
        Reflectivity the recordings' seabed is taken to have.
    frequency : float or {"low", "high"}, optional
        Of dual-frequency recordings, the channel pair read (Hz, or "low" / "high"); None: the
        first.
    """

    recordings: tuple[str, ...]
    samples: str = "auto"
    seabed_reflectivity: float = 0.3
    frequency: float | str | None = None


def _background(table: dict | None, base: Path, where: str) -> BackgroundSpec | None:
    """Parse ``[background]``; None when the config has none."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise SonarRasterError(f"{where}: [background] must be a table")
    table = dict(table)
    files = table.pop("recordings", None)
    if not isinstance(files, list) or not files or not all(isinstance(f, str) for f in files):
        raise SonarRasterError(
            f"{where}: 'recordings' must be a list of .xtf files, e.g. [\"a.xtf\"]"
        )
    samples = table.pop("samples", "auto")
    if samples not in ("auto", "amplitude", "intensity"):
        raise SonarRasterError(f"{where}: 'samples' must be auto, amplitude or intensity")
    refl = _number(table.pop("seabed_reflectivity", 0.3), f"{where} 'seabed_reflectivity'")
    frequency = _frequency(table.pop("frequency", None), where)
    _no_leftovers(table, where)
    if refl <= 0:
        raise SonarRasterError(f"{where}: 'seabed_reflectivity' must be > 0")
    paths = []
    for f in files:
        path = (base / f).resolve()
        if path.suffix.lower() != ".xtf" or not path.is_file():
            raise SonarRasterError(f"{where}: recording {f} is not an .xtf file that exists")
        if frequency is not None:
            from ..io.xtf import XtfReader

            XtfReader(path, frequency).close()  # a pair the file lacks: one line naming its own
        paths.append(str(path))
    return BackgroundSpec(tuple(paths), samples, refl, frequency)


def _frequency(value: Any, where: str) -> float | str | None:
    """``[background] frequency``: "low", "high" or kHz, as Hz; None when not given."""
    if value is None or value in ("low", "high"):
        return value
    khz = value if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan
    if not (math.isfinite(khz) and khz > 0):
        raise SonarRasterError(
            f'{where}: \'frequency\' must be "low", "high" or the channels\' frequency in kHz, '
            f"e.g. 900; got {value!r}"
        )
    return 1e3 * float(khz)


@dataclass(frozen=True)
class DatasetConfig:
    """A parsed dataset configuration (plain, picklable data)."""

    source: str
    name: str
    count: int
    seed: int
    pings: int
    bins: int
    sides: tuple[str, ...]
    sonar: dict[str, Dist]
    track: dict[str, Dist]
    seabeds: tuple[SeabedSpec, ...]
    objects: tuple[ObjectSpec, ...]
    placement: dict[str, Dist]
    min_separation: float
    shadow_ratio: float
    box: str
    min_pixels: int
    formats: tuple[str, ...]
    bits: int
    dynamic_range_db: float | None
    render: dict[str, Any]
    effects: dict[str, Any] | None
    digest: str = ""
    raw: dict = field(default_factory=dict, repr=False)
    background: BackgroundSpec | None = None
    #: ``[sonar] preset``: a sensor preset name or a choice of them, drawn per sample; its
    #: sonar fills the ``[sonar]`` keys the config leaves out, its effects are the base.
    sensor: Dist | None = None

    @property
    def categories(self) -> tuple[str, ...]:
        """Class names in first-declared order; COCO category id = position + 1."""
        return tuple(dict.fromkeys(o.label for o in self.objects))

    @property
    def base(self) -> Path:
        """Folder that relative paths in the config are resolved against."""
        return Path(self.source).parent


_SONAR_DEFAULTS = {
    "frequency_hz": 400e3,
    "max_range": 40.0,
    "tilt_deg": 15.0,
    "beamwidth_deg": 40.0,
    "sound_speed": 1500.0,
}
_TRACK_DEFAULTS = {"altitude": 8.0, "heading_deg": {"uniform": [0.0, 360.0]}, "spacing": 0.1}
_PLACEMENT_DEFAULTS = {
    "along_track": {"uniform": [0.05, 0.95]},
    "ground_range": {"uniform": [0.1, 0.95]},
}
_OBJECT_COMMON = {
    "count": 1,
    "reflectivity": 0.9,
    "scale": 1.0,
    "burial_fraction": 0.0,
    "yaw_deg": {"uniform": [0.0, 360.0]},
    "pitch_deg": 0.0,
    "roll_deg": 0.0,
}


#: The interval each numeric value may lie in, ``(low, high, low open, high open)``, checked
#: when the config loads: a fixed value, a choice or a range that can only give values outside
#: it fails then, not in every sample.
_RANGES: dict[str, tuple[float, float, bool, bool]] = {
    "frequency_hz": (0.0, math.inf, True, True),
    "max_range": (0.0, math.inf, True, True),
    "tilt_deg": (-90.0, 90.0, False, False),
    "beamwidth_deg": (0.0, 180.0, True, False),
    "sound_speed": (0.0, math.inf, True, True),
    "altitude": (0.0, math.inf, True, True),
    "spacing": (0.0, math.inf, True, True),
    "heading_deg": (-math.inf, math.inf, True, True),
    "along_track": (0.0, 1.0, False, False),
    "ground_range": (0.0, 1.0, False, False),
    "reflectivity": (0.0, math.inf, False, True),
    "scale": (0.0, math.inf, True, True),
    "burial_fraction": (0.0, 1.0, False, True),
    "yaw_deg": (-math.inf, math.inf, True, True),
    "pitch_deg": (-math.inf, math.inf, True, True),
    "roll_deg": (-math.inf, math.inf, True, True),
}


#: A sample's ``max_range`` must exceed its altitude by this factor (a swath to draw).
REACH_PAST_ALTITUDE = 1.05


def allowed(key: str, value: float) -> bool:
    """Whether ``value`` lies in ``key``'s interval (:data:`_RANGES`)."""
    low, high, low_open, high_open = _RANGES[key]
    return (
        low < value < high or (value == low and not low_open) or (value == high and not high_open)
    )


def rule(key: str) -> str:
    """``key``'s interval in words: ``"> 0"``, ``"in [0, 1)"``, ``"a number"``."""
    low, high, low_open, high_open = _RANGES[key]
    if math.isinf(low) and math.isinf(high):
        return "a number"
    if math.isinf(high):
        return f"{'>' if low_open else '>='} {low:g}"
    return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"


def _check_ranges(dists: dict[str, Dist], where: str) -> None:
    """Fail now where a value is not a number, or can only be drawn outside its interval."""
    for key, dist in dists.items():
        if key not in _RANGES:
            continue
        low, high, low_open, high_open = _RANGES[key]
        values = dist.args if dist.kind in ("fixed", "choice") else ()
        if dist.kind == "vector" or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) for v in values
        ):
            shown = "a list" if dist.kind == "vector" else repr(values[0])
            raise SonarRasterError(f"{where} '{key}': must be a number, got {shown}")
        lo, hi = dist.bounds  # every value it can draw lies in [lo, hi]
        bad = [v for v in values if not allowed(key, float(v))]
        if bad:
            raise SonarRasterError(f"{where} '{key}': must be {rule(key)}, got {bad[0]:g}")
        if hi < low or lo > high or (hi == low and low_open) or (lo == high and high_open):
            raise SonarRasterError(
                f"{where} '{key}': must be {rule(key)}; {dist.kind} [{lo:g}, {hi:g}] never is"
            )


def _sensor_dist(value: Any, where: str) -> Dist | None:
    """A sensor preset name or ``{ choice = [names] }`` (see ``sonar-raster sensors``)."""
    from ..effects.presets import preset

    return _names_dist(value, where, 'a sensor preset name such as "klein-3900-900"', preset)


def _names_dist(value: Any, where: str, what: str, find: Any) -> Dist | None:
    """A name or ``{ choice = [names] }``, each known to ``find``; None when not given.

    ``find`` raises on a name it does not know, listing the known ones.
    """
    if value is None:
        return None
    dist = parse_dist(value, where)
    if dist.kind not in ("fixed", "choice") or not all(isinstance(v, str) for v in dist.args):
        raise SonarRasterError(f"{where}: give {what} or {{ choice = [names] }}")
    for name in dist.args:
        try:
            find(name)
        except SonarRasterError as exc:
            raise SonarRasterError(f"{where}: {exc}") from None
    return dist


def range_bounds(sonar: dict[str, Dist], sensor: Dist | None) -> tuple[float, float]:
    """Shortest and longest maximum range a config draws, metres.

    ``[sonar] max_range`` when given, else the presets' default ranges.
    """
    if "max_range" in sonar or sensor is None:
        return sonar["max_range"].bounds
    from ..effects.presets import preset

    ranges = [preset(str(name)).max_ranges_m[0] for name in sensor.args]
    return (min(ranges), max(ranges))


def _dists(table: dict, defaults: dict, where: str) -> dict[str, Dist]:
    out = {}
    for key, default in defaults.items():
        out[key] = parse_dist(table.pop(key, default), f"{where} '{key}'")
    _no_leftovers(table, where)
    _check_ranges(out, where)
    return out


def _table(data: dict, key: str, where: str) -> dict:
    value = data.pop(key, {})
    if not isinstance(value, dict):
        raise SonarRasterError(f"{where}: [{key}] must be a table")
    return dict(value)


def _tables(data: dict, key: str, where: str) -> list[dict]:
    value = data.pop(key, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise SonarRasterError(f"{where}: {key} must be [[{key}]] tables")
    return [dict(v) for v in value]


def _seabed_spec(table: dict, where: str) -> SeabedSpec:
    kind = table.pop("kind", "flat")
    if kind not in SEABED_KINDS:
        raise SonarRasterError(f"{where}: seabed kind must be one of {', '.join(SEABED_KINDS)}")
    weight = _number(table.pop("weight", 1.0), f"{where} 'weight'")
    if weight < 0:
        raise SonarRasterError(f"{where}: 'weight' must be >= 0")
    given = "reflectivity" in table
    reflectivity = parse_dist(table.pop("reflectivity", 0.3), f"{where} 'reflectivity'")
    material = _sediment_dist(table.pop("material", None), f"{where} 'material'")
    scattering = _scattering(table.pop("scattering", None), material, f"{where} 'scattering'")
    if material is not None and given:
        raise SonarRasterError(
            f"{where}: give 'reflectivity' or 'material', not both (a material sets its own)"
        )
    relief = table.pop("micro_relief", None)
    relief = None if relief is False else relief  # false: none, as leaving the key out
    if relief is True and material is None:
        raise SonarRasterError(
            f"{where}: micro_relief = true takes the seabed's 'material'; give one, or name "
            'the sediment (micro_relief = "sand")'
        )
    relief = (
        Dist("fixed", (True,))
        if relief is True
        else _sediment_dist(relief, f"{where} 'micro_relief'")
    )
    valid = set(inspect.signature(getattr(_seabed, kind)).parameters) - set(_SEABED_FIXED)
    fixed = sorted(set(table) & set(_SEABED_FIXED))
    if fixed:
        raise SonarRasterError(
            f"{where}: {', '.join(fixed)} are set per sample from the swath; remove them"
        )
    unknown = sorted(set(table) - valid)
    if unknown:
        raise SonarRasterError(
            f"{where}: unknown parameter(s) {', '.join(unknown)} for seabed kind '{kind}'; "
            f"valid: {', '.join(sorted(valid))}"
        )
    params = tuple((k, parse_dist(v, f"{where} '{k}'")) for k, v in table.items())
    return SeabedSpec(kind, weight, reflectivity, params, relief, material, scattering)


def _scattering(value: Any, material: Dist | None, where: str) -> str:
    """The material's scattering law: "apl" (the default) or "lambert"."""
    from ..scenes.sediments import LAWS

    if value is None:
        return "apl"
    if material is None:
        raise SonarRasterError(f"{where}: needs a 'material' (a reflectivity is Lambert's)")
    if value not in LAWS:
        raise SonarRasterError(f"{where}: must be one of {', '.join(LAWS)}, got {value!r}")
    return str(value)


def _sediment_dist(value: Any, where: str) -> Dist | None:
    """A sediment name or ``{ choice = [names] }`` (see ``scenes.sediments.sediment``)."""
    from ..scenes.sediments import sediment

    return _names_dist(value, where, 'a sediment name such as "sand"', sediment)


def _object_spec(table: dict, k: int, where: str) -> ObjectSpec:
    where = f"{where} object {k + 1}"
    primitive = table.pop("primitive", None)
    file = table.pop("file", None)
    if (primitive is None) == (file is None):
        raise SonarRasterError(f"{where}: give exactly one of 'primitive' or 'file'")
    if primitive is not None and primitive not in PRIMITIVES:
        raise SonarRasterError(
            f"{where}: unknown primitive {primitive!r}; use one of {', '.join(sorted(PRIMITIVES))}"
        )
    if file is not None and not str(file).lower().endswith(MODEL_SUFFIXES):
        raise SonarRasterError(
            f"{where}: '{file}' is not a model file ({' '.join(MODEL_SUFFIXES)})"
        )
    label = table.pop("class", None) or primitive or Path(str(file)).stem
    y_up = file is not None and str(file).lower().endswith(Y_UP_SUFFIXES)
    up = table.pop("up", "y" if y_up else "z")
    if up not in ("y", "z"):
        raise SonarRasterError(f'{where}: \'up\' must be "y" or "z"')
    common = {key: table.pop(key, default) for key, default in _OBJECT_COMMON.items()}
    dists = _dists(common, _OBJECT_COMMON, where)
    count = dists["count"]
    values = count.args if count.kind in ("fixed", "choice") else (0,)
    if count.kind not in ("fixed", "integers", "poisson", "choice") or not all(
        isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in values
    ):
        raise SonarRasterError(
            f"{where}: 'count' must be an integer >= 0, or integers, poisson or choice of them"
        )
    if primitive is not None:
        valid = set(inspect.signature(PRIMITIVES[primitive]).parameters)
        unknown = sorted(set(table) - valid)
        if unknown:
            raise SonarRasterError(
                f"{where}: unknown parameter(s) {', '.join(unknown)} for primitive "
                f"'{primitive}'; valid: {', '.join(sorted(valid))}"
            )
    else:
        _no_leftovers(table, where)
    params = tuple((key, parse_dist(v, f"{where} '{key}'")) for key, v in table.items())
    return ObjectSpec(
        label=str(label),
        primitive=primitive,
        file=None if file is None else str(file),
        up=up,
        params=params,
        **dists,
    )


def _positive_int(table: dict, key: str, default: int, where: str) -> int:
    """Pop ``key`` from ``table``: a whole number >= 1."""
    return integer(f"{where}: '{key}'", table.pop(key, default), minimum=1)


def _check_render(render: dict, where: str) -> None:
    """Fail now on a bad ``[render]`` table rather than in every worker."""
    from ..rendering.gl.context import requested_backends
    from ..rendering.gl.raster import RasterSettings

    unknown = set(render) - {"oversample", "along_samples", "backend"}
    if unknown:
        raise SonarRasterError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}")
    if "backend" in render:
        if not isinstance(render["backend"], str):
            raise SonarRasterError(f'{where}: \'backend\' must be "egl" or "osmesa"')
        requested_backends(render["backend"])
    try:
        RasterSettings(**{k: v for k, v in render.items() if k != "backend"})
    except (TypeError, ValueError) as exc:
        raise SonarRasterError(f"{where}: {exc}") from None


def _check_finite(value: Any, where: str, key: str = "") -> None:
    """One line naming the first nan or inf in a parsed TOML value (TOML allows both)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise SonarRasterError(f"{where}: '{key}' must be a finite number, got {value}")
    items = (
        value.items()
        if isinstance(value, dict)
        else enumerate(value)
        if isinstance(value, list)
        else ()
    )
    for name, inner in items:
        _check_finite(inner, where, f"{key}.{name}" if key else str(name))


def _config_path(name: str | Path) -> Path:
    """A config file, or a bundled config by name (``dataset_default``)."""
    path = Path(name)
    if path.exists() or path.suffix:
        return path
    from ..scenes.bundled import bundled_dataset_config

    bundled = bundled_dataset_config(str(name))
    if bundled is None:
        raise SonarRasterError(f"no dataset config {name!r}; give a .toml file or dataset_default")
    return bundled


def load_dataset_config(path: str | Path) -> DatasetConfig:
    """Read and check a dataset configuration file.

    Parameters
    ----------
    path : str or Path
        A ``.toml`` file (format: docs/datasets.md), or the name of a bundled config
        (``"dataset_default"``).

    Returns
    -------
    DatasetConfig

    Raises
    ------
    SonarRasterError
        On a missing file, invalid TOML, an unknown key or an invalid value (the message names
        the table and key).
    """
    path = _config_path(path)
    if not path.is_file():
        raise SonarRasterError(f"dataset config {path} does not exist")
    where = path.name
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a BOM from Windows editors
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SonarRasterError(f"{where}: not valid TOML ({exc})") from None
    _check_finite(raw, where)
    data = json.loads(json.dumps(raw))  # a deep copy to consume
    ds = _table(data, "dataset", where)
    name = str(ds.pop("name", path.stem))
    ds.pop("description", None)
    count = _positive_int(ds, "count", 100, f"{where} [dataset]")
    seed = ds.pop("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SonarRasterError(f"{where} [dataset]: 'seed' must be an integer >= 0")
    pings = _positive_int(ds, "pings", 512, f"{where} [dataset]")
    bins = _positive_int(ds, "bins", 1024, f"{where} [dataset]")
    sides = ds.pop("sides", ["starboard"])
    if (
        not isinstance(sides, list)
        or not sides
        or any(s not in SIDES for s in sides)
        or len(set(sides)) < len(sides)
    ):
        raise SonarRasterError(
            f"{where} [dataset]: 'sides' must be a list from port, starboard, each once, "
            f"got {sides!r}"
        )
    _no_leftovers(ds, f"{where} [dataset]")
    sonar = _table(data, "sonar", where)
    sensor = _sensor_dist(sonar.pop("preset", None), f"{where} [sonar] 'preset'")
    given = {k: v for k, v in _SONAR_DEFAULTS.items() if sensor is None or k in sonar}
    sonar_d = _dists({k: sonar.pop(k, v) for k, v in given.items()}, given, f"{where} [sonar]")
    _no_leftovers(sonar, f"{where} [sonar]")
    track_t = _table(data, "track", where)
    track = _dists(
        {k: track_t.pop(k, v) for k, v in _TRACK_DEFAULTS.items()},
        _TRACK_DEFAULTS,
        f"{where} [track]",
    )
    _no_leftovers(track_t, f"{where} [track]")
    reach, lowest = range_bounds(sonar_d, sensor)[1], track["altitude"].bounds[0]
    if reach <= REACH_PAST_ALTITUDE * lowest:
        raise SonarRasterError(
            f"{where}: [sonar] max_range (at most {reach:g} m) never reaches past [track] "
            f"altitude (at least {lowest:g} m); make the range longer or the altitude lower"
        )
    seabeds = tuple(_seabed_spec(t, f"{where} [[seabed]]") for t in _tables(data, "seabed", where))
    if not seabeds:
        seabeds = (_seabed_spec({}, f"{where} [[seabed]]"),)
    if not sum(s.weight for s in seabeds) > 0:
        raise SonarRasterError(f"{where}: at least one [[seabed]] needs a weight > 0")
    objects = tuple(
        _object_spec(t, k, where) for k, t in enumerate(_tables(data, "objects", where))
    )
    place = _table(data, "placement", where)
    min_sep = _number(place.pop("min_separation", 2.0), f"{where} [placement] min_separation")
    placement = _dists(
        {k: place.pop(k, v) for k, v in _PLACEMENT_DEFAULTS.items()},
        _PLACEMENT_DEFAULTS,
        f"{where} [placement]",
    )
    _no_leftovers(place, f"{where} [placement]")
    labels = _table(data, "labels", where)
    ratio = _number(labels.pop("shadow_ratio", 0.5), f"{where} [labels] shadow_ratio")
    box = labels.pop("box", "highlight")
    min_pixels = _positive_int(labels, "min_pixels", 1, f"{where} [labels]")
    _no_leftovers(labels, f"{where} [labels]")
    if not 0 < ratio < 1:
        raise SonarRasterError(f"{where} [labels]: 'shadow_ratio' must be in (0, 1)")
    if box not in BOX_MODES:
        raise SonarRasterError(f"{where} [labels]: 'box' must be one of {', '.join(BOX_MODES)}")
    output = _table(data, "output", where)
    formats = output.pop("formats", ["png", "exr"])
    bits = output.pop("bits", 8)
    dr = output.pop("dynamic_range_db", None)
    _no_leftovers(output, f"{where} [output]")
    if not isinstance(formats, list) or "png" not in formats or set(formats) - set(FORMATS):
        raise SonarRasterError(f'{where} [output]: \'formats\' must be ["png"] or ["png", "exr"]')
    if bits not in (8, 16):
        raise SonarRasterError(f"{where} [output]: 'bits' must be 8 or 16")
    render = _table(data, "render", where)
    _check_render(render, f"{where} [render]")
    effects = data.pop("effects", None)
    if effects is not None and not isinstance(effects, dict):
        raise SonarRasterError(f"{where}: [effects] must be a table")
    background = _background(data.pop("background", None), path.parent, f"{where} [background]")
    _no_leftovers(data, f"{where} (top level)")
    config = DatasetConfig(
        source=str(path.resolve()),
        name=name,
        count=count,
        seed=seed,
        pings=pings,
        bins=bins,
        sides=tuple(s for s in SIDES if s in sides),
        sonar=sonar_d,
        sensor=sensor,
        track=track,
        seabeds=seabeds,
        objects=objects,
        placement=placement,
        min_separation=min_sep,
        shadow_ratio=ratio,
        box=box,
        min_pixels=min_pixels,
        formats=tuple(f for f in FORMATS if f in formats),
        bits=int(bits),
        dynamic_range_db=None if dr is None else _number(dr, f"{where} [output] dynamic_range_db"),
        render=render,
        effects=effects,
        raw=raw,
        background=background,
    )
    return _with_digest(config)


def _with_digest(config: DatasetConfig) -> DatasetConfig:
    """Stamp the config with a SHA-256 of its content and of every user mesh it names.

    The sample count is left out: a later run may ask for more samples (``-n``).
    """
    raw = json.loads(json.dumps(config.raw))
    raw.get("dataset", {}).pop("count", None)  # a run may ask for more samples (-n)
    h = hashlib.sha256(json.dumps(raw, sort_keys=True).encode())
    for spec in config.objects:
        if spec.file is not None:
            mesh = config.base / spec.file
            h.update(mesh.read_bytes() if mesh.is_file() else b"<missing>")
    for recording in config.background.recordings if config.background else ():
        h.update(Path(recording).read_bytes())
    return replace(config, digest=h.hexdigest())
