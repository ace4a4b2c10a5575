"""Streaming rainflow counting (ASTM E1049-85) whose cycles do not depend on how a record is split.

The counting itself is pyLife's :class:`pylife.stress.rainflow.FourPointDetector` (Bosch Research,
Apache-2.0, kept and released). We compared the three counters the field uses:

* ``rainflow`` (ASTM E1049-85 §5.4.4, three-point): counts a whole series only; its generator
  cannot be resumed with a new batch, and the start point's half cycles are emitted as it goes,
  so a split record counts different cycles. Pure Python: ~0.5 s per 360 000 samples here.
* ``fatpack``: ``find_rainflow_cycles`` returns the residue, but its reversal finder
  (``find_reversals``) quantises the signal into ``k`` classes of the *batch's* range, so a split
  record is counted on a different grid. Usable only with the racetrack filter, not exactly.
* pyLife ``FourPointDetector``: designed to be chunk invariant (``process(chunk)`` carries the
  turning points not yet closed, the *residue*, and the sample tail), the loop in Cython
  (~0.03 s per 360 000 samples whole, ~0.25 ms per call). Its residue is public
  (``residuals``), so it can be persisted and a detector restored from it.

So pyLife counts; this module adds what a monitoring service needs around it: validation (a
NaN is an error naming the sample, pyLife would drop it with a warning and miss a turning
point), a serialisable :class:`RainflowResidue`, restoration after a restart, and the ASTM
treatment of the residue at the end of a record (each pair of neighbouring residue points a half
cycle). The four-point method with the residue counted as half cycles gives the same cycles as
the ASTM three-point method (tested against the ``rainflow`` package, whole and split).

Ranges are in the signal's unit; counts are 1 (a closed cycle) or, for the residue, 0.5 (policy
``"half"``, ASTM), 1 (``"full"``, conservative) or 0 (``"ignore"``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

__all__ = ["Cycles", "HalfCyclePolicy", "RainflowCounter", "RainflowResidue", "cycles_by_range", "rainflow_cycles"]

HalfCyclePolicy = Literal["half", "full", "ignore"]
_HALF_WEIGHT = {"half": 0.5, "full": 1.0, "ignore": 0.0}

#: Above this many distinct cycles ``cycles_by_range`` bins the ranges.
EXACT_CYCLE_LIMIT = 10_000


def _half_weight(policy: str) -> float:
    if policy in _HALF_WEIGHT:
        return _HALF_WEIGHT[policy]
    raise ValueError(f"half_cycles={policy!r} must be one of {sorted(_HALF_WEIGHT)}")


def _finite_samples(name: str, samples: object) -> np.ndarray:
    x = np.asarray(samples, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {x.shape}")
    bad = ~np.isfinite(x)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name}[{i}] = {x[i]} is not finite ({int(bad.sum())} non-finite samples): "
                         "a gap would hide a turning point, so the batch is not counted")
    return x


@dataclass(frozen=True)
class Cycles:
    """Counted cycles: ``ranges`` (K,) and ``means`` (K,) in the signal's unit, ``counts`` (K,) 1 or a
    residue's weight (0.5 by default)."""

    ranges: np.ndarray
    means: np.ndarray
    counts: np.ndarray

    @staticmethod
    def empty() -> "Cycles":
        z = np.zeros(0)
        return Cycles(z, z.copy(), z.copy())

    @staticmethod
    def concatenate(parts: "list[Cycles] | tuple[Cycles, ...]") -> "Cycles":
        if not parts:
            return Cycles.empty()
        return Cycles(np.concatenate([p.ranges for p in parts]), np.concatenate([p.means for p in parts]),
                      np.concatenate([p.counts for p in parts]))

    @property
    def total(self) -> float:
        """Number of cycles (half cycles count as their weight)."""
        return float(np.sum(self.counts))

    def scaled(self, factor: float) -> "Cycles":
        """Ranges and means times ``factor`` (strain → stress, stress concentration)."""
        return Cycles(self.ranges * abs(factor), self.means * factor, self.counts)


