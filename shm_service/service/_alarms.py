"""Alarm logic: the analytics' chart levels per window become alarms with hysteresis.

A chart (``mode1`` ... or ``curvature``) at "warning" for ``raise_windows`` consecutive windows
raises a warning alarm; "alarm" (which the chart itself reaches only after its own hold
windows) raises or escalates at once; a raised alarm clears after ``clear_windows``
consecutive windows at "ok". The state is plain data, stored with the monitor state.
"""

from __future__ import annotations

from typing import Any

from ._storage import AlarmChange

__all__ = ["AlarmLogic"]

_RANK = {"ok": 0, "warning": 1, "alarm": 2}
_LEVEL = {1: "warning", 2: "alarm"}


class AlarmLogic:
    def __init__(self, *, raise_windows: int, clear_windows: int, warning_sigma: float, alarm_sigma: float,
                 state: dict[str, Any] | None = None) -> None:
        self.raise_windows = raise_windows
        self.clear_windows = clear_windows
        self.warning_sigma = warning_sigma
        self.alarm_sigma = alarm_sigma
        self.charts: dict[str, dict[str, int]] = {k: dict(v) for k, v in (state or {}).items()}

    def state_dict(self) -> dict[str, Any]:
        return {k: dict(v) for k, v in self.charts.items()}

    def active(self) -> dict[str, str]:
        return {k: _LEVEL[v["raised"]] for k, v in self.charts.items() if v["raised"]}

    def update(self, levels: dict[str, str], scores: dict[str, float | None], at_s: float) -> list[AlarmChange]:
        """Feed one window's chart levels; returns the alarm changes it causes."""
        changes: list[AlarmChange] = []
        for chart, level in sorted(levels.items()):
            rank = _RANK.get(level)
            if rank is None:
                continue
            st = self.charts.setdefault(chart, {"raised": 0, "up": 0, "down": 0})
            if rank > st["raised"]:
                st["up"] += 1
                st["down"] = 0
                needed = 1 if rank == 2 else self.raise_windows
                if st["up"] >= needed:
                    action = "raise" if st["raised"] == 0 else "escalate"
                    st["raised"], st["up"] = rank, 0
                    changes.append(self._change(action, chart, _LEVEL[rank], at_s, scores.get(chart)))
            elif rank == 0 and st["raised"]:
                st["up"] = 0
                st["down"] += 1
                if st["down"] >= self.clear_windows:
                    changes.append(self._change("clear", chart, _LEVEL[st["raised"]], at_s, scores.get(chart)))
                    st["raised"], st["down"] = 0, 0
            else:
                st["up"] = 0 if rank <= st["raised"] else st["up"]
                st["down"] = 0
        return changes

    def _change(self, action: str, chart: str, level: str, at_s: float, score: float | None) -> AlarmChange:
        mode = int(chart[4:]) if chart.startswith("mode") and chart[4:].isdigit() else None
        kind = "frequency" if mode is not None else chart
        threshold = self.alarm_sigma if level == "alarm" else self.warning_sigma
        what = f"eigenfrequency of mode {mode}" if mode is not None else f"{chart} index"
        score_text = "" if score is None else f" ({score:+.1f} σ)"
        if action == "clear":
            message = f"{what}: back within the baseline{score_text}"
        else:
            message = f"{what} deviates from the baseline{score_text}: {level}"
        return AlarmChange(action, chart, kind, mode, level, at_s, score, threshold, message)
