"""Alarm changes for storage from the engine's alarm events.

There is one alarm path: :class:`analytics.AlarmLogic` inside the engine's monitor decides when a
chart's levels raise, escalate or clear an alarm (``shm analyze`` and ``shm serve`` alike). The
service only records its events: this module turns them into ``AlarmChange`` rows (the chart,
its level, the score and the line it crossed, a message) and clears the stored active alarms
when a new baseline is requested.
"""

from __future__ import annotations

from collections.abc import Iterable

from analytics import AlarmEvent
from contract import AlarmDocument, ChartKind

from ..storage._storage import AlarmChange

__all__ = ["alarm_changes", "clear_changes"]


def _what(kind: ChartKind, mode: int | None) -> str:
    if kind == "frequency":
        return f"eigenfrequency of mode {mode}"
    if kind == "curvature":
        return "curvature index"
    if kind == "fatigue":
        return "fatigue of a hot spot"
    raise ValueError(f"unknown chart kind {kind!r}")


def alarm_changes(events: Iterable[AlarmEvent]) -> list[AlarmChange]:
    """The storage rows of one window's alarm events."""
    out = []
    for e in events:
        if not isinstance(e, AlarmEvent):
            raise ValueError(f"events must be analytics.AlarmEvent, got {type(e).__name__}")
        out.append(AlarmChange(e.action, e.chart, e.kind, e.mode, e.level, e.at_s, e.score_sigma, e.threshold_sigma, e.message()))
    return out


def clear_changes(active: Iterable[AlarmDocument], at_s: float) -> list[AlarmChange]:
    """Clear the stored ``active`` alarms (a new baseline starts; the engine forgets its charts)."""
    return [
        AlarmChange("clear", a.chart, a.kind, a.mode, a.level, at_s, None, None,
                    f"{_what(a.kind, a.mode)}: cleared, a new baseline is being learnt")
        for a in active if a.state == "active"
    ]
