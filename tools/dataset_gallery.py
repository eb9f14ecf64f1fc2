"""Picture of a few dataset samples with their boxes and shadow masks (docs/dataset_samples.png).

Makes the first N samples of a dataset config (default: the bundled ``dataset_default``) in a
folder, or reads an existing dataset folder, and draws each display image with its COCO boxes
(highlight, coloured by class) and its shadow mask (translucent blue).

    python tools/dataset_gallery.py [--dataset DIR | --config PATH] [-n 4] [-o OUT.png]
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
from _common import DATASET_CONFIG, DOCS, parser, pyplot


def _read(path: Path) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    try:
        return inp.read_image(inp.spec().format)[:, :, 0]
    finally:
        inp.close()


def draw(dataset: Path, n: int, out: Path) -> None:
    from matplotlib.patches import Rectangle

    plt = pyplot()

    coco = json.loads((dataset / "coco.json").read_text())
    names = {c["id"]: c["name"] for c in coco["categories"]}
    colours = dict(zip(names, plt.cm.tab10.colors, strict=False))
    images = coco["images"][:n]
    cols = 2
    rows = (len(images) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 3.6 * rows), squeeze=False)
    for ax, im in zip(axes.ravel(), images, strict=False):
        stem = Path(im["file_name"]).stem
        ax.imshow(_read(dataset / im["file_name"]), cmap="copper", aspect="auto")
        shadow = _read(dataset / "classes" / f"{stem}.png") == 2
        overlay = np.zeros((*shadow.shape, 4))
        overlay[shadow] = (0.2, 0.5, 1.0, 0.45)
        ax.imshow(overlay, aspect="auto")
        meta = json.loads((dataset / "meta" / f"{stem}.json").read_text())
        for a in (a for a in coco["annotations"] if a["image_id"] == im["id"]):
            x, y, w, h = a["bbox"]
            c = colours[a["category_id"]]
            ax.add_patch(Rectangle((x - 0.5, y - 0.5), w, h, fill=False, lw=1.2, ec=c))
            ax.text(x, y - 4, names[a["category_id"]], color=c, fontsize=7)
        ax.set_title(
            f"sample {stem}: {meta['seabed']['kind']} seabed, altitude "
            f"{meta['track']['altitude_m']:.1f} m, range {meta['sonar']['max_range_m']:.0f} m",
            fontsize=8,
        )
        ax.set_xlabel("slant-range bin (starboard)", fontsize=7)
        ax.set_ylabel("ping", fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in axes.ravel()[len(images) :]:
        ax.axis("off")
    fig.suptitle(
        "sonar-raster dataset samples: boxes from the renderer's object-id pass, shadows in blue",
        fontsize=9,
    )
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--dataset", type=Path, help="an existing dataset folder")
    ap.add_argument("--config", default=str(DATASET_CONFIG))
    ap.add_argument("-n", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-o", "--output", type=Path, default=DOCS / "dataset_samples.png")
    args = ap.parse_args()
    if args.dataset is not None:
        draw(args.dataset, args.n, args.output)
        return
    from sonar_raster.dataset.generate import generate_dataset

    with tempfile.TemporaryDirectory(prefix="gallery-") as tmp:
        generate_dataset(args.config, tmp, count=args.n, seed=args.seed)
        draw(Path(tmp), args.n, args.output)


if __name__ == "__main__":
    main()
