"""Incremental reading (follow, truncated files) and ingest validation: bad input is counted,
never fatal, and valid data is kept."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shm_service.recording import RecordingFollower, RecordingWriter
from shm_service.rig_layouts import default_rig
from shm_service.service._ingest import IngestError, IngestValidator, parse_body


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
    from shm_service.service._config import ServiceSettings
    from shm_service.service._sources import SimSource

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
