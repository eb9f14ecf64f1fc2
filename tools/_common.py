"""What every script in tools/ shares: paths, the argument parser prelude, matplotlib headless.

Scripts run as ``python tools/NAME.py``, which puts this folder on ``sys.path``, so they
``from _common import ...`` directly. Nothing here imports tests/.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

#: The repository root, the docs folder, and the real recording beside the clone.
ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REAL_XTF = ROOT.parent / "shared" / "data" / "xtf" / "scotsman-iver2.xtf"
DATASET_CONFIG = ROOT / "sonar_raster" / "scenes" / "data" / "dataset_default.toml"


def parser(doc: str | None, out: Path | None = None) -> argparse.ArgumentParser:
    """An ArgumentParser described by the first paragraph of ``doc``, with ``--out`` if given."""
    ap = argparse.ArgumentParser(description=(doc or "").strip().split("\n\n")[0])
    if out is not None:
        ap.add_argument("--out", type=Path, default=out, help=f"output folder (default {out})")
    return ap


def pyplot() -> Any:
    """matplotlib's pyplot on the headless Agg backend (matplotlib is a package dependency)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path, dpi: int = 110, small: Path | None = None) -> None:
    """Save ``fig`` to ``path`` (and a 60-dpi copy to ``small``), creating folders; close it."""
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    if small is not None:
        fig.savefig(small, dpi=60)
    plt.close(fig)
