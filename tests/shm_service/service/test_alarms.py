"""The one alarm path (analytics.AlarmLogic): hysteresis, the threshold each chart was judged
against, and the service's storage rows of its events."""

from __future__ import annotations

import json

import pytest

from analytics import AlarmLogic, AnalysisConfig
from contract import AlarmDocument, ChartDocument
from shm_service.service.alarms._changes import alarm_changes, clear_changes


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


def test_alarm_events_carry_the_charts_fields_levels_and_onset():
    logic = AlarmLogic(raise_windows=2, clear_windows=2, clear_sigma=2.0)
    assert logic.update([_chart("frequency", "warning", 3.4, mode=2)], 30.0) == []  # one warning window: not yet
    (warned,) = logic.update([_chart("frequency", "warning", 3.6, mode=2)], 60.0)
    assert (warned.action, warned.chart, warned.kind, warned.mode, warned.level, warned.threshold_sigma, warned.since_s) == \
        ("raise", "mode2", "frequency", 2, "warning", 3.0, 30.0)  # the excursion began with the first window beyond the line
    assert logic.update([_chart("curvature", "alarm", 7.1)], 90.0) == []  # an alarm needs raise_windows windows too
    (curv,) = logic.update([_chart("curvature", "alarm", 7.3)], 120.0)
    assert (curv.action, curv.chart, curv.kind, curv.mode, curv.threshold_sigma, curv.score_sigma, curv.since_s) == \
        ("raise", "curvature", "curvature", None, 6.0, 7.3, 90.0)
    assert "curvature index deviates" in curv.message() and "+7.3 σ" in curv.message()
    assert logic.update([_chart("frequency", "alarm", 5.5, mode=2)], 150.0) == []
    (escalated,) = logic.update([_chart("frequency", "alarm", 5.6, mode=2)], 180.0)
    assert escalated.action == "escalate" and escalated.threshold_sigma == 5.0 and escalated.since_s == 30.0
    assert logic.raised() == {"mode2": "alarm", "curvature": "alarm"}
    # between the clear line (2 σ) and the warning line a raised alarm holds (hysteresis)
    hold = [_chart("frequency", "ok", 2.5, mode=2), _chart("curvature", "ok", 2.9)]
    assert logic.update(hold, 210.0) == [] and logic.update(hold, 240.0) == []
    ok = [_chart("frequency", "ok", 0.1, mode=2), _chart("curvature", "ok", 0.2)]
    assert logic.update(ok, 270.0) == []
    cleared = logic.update(ok, 300.0)
    assert sorted(c.chart for c in cleared) == ["curvature", "mode2"] and all(c.action == "clear" for c in cleared)
    assert logic.raised() == {} and logic.since("mode2") is None
    # the state is plain data: a restarted logic continues where it was
    logic.update([_chart("frequency", "warning", 3.5, mode=3)], 330.0)
    again = AlarmLogic(raise_windows=2, clear_windows=2, clear_sigma=2.0, state=json.loads(json.dumps(logic.state_dict())))
    (raised,) = again.update([_chart("frequency", "warning", 3.5, mode=3)], 360.0)
    assert raised.chart == "mode3" and raised.since_s == 330.0


def test_storage_rows_of_the_events_and_a_new_baseline_clears_the_active_alarms():
    logic = AlarmLogic(raise_windows=1, clear_windows=1, clear_sigma=2.0)
    (event,) = logic.update([_chart("curvature", "alarm", 7.0)], 10.0)
    (change,) = alarm_changes([event])
    assert (change.action, change.chart, change.kind, change.mode, change.level, change.at_s, change.value, change.threshold) == \
        ("raise", "curvature", "curvature", None, "alarm", 10.0, 7.0, 6.0)
    (cleared,) = logic.clear_all(20.0)
    assert cleared.action == "clear" and logic.raised() == {}
    active = AlarmDocument(id=4, source="s", chart="curvature", kind="curvature", level="alarm", state="active",
                           raised_at_s=10.0, message="m")
    (change,) = clear_changes([active], 20.0)
    assert (change.action, change.chart, change.kind, change.mode, change.level) == ("clear", "curvature", "curvature", None, "alarm")
    assert "new baseline" in change.message


@pytest.mark.parametrize("call, match", [
    (lambda: AlarmLogic(raise_windows=0, clear_windows=1, clear_sigma=2.0), "raise_windows=0"),
    (lambda: AlarmLogic(raise_windows=1, clear_windows=0, clear_sigma=2.0), "clear_windows=0"),
    (lambda: AlarmLogic(raise_windows=1, clear_windows=1, clear_sigma=-1.0), "clear_sigma=-1.0"),
    (lambda: AlarmLogic(raise_windows=1, clear_windows=1, clear_sigma=1.0, state={"mode1": {"raised": 1}}), "mode1"),
    (lambda: alarm_changes(["x"]), "AlarmEvent"),
])
def test_bad_input_names_the_value(call, match):
    with pytest.raises(ValueError, match=match):
        call()
