"""The one alarm path: control-chart levels per window become raised and cleared alarms.

Every entry point (``shm analyze``, ``shm serve``, ``shm reprocess``) runs the charts of
:class:`analytics.ModalMonitor` through this logic, so a replay raises the same alarms as the
live service did. A chart's level is judged per window (:func:`analytics.chart_level`); an
alarm needs ``raise_windows`` consecutive windows at or beyond its level (a warning at the
warning line, an alarm at the alarm line; an alarm escalates a raised warning), and clears after
``clear_windows`` consecutive windows below ``clear_sigma`` (hysteresis: between the clear and
the warning line a raised alarm holds). ``since_s`` is when the excursion began: the end of the
first of its windows beyond the warning line (the data first showed it then), before the alarm
was raised. The state is plain data.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Literal

from contract import ChartDocument, ChartKind

__all__ = ["AlarmEvent", "AlarmLogic"]

_RANK = {"ok": 0, "warning": 1, "alarm": 2}
_LEVEL = {1: "warning", 2: "alarm"}


@dataclass(frozen=True)
class AlarmEvent:
    """An alarm raised, escalated or cleared by one window.

    chart, kind, mode, unit : the chart (``contract.chart_name``). level : the alarm's level.
    at_s : end of the window that caused it (the time unit of the windows). since_s : onset of
    the excursion. score_sigma : the chart's score then (σ). threshold_sigma : the level it
    crossed (warning or alarm line; for a clear, the clear line).
    """

    action: Literal["raise", "escalate", "clear"]
    chart: str
    kind: ChartKind
    mode: int | None
    unit: int | None
    level: Literal["warning", "alarm"]
    at_s: float
    since_s: float | None
    score_sigma: float | None
    threshold_sigma: float
    reason: str = ""

    def message(self) -> str:
        if self.kind == "fatigue":
            return self._fatigue_message()
        what = f"eigenfrequency of mode {self.mode}" if self.kind == "frequency" else "curvature index"
        score = "" if self.score_sigma is None else f" ({self.score_sigma:+.1f} σ)"
        if self.action == "clear":
            return f"{what}: {self.reason or 'back within the baseline'}{score}"
        return f"{what} deviates from the baseline{score}: {self.level}"


    def _fatigue_message(self) -> str:
        # score: the condition in units of its warning line (analytics._loads_monitor)
        spot, _, condition = self.chart.removeprefix("fatigue:").rpartition(":")
        what = {"rate": "damage rate would exhaust the design life early", "del": "DEL jumped against its baseline",
                "consumed": "consumed life passed its level"}[condition]
        score = "" if self.score_sigma is None else f" ({self.score_sigma:.2f} x the warning line)"
        if self.action == "clear":
            return f"hot spot {spot}: {self.reason or 'fatigue condition back below its warning line'}{score}"
        return f"hot spot {spot}: {what}{score}: {self.level}"


class AlarmLogic:
    """Hysteresis from chart levels to alarms (see the module docstring).

    Parameters
    ----------
    raise_windows : int
        Consecutive windows at or beyond a level before it is raised (>= 1).
    clear_windows : int
        Consecutive windows below ``clear_sigma`` before a raised alarm clears (>= 1).
    clear_sigma : float
        The clear line, σ (below every chart's warning line).
    state : dict, optional
        From :meth:`state_dict`.

    Raises
    ------
    ValueError
        For a window count below 1, a negative clear line or a malformed state.
    """

    def __init__(self, *, raise_windows: int, clear_windows: int, clear_sigma: float, state: dict[str, Any] | None = None) -> None:
        if isinstance(raise_windows, bool) or not isinstance(raise_windows, int) or raise_windows < 1:
            raise ValueError(f"{raise_windows=} must be an integer >= 1")
        if isinstance(clear_windows, bool) or not isinstance(clear_windows, int) or clear_windows < 1:
            raise ValueError(f"{clear_windows=} must be an integer >= 1")
        if not clear_sigma >= 0:
            raise ValueError(f"{clear_sigma=} must be >= 0")
        self.raise_windows, self.clear_windows, self.clear_sigma = raise_windows, clear_windows, float(clear_sigma)
        self.charts: dict[str, dict[str, Any]] = {}
        for name, st in (state or {}).items():
            try:
                self.charts[name] = {"raised": int(st["raised"]), "warn": int(st["warn"]), "alarm": int(st["alarm"]),
                                     "down": int(st["down"]), "since": None if st["since"] is None else float(st["since"]),
                                     "kind": st["kind"], "mode": st["mode"], "unit": st["unit"]}
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"alarm state of chart {name!r} is malformed: {exc}") from exc

    def state_dict(self) -> dict[str, Any]:
        return {k: dict(v) for k, v in self.charts.items()}

    def raised(self) -> dict[str, str]:
        """Chart name → level of every raised alarm."""
        return {k: _LEVEL[v["raised"]] for k, v in self.charts.items() if v["raised"]}

    def since(self, chart: str) -> float | None:
        st = self.charts.get(chart)
        return None if st is None else st["since"]

    def update(self, charts: Iterable[ChartDocument], at_s: float, onset_s: float | None = None) -> list[AlarmEvent]:
        """Feed one window's charts (their levels judged this window); returns the alarm events.

        at_s : the time the window is judged (its end); onset_s : the time an excursion starting in
        this window is dated to (default at_s)."""
        onset = float(at_s if onset_s is None else onset_s)
        events: list[AlarmEvent] = []
        for chart in sorted(charts, key=lambda c: c.name):
            rank = _RANK[chart.level]
            st = self.charts.setdefault(chart.name, {"raised": 0, "warn": 0, "alarm": 0, "down": 0, "since": None,
                                                     "kind": chart.kind, "mode": chart.mode, "unit": chart.unit})
            st["warn"] = st["warn"] + 1 if rank >= 1 else 0
            st["alarm"] = st["alarm"] + 1 if rank == 2 else 0
            if rank >= 1 and st["since"] is None:
                st["since"] = onset
            target = 2 if st["alarm"] >= self.raise_windows else (1 if st["warn"] >= self.raise_windows else 0)
            if target > st["raised"]:
                action = "raise" if st["raised"] == 0 else "escalate"
                st["raised"], st["down"] = target, 0
                events.append(AlarmEvent(action, chart.name, chart.kind, chart.mode, chart.unit, _LEVEL[target], float(at_s),
                                         st["since"], chart.score_sigma, chart.alarm_sigma if target == 2 else chart.warning_sigma))
                continue
            if st["raised"]:
                below = chart.score_sigma is not None and abs(chart.score_sigma) < self.clear_sigma
                st["down"] = st["down"] + 1 if below else 0
                if st["down"] >= self.clear_windows:
                    events.append(AlarmEvent("clear", chart.name, chart.kind, chart.mode, chart.unit, _LEVEL[st["raised"]],
                                             float(at_s), st["since"], chart.score_sigma, self.clear_sigma))
                    st.update(raised=0, down=0, since=None, warn=0, alarm=0)
            elif rank == 0:
                st["since"] = None
        return events

    def clear_all(self, at_s: float, reason: str = "cleared, a new baseline is being learnt") -> list[AlarmEvent]:
        """Clear every raised alarm and forget the charts (a new baseline starts)."""
        events = [AlarmEvent("clear", name, st["kind"], st["mode"], st["unit"], _LEVEL[st["raised"]], float(at_s), st["since"], None,
                             self.clear_sigma, reason)
                  for name, st in sorted(self.charts.items()) if st["raised"]]
        self.charts.clear()
        return events
