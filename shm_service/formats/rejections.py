"""Counted rejections of single samples: what a reader refused, per channel and reason.

Every entry point that takes measured data (``shm import``, ``shm oma``, ``shm analyze``, the
recording reader, ingest) rejects a bad value at the smallest unit it can: one channel's one
sample. What was rejected is counted here, per channel and per reason, with the first few
positions, so a command's output and JSON say exactly what was left out and where.

Reasons (``REASONS``):

- ``blank``: an empty cell;
- ``unparsable``: a cell that is not a number (``ERR``, ``1,2.3``, ``--``);
- ``nonfinite``: NaN or ±infinity;
- ``implausible``: beyond the limit of the sensor kind or channel (the message names the limit);
- ``truncated``: a row cut short (the last line of a file cut mid-write), its missing cells;
- ``time``: the row's time cell is blank, not a number, repeated or earlier than the previous
  row's: every channel of that row is rejected (the sample has no instant).

Also the module's pure helpers for plain channels (``shm oma``): :func:`outliers` (a value
absurdly far from the channel's own scale) and :func:`fill_short_gaps` (linear interpolation over
runs of at most a few rejected samples, counted).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["REASONS", "Rejections", "fill_short_gaps", "longest_clean_span", "outliers"]

REASONS = ("blank", "unparsable", "nonfinite", "implausible", "truncated", "time")
#: How many first positions are kept per channel.
FIRST_KEPT = 5


@dataclass
class _Channel:
    reasons: dict[str, int] = field(default_factory=dict)
    first: list[tuple[int, str]] = field(default_factory=list)
    limits: dict[str, str] = field(default_factory=dict)

    @property
    def total(self) -> int:
        return sum(self.reasons.values())


class Rejections:
    """Rejected samples per channel and reason, with the first positions (sample indices).

    ``line_of`` maps a sample index to the file's line number (1-based) where the file has lines.

    Examples
    --------
    >>> r = Rejections()
    >>> r.add("a", "blank", [3])
    >>> r.total, r.as_dict()["channels"]["a"]["reasons"]
    (1, {'blank': 1})
    """

    def __init__(self) -> None:
        self._channels: dict[str, _Channel] = {}
        self.line_of: np.ndarray | None = None

    def add(self, channel: str, reason: str, positions: Any, *, limit: str | None = None) -> None:
        """Count the samples at ``positions`` (indices) of ``channel`` as rejected for ``reason``;
        ``limit`` (text) says which limit an ``implausible`` value broke."""
        if reason not in REASONS:
            raise ValueError(f"{reason=} is not one of {REASONS}")
        where = np.unique(np.asarray(positions, dtype=np.int64).ravel())
        if not where.size:
            return
        entry = self._channels.setdefault(channel, _Channel())
        entry.reasons[reason] = entry.reasons.get(reason, 0) + int(where.size)
        entry.first = sorted(entry.first + [(int(p), reason) for p in where[:FIRST_KEPT]])[:FIRST_KEPT]
        if limit is not None:
            entry.limits[reason] = limit

    def merge(self, other: "Rejections", rename: dict[str, str] | None = None) -> None:
        """Add ``other``'s counts (channels renamed by ``rename``)."""
        for name, entry in other._channels.items():
            mine = self._channels.setdefault((rename or {}).get(name, name), _Channel())
            for reason, count in entry.reasons.items():
                mine.reasons[reason] = mine.reasons.get(reason, 0) + count
            mine.first = sorted(mine.first + entry.first)[:FIRST_KEPT]
            mine.limits.update(entry.limits)

    def only(self, channel: str) -> "Rejections":
        """The rejections of ``channel`` alone."""
        out = Rejections()
        out.line_of = self.line_of
        if channel in self._channels:
            entry = self._channels[channel]
            out._channels[channel] = _Channel(dict(entry.reasons), list(entry.first), dict(entry.limits))
        return out

    @property
    def total(self) -> int:
        """Rejected (channel, sample) pairs."""
        return sum(c.total for c in self._channels.values())

    def of(self, channel: str) -> int:
        entry = self._channels.get(channel)
        return 0 if entry is None else entry.total

    def by_reason(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for entry in self._channels.values():
            for reason, count in entry.reasons.items():
                out[reason] = out.get(reason, 0) + count
        return out

    def channels(self) -> list[str]:
        return list(self._channels)

    def _position(self, sample: int, reason: str) -> dict[str, Any]:
        out: dict[str, Any] = {"sample": sample, "reason": reason}
        if self.line_of is not None and 0 <= sample < len(self.line_of):
            out["line"] = int(self.line_of[sample])
        return out

    def as_dict(self) -> dict[str, Any]:
        """``{"total", "by_reason", "channels": {name: {"total", "reasons", "first": [...], "limits"}}}``."""
        return {
            "total": self.total,
            "by_reason": self.by_reason(),
            "channels": {
                name: {"total": entry.total, "reasons": dict(entry.reasons),
                       "first": [self._position(p, r) for p, r in entry.first],
                       **({"limits": dict(entry.limits)} if entry.limits else {})}
                for name, entry in self._channels.items()
            },
        }

    def format(self, indent: str = "  ") -> list[str]:
        """One line per channel: ``name: 2 rejected (1 blank, 1 implausible |x| <= 2000 m/s²); first: line 3 (blank), ...``."""
        lines = []
        for name, entry in self._channels.items():
            reasons = ", ".join(f"{n} {r}" + (f" ({entry.limits[r]})" if r in entry.limits else "")
                                for r, n in entry.reasons.items())
            first = ", ".join((f"line {self.line_of[p]}" if self.line_of is not None and p < len(self.line_of)
                               else f"sample {p}") + f" ({r})" for p, r in entry.first)
            lines.append(f"{indent}{name}: {entry.total} rejected ({reasons}); first: {first}")
        return lines


def outliers(x: np.ndarray, factor: float) -> np.ndarray:
    """Samples of one channel absurdly far from its own scale: ``|x - median| > factor · P90``,
    with P90 the 90th percentile of ``|x - median|`` over the finite samples (so up to 10 % of
    the samples may be corrupt without hiding the rest).

    A random response exceeds its P90 by a factor 3 to 5 at its largest; a transient (an impact
    in a record of mostly quiet tail) by a few hundred at most. A DAQ's overflow code (1e30,
    9.9e37) or a corrupted float is beyond any.

    Parameters
    ----------
    x : (N,) array, NaN where already rejected.
    factor : float > 0

    Returns
    -------
    (N,) bool, True for an outlier (never for NaN).

    Examples
    --------
    >>> x = np.array([0.1, -0.2, 0.15, 1e30, -0.1, 0.05, -0.15, 0.2, 0.0, -0.05, 0.1, -0.1])
    >>> np.flatnonzero(outliers(x, 1000.0)).tolist()  # the overflow code; its P90 is of the others
    [3]
    """
    x = np.asarray(x, dtype=float)
    if not np.isfinite(factor) or factor <= 0:
        raise ValueError(f"{factor=} must be a positive finite number")
    good = np.isfinite(x)
    out = np.zeros(x.shape, dtype=bool)
    if good.sum() < 3:
        return out
    centre = float(np.median(x[good]))
    dev = np.abs(x[good] - centre)
    scale = float(np.percentile(dev, 90))
    if scale == 0.0:
        return out  # a channel constant at 90 % of its samples is left to the caller's limits
    with np.errstate(invalid="ignore"):
        out[good] = dev > factor * scale
    return out


def fill_short_gaps(data: np.ndarray, max_run: int) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation over runs of at most ``max_run`` NaN samples inside each channel.

    Parameters
    ----------
    data : (N, k) array, NaN where a sample was rejected.
    max_run : int >= 0
        Longest run filled; longer runs (and runs at either end) stay NaN.

    Returns
    -------
    filled : (N, k) array
    count : (k,) int, samples filled per channel.

    Examples
    --------
    >>> y, n = fill_short_gaps(np.array([[0.0], [np.nan], [2.0]]), 1)
    >>> y.ravel().tolist(), n.tolist()
    ([0.0, 1.0, 2.0], [1])
    """
    y = np.array(data, dtype=float, copy=True)
    if y.ndim != 2:
        raise ValueError(f"data must be (N, k), got shape {y.shape}")
    if max_run < 0:
        raise ValueError(f"{max_run=} must be >= 0")
    count = np.zeros(y.shape[1], dtype=np.int64)
    idx = np.arange(y.shape[0])
    for j in range(y.shape[1]):
        bad = ~np.isfinite(y[:, j])
        if not bad.any() or bad.all():
            continue
        edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        for a, b in zip(starts.tolist(), stops.tolist()):
            if b - a > max_run or a == 0 or b == y.shape[0]:
                continue
            y[a:b, j] = np.interp(idx[a:b], [a - 1, b], [y[a - 1, j], y[b, j]])
            count[j] += b - a
    return y, count


def longest_clean_span(data: np.ndarray) -> tuple[int, int]:
    """``(start, stop)`` of the longest run of rows with every channel finite (0, 0 if none)."""
    good = np.all(np.isfinite(data), axis=1)
    edges = np.diff(np.concatenate([[0], good.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if not starts.size:
        return 0, 0
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])
