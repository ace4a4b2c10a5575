"""argparse ``type`` functions of the ``shm`` command line: a value out of range is refused with
the valid range, never clamped. Light on purpose (no numpy, no pydantic): ``shm --help`` and
argument errors answer without importing the numerics."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Callable

__all__ = ["number", "output_path"]


def number(kind: type = float, *, low: float | None = None, high: float | None = None, low_open: bool = False,
           unit: str = "") -> Callable[[str], float]:
    """An argparse ``type``: a finite ``kind`` in [low, high] (``low_open``: (low, high]); a value
    outside is refused naming the valid range, never clamped."""
    what = "an integer" if kind is int else "a number"
    if low is not None and high is not None and not low_open:
        valid = f"{what} from {low:g} to {high:g}"
    else:
        parts = []
        if low is not None:
            parts.append(f"{'>' if low_open else '>='} {low:g}")
        if high is not None:
            parts.append(f"<= {high:g}")
        valid = f"{what} " + (" and ".join(parts) or "that is finite")
    valid += f" {unit}" if unit else ""

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {what} (valid: {valid})") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} must be finite (valid: {valid})")
        if (low is not None and (value <= low if low_open else value < low)) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{text} is out of range (valid: {valid})")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


def output_path(text: str) -> str:
    """An argparse ``type`` for an output file: its directory must exist (nothing is created)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"directory {parent} does not exist (create it first)")
    return text
