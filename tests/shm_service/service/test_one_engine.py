"""One engine: a recording replayed through ``shm serve`` and the service's own archive of it
analysed by ``shm analyze`` give the same windows, per-window frequencies and alarms."""

from __future__ import annotations

import json
import sqlite3

import numpy as np
import pytest
import tomli_w
from svc_helpers import fast_overrides

from shm_service.cli import main
from shm_service.recording import read_recording
from shm_service.service import MonitoringService, load_settings


@pytest.fixture(scope="module")
def served(tmp_path_factory, short_recording):
    """The short recording replayed through the service, its archive holding every raw sample and estimate."""
    tmp = tmp_path_factory.mktemp("one_engine")
    config = fast_overrides(tmp)
    db = config.pop("db")
    archive = config.pop("archive")
    toml = tmp / "serve.toml"
    toml.write_text(tomli_w.dumps(config))
    settings = load_settings(toml, {"db": db, "source": {"spec": f"replay:{short_recording}", "speed": "max"},
                                    "archive": {**archive, "raw": "always", "estimate_decimation": 1}})
    service = MonitoringService(settings, environ={})
    service.start()
    assert service.wait(180)
    status = service.status()
    (structure,) = service.structures.values()
    last_window = structure.pipeline.last_window  # the document the dashboard was sent last
    service.stop(drain_s=0)
    assert status.service.pipeline_errors == 0
    (path,) = sorted((tmp / "recordings").glob("*.mcap"))
    return tmp, toml, status, path, settings, last_window


def test_serve_and_analyze_run_the_same_windows_and_raise_the_same_alarms(served, capsys):
    tmp, toml, status, archive, settings, last_window = served
    rec = read_recording(archive)
    epoch = rec.start_ns - rec.start_ns % 1_000_000_000  # the service's estimator epoch: the first second
    rest_end = status.pipeline.estimator.rest_calibration.rest_end_s
    not_before = (epoch - rec.start_ns) / 1e9 + rest_end + settings.estimator.warmup_s
    assert main(["analyze", str(archive), "--config", str(toml), "--not-before", f"{not_before:.9f}", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    con = sqlite3.connect(tmp / "shm.sqlite")
    trends = con.execute("SELECT window_start_s, mode, frequency_hz, level FROM trends ORDER BY window_start_s, mode").fetchall()
    events = con.execute("SELECT a.chart, e.event, e.level, e.at_s FROM alarm_events e JOIN alarms a ON a.id = e.alarm_id "
                         "ORDER BY e.at_s, a.chart").fetchall()
    con.close()
    zero = rec.start_ns / 1e9
    served_windows = sorted({round(r[0], 6) for r in trends})
    analysed = [w for w in doc["windows"]]
    assert len(served_windows) >= 8 and [round(zero + w["start_s"], 6) for w in analysed] == served_windows
    # the same per-window frequencies to 1e-9 and the same chart levels
    by = {(round(r[0], 6), r[1]): r for r in trends}
    compared, worst = 0, 0.0
    for w in analysed:
        for m in w["modes"]:
            _, _, f, level = by[(round(zero + w["start_s"], 6), m["mode"])]
            if f is None:
                assert m["frequency_hz"] is None
                continue
            assert m["frequency_hz"] == pytest.approx(f, abs=1e-9, rel=0)
            worst = max(worst, abs(m["frequency_hz"] - f))
            assert w["levels"].get(f"mode{m['mode']}") == level
            compared += 1
    assert compared >= 30
    # the same alarm events, window by window
    action = {"raise": "raised", "escalate": "escalated", "clear": "cleared"}
    mine = sorted((e["chart"], action[e["action"]], e["level"], round(zero + e["at_s"], 3)) for w in analysed for e in w["alarm_events"])
    theirs = sorted((c, ev, lvl, round(at, 3)) for c, ev, lvl, at in events)
    assert mine == theirs and mine, (mine, theirs)
    print(f"one engine: {len(analysed)} windows, {compared} frequencies (largest difference {worst:.1e} Hz), {len(mine)} alarm events")
    # the flags are the alarms at "alarm": the charts in alarm after the last window agree too
    in_alarm = {f["kind"] if f["kind"] == "curvature" else f"mode{f['mode']}" for f in analysed[-1]["flags"]}
    assert in_alarm == {k for k, v in status.pipeline.active_alarms.items() if v == "alarm"}
    assert np.isfinite([m["frequency_hz"] for m in doc["modes"] if m["frequency_hz"] is not None]).all()
    # the served window documents carry each mode's track as shm analyze's windows do (one tracker)
    last = next(w for w in analysed if round(zero + w["start_s"], 6) == round(last_window.start_s, 6))
    served_tracks = [(m.mode, m.track) for m in last_window.modes]
    assert served_tracks == [(m["mode"], m["track"]) for m in last["modes"]]
    assert any(track is not None for _, track in served_tracks), served_tracks
