"""Labelled datasets: configs, randomised scenes, rendering, labels (masks, YOLO, COCO), runners.

:func:`generate_dataset` renders N samples of a config into a folder, seeded per sample and
resumable, on a process pool or a Dask cluster.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .config import DatasetConfig, load_dataset_config
    from .generate import DatasetSummary, generate_dataset

__all__ = ["DatasetConfig", "DatasetSummary", "generate_dataset", "load_dataset_config"]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "DatasetConfig": "config",
        "load_dataset_config": "config",
        "DatasetSummary": "generate",
        "generate_dataset": "generate",
    },
)
