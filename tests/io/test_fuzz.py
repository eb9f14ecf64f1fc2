"""Fuzzing the readers: damaged XTF and VRML inputs from a fixed seed, for a time budget.

Every input must read or raise :class:`SonarRasterError` with a one-line message; any other
exception, and any warning other than a one-line :class:`InputWarning` (a documented note on
the input, e.g. a VRML departure from the spec), is a crash. The budget is 30 s per
reader; ``SONAR_RASTER_FUZZ_SECONDS`` changes it (longer runs go further down the same
sequence of inputs).
"""

from __future__ import annotations

import gzip
import logging
import os
import random
import re
import struct
import time
import traceback
import warnings
from collections import Counter
from collections.abc import Callable
from functools import partial
from pathlib import Path

import pytest
from conftest import SHARED_DATA

from sonar_raster.errors import InputWarning, SonarRasterError
from sonar_raster.io.xtf import iter_pings, read_xtf
from sonar_raster.meshio.load import load_model
from sonar_raster.meshio.vrml import parse_vrml

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"
BUDGET = float(os.environ.get("SONAR_RASTER_FUZZ_SECONDS", "30"))
PACKET = 4480  # bytes of each ping of the sample: header 256, two channels of 64 + 2048


class Crashes:
    """Exceptions other than one-line SonarRasterErrors, by kind, with the first input of each."""

    def __init__(self, directory: Path) -> None:
        self.directory, self.kinds, self.inputs = directory, Counter(), 0
        self.first: dict[tuple[str, str, int], tuple[str, Path]] = {}

    def run(self, call: Callable[[], object], data: bytes, suffix: str) -> None:
        try:
            with warnings.catch_warnings(record=True) as seen:
                warnings.simplefilter("error")
                warnings.simplefilter("always", InputWarning)  # a one-line note on the input
                call()
            for note in seen:
                if "\n" in str(note.message):
                    raise SonarRasterError(f"multi-line warning:\n{note.message}")
        except SonarRasterError as exc:
            if "\n" not in str(exc):
                return
            where, exc_text = ("multi-line message", "", 0), str(exc)
        except Exception as exc:  # anything else is what the fuzzer looks for
            frame = traceback.extract_tb(exc.__traceback__)[-1]
            where = (type(exc).__name__, Path(frame.filename).name, frame.lineno or 0)
            exc_text = str(exc)
        else:
            return
        self.kinds[where] += 1
        if where not in self.first:
            path = self.directory / f"crash_{len(self.first)}{suffix}"
            path.write_bytes(data)
            self.first[where] = (exc_text[:200], path)

    def report(self) -> str:
        lines = [f"{self.inputs} inputs, {sum(self.kinds.values())} crashes"]
        for where, n in self.kinds.most_common():
            message, path = self.first[where]
            lines.append(f"{n} x {where}: {message} (input kept in {path})")
        return "\n".join(lines)


def _special(rng: random.Random, width: int) -> bytes:
    """A value that breaks fields of ``width`` bytes: extremes, NaN, infinity, random bytes."""
    numbers = {
        1: [0, 255, 127, 128],
        2: [struct.pack("<h", v) for v in (-32768, 32767, -200, 200, 0, -1)],
        4: [struct.pack("<f", v) for v in (1e30, float("nan"), float("inf"), -1.0, 0.0)]
        + [struct.pack("<I", v) for v in (0xFFFFFFFF, 0x80000000, 5000)],
        8: [struct.pack("<d", v) for v in (1e300, -1e300, float("nan"), float("inf"), 0.01)],
    }[width]
    pick = rng.choice(numbers)
    if isinstance(pick, int):
        return bytes([pick])
    return pick if rng.random() < 0.8 else bytes(rng.randrange(256) for _ in range(width))


