"""Argument validators shared by every stage: one message style, one error type.

Each returns the value as a float (or int) once it passes, so a caller can write
``radius = positive("object parameter 'radius'", radius)``. ``label`` names the value the way
the user gave it (a keyword, a TOML key with its table, a command-line option).
"""

from __future__ import annotations

import argparse
import math
import numbers
from collections.abc import Callable, Iterable
from difflib import get_close_matches
from typing import Any

from .errors import SonarRasterError

__all__ = [
    "cli_positive",
    "did_you_mean",
    "fraction",
    "integer",
    "non_negative",
    "number",
    "positive",
]


def number(label: str, value: Any) -> float:
    """``value`` as a finite float; raise naming ``label`` if it is not a real, finite number."""
    if isinstance(value, bool):
        raise SonarRasterError(f"{label} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SonarRasterError(f"{label} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise SonarRasterError(f"{label} must be finite, got {value!r}")
    return v


def positive(label: str, value: Any) -> float:
    """``value`` as a finite float > 0."""
    v = number(label, value)
    if v <= 0:
        raise SonarRasterError(f"{label} must be > 0, got {value!r}")
    return v


def non_negative(label: str, value: Any) -> float:
    """``value`` as a finite float >= 0."""
    v = number(label, value)
    if v < 0:
        raise SonarRasterError(f"{label} must be >= 0, got {value!r}")
    return v


def fraction(label: str, value: Any, upper: float = 1.0) -> float:
    """``value`` as a float in ``[0, upper]``."""
    v = number(label, value)
    if not 0.0 <= v <= upper:
        raise SonarRasterError(f"{label} must be between 0 and {upper:g}, got {value!r}")
    return v


def integer(label: str, value: Any, minimum: int = 1) -> int:
    """``value`` as an int >= ``minimum`` (bools and non-integral floats refused)."""
    real = isinstance(value, numbers.Real)  # numpy's integers and floats too
    whole = real and math.isfinite(value) and value == int(value)
    if isinstance(value, bool) or not whole:
        raise SonarRasterError(f"{label} must be a whole number, got {value!r}")
    if value < minimum:
        raise SonarRasterError(f"{label} must be >= {minimum}, got {value!r}")
    return int(value)


def did_you_mean(unknown: Iterable[str], keys: Iterable[str]) -> str:
    """`` (k: did you mean key?; ...)`` for the unknown keys with a close known one, else ``""``."""
    known = list(keys)
    hints = [
        f"{k}: did you mean {m[0]}?"
        for k in unknown
        if isinstance(k, str) and (m := get_close_matches(k, known, 1))
    ]
    return f" ({'; '.join(hints)})" if hints else ""


def cli_positive(kind: type) -> Callable[[str], Any]:
    """An argparse ``type=`` that accepts a finite number > 0 of ``kind`` (int or float)."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
        if value <= 0:
            raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
        return value

    parse.__name__ = f"positive {kind.__name__}"
    return parse


def cli_seed(text: str) -> int:
    """An argparse ``type=`` for a seed: a whole number >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


cli_seed.__name__ = "seed"
