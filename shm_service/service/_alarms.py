"""Alarm logic: the analytics' chart levels per window become alarms with hysteresis.

A chart (a mode's frequency chart or the curvature chart) at "warning" for ``raise_windows``
consecutive windows raises a warning alarm; "alarm" (which the chart itself reaches only after
its own hold windows) raises or escalates at once; a raised alarm clears after
``clear_windows`` consecutive windows at "ok". Charts come as ``contract.ChartDocument`` (name,
kind, mode and the levels they were judged against), so an alarm's threshold is the level its
chart crossed. The state is plain data, stored with the monitor state.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from contract import AlarmDocument, ChartDocument, ChartKind

from ._storage import AlarmChange

__all__ = ["AlarmLogic"]

_RANK = {"ok": 0, "warning": 1, "alarm": 2}
_LEVEL = {1: "warning", 2: "alarm"}


def _what(kind: ChartKind, mode: int | None) -> str:
    if kind == "frequency":
        return f"eigenfrequency of mode {mode}"
    if kind == "curvature":
        return "curvature index"
    raise ValueError(f"unknown chart kind {kind!r}")


class AlarmLogic:
    """The hysteresis of the alarms. ``charts`` is the COMMITTED state (what the database holds):
    ``propose`` computes a window's changes and the state after them without touching it, and
    ``commit`` adopts that state once the window's transaction is written. So a window that
    could not be stored changes no alarm, in memory as on disk."""

    def __init__(self, *, raise_windows: int, clear_windows: int, state: dict[str, Any] | None = None) -> None:
        if raise_windows < 1 or clear_windows < 1:
            raise ValueError(f"{raise_windows=} and {clear_windows=} must be >= 1")
        self.raise_windows = raise_windows
        self.clear_windows = clear_windows
        self.charts: dict[str, dict[str, int]] = _copy(state or {})

    def state_dict(self) -> dict[str, Any]:
        return _copy(self.charts)

    def active(self) -> dict[str, str]:
        return {k: _LEVEL[v["raised"]] for k, v in self.charts.items() if v["raised"]}

    def propose(self, charts: Iterable[ChartDocument], at_s: float,
                state: dict[str, Any] | None = None) -> tuple[list[AlarmChange], dict[str, Any]]:
        """One window's charts, judged from ``state`` (default: the committed state): the alarm
        changes and the state after them. Neither this object nor ``state`` is changed."""
        work = _copy(self.charts if state is None else state)
        changes: list[AlarmChange] = []
        for chart in sorted(charts, key=lambda c: c.name):
            rank = _RANK[chart.level]
            st = work.setdefault(chart.name, {"raised": 0, "up": 0, "down": 0})
            if rank > st["raised"]:
                st["up"] += 1
                st["down"] = 0
                needed = 1 if rank == 2 else self.raise_windows
                if st["up"] >= needed:
                    action = "raise" if st["raised"] == 0 else "escalate"
                    st["raised"], st["up"] = rank, 0
                    changes.append(self._change(action, chart, _LEVEL[rank], at_s))
            elif rank == 0 and st["raised"]:
                st["up"] = 0
                st["down"] += 1
                if st["down"] >= self.clear_windows:
                    changes.append(self._change("clear", chart, _LEVEL[st["raised"]], at_s))
                    st["raised"], st["down"] = 0, 0
            else:
                st["up"] = 0 if rank <= st["raised"] else st["up"]
                st["down"] = 0
        return changes, work

    def commit(self, state: dict[str, Any]) -> None:
        """Adopt ``state`` (from ``propose``) once its window is stored."""
        self.charts = _copy(state)

    def update(self, charts: Iterable[ChartDocument], at_s: float) -> list[AlarmChange]:
        """``propose`` and ``commit`` in one (for callers without a transaction to wait for)."""
        changes, state = self.propose(charts, at_s)
        self.commit(state)
        return changes

    def clear_all(self, active: Iterable[AlarmDocument], at_s: float) -> list[AlarmChange]:
        """Forget every chart (a new baseline starts) and clear the ``active`` alarms."""
        self.charts.clear()
        return self.clear_changes(active, at_s)

    @staticmethod
    def clear_changes(active: Iterable[AlarmDocument], at_s: float) -> list[AlarmChange]:
        """The changes that clear the ``active`` alarms because a new baseline is being learnt."""
        return [
            AlarmChange("clear", a.chart, a.kind, a.mode, a.level, at_s, None, None,
                        f"{_what(a.kind, a.mode)}: cleared, a new baseline is being learnt")
            for a in active if a.state == "active"
        ]

    @staticmethod
    def _change(action: str, chart: ChartDocument, level: str, at_s: float) -> AlarmChange:
        threshold = chart.alarm_sigma if level == "alarm" else chart.warning_sigma
        what = _what(chart.kind, chart.mode)
        score = chart.score_sigma
        score_text = "" if score is None else f" ({score:+.1f} σ)"
        if action == "clear":
            message = f"{what}: back within the baseline{score_text}"
        else:
            message = f"{what} deviates from the baseline{score_text}: {level}"
        return AlarmChange(action, chart.name, chart.kind, chart.mode, level, at_s, score, threshold, message)


def _copy(state: dict[str, Any]) -> dict[str, dict[str, int]]:
    return {k: dict(v) for k, v in state.items()}