@dataclass(frozen=True)
class RainflowResidue:
    """The state of a streaming count: the open reversals and how many samples were counted.

    values : turning points not yet closed, oldest first: the record's first sample, the
    residue's reversals, and the latest sample (which may or may not become a reversal).
    samples : samples counted so far. JSON-serialisable through :meth:`as_dict`.
    """

    values: tuple[float, ...] = ()
    samples: int = 0

    def as_dict(self) -> dict[str, Any]:
        # float repr round-trips exactly through JSON.
        return {"values": [float(v) for v in self.values], "samples": int(self.samples)}

    @staticmethod
    def from_dict(data: dict[str, Any]) -> "RainflowResidue":
        try:
            values = tuple(float(v) for v in data["values"])
            samples = int(data["samples"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a rainflow residue: {data!r} ({exc})") from None
        if samples < len(values) - 1 or samples < 0 or not all(np.isfinite(values)):
            raise ValueError(f"not a rainflow residue: samples={samples} with {len(values)} values")
        return RainflowResidue(values, samples)

    def half_cycles(self, half_cycles: HalfCyclePolicy = "half") -> Cycles:
        """The residue closed as ASTM E1049-85 does at the end of a record: each pair of
        neighbouring residue points is one half cycle (weight by the policy)."""
        weight = _half_weight(half_cycles)
        v = np.asarray(self.values, dtype=float)
        if v.size < 2 or weight == 0.0:
            return Cycles.empty()
        ranges = np.abs(np.diff(v))
        keep = ranges > 0
        return Cycles(ranges[keep], (0.5 * (v[1:] + v[:-1]))[keep], np.full(int(keep.sum()), weight))


class _BatchRecorder:
    """pyLife recorder that keeps only the loops of the current batch."""

    def __init__(self) -> None:
        self.start: list[np.ndarray] = []
        self.end: list[np.ndarray] = []

    def record_values(self, values_from, values_to) -> None:
        self.start.append(np.asarray(values_from, dtype=float))
        self.end.append(np.asarray(values_to, dtype=float))

    def record_index(self, index_from, index_to) -> None:  # indices are not needed
        pass

    def report_chunk(self, chunk_size) -> None:
        pass

    def take(self) -> Cycles:
        if not self.start:
            return Cycles.empty()
        a, b = np.concatenate(self.start), np.concatenate(self.end)
        self.start.clear()
        self.end.clear()
        return Cycles(np.abs(b - a), 0.5 * (a + b), np.ones(a.size))


class RainflowCounter:
    """Streaming four-point rainflow counter (pyLife) with a persistable residue.

    ``push(batch)`` returns the cycles closed by the batch; :attr:`residue` is the open part. The
    closed cycles of all batches plus ``residue.half_cycles()`` are the cycles of the whole record
    counted at once, for any split. A counter built from a saved residue continues exactly.

    Examples
    --------
    >>> c = RainflowCounter()
    >>> closed = c.push([-2, 1, -3, 5, -1])
    >>> closed = Cycles.concatenate([closed, c.push([3, -4, 4, -2])])
    >>> closed.ranges.tolist(), c.residue.half_cycles().ranges.tolist()
    ([4.0], [3.0, 4.0, 8.0, 9.0, 8.0, 6.0])
    """

    def __init__(self, residue: RainflowResidue | None = None) -> None:
        from pylife.stress.rainflow import FourPointDetector

        self._recorder = _BatchRecorder()
        self._detector = FourPointDetector(recorder=self._recorder)
        self._samples = 0
        if residue is not None and residue.values:
            # The residue holds no closable loop: replaying it restores the detector's state.
            self._detector.process(np.asarray(residue.values, dtype=float))
            replayed = self._recorder.take()
            if replayed.ranges.size:
                raise ValueError(f"not a rainflow residue: {list(residue.values)} closes {replayed.ranges.size} cycle(s)")
            self._samples = int(residue.samples)

    @property
    def samples(self) -> int:
        return self._samples

    @property
    def residue(self) -> RainflowResidue:
        return RainflowResidue(tuple(float(v) for v in np.asarray(self._detector.residuals)), self._samples)

    def push(self, samples: object, *, name: str = "samples") -> Cycles:
        """Count a batch (1-D, finite); returns the cycles it closes (counts 1)."""
        x = _finite_samples(name, samples)
        if x.size == 0:
            return Cycles.empty()
        self._detector.process(x)
        self._samples += int(x.size)
        return self._recorder.take()


def rainflow_cycles(signal: object, *, half_cycles: HalfCyclePolicy = "half") -> Cycles:
    """All cycles of a whole record (ASTM E1049-85): closed cycles, then the residue by the policy.

    Parameters
    ----------
    signal : (N,) finite samples (any unit).
    half_cycles : "half" (ASTM, default), "full" or "ignore": the weight of the residue's half cycles.

    Returns
    -------
    Cycles with ranges and means in the signal's unit.

    Raises
    ------
    ValueError : a non-finite sample (named by index) or an unknown policy.

    Examples
    --------
    >>> c = rainflow_cycles([-2, 1, -3, 5, -1, 3, -4, 4, -2])
    >>> cycles_by_range(c)[0]
    [[3.0, 0.5], [4.0, 1.5], [6.0, 0.5], [8.0, 1.0], [9.0, 0.5]]
    """
    _half_weight(half_cycles)
    counter = RainflowCounter()
    closed = counter.push(signal, name="signal")
    return Cycles.concatenate([closed, counter.residue.half_cycles(half_cycles)])


def cycles_by_range(cycles: Cycles, *, limit: int = EXACT_CYCLE_LIMIT, bins: int = 200) -> tuple[list[list[float]], float | None]:
    """``[[range, count], ...]`` ascending and the bin width (None when exact).

    Exact (equal ranges merged) when there are fewer than ``limit`` cycles; otherwise the ranges
    are binned into ``bins`` classes of equal width from 0 to the largest range, each reported at
    its upper edge (conservative for damage)."""
    r, n = cycles.ranges, cycles.counts
    keep = n > 0
    r, n = r[keep], n[keep]
    if r.size == 0:
        return [], None
    if cycles.total < limit:
        uniq, inv = np.unique(r, return_inverse=True)
        return [[float(a), float(b)] for a, b in zip(uniq, np.bincount(inv, weights=n))], None
    width = float(r.max()) / bins
    idx = np.minimum(np.ceil(r / width).astype(int), bins)
    idx = np.maximum(idx, 1)
    counts = np.bincount(idx, weights=n, minlength=bins + 1)
    return [[float(i * width), float(counts[i])] for i in range(1, bins + 1) if counts[i] > 0], width
