"""Modes followed across windows: each window's modes get the id of the physical mode (a track).

A mode of one window continues a track of the windows before if its frequency is near the
track's last one (its end frequency where it moved within that window), its shape alike where
there are several channels (MAC) and its share of the response of the same order; the windows'
modes and the live tracks are paired by least total cost (the Hungarian algorithm, as
``scipy.optimize.linear_sum_assignment``), a mode left over opens a track, a track unseen for
``max_gap`` windows closes. ``shm oma`` (windows of a record) and the monitoring engine
(``shm analyze``, ``shm serve``) use the same :class:`ModeTracker`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ._ssi import modal_assurance

__all__ = ["ModeTrack", "ModeTracker"]


@dataclass(frozen=True)
class ModeTrack:
    """One physical mode followed through the record.

    track : its id (0, 1, … in order of appearance); windows : windows it was found in;
    min_hz, max_hz : the frequency range it covered (moving modes: their start and end too);
    mean_hz : the mean of its windows' frequencies; first_s, last_s : start of its first and last window (s).
    """

    track: int
    windows: int
    min_hz: float
    max_hz: float
    mean_hz: float
    first_s: float
    last_s: float

    def as_dict(self) -> dict:
        return {"track": self.track, "windows": self.windows, "min_hz": self.min_hz, "max_hz": self.max_hz,
                "mean_hz": self.mean_hz, "first_s": self.first_s, "last_s": self.last_s}


@dataclass
class _Live:
    track: int
    f_hz: float
    shape: np.ndarray
    share: float
    last_window: int
    n: int = 0
    lo: float = math.inf
    hi: float = -math.inf
    total: float = 0.0
    first_s: float = 0.0
    last_s: float = 0.0


@dataclass
class ModeTracker:
    """Pairs each window's modes with the tracks of the windows before.

    Parameters
    ----------
    gate_rel : float
        Largest relative frequency change from a track's last frequency [0.1]; a mode that moved
        within a window is compared by its start frequency.
    mac_min : float
        Smallest MAC with the track's last shape (several channels) [0.8].
    max_gap : int
        A track not seen for this many windows closes [4].
    """

    gate_rel: float = 0.1
    mac_min: float = 0.8
    max_gap: int = 4
    _live: list[_Live] = field(default_factory=list)
    _closed: list[_Live] = field(default_factory=list)
    _next: int = 0
    _window: int = 0

    def __post_init__(self) -> None:
        if not (0 < self.gate_rel <= 1):
            raise ValueError(f"gate_rel={self.gate_rel} must be in (0, 1]")
        if not (0 < self.mac_min <= 1):
            raise ValueError(f"mac_min={self.mac_min} must be in (0, 1]")
        if isinstance(self.max_gap, bool) or not isinstance(self.max_gap, int) or self.max_gap < 1:
            raise ValueError(f"max_gap={self.max_gap!r} must be an integer >= 1")

    def assign(self, start_s: float, modes: list[tuple[float, float, float, tuple[float, ...], float]]) -> list[int]:
        """Track ids of one window's modes.

        Parameters
        ----------
        start_s : float
            The window's start (s).
        modes : list of (frequency_hz, start_hz, end_hz, shape, share)
            Each mode's (time-averaged) frequency, its frequency at the window's start and end
            (equal for a mode that did not move), its real shape and its share of the response.

        Returns
        -------
        list of int, one track id per mode.
        """
        w = self._window
        self._window += 1
        self._closed.extend(t for t in self._live if w - t.last_window > self.max_gap)
        self._live = [t for t in self._live if w - t.last_window <= self.max_gap]
        ids = [-1] * len(modes)
        if modes and self._live:
            cost = np.full((len(modes), len(self._live)), np.inf)
            for i, (f, f0, _, shape, share) in enumerate(modes):
                s = np.asarray(shape, float)
                for j, t in enumerate(self._live):
                    df = min(abs(f0 - t.f_hz), abs(f - t.f_hz)) / t.f_hz
                    if df > self.gate_rel:
                        continue
                    mac = 1.0
                    if s.size > 1 and s.size == t.shape.size:
                        mac = float(modal_assurance(s[None], t.shape[None])[0, 0])
                        if mac < self.mac_min:
                            continue
                    ratio = abs(math.log(max(share, 1e-6) / max(t.share, 1e-6)))
                    cost[i, j] = df / self.gate_rel + (1 - mac) + 0.05 * ratio + 0.01 * (w - t.last_window - 1)
            big = 1e6
            rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, big))
            for i, j in zip(rows, cols):
                if cost[i, j] < big:
                    ids[i] = self._live[j].track
        for i, (f, f0, f1, shape, share) in enumerate(modes):
            if ids[i] < 0:
                t = _Live(self._next, f, np.asarray(shape, float), share, w, first_s=start_s)
                self._next += 1
                self._live.append(t)
                ids[i] = t.track
            t = next(t for t in self._live if t.track == ids[i])
            t.f_hz, t.shape, t.share, t.last_window = f1, np.asarray(shape, float), share, w
            t.n += 1
            t.lo, t.hi = min(t.lo, f, f0, f1), max(t.hi, f, f0, f1)
            t.total += f
            t.last_s = start_s
        return ids

    def tracks(self) -> tuple[ModeTrack, ...]:
        """Every track so far, by id."""
        allt = sorted(self._closed + self._live, key=lambda t: t.track)
        return tuple(ModeTrack(t.track, t.n, float(t.lo), float(t.hi), float(t.total / t.n), float(t.first_s), float(t.last_s))
                     for t in allt if t.n)

    def state_dict(self) -> dict:
        """JSON-safe state (a restart continues the ids)."""
        def one(t: _Live) -> dict:
            return {**{k: getattr(t, k) for k in ("track", "f_hz", "share", "last_window", "n", "lo", "hi", "total", "first_s", "last_s")},
                    "shape": [float(v) for v in t.shape]}
        return {"gate_rel": self.gate_rel, "mac_min": self.mac_min, "max_gap": self.max_gap, "next": self._next, "window": self._window,
                "live": [one(t) for t in self._live], "closed": [one(t) for t in self._closed]}

    @classmethod
    def from_state_dict(cls, d: dict) -> ModeTracker:
        try:
            tr = cls(float(d["gate_rel"]), float(d["mac_min"]), int(d["max_gap"]))
            tr._next, tr._window = int(d["next"]), int(d["window"])
            for key, dest in (("live", tr._live), ("closed", tr._closed)):
                for t in d[key]:
                    dest.append(_Live(int(t["track"]), float(t["f_hz"]), np.asarray(t["shape"], float), float(t["share"]),
                                      int(t["last_window"]), int(t["n"]), float(t["lo"]), float(t["hi"]), float(t["total"]),
                                      float(t["first_s"]), float(t["last_s"])))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"tracker state is malformed: {exc}") from exc
        return tr
