"""Incremental reading (follow, truncated files) and ingest validation: bad input is counted,
never fatal, and valid data is kept."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shm_service.recording import RecordingFollower, RecordingWriter
from shm_service.rig_layouts import default_rig
from shm_service.service.sources._ingest import IngestError, IngestValidator, parse_body


def _imu(i):
    return {"accel": [-9.81, 0.001 * i, 0.0], "gyro": [0.0, 0.0, 1e-4 * i]}


def test_follow_sees_flushed_chunks_and_counts_bad_samples(tmp_path):
    path = tmp_path / "growing.mcap"
    rig = default_rig("benchmark")
    w = RecordingWriter(path, rig)
    f = RecordingFollower(path)
    for i in range(10):
        w.write("/imu/D", 1_000_000_000 + i * 5_000_000, _imu(i))
    w.flush()
    blocks = f.poll()
    assert sum(len(b) for b in blocks) == 10 and f.rig is not None
    assert f.poll() == []
    w.write("/imu/D", 1_000_000_000 + 3 * 5_000_000, _imu(3))  # backwards
    w.write("/imu/D", 1_000_000_000 + 10 * 5_000_000, b'{"accel": [NaN, 0, 0], "gyro": [0, 0, 0]}')
    w.write("/imu/D", 1_000_000_000 + 11 * 5_000_000, b'{"accel": "x"}')
    w.write("/imu/D", 1_000_000_000 + 12 * 5_000_000, _imu(12))
    w.flush()
    blocks = f.poll()
    assert [int(t) for b in blocks for t in b.log_time_ns] == [1_000_000_000 + 12 * 5_000_000]
    r = f.topic_reports["/imu/D"]
    assert (r.backwards, r.nonfinite, r.malformed) == (1, 1, 1)
    w.close()
    f.poll()
    assert f.finished


def test_truncated_file_yields_everything_before_the_damage(tmp_path):
    path = tmp_path / "cut.mcap"
    with RecordingWriter(path, default_rig("benchmark"), chunk_size=4096) as w:
        for i in range(2000):
            w.write("/imu/D", 1_000_000_000 + i * 5_000_000, _imu(i))
    data = path.read_bytes()
    cut = tmp_path / "cut2.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    f = RecordingFollower(cut)
    n = 0
    while True:
        before = f.bytes_read
        n += sum(len(b) for b in f.poll())
        if f.bytes_read == before:
            break
    n += sum(len(b) for b in f.finish())
    assert 0 < n < 2000 and f.report.truncated
    assert any("cut off" in p for p in f.report.problems)


def test_ingest_validation_counts_each_kind_of_bad_message():
    v = IngestValidator(default_rig("benchmark"), max_messages=100)
    msgs = [
        {"topic": "/imu/D", "log_time_ns": 10, "payload": _imu(1)},
        {"topic": "/imu/D", "log_time_ns": 5, "payload": _imu(1)},  # backwards
        {"topic": "/imu/D", "log_time_ns": 10, "payload": _imu(1)},  # duplicate
        {"topic": "/imu/D", "log_time_ns": 20, "payload": {"accel": [math.nan, 0, 0], "gyro": [0, 0, 0]}},
        {"topic": "/imu/D", "log_time_ns": 21, "payload": {"distance": 0.5}},  # wrong schema
        {"topic": "/imu/nope", "log_time_ns": 22, "payload": _imu(1)},  # not in rig.json
        {"topic": "/truth/state", "log_time_ns": 22, "payload": {}},  # not a sensor topic
        {"topic": "/tof/s1", "log_time_ns": "x", "payload": {"distance": 0.5}},  # malformed time
        "not an object",
        {"topic": "/tof/s1", "log_time_ns": 30, "payload": {"distance": 0.5}},
    ]
    r = v.validate({"messages": msgs})
    assert r.accepted == 2
    assert dict(r.rejected) == {"backwards": 1, "duplicate": 1, "nonfinite": 1, "wrong_schema": 1, "unknown_topic": 2,
                                "malformed": 2}
    assert {b.topic for b in r.blocks} == {"/imu/D", "/tof/s1"}
    d = next(b for b in r.blocks if b.topic == "/imu/D")
    assert d.values.shape == (1, 6) and np.all(np.isfinite(d.values))
    for bad in ([], {"messages": 3}, {"messages": [], "x": 1}, {"messages": [{}] * 101}):
        with pytest.raises(IngestError):
            v.validate(bad)
    with pytest.raises(IngestError, match="JSON"):
        parse_body(b"{nope")
    assert parse_body(b'{"a": NaN}')["a"] != parse_body(b'{"a": NaN}')["a"]  # NaN parsed, rejected per message


def test_sim_source_takes_support_orientation_and_length_from_the_sim_table(tmp_path):
    import queue
    import tomllib

    from estimator import BucklingError
    from shm_service.service import ServiceSettings
    from shm_service.service.sources._sources import SimSource

    cfg = tomllib.loads('[sim]\nsupport = "clamped"\norientation = "standing"\nlength_m = 1.5\n'
                        'damage = ["mass:0.05@1.5"]\ntemperature_swing_k = 0.0\n')
    source = SimSource("sim", queue.Queue(), ServiceSettings.model_validate(cfg), raw=False, truth=True)
    rig = source.rig
    assert (rig.support, rig.orientation, rig.beam.length) == ("clamped", "standing", 1.5)
    assert source.rigsim.plants[0].clamped and source.metadata["truth"]["orientation"] == "standing"
    block = next(source.rigsim.blocks(1.0))
    assert np.all(block.truth["phi"] == 0)
    # +g standing (the realistic boards carry a scale-factor error of ~1 % and a bias)
    np.testing.assert_allclose(block.measurements["/imu/s1"][1][:, 0].mean(), 9.81, rtol=0.05)
    mast = tomllib.loads('[sim]\nsupport = "clamped"\norientation = "standing"\ndamage = []\n')
    with pytest.raises(BucklingError, match="buckles"):
        SimSource("sim", queue.Queue(), ServiceSettings.model_validate(mast), raw=False, truth=True)


# -- plausibility of times and values ----------------------------------

S = 1_000_000_000


def test_source_clock_rejects_stamps_off_the_clock_and_keeps_the_valid_ones():
    from shm_service.recording._plausibility import SourceClock

    clock = SourceClock(window_s=3600.0, max_ahead_s=1.0, live=False)
    for topic in ("/imu/D", "/tof/s1", "/strain/g1"):
        clock.take(topic, 1000 * S, mono=0.0)
    stamps = np.array([1000 * S + S // 2, 1003 * S, 1000 * S + 4000 * S, 1000 * S - 4000 * S, 1000 * S + 10 * 365 * 86400 * S])
    ok, codes = clock.judge("/imu/D", stamps, mono=0.0)
    # 0.5 s ahead: fine; 3 s ahead of every other sensor: its clock jumped; ±4000 s and +10 years: off the window
    assert codes.tolist() == [0, 2, 1, 1, 1] and ok.tolist() == [True, False, False, False, False]
    assert clock.count("/imu/D", codes, stamps, mono=0.0) == {"ahead_of_source": 1, "implausible_time": 3}
    assert clock.newest() == 1000 * S  # nothing rejected moved the clock
    assert any("clock jump" in p for p in clock.problems())
    # the whole source moving together (a recording resumed after two hours) is the source's time
    firsts = {t: 1000 * S + 7200 * S for t in ("/imu/D", "/tof/s1", "/strain/g1")}
    assert clock.source_jump(firsts, mono=0.0)
    assert not clock.source_jump({"/imu/D": 1000 * S + 7200 * S}, mono=0.0)  # one sensor is not the source
    with pytest.raises(ValueError, match="window_s"):
        SourceClock(window_s=0.0, max_ahead_s=1.0, live=False)


def test_a_live_sources_clock_runs_on_with_the_wall_clock():
    from shm_service.recording._plausibility import SourceClock

    wall = 2_000_000 * S
    clock = SourceClock(window_s=3600.0, max_ahead_s=1.0, live=True, future_tolerance_s=60.0)
    assert clock.judge_one("/imu/D", wall + 61 * S, wall_ns=wall, mono=0.0) == 1  # beyond the wall clock
    clock.take("/imu/D", wall - 3 * 3600 * S, mono=0.0)  # a device whose clock was three hours behind
    clock.take("/tof/s1", wall - 3 * 3600 * S, mono=0.0)
    # two hours later (wall clock) it resumes where its clock stands now: not ahead, not off the window
    assert clock.judge_one("/imu/D", wall - 3600 * S, wall_ns=wall + 7200 * S, mono=7200.0) == 0
    # one sensor's clock alone corrected to the wall clock while the source is three hours behind
    # (a backfill): far from its stream's time, a clock jump of that sensor
    assert clock.judge_one("/imu/D", wall + 7200 * S, wall_ns=wall + 7200 * S, mono=7200.0) == 1
    # a source running near the wall clock: a stamp near the wall clock is on time whatever its past
    near = SourceClock(window_s=3600.0, max_ahead_s=1.0, live=True, future_tolerance_s=60.0)
    near.take("/imu/D", wall - 300 * S, mono=0.0)
    near.take("/tof/s1", wall - 300 * S, mono=0.0)
    assert near.judge_one("/imu/D", wall, wall_ns=wall, mono=0.0) == 0
    assert near.judge_stamps(wall_ns=wall, mono=0.0).judge("/imu/D", wall) == 0
    assert near.judge("/imu/D", np.array([wall]), wall_ns=wall, mono=0.0)[1].tolist() == [0]
    # one sensor five minutes ahead of the others at once: its clock jumped
    assert clock.judge_one("/imu/D", wall - 3 * 3600 * S + 300 * S, wall_ns=wall, mono=0.0) == 2


def test_implausible_values_by_sensor_kind():
    from shm_service.recording._plausibility import ValueLimits, implausible_values

    limits = ValueLimits()
    imu = np.array([[-9.81, 0.1, 0.0, 0.0, 0.0, 0.01], [2500.0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, -250.0], [np.nan, 0, 0, 0, 0, 0]])
    assert implausible_values("imu", imu, limits).tolist() == [False, True, True, True]
    assert implausible_values("tof", np.array([0.5, -0.1, 150.0]), limits).tolist() == [False, True, True]
    assert implausible_values("strain", np.array([[1e-4], [-0.06]]), limits).tolist() == [False, True]
    assert implausible_values("temperature", np.array([20.0, 250.0]), limits).tolist() == [False, True]
    with pytest.raises(ValueError, match="kind"):
        implausible_values("truth", np.zeros((1, 1)), limits)
    with pytest.raises(ValueError, match="shape"):
        implausible_values("imu", np.zeros((2, 3)), limits)
    with pytest.raises(ValueError, match="distance_min_m"):
        ValueLimits(distance_min_m=5.0, distance_max_m=1.0)


def test_ingest_never_fails_on_what_a_message_holds_and_moves_time_only_when_taken():
    wall = 1_767_225_600 * S
    v = IngestValidator(default_rig("benchmark"), max_messages=100)
    huge = 10**29
    msgs = [
        {"topic": "/tof/s1", "log_time_ns": wall, "payload": {"distance": 0.5}},
        {"topic": "/tof/s1", "log_time_ns": wall + S // 30, "payload": {"distance": huge}},  # 1e29 m
        {"topic": "/tof/s1", "log_time_ns": wall + 2 * S // 30, "payload": {"distance": 10**400}},  # beyond a float
        {"topic": "/imu/D", "log_time_ns": wall, "payload": {"accel": [3000.0, 0, 0], "gyro": [0, 0, 0]}},
        {"topic": "/strain/g1", "log_time_ns": wall, "payload": {"strain": 0.2}},
        {"topic": "/imu/D", "log_time_ns": huge, "payload": _imu(1)},
        {"topic": "/imu/D", "log_time_ns": wall + S, "publish_time_ns": huge, "payload": _imu(1)},
        {"topic": "/imu/D", "log_time_ns": wall + S, "payload": {"accel": [[[1]]], "gyro": [0, 0, 0]}},
        {"topic": "/imu/D", "log_time_ns": wall + S, "payload": {"accel": [1, 2, 3], "gyro": [0, 0, 0], huge: 1}},
        {huge: 1},
    ]
    r = v.validate({"messages": msgs}, wall_ns=wall)
    assert r.accepted == 1 and r.raw[0][2] == b'{"distance":0.5}'
    assert dict(r.rejected) == {"implausible_value": 3, "nonfinite": 1, "malformed": 3, "wrong_schema": 2}
    assert v.last == {}  # nothing moves before the batch is handed on...
    assert v.validate({"messages": msgs[:1]}, wall_ns=wall).accepted == 1  # ...so a retry is no duplicate
    v.commit(r)
    assert v.validate({"messages": msgs[:1]}, wall_ns=wall).rejected == {"duplicate": 1}
    # one sample stamped ten years ahead, then the valid data go on being taken
    ahead = {"topic": "/tof/s1", "log_time_ns": wall + 10 * 365 * 86400 * S, "payload": {"distance": 0.5}}
    later = [{"topic": "/tof/s1", "log_time_ns": wall + k * S // 30, "payload": {"distance": 0.5}} for k in range(1, 31)]
    r = v.validate({"messages": [ahead, *later]}, wall_ns=wall + S)
    assert r.accepted == 30 and dict(r.rejected) == {"implausible_time": 1}
    v.commit(r)
    assert any("clock jump" in p for p in v.clock.problems())


@pytest.mark.parametrize("kind, good, bad", [
    ("imu", [-9.81, 0.1, 0.0, 0.01, -0.02, 0.0], [[2000.5, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, -200.5], [0, math.nan, 0, 0, 0, 0],
                                                   [0, 0, 0, math.inf, 0, 0]]),
    ("tof", [0.4], [[-0.01], [100.5], [math.nan]]),
    ("strain", [-1e-4], [[0.06], [-0.06], [math.inf]]),
    ("bearing", [0.002], [[-101.0], [math.nan]]),
    ("temperature", [21.5], [[-101.0], [201.0], [math.nan]]),
])
def test_all_plausible_agrees_with_the_per_sample_judgement(kind, good, bad):
    """The block shortcut of the pipeline: True exactly when no sample is implausible or
    non-finite, a single bad sample anywhere in the block making it False."""
    from shm_service.recording._plausibility import ValueLimits, all_plausible, implausible_values

    limits = ValueLimits()
    block = np.array([good] * 50, dtype=float)
    assert all_plausible(kind, block, limits) and not implausible_values(kind, block, limits).any()
    assert all_plausible(kind, block[:0], limits)
    for row in bad:
        spoilt = block.copy()
        spoilt[17] = row
        assert not all_plausible(kind, spoilt, limits)
        assert implausible_values(kind, spoilt, limits)[17] or not np.isfinite(spoilt[17]).all()
    assert not all_plausible("sonar", block[:, :1], limits)  # an unknown kind is left to the per-sample path


def _backfill(t0: int, n: int, topics=("/imu/D", "/tof/s1", "/strain/g1"), step=5_000_000) -> list[dict]:
    payloads = {"/imu/D": _imu(1), "/tof/s1": {"distance": 0.5}, "/strain/g1": {"strain": 1e-5}}
    return [{"topic": topic, "log_time_ns": t0 + k * step, "payload": payloads[topic]} for k in range(n) for topic in topics]


def test_a_wall_clock_stamp_inside_a_backfill_is_a_clock_jump_not_the_channels_new_time():
    """Backfilling data stamped from 1970, one /strain/g1 sample stamped with the
    present time is rejected (a clock jump, counted), and every later g1 sample is taken."""
    wall = 1_767_225_600 * S
    v = IngestValidator(default_rig("benchmark"), max_messages=10_000)
    t0 = 1000 * S  # 1970
    first = v.validate({"messages": _backfill(t0, 100)}, wall_ns=wall)
    assert first.accepted == 300 and not first.rejected
    v.commit(first)
    batch = _backfill(t0 + 100 * 5_000_000, 100)
    present = {"topic": "/strain/g1", "log_time_ns": wall, "payload": {"strain": 1e-5}}
    r = v.validate({"messages": batch[:30] + [present] + batch[30:]}, wall_ns=wall)
    assert r.accepted == 300 and dict(r.rejected) == {"implausible_time": 1}
    v.commit(r)
    assert v.last["/strain/g1"] == t0 + 199 * 5_000_000  # the channel's time is its stream's, not the jump's
    assert v.clock.jump_count == 1 and any("clock jump" in p for p in v.clock.problems())
    # the following g1 samples (alone in their request: the per-topic path) are accepted
    later = v.validate({"messages": _backfill(t0 + 200 * 5_000_000, 50, topics=("/strain/g1",))}, wall_ns=wall)
    assert later.accepted == 50 and not later.rejected


def test_a_resent_accepted_batch_is_duplicate_not_backwards():
    wall = 1_767_225_600 * S
    v = IngestValidator(default_rig("benchmark"), max_messages=10_000)
    batches = [_backfill(wall - 600 * S + k * S, 200) for k in range(3)]  # 1 s each
    for b in batches:
        r = v.validate({"messages": b}, wall_ns=wall)
        assert r.accepted == 600
        v.commit(r)
    for b in batches:  # the first (two batches behind) as the last: every sample a duplicate
        again = v.validate({"messages": b}, wall_ns=wall)
        assert again.accepted == 0 and dict(again.rejected) == {"duplicate": 600}
    # a batch of stamps never accepted, before the last: backwards
    between = _backfill(wall - 600 * S + 2_500_000, 3)
    assert dict(v.validate({"messages": between}, wall_ns=wall).rejected) == {"backwards": 9}
