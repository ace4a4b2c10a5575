"""DAQ files with the faults field data has, for the campaign and the property tests.

:func:`write_faulted_csv` writes a clean table of channels with a time column, then applies
faults: cells made blank, ``NaN``, ``inf``/``-inf``, ``1e30`` or text; a row's time repeated or
set backwards; the last row cut short; a units row; decimal commas (with ``;`` separators). It
returns what a reader must do with each fault, so a test or the campaign can compare what was
kept with the clean values sample by sample and check every rejection was counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["CELL_FAULTS", "FaultedFile", "modal_response", "write_faulted_csv"]

#: Cell faults and the reason a reader counts (1e30 is a number: the table keeps it, the kind's
#: limits or the outlier test reject it as implausible).
CELL_FAULTS = {"blank": "blank", "nan": "nonfinite", "inf": "nonfinite", "-inf": "nonfinite", "1e30": "implausible",
               "ERR": "unparsable"}


@dataclass
class FaultedFile:
    """The file, its clean values (N, k) and times, and the expected rejections.

    ``cells``: (row, column index) → expected reason; ``rows``: rows whose time is bad (every
    channel rejected, reason ``time``); ``truncated``: columns missing from the last row."""

    path: Path
    clean: np.ndarray
    time: np.ndarray
    names: list[str]
    cells: dict[tuple[int, int], str] = field(default_factory=dict)
    rows: set[int] = field(default_factory=set)
    truncated: list[int] = field(default_factory=list)


def write_faulted_csv(path: Path, clean: np.ndarray, fs: float, *, cells: dict[tuple[int, int], str] | None = None,
                      repeated_times: tuple[int, ...] = (), backwards_times: tuple[int, ...] = (), cut_last_row: int | None = None,
                      units_row: bool = False, decimal_comma: bool = False) -> FaultedFile:
    """Write ``clean`` (N, k) with a ``time`` column at ``fs`` Hz and the faults to ``path``.

    ``cells`` maps (row, column) to a key of ``CELL_FAULTS``; ``repeated_times`` rows take the
    previous row's time, ``backwards_times`` rows a time 3 steps back; ``cut_last_row`` keeps that
    many fields of the last row (time included, >= 1)."""
    n, k = clean.shape
    time = np.arange(n) / fs
    names = [f"ch{j}" for j in range(k)]
    out = FaultedFile(path, clean, time, names)
    stamps = [repr(float(t)) for t in time]
    for r in repeated_times:
        if 0 < r < n:
            stamps[r] = stamps[r - 1]
            out.rows.add(r)
    for r in backwards_times:
        # just before a repeated row, that row carries this one's true stamp: one step early between
        # valid rows, off the clock, which the reader rejects as that row's time (expected here too)
        if 3 <= r < n and r not in out.rows and (r - 1) not in out.rows:
            stamps[r] = repr(float(time[r - 3]))
            out.rows.add(r)
    sep = ";" if decimal_comma else ","
    lines = [sep.join(["time", *names])]
    if units_row:
        lines.append(sep.join(["s", *["m/s^2"] * k]))
    for i in range(n):
        row = [stamps[i]] + [repr(float(v)) for v in clean[i]]
        for j in range(k):
            fault = (cells or {}).get((i, j))
            if fault is not None:
                row[j + 1] = "" if fault == "blank" else fault
                if i not in out.rows:
                    out.cells[i, j] = CELL_FAULTS[fault]
        if decimal_comma:
            row = [c.replace(".", ",") for c in row]
        lines.append(sep.join(row))
    if cut_last_row is not None and 1 <= cut_last_row <= k and (n - 1) not in out.rows:
        fields = lines[-1].split(sep)[:cut_last_row]
        lines[-1] = sep.join(fields)
        out.truncated = list(range(cut_last_row - 1, k))
        for j in out.truncated:
            out.cells.pop((n - 1, j), None)
    path.write_text("\n".join(lines) + "\n")
    return out


def modal_response(n: int, fs: float, channels: int = 8, seed: int = 7) -> np.ndarray:
    """``channels`` outputs of a three-mode system (2.1, 5.3 and 9.7 Hz; 1, 1.5 and 2 % damping;
    the shapes of a cantilever's first three modes) under white noise, with 1 % sensor noise."""
    from scipy import signal

    rng = np.random.default_rng(seed)
    freqs, zetas = (2.1, 5.3, 9.7), (0.01, 0.015, 0.02)
    x = np.linspace(0.1, 1.0, channels)
    shapes = np.array([np.sin((2 * k + 1) * np.pi / 2 * x) for k in range(3)])
    y = np.zeros((n, channels))
    for f, z, phi in zip(freqs, zetas, shapes):
        w = 2 * np.pi * f
        b, a, _ = signal.cont2discrete(([w * w], [1, 2 * z * w, w * w]), 1 / fs)
        y += np.outer(signal.lfilter(np.ravel(b), a, rng.normal(size=n)), phi)
    return y + 0.01 * rng.normal(size=y.shape) * y.std()
