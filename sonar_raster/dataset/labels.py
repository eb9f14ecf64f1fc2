"""Dataset labels from the renderer's object-id pass: instances, classes, shadows, boxes, COCO.

Images are in the display layout of :meth:`SonarImage.display`: rows = pings, port bins far to
near on the left, then starboard bins near to far. Per pixel:

- instance id (uint16): k for object instance k (1-based, as in the sample's sidecar) on its
  highlight *and* on its shadow; 0 for seabed, water column and unlabelled cells;
- class (uint8): 0 background (seabed, water column), 1 highlight (the renderer's label is an
  object), 2 shadow.

Shadow cells are those where the seabed alone is lit, the full scene is darker than
``ratio`` times the seabed alone (0.5 by default: more than half of the cell's seabed echo is
hidden) and the renderer's label is not an object; each is given to the object whose highlight
lies nearest at shorter range in the same ping (no such highlight: not a shadow).
"""

from __future__ import annotations

import numpy as np

#: Seabed-only cells below this fraction of the median lit cell count as unlit.
_LIT_FLOOR = 1e-3


def to_display(sides: dict[str, np.ndarray]) -> np.ndarray:
    """Port (flipped, range increasing to the left) then starboard, side by side (pings, bins)."""
    parts = []
    if "port" in sides:
        parts.append(sides["port"][:, ::-1])
    if "starboard" in sides:
        parts.append(sides["starboard"])
    return np.ascontiguousarray(np.concatenate(parts, axis=1))


def instances_from_labels(labels: np.ndarray) -> np.ndarray:
    """Renderer labels (0 none, 1 seabed, k + 1 object id k) to instance ids (0 none, k object).

    The seabed is scene object 0 and instance k is scene object k, so an object label
    ``v >= 2`` is instance ``v - 1``.
    """
    lab = np.asarray(labels).astype(np.int64)
    return np.where(lab >= 2, lab - 1, 0).astype(np.uint16)


def shadow_owners(
    intensity: np.ndarray, seabed_only: np.ndarray, instance: np.ndarray, ratio: float
) -> np.ndarray:
    """Instance id owning each shadow cell of one side, 0 elsewhere.

    Parameters
    ----------
    intensity : ndarray, shape (pings, bins), float
        The full scene's raw intensity (before effects).
    seabed_only : ndarray, shape (pings, bins), float
        The same pings rendered with the seabed alone.
    instance : ndarray, shape (pings, bins), uint16
        Highlight instance ids (0 where the label is not an object).
    ratio : float
        A cell is shadow when ``intensity < ratio * seabed_only``.

    Returns
    -------
    ndarray, shape (pings, bins), uint16
        For shadow cells, the instance whose highlight lies nearest at shorter range in the
        same ping; 0 for every other cell.
    """
    lit_values = seabed_only[seabed_only > 0]
    floor = _LIT_FLOOR * float(np.median(lit_values)) if lit_values.size else np.inf
    candidate = (seabed_only > floor) & (intensity < ratio * seabed_only) & (instance == 0)
    cols = np.arange(instance.shape[1])
    last = np.maximum.accumulate(np.where(instance > 0, cols, -1), axis=1)
    owner = np.take_along_axis(instance, np.maximum(last, 0), axis=1)
    owner = np.where(last >= 0, owner, 0)
    return np.where(candidate, owner, 0).astype(np.uint16)


def rle_encode(mask: np.ndarray) -> dict:
    """COCO uncompressed RLE of a boolean (h, w) mask: column-major run lengths from 0s."""
    flat = np.asarray(mask, dtype=bool).ravel(order="F")
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    edges = np.concatenate([[0], change, [flat.size]])
    runs = np.diff(edges).tolist()
    if flat.size and flat[0]:
        runs = [0, *runs]
    return {"counts": runs, "size": [int(mask.shape[0]), int(mask.shape[1])]}


