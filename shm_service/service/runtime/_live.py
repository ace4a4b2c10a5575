"""A structure's live estimates for a dashboard that does not share its process (the front of a
fleet's worker processes): a small ring of the newest state estimates, decimated in data time,
kept only while someone watches (reads) the structure. An unwatched structure pays one clock
read per batch and keeps nothing, so a fleet of hundreds costs nothing for the ones not shown.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from contract import LiveEstimatesDocument

__all__ = ["LiveRing"]

#: Estimates kept per second of data (a live 3-D view needs no more) and how many (≈ 60 s).
LIVE_HZ = 10.0
LIVE_CAPACITY = 600
#: A read keeps the ring filled this long (a dashboard polls every fraction of a second).
WATCH_S = 20.0
#: A biaxial beam's "all" hot spots are judged anew at most this often (wall s): a judgement counts
#: the rainflow of every kept estimate at each of ~72 points around the section, about 0.8 s of a
#: core for a full ring of noisy estimates, so at most ~8 % of a core while someone watches.
JUDGE_EVERY_S = 10.0


class LiveRing:
    """The newest estimates of one structure (thread-safe: the pipeline adds, the API reads)."""

    def __init__(self, source_id: str, state_names: list[str], *, hz: float = LIVE_HZ, capacity: int = LIVE_CAPACITY,
                 watch_s: float = WATCH_S, loads: tuple[Any, Callable[[np.ndarray], np.ndarray]] | None = None) -> None:
        if not (hz > 0 and capacity >= 1 and watch_s > 0):
            raise ValueError(f"{hz=} must be > 0, {capacity=} >= 1 and {watch_s=} > 0")
        self.source_id = source_id
        self.state_names = list(state_names)
        self.hz = float(hz)
        self.watch_s = float(watch_s)
        self._items: deque[tuple[int, float, np.ndarray, list[float] | None]] = deque(maxlen=capacity)
        self._truths = False  # a simulated source handed true deflections
        self._seq = 0
        self._last_tick = -np.inf
        self._watch_until = -np.inf  # monotonic s
        self._lock = threading.Lock()
        # (analytics.VirtualLoads, b of states): each estimate's strain, stress and moment at the stations
        self.loads = loads
        self._judged_at = -np.inf  # monotonic s when an "all" hot spot's worst angle was last judged

    @property
    def watched(self) -> bool:
        return time.monotonic() < self._watch_until

    def add(self, t_s: np.ndarray, x: np.ndarray,
            truth: Callable[[np.ndarray], list[np.ndarray | None]] | None = None) -> None:
        """A batch's estimates (``t_s`` (n,) UNIX s, ``x`` (n, nx)): kept at ``hz`` while watched.
        ``truth`` (a simulated source): the true deflection at the stations for given times (asked
        only for the estimates kept)."""
        if time.monotonic() >= self._watch_until:
            return
        t = np.asarray(t_s, dtype=float)
        if t.size == 0:
            return
        tick = np.floor(t * self.hz + 1e-6)  # (a stamp on a tick is in it, whatever the rounding of t·hz)
        with self._lock:
            # the first estimate of each new tick of data time (ticks of 1/hz s)
            keep = np.flatnonzero(np.diff(np.concatenate([[self._last_tick], tick])) > 0)
            truths = truth(t[keep]) if truth is not None and keep.size else [None] * keep.size
            self._truths = self._truths or truth is not None
            for k, true in zip(keep, truths):
                self._seq += 1
                self._items.append((self._seq, float(t[k]), np.array(x[k], dtype=float),
                                    None if true is None else np.asarray(true, dtype=float).tolist()))
            if keep.size:
                self._last_tick = float(tick[keep[-1]])

    def read(self, after: int = 0) -> tuple[int, list[float], list[list[float]]]:
        """(newest seq, times, states) of the estimates newer than ``after``; starts or extends the watch."""
        seq, times, states, _ = self._read(after)
        return seq, times, states

    def _read(self, after: int) -> tuple[int, list[float], list[list[float]], list[list[float] | None] | None]:
        """``read``, and the true deflections (None unless a simulated source handed them)."""
        if after < 0:
            raise ValueError(f"{after=} must be >= 0")
        with self._lock:
            if not self.watched:  # a new watch: what was kept before is stale
                self._items.clear()
                self._last_tick = -np.inf
            self._watch_until = time.monotonic() + self.watch_s
            items = [it for it in self._items if it[0] > after]
            truths = [it[3] for it in items] if self._truths else None
            return self._seq, [it[1] for it in items], [it[2].tolist() for it in items], truths

    def _biaxial(self, virtual: Any, b: tuple[np.ndarray, np.ndarray],
                 b_of: Callable[[np.ndarray], Any]) -> dict[str, np.ndarray | None]:
        """A biaxial beam's loads of the estimates read; an "all" hot spot's worst angle judged anew
        over every estimate kept, at most every ``JUDGE_EVERY_S`` (a few estimates read at a time say
        little of its DELs, and a steady angle reads better than one that jumps between reads)."""
        now = time.monotonic()
        if virtual.worst_around.any() and now - self._judged_at >= JUDGE_EVERY_S:
            with self._lock:
                kept = np.array([it[2] for it in self._items], dtype=float)
            if kept.shape[0] >= 2:
                virtual.judge(*b_of(kept))
                self._judged_at = now
        return virtual(b[0], b_xi=b[1])

    def document(self, after: int, sensors: dict[str, str]) -> LiveEstimatesDocument:
        seq, times, states, truths = self._read(after)
        extra: dict[str, Any] = {}
        if self.loads is not None:
            virtual, b_of = self.loads
            extra = {"loads_stations_m": virtual.positions.tolist(), "loads_station_names": list(virtual.names)}
            if states:
                b = b_of(np.asarray(states, dtype=float))
                out = virtual(b) if not isinstance(b, tuple) else self._biaxial(virtual, b, b_of)
                extra.update({k: None if v is None else v.tolist() for k, v in out.items() if k != "angles_deg"})
            if hasattr(virtual, "angles_deg"):  # a biaxial beam's (analytics.BiaxialVirtualLoads)
                extra.update(loads_angles_deg=virtual.angles_deg.tolist(), loads_worst_around=virtual.worst_around.tolist())
        return LiveEstimatesDocument(source=self.source_id, seq=seq, state_names=self.state_names, t_s=times, x=states,
                                     sensors=sensors, watch_s=self.watch_s, truth_deflection=truths, **extra)
