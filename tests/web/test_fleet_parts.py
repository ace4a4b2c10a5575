"""The dashboard's parts without a browser: a structure's live estimates played out at their data
pace, the overview's order and marks, a sectioned mast's feed."""

from __future__ import annotations

import numpy as np
import pytest

import estimator
from contract import LiveEstimatesDocument, StateLayout, StructuresDocument, StructureSummaryDocument
from shm_service.rig_layouts import default_rig
from web import StructureFeed, overview_html, severity

LAYOUT = StateLayout("gyro", 2, 0)  # d, h, d_rate, h_rate, phi, b1, b2, gyro_bias_D


@pytest.fixture(scope="module")
def feed_args():
    rig = default_rig()
    units = estimator.unit_deformations(estimator.assemble_beam(rig), 2)
    return {"rig": rig, "units": units, "layout": LAYOUT, "stations": np.linspace(0.5, 4.0, 8)}


def _live(t, *, d=None, names=LAYOUT.names, source="s1", seq=1):
    x = np.zeros((len(t), len(names)))
    x[:, 0] = t if d is None else d  # d carries the data time: which estimate is drawn
    return LiveEstimatesDocument(source=source, seq=seq, state_names=list(names), t_s=list(t), x=x.tolist(),
                                 sensors={"/imu/D": "ok"}, watch_s=20.0)


def test_live_estimates_play_at_their_data_pace_one_batch_behind(feed_args):
    feed = StructureFeed(**feed_args, structure_id="s1")
    batch = np.round(np.arange(20) * 0.1, 1)  # one 2 s batch at 10 estimates per data second
    feed.add_live(_live(batch), now=100.0)
    assert feed.snapshot().estimate is None  # nothing drawn before its turn
    feed.play(100.0)
    assert feed.snapshot().estimate.state.d == 0.0  # the batch's first: played one batch (1.9 s) behind
    feed.play(101.0)
    assert feed.snapshot().estimate.state.d == 1.0
    feed.play(101.05)
    assert feed.snapshot().estimate.state.d == 1.0  # the next one's turn has not come
    # the next batch arrives 2 s later: played on from where the picture is, at 1 data s per s
    feed.add_live(_live(batch + 2.0, seq=21), now=102.0)
    feed.play(102.5)
    assert feed.snapshot().estimate.state.d == 2.5
    assert feed.snapshot().estimate.sensor_states == {"/imu/D": "ok"}


def test_live_estimates_of_another_layout_are_refused(feed_args):
    feed = StructureFeed(**feed_args, structure_id="s1")
    with pytest.raises(ValueError, match="states"):
        feed.add_live(_live([0.0], names=StateLayout("gyro", 3, 0).names))
    with pytest.raises(ValueError, match="sensor_states"):
        feed.add_live(LiveEstimatesDocument(source="s1", seq=0, state_names=list(LAYOUT.names), sensors={}, watch_s=1.0)
                      .model_copy(update={"sensors": {"/imu/D": "bogus"}}))


def _summary(sid, state="running", alarms=None, lag=0.5):
    return StructureSummaryDocument(id=sid, kind="sim", state=state, lag_s=lag, windows=3, active_alarms=alarms or {},
                                    error="file gone" if state == "failed" else None)


def test_the_overview_lists_problems_first_and_marks_the_one_shown():
    doc = StructuresDocument(structures=[
        _summary("a-ok"), _summary("b-warn", alarms={"mode2": "warning"}), _summary("c-failed", "failed", lag=None),
        _summary("d-alarm", alarms={"mode1": "alarm", "curvature": "warning"}), _summary("e-degraded", "degraded"),
        _summary("f-late", lag=30.0),
    ])
    assert [severity(s) for s in doc.structures] == ["running", "warning", "failed", "alarm", "degraded", "running"]
    text = overview_html(doc, None, "b-warn")
    order = [text.index(sid) for sid in ("c-failed", "d-alarm", "e-degraded", "b-warn", "f-late", "a-ok")]
    assert order == sorted(order), "failed, alarm, degraded, warning, then the running ones by lag"
    assert "<b>6 structures</b>" in text and "<b>▶ b-warn</b>" in text
    assert "curvature: warning, mode1: alarm" in text and "title='file gone'" in text
    assert "Waiting for the fleet" in overview_html(None, None, None)
    assert "boom" in overview_html(None, "boom", None)


def test_a_feed_of_a_sectioned_mast_without_a_reflector():
    # a beam from sections has no beam.width and a rig without ToFs no reflector_distance
    from pathlib import Path

    from contract import load_rig

    rig = load_rig(Path(__file__).resolve().parents[2] / "examples" / "mast" / "rig.json")
    units = estimator.unit_deformations(estimator.assemble_beam(rig), 2)
    feed = StructureFeed(rig=rig, units=units, layout=LAYOUT, stations=np.linspace(2.0, 20.0, 10))
    assert feed.width == pytest.approx(0.5)  # the tube's diameter at the foundation
    assert feed.reflector_distance is None and feed.standing and feed.clamped
    # drawn to scale: the tube's diameter along the taper, the section beyond the 8 m joint's step
    np.testing.assert_allclose(feed.width_at([0.0, 4.0, 8.0, 14.0, 20.0]), [0.5, 0.44, 0.38, 0.29, 0.2], rtol=1e-12)