def rle_decode(rle: dict) -> np.ndarray:
    """Inverse of :func:`rle_encode`: a boolean (h, w) mask."""
    h, w = rle["size"]
    values = np.arange(len(rle["counts"])) % 2 == 1
    flat = np.repeat(values, rle["counts"])
    return flat.reshape((w, h)).T


def _bbox(mask: np.ndarray) -> list[int] | None:
    """[x, y, width, height] in pixels (x = column, y = row), or None for an empty mask."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return [
        int(cols[0]),
        int(rows[0]),
        int(cols[-1] - cols[0] + 1),
        int(rows[-1] - rows[0] + 1),
    ]


def annotate(
    instance: np.ndarray,
    classes: np.ndarray,
    categories: list[int],
    box: str = "highlight",
    min_pixels: int = 1,
) -> list[dict]:
    """One annotation per instance whose highlight has at least ``min_pixels`` pixels.

    Parameters
    ----------
    instance, classes : ndarray, shape (h, w)
        Display-layout instance ids (uint16) and classes (uint8, 0/1/2).
    categories : list of int
        Category id of instance k at position k - 1.
    box : {"highlight", "highlight+shadow"}
        What the box (and area, segmentation) covers.
    min_pixels : int
        Smallest highlight kept.

    Returns
    -------
    list of dict
        ``instance``, ``category_id``, ``bbox`` [x, y, w, h], ``area`` (pixels), ``segmentation``
        (uncompressed RLE), ``shadow_bbox``/``shadow_area`` (None/0 without a shadow).
    """
    out = []
    for k, category in enumerate(categories, start=1):
        mine = instance == k
        highlight = mine & (classes == 1)
        n = int(highlight.sum())
        if n < min_pixels:
            continue
        shadow = mine & (classes == 2)
        region = highlight | shadow if box == "highlight+shadow" else highlight
        out.append(
            {
                "instance": k,
                "category_id": int(category),
                "bbox": _bbox(region),
                "area": int(region.sum()),
                "segmentation": rle_encode(region),
                "highlight_bbox": _bbox(highlight),
                "highlight_area": n,
                "shadow_bbox": _bbox(shadow),
                "shadow_area": int(shadow.sum()),
            }
        )
    return out


def yolo_lines(annotations: list[dict], width: int, height: int) -> str:
    """YOLO text: ``class cx cy w h`` per box, class = category id - 1, coordinates in [0, 1]."""
    lines = []
    for a in annotations:
        x, y, w, h = a["bbox"]
        lines.append(
            f"{a['category_id'] - 1} {(x + 0.5 * w) / width:.6f} {(y + 0.5 * h) / height:.6f} "
            f"{w / width:.6f} {h / height:.6f}"
        )
    return "".join(line + "\n" for line in lines)


def coco_document(records: list[dict], categories: tuple[str, ...], info: dict) -> dict:
    """The COCO detection document of every successful sample record, in index order.

    Image id = sample index + 1; annotation ids count from 1 in (image, instance) order.
    """
    images: list[dict] = []
    annotations: list[dict] = []
    for rec in sorted(records, key=lambda r: r["index"]):
        image_id = rec["index"] + 1
        images.append({"id": image_id, **rec["image"]})
        for a in rec["annotations"]:
            annotations.append(
                {
                    "id": len(annotations) + 1,
                    "image_id": image_id,
                    "category_id": a["category_id"],
                    "bbox": a["bbox"],
                    "area": a["area"],
                    "segmentation": a["segmentation"],
                    "iscrowd": 0,
                    "instance": a["instance"],
                    "shadow_bbox": a["shadow_bbox"],
                    "shadow_area": a["shadow_area"],
                }
            )
    return {
        "info": info,
        "licenses": [],
        "categories": [
            {"id": k, "name": name, "supercategory": "object"}
            for k, name in enumerate(categories, start=1)
        ],
        "images": images,
        "annotations": annotations,
    }
