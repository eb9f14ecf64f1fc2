"""Hash what the CLI writes for every bundled scene, to prove a refactor changes no output.

Renders each bundled scene (and the ``default`` scene) with the GL raster renderer and with the
numpy reference, a speckled render with effects, a coherent render, an XTF file, a two-sample
dataset, runs ``track`` on the shared XTF file when it is
there, and inverts two renders. Each output is hashed by content, not bytes: pixels of EXR/PNG
files, JSON with run-dependent fields (times, versions, paths) removed, text files as they are.

    python tools/hash_outputs.py -o hashes.json          # run and write the table
    python tools/hash_outputs.py --compare before.json after.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

_VOLATILE = (
    "time",
    "timing",
    "version",
    "seconds",
    "created",
    "elapsed",
    "written",
    "committed",
    "pid",
)
_SCENES = (
    "default",
    "barrel_on_sand",
    "cylinder_on_flat",
    "flat_calibration",
    "truck_wheel_on_clay",
)
_SHARED_XTF = Path(__file__).resolve().parents[2] / "shared" / "data" / "xtf"


def _cli(*args: str) -> None:
    cmd = [str(Path(sys.executable).parent / "sonar-raster"), *args, "--quiet"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stderr}")


def _scrub(doc: object) -> object:
    if isinstance(doc, dict):
        return {
            k: _scrub(v) for k, v in doc.items() if not any(word in k.lower() for word in _VOLATILE)
        }
    if isinstance(doc, list):
        return [_scrub(v) for v in doc]
    if isinstance(doc, str) and doc.startswith("/"):
        return Path(doc).name  # absolute paths differ between runs and checkouts
    if isinstance(doc, float):
        return float(f"{doc:.9g}")
    return doc


def _content(path: Path) -> bytes:
    suffix = path.suffix.lower()
    if suffix in (".exr", ".png", ".tif"):
        inp = oiio.ImageInput.open(str(path))
        pixels = inp.read_image(format=oiio.UNKNOWN)
        inp.close()
        return np.ascontiguousarray(pixels).tobytes()
    if suffix == ".json":
        return json.dumps(_scrub(json.loads(path.read_text())), sort_keys=True).encode()
    if suffix == ".jsonl":
        lines = [_scrub(json.loads(line)) for line in path.read_text().splitlines()]
        return json.dumps(lines, sort_keys=True).encode()
    return path.read_bytes()


def _hash_tree(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(_content(p)).hexdigest()[:16]
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def run(out: Path) -> dict[str, str]:
    """Produce every output in a temporary folder and return {relative path: content hash}."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name in _SCENES:
            _cli(
                "render",
                name,
                "-o",
                str(work / f"{name}.exr"),
                "-o",
                str(work / f"{name}.png"),
                "--pings",
                "40",
            )
            _cli(
                "render",
                name,
                "-o",
                str(work / f"{name}_ref.exr"),
                "--renderer",
                "reference",
                "--pings",
                "4",
            )
        _cli(
            "render",
            "default",
            "-o",
            str(work / "speckled.exr"),
            "-o",
            str(work / "speckled.png"),
            "--speckle",
            "exponential",
            "--tvg",
            "log",
            "--spreading",
            "--absorption",
            "--along-beam-deg",
            "1",
            "--seed",
            "3",
            "--pings",
            "60",
        )
        _cli(
            "render",
            "cylinder_on_flat",
            "-o",
            str(work / "coherent.exr"),
            "--model",
            "coherent",
            "--pings",
            "2",
            "--spacing",
            "2",
            "--seed",
            "1",
        )
        _cli("render", "barrel_on_sand", "-o", str(work / "barrel.xtf"), "--pings", "10")
        _cli("dataset", "dataset_default", "-o", str(work / "dataset"), "-n", "2", "--seed", "5")
        _cli(
            "invert",
            str(work / "default.exr"),
            "-o",
            str(work / "inv_default"),
            "--max-iter",
            "5",
            "--no-previews",
        )
        _cli(
            "invert",
            str(work / "speckled.exr"),
            "-o",
            str(work / "inv_speckled"),
            "--side",
            "starboard",
            "--max-iter",
            "5",
            "--no-previews",
        )
        xtf = sorted(_SHARED_XTF.glob("*.xtf"))
        if xtf:
            _cli("track", str(xtf[0]), "-o", str(work / "track.csv"))
        hashes = _hash_tree(work)
    out.write_text(json.dumps(hashes, indent=1, sort_keys=True) + "\n")
    return hashes


def compare(before: Path, after: Path) -> int:
    """Print every output whose hash differs; return the number of differences."""
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    diffs = [k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
    for k in diffs:
        print(f"DIFFERS {k}: {a.get(k)} -> {b.get(k)}")
    print(f"{len(a)} outputs before, {len(b)} after, {len(diffs)} differ")
    return len(diffs)


def main() -> int:
    """Command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=Path("hashes.json"))
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"))
    args = parser.parse_args()
    if args.compare:
        return 1 if compare(*args.compare) else 0
    hashes = run(args.output)
    print(f"{len(hashes)} outputs hashed into {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
