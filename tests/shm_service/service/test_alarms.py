"""Alarm logic on structured charts: hysteresis, and the threshold each chart was judged against."""

from __future__ import annotations

import pytest

from analytics import AnalysisConfig
from contract import AlarmDocument, ChartDocument
from shm_service.service._alarms import AlarmLogic


def _chart(kind: str, level: str, score: float, mode: int | None = None) -> ChartDocument:
    warning, alarm = AnalysisConfig().chart_levels(kind)
    name = "curvature" if kind == "curvature" else f"mode{mode}"
    return ChartDocument(name=name, kind=kind, mode=mode, unit=None if mode is None else 1, level=level, score_sigma=score,
                         warning_sigma=warning, alarm_sigma=alarm)


def test_the_curvature_chart_has_its_own_alarm_level():
    assert AnalysisConfig().chart_levels("frequency") == (3.0, 5.0)
    assert AnalysisConfig().chart_levels("curvature") == (3.0, 6.0)
    # a curvature alarm level below the warning level cannot be: the chart warns first
    assert AnalysisConfig(curvature_alarm_sigma=2.5).chart_levels("curvature") == (3.0, 3.0)
    with pytest.raises(ValueError, match="kind='strain'"):
        AnalysisConfig().chart_levels("strain")


def test_alarm_changes_carry_the_charts_fields_and_levels():
    logic = AlarmLogic(raise_windows=2, clear_windows=2)
    assert logic.update([_chart("frequency", "warning", 3.4, mode=2)], 30.0) == []  # one warning window: not yet
    (warned,) = logic.update([_chart("frequency", "warning", 3.6, mode=2)], 60.0)
    assert (warned.action, warned.chart, warned.kind, warned.mode, warned.level, warned.threshold) == \
        ("raise", "mode2", "frequency", 2, "warning", 3.0)
    (curv,) = logic.update([_chart("curvature", "alarm", 7.1)], 90.0)  # "alarm" raises at once
    assert (curv.action, curv.chart, curv.kind, curv.mode, curv.threshold, curv.value) == ("raise", "curvature", "curvature", None, 6.0, 7.1)
    assert "curvature index deviates" in curv.message and "+7.1 σ" in curv.message
    (escalated,) = logic.update([_chart("frequency", "alarm", 5.5, mode=2)], 120.0)
    assert escalated.action == "escalate" and escalated.threshold == 5.0
    assert logic.active() == {"mode2": "alarm", "curvature": "alarm"}
    ok = [_chart("frequency", "ok", 0.1, mode=2), _chart("curvature", "ok", 0.2)]
    assert logic.update(ok, 150.0) == []
    cleared = logic.update(ok, 180.0)
    assert sorted(c.chart for c in cleared) == ["curvature", "mode2"] and all(c.action == "clear" for c in cleared)
    assert logic.active() == {}


def test_a_new_baseline_clears_the_active_alarms():
    logic = AlarmLogic(raise_windows=1, clear_windows=1)
    logic.update([_chart("curvature", "alarm", 7.0)], 10.0)
    active = AlarmDocument(id=4, source="s", chart="curvature", kind="curvature", level="alarm", state="active",
                           raised_at_s=10.0, message="m")
    (change,) = logic.clear_all([active], 20.0)
    assert (change.action, change.chart, change.kind, change.mode, change.level) == ("clear", "curvature", "curvature", None, "alarm")
    assert logic.active() == {}
    with pytest.raises(ValueError, match="raise_windows=0"):
        AlarmLogic(raise_windows=0, clear_windows=1)
