"""The first stage of a structure's pipeline: merge the sensors' streams on one data clock."""

from __future__ import annotations

from collections import Counter

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...recording import FollowBlock

__all__ = ["MergeSettings", "MergeStage"]

_NS = 1_000_000_000


class MergeSettings(BaseModel):
    """How long the merge waits for a late sensor."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    lateness_s: float = Field(1.0, gt=0, le=60, description="how long the merge waits for a late sensor before moving on, s")


class MergeStage:
    """Holds samples until every sensor has reported up to a time (or ``lateness_s`` passed),
    then releases them in time order; a sample older than what was released is late (counted
    per topic in ``late``).

    ``release()`` gives, per topic, the samples before the cutoff ``max(newest - lateness,
    oldest topic's newest + 1)``; ``release(final=True)`` all of them. Everything released is in
    time order per topic, and after a release every sample older than the newest one released
    has been released (what the streaming estimator relies on)."""

    def __init__(self, settings: MergeSettings | None = None) -> None:
        self.settings = settings or MergeSettings()
        self.lateness_ns = int(round(self.settings.lateness_s * _NS))
        self.pending: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self.last: dict[str, int] = {}
        self.released_to = -1  # everything < released_to was released
        self.late: Counter = Counter()

    def add(self, block: FollowBlock) -> None:
        t, v = block.log_time_ns, block.values
        if self.released_to >= 0 and len(t) and t[0] < self.released_to:
            keep = t >= self.released_to
            self.late[block.topic] += int(np.count_nonzero(~keep))
            t, v = t[keep], v[keep]
        if not len(t):
            return
        self.pending.setdefault(block.topic, []).append((t, v))
        self.last[block.topic] = max(self.last.get(block.topic, -1), int(t[-1]))

    def release(self, final: bool = False) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        if not self.last:
            return {}
        newest = max(self.last.values())
        if final:
            cutoff = newest + 1
        else:
            cutoff = max(newest - self.lateness_ns, min(self.last.values()) + 1)
        if cutoff <= self.released_to:
            return {}
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for topic, parts in self.pending.items():
            if not parts:
                continue
            t = np.concatenate([p[0] for p in parts]) if len(parts) > 1 else parts[0][0]
            v = np.concatenate([p[1] for p in parts]) if len(parts) > 1 else parts[0][1]
            k = int(np.searchsorted(t, cutoff))
            if k:
                out[topic] = (t[:k], v[:k])
            parts[:] = [(t[k:], v[k:])] if k < len(t) else []
        self.released_to = cutoff
        return out