def _mutate_xtf(rng: random.Random, base: bytes) -> bytes:
    """Byte flips, truncation, field overwrites in packet and file headers, cut or repeated
    spans: one to three of them."""
    b = bytearray(base)
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        op = rng.randrange(6)
        if op == 0:
            for _ in range(rng.randint(1, 16)):
                i = rng.randrange(len(b))
                b[i] ^= 1 << rng.randrange(8)
        elif op == 1:
            b = b[: rng.randrange(len(b) + 1)]
        elif op == 2 and len(b) > 1024 + PACKET:
            ping = rng.randrange((len(b) - 1024) // PACKET)
            field = rng.choice(  # start of packet, ping header, either channel header
                [rng.randrange(14), rng.randrange(256), 256 + rng.randrange(64)]
                + [256 + 64 + 2048 + rng.randrange(64)]
            )
            width = rng.choice([1, 2, 4, 8])
            at = 1024 + ping * PACKET + field
            b[at : at + width] = _special(rng, width)
        elif op == 3:
            width = rng.choice([1, 2, 4])
            at = rng.randrange(1024)
            b[at : at + width] = _special(rng, width)
        elif op == 4 and len(b) > 10:
            i = rng.randrange(len(b))
            j = min(len(b), i + rng.randrange(1, 5000))
            b[i:j] = b"" if rng.random() < 0.5 else b[i:j] * 2
        elif b:
            b[rng.randrange(len(b))] = rng.randrange(256)
    return bytes(b)


@pytest.mark.slow
def test_fuzz_xtf_reader(tmp_path, caplog):
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    caplog.set_level(logging.ERROR, logger="sonar_raster")  # skipped pings are not news here
    whole = SAMPLE.read_bytes()
    head = whole[: 1024 + 12 * PACKET]  # twelve pings: ten times the inputs of the whole file
    rng = random.Random(20240519)
    crashes = Crashes(tmp_path)
    path = tmp_path / "fuzzed.xtf"
    end = time.monotonic() + BUDGET
    while time.monotonic() < end:
        data = _mutate_xtf(rng, head if rng.random() < 0.9 else whole)
        path.write_bytes(data)
        crashes.inputs += 1
        crashes.run(partial(read_xtf, path), data, ".xtf")
        crashes.run(partial(list, iter_pings(path)), data, ".xtf")
        crashes.run(partial(read_xtf, path, slice(3, 8)), data, ".xtf")
    print(crashes.report())
    assert crashes.inputs > 100
    assert not crashes.kinds, crashes.report()


VRML = """#VRML V2.0 utf8
# every node kind the reader knows
PROTO Block [ field SFVec3f size 1 1 1 field SFVec3f where 0 0 0 field SFColor colour 1 1 1 ] {
  Transform { translation IS where children [ Shape {
    appearance Appearance { material Material { diffuseColor IS colour } }
    geometry Box { size IS size } } ] }
}
DEF root Transform {
  translation 1 2 3 rotation 0 0 1 0.5 scale 2 1 1 scaleOrientation 1 0 0 0.3 center 0.5 0 0
  children [
    DEF tri Shape { appearance Appearance { material Material { diffuseColor 0.8 0.2 0.1 } }
      geometry IndexedFaceSet { ccw FALSE
        coord Coordinate { point [ 0 0 0, 1 0 0, 1 1 0, 0 1 0, 0.5 0.5 1 ] }
        coordIndex [ 0 1 2 3 -1 0 1 4 -1 1 2 4 -1 ] } }
    Shape { geometry Cylinder { radius 0.25 height 2 top FALSE } }
    Shape { geometry Cone { bottomRadius 1 height 2 } }
    Shape { geometry Sphere { radius 0.5 } }
    Shape { geometry ElevationGrid { xDimension 3 zDimension 2 xSpacing 0.5 zSpacing 0.5
      height [ 0 1 0, 1 2 1 ] } }
    Switch { whichChoice 1 choice [ Shape { geometry Box { } } USE tri ] }
    LOD { range [ 10 ] level [ Group { children [ USE tri ] } ] }
    Block { size 2 4 6 where 10 0 0 colour 1 0 1 }
    Collision { children [ Anchor { children [ Billboard { children [ Block { } ] } ] } ] }
  ]
}
Transform { translation 0x10 0 -5 children USE root }
"""
NUMBERS = ["1e999", "-1e999", "nan", "inf", "-0.25", "0", "-1", "1e308", "0x7fffffff"]
NUMBERS += ["0x1" + "0" * 300, "2147483648", "99999999999999999999", "-", "1e30", "3.4e38"]
INSERTS = ["USE root", "USE nothing", "DEF x", "PROTO P [ ] { }", "IS size", "{", "}", "[", "]"]
INSERTS += ['Inline { url "missing.wrl" }', 'Inline { url "self.wrl" }', '"', "#"]
INSERTS += ['EXTERNPROTO E [ ] "nowhere.wrl#E"', "E { }", "Transform { children [", "0x"]
NUMBER = re.compile(r"[-+]?(?:0x[0-9a-fA-F]+|\d+\.?\d*(?:e[-+]?\d+)?|\.\d+)")


def _mutate_vrml(rng: random.Random, text: str) -> str:
    """Character flips, truncation, numbers replaced by extremes, spans cut or repeated,
    keywords inserted, brackets swapped, names exchanged: one to five of them."""
    for _ in range(rng.choice([1, 1, 2, 3, 5])):
        op = rng.randrange(7)
        if op == 0 and text:
            i = rng.randrange(len(text))
            char = chr(rng.choice([rng.randrange(32, 127), rng.randrange(32), 0x2028, 0xFEFF]))
            text = text[:i] + char + text[i + 1 :]
        elif op == 1:
            text = text[: rng.randrange(len(text) + 1)]
        elif op == 2 and (numbers := list(NUMBER.finditer(text))):
            m = rng.choice(numbers)
            text = text[: m.start()] + rng.choice(NUMBERS) + text[m.end() :]
        elif op == 3 and text:
            i = rng.randrange(len(text))
            j = min(len(text), i + rng.randrange(1, 200))
            text = text[:i] + text[i:j] * rng.choice([0, 2, 3]) + text[j:]
        elif op == 4:
            i = rng.randrange(len(text) + 1)
            text = f"{text[:i]} {rng.choice(INSERTS)} {text[i:]}"
        elif op == 5 and (brackets := [m.start() for m in re.finditer(r"[\[\]{}]", text)]):
            i = rng.choice(brackets)
            text = text[:i] + rng.choice("[]{} ") + text[i + 1 :]
        elif words := list(re.finditer(r"[A-Za-z]+", text)):
            a, b = rng.choice(words), rng.choice(words)
            text = text[: a.start()] + b.group() + text[a.end() :]
    return text


def _damage_bytes(rng: random.Random, text: str) -> tuple[bytes, str]:
    """The text as file bytes and suffix: sometimes with bytes that are not UTF-8, sometimes
    gzipped (and the gzip stream damaged or cut)."""
    data = bytearray(text.encode("utf-8"))
    if rng.random() < 0.2 and data:
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    if rng.random() > 0.1:
        return bytes(data), ".wrl"
    packed = bytearray(gzip.compress(bytes(data)))
    if rng.random() < 0.5:
        for _ in range(rng.randint(1, 4)):
            packed[rng.randrange(10, len(packed))] = rng.randrange(256)
    if rng.random() < 0.3:
        packed = packed[: rng.randrange(len(packed))]
    return bytes(packed), ".wrl.gz"


@pytest.mark.slow
def test_fuzz_vrml_loader(tmp_path):
    rng = random.Random(20240519)
    crashes = Crashes(tmp_path)
    (tmp_path / "self.wrl").write_text(VRML.replace("0x10", 'Inline { url "self.wrl" }'))
    end = time.monotonic() + BUDGET
    while time.monotonic() < end:
        text = _mutate_vrml(rng, VRML)
        data, suffix = _damage_bytes(rng, text)
        path = tmp_path / f"fuzzed{suffix}"
        path.write_bytes(data)
        crashes.inputs += 1
        crashes.run(partial(parse_vrml, text, base_dir=tmp_path), text.encode(), ".txt")
        crashes.run(partial(load_model, path), data, suffix)
    print(crashes.report())
    assert crashes.inputs > 100
    assert not crashes.kinds, crashes.report()
