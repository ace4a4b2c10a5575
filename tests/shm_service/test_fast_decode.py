"""The compiled payload decoder and the column-wise ingest path against their reference paths."""

from __future__ import annotations

import json
import time
import tracemalloc

import numpy as np
import orjson
import pytest

from shm_service.recording import RecordingWriter, encode_payloads_json, read_recording
from shm_service.recording._fastdecode import decode_template, template_codes
from shm_service.rig_layouts import build_rig
from shm_service.service.sources._ingest import IngestValidator


def _decode(tokens: list[bytes], skeleton: bytes = b'{"x":#}', wrap=lambda t: b'{"x":' + t + b"}"):
    payloads = [wrap(t) for t in tokens]
    lengths = np.array([len(p) for p in payloads], dtype=np.int64)
    stops = np.cumsum(lengths)
    buf = np.frombuffer(b"".join(payloads), dtype=np.uint8)
    return decode_template(buf, stops - lengths, stops, template_codes(skeleton), skeleton.count(b"#"))


def test_numbers_are_parsed_exactly_as_float_does():
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**63 - 1, size=60_000, dtype=np.int64).view(np.float64)
    values = np.concatenate([bits[np.isfinite(bits)], rng.normal(size=60_000), rng.normal(size=20_000) * 1e-7,
                             np.exp(rng.uniform(-690, 700, 20_000))])
    tokens = [orjson.dumps(float(v)) for v in values] + [b"%.17e" % v for v in values[:5000]] + [b"%.4f" % v for v in values[-5000:]]
    got, ok = _decode(tokens)
    expected = np.array([float(t) for t in tokens])
    finite = int(np.isfinite(bits).sum())
    # sensor-like values all decided here; the rest (subnormals, > 19 digits, ...) goes the reference way
    assert ok.mean() > 0.97 and ok[finite : finite + 80_000].all()
    np.testing.assert_array_equal(got[ok, 0].view(np.uint64), expected[ok].view(np.uint64))


@pytest.mark.parametrize("token, value", [(b"0", 0.0), (b"-0.0", -0.0), (b"1E+2", 100.0), (b"2.5e-3", 0.0025),
                                          (b"123456789012345678", 123456789012345678.0), (b"0.000001", 1e-6)])
def test_valid_json_numbers(token, value):
    got, ok = _decode([token])
    assert ok[0] and got[0, 0] == value and np.signbit(got[0, 0]) == np.signbit(value)


@pytest.mark.parametrize("payload", [b'{"x":01}', b'{"x":1.}', b'{"x":.5}', b'{"x":-}', b'{"x":1e}', b'{"x":NaN}',
                                     b'{"x":Infinity}', b'{"x":1,}', b'{"y":1}', b'{"x":1e400}', b'{"x":true}',
                                     b'{"x":"1"}', b'{"x":[1]}', b'{"x":1}x', b'{"x" :1.5', b'{"x":12345678901234567890123}'])
def test_what_the_kernel_leaves_to_the_reference_path(payload):
    _, ok = _decode([payload], wrap=lambda t: t)
    assert not ok[0]


def test_whitespace_between_tokens_but_not_inside_keys():
    got, ok = _decode([b' { "accel" : [ 1 , 2.5 ,-3 ] ,\n"gyro":[0,0,1e-3] } ', b'{"acc el":[1,2,3],"gyro":[0,0,0]}'],
                      b'{"accel":[#,#,#],"gyro":[#,#,#]}', wrap=lambda t: t)
    assert ok.tolist() == [True, False]
    assert got[0].tolist() == [1.0, 2.5, -3.0, 0.0, 0.0, 1e-3]


def test_reader_mixes_both_paths_in_file_order(tmp_path):
    """Compact payloads, spaced ones (Python's json.dumps), other key orders, NaN and a bad one in
    one chunk: each message decoded as the reference would, in order, the bad ones counted."""
    rig = build_rig("benchmark")
    path = tmp_path / "mixed.mcap"
    t0 = 1_700_000_000_000_000_000
    with RecordingWriter(path, rig) as writer:
        for i in range(400):
            accel, gyro = [-9.81, i * 1e-3, 0.1], [0.0, 0.0, i * 1e-5]
            payload = [orjson.dumps({"accel": accel, "gyro": gyro}), json.dumps({"accel": accel, "gyro": gyro}).encode(),
                       orjson.dumps({"gyro": gyro, "accel": accel}), b'{"accel":[NaN,0,0],"gyro":[0,0,0]}',
                       b'{"accel":[1,2],"gyro":[0,0,0]}'][i % 5]
            writer.write("/imu/D", t0 + i * 5_000_000, payload)
    rec = read_recording(path, topics={"/imu/D"})
    report = rec.report.topics["/imu/D"]
    assert (report.accepted, report.nonfinite, report.malformed) == (240, 80, 80)
    i = np.array([k for k in range(400) if k % 5 < 3])
    np.testing.assert_array_equal(rec.channels["/imu/D"].log_time_ns, t0 + i * 5_000_000)
    np.testing.assert_array_equal(rec.channels["/imu/D"].values[:, 1], i * 1e-3)


def test_encoded_payloads_are_the_same_bytes_at_their_size():
    rows = [{"accel": [float(i), -9.81, 1e-7], "gyro": [0.5, 0.0, -0.25]} for i in range(2000)]
    tracemalloc.start()
    try:
        encoded = encode_payloads_json(rows)
        held = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert encoded == [orjson.dumps(r) for r in rows]
    assert held / len(rows) < 400  # one orjson.dumps per payload holds about 4 kB each
    assert encode_payloads_json([{"a": {"b": 1}}, {"c": [1]}]) == [b'{"a":{"b":1}}', b'{"c":[1]}']


def _body(rng: np.random.Generator, rig, t0: int, faults: bool, edge_cases: bool = True) -> dict:
    messages = []
    for sensor in rig.sensors:
        n = 20 if sensor.kind in ("imu", "strain") else 3
        for k in range(n):
            t = t0 + k * 5_000_000
            if sensor.kind == "imu":
                payload = {"accel": rng.normal(size=3).tolist(), "gyro": rng.normal(size=3).tolist()}
            elif sensor.kind == "temperature":
                payload = {"celsius": 20.0}
            else:
                # readings a sensor can give: a ToF's distance about 0.5 m, a gauge's strain about 1e-4
                value = 1e-4 * rng.normal() if sensor.kind == "strain" else 0.5 + 0.01 * rng.normal()
                payload = {sensor.kind if sensor.kind == "strain" else "distance": float(value)}
            messages.append({"topic": sensor.topic, "log_time_ns": t, "payload": payload})
    if edge_cases:
        # values a plausibility rule refuses (huge accelerations, far-future stamps), integers
        messages[0]["payload"]["accel"][0] = 1e6
        messages[19]["log_time_ns"] += 10 * 365 * 86400 * 10**9  # the last of /imu/D
        messages[2]["payload"]["gyro"] = [0, 1, 2]
        messages[3]["publish_time_ns"] = messages[3]["log_time_ns"] + 7
    if faults:
        bad = rng.choice(len(messages), 6, replace=False)
        messages[bad[0]]["payload"]["accel" if "accel" in messages[bad[0]]["payload"] else next(iter(messages[bad[0]]["payload"]))] = None
        messages[bad[1]]["topic"] = "/imu/nowhere"
        messages[bad[2]]["log_time_ns"] = -1
        messages[bad[3]]["payload"]["extra"] = 1.0
        messages[bad[4]]["log_time_ns"] = messages[bad[5]]["log_time_ns"]
        messages[bad[5]] = {"topic": messages[bad[5]]["topic"]}
        rng.shuffle(messages)
    return {"messages": messages}


@pytest.mark.parametrize("faults", [False, True])
def test_column_wise_ingest_gives_what_the_per_message_path_gives(faults, monkeypatch):
    """A rule added to the per-message path (_message) must hold on the column-wise path too:
    this compares both on clean and faulty requests, plausibility edge cases included."""
    rig = build_rig("benchmark")
    rng = np.random.default_rng(3)
    fast, reference = IngestValidator(rig, max_messages=10_000), IngestValidator(rig, max_messages=10_000)
    monkeypatch.setattr(reference, "_validate_columns", lambda *args: None)
    taken = []
    columns = fast._validate_columns
    monkeypatch.setattr(fast, "_validate_columns", lambda *args: taken.append(columns(*args)) or taken[-1])
    for second in range(3):
        body = _body(rng, rig, 1_700_000_000_000_000_000 + second * 10**9, faults)
        a = fast.validate(json.loads(json.dumps(body)))
        b = reference.validate(json.loads(json.dumps(body)))
        fast.commit(a)  # the batch was handed on: its times become the topics' and the clock's
        reference.commit(b)
        assert (a.accepted, dict(a.rejected), a.errors) == (b.accepted, dict(b.rejected), b.errors)
        assert sorted(a.raw) == sorted(b.raw)
        blocks_a = {x.topic: x for x in a.blocks}
        blocks_b = {x.topic: x for x in b.blocks}
        assert blocks_a.keys() == blocks_b.keys()
        for topic, x in blocks_a.items():
            y = blocks_b[topic]
            np.testing.assert_array_equal(x.log_time_ns, y.log_time_ns)
            np.testing.assert_array_equal(x.publish_time_ns, y.publish_time_ns)
            np.testing.assert_array_equal(x.values, y.values)
        assert fast.last == reference.last
    # implausible values and stamps go the per-message way, which explains each rejection
    assert all(r is None for r in taken)


def test_a_clean_request_takes_the_column_wise_path_with_the_same_result(monkeypatch):
    rig = build_rig("benchmark")
    rng = np.random.default_rng(4)
    fast, reference = IngestValidator(rig, max_messages=10_000), IngestValidator(rig, max_messages=10_000)
    monkeypatch.setattr(reference, "_validate_columns", lambda *args: None)
    t0 = time.time_ns() - 10 * 10**9
    for second in range(3):
        body = _body(rng, rig, t0 + second * 10**9, False, edge_cases=False)
        a, b = fast.validate(json.loads(json.dumps(body))), reference.validate(json.loads(json.dumps(body)))
        fast.commit(a)
        reference.commit(b)
        assert a.accepted == b.accepted == len(body["messages"]) and not a.rejected and not b.rejected
        assert sorted(a.raw) == sorted(b.raw)
        for x, y in zip(sorted(a.blocks, key=lambda x: x.topic), sorted(b.blocks, key=lambda x: x.topic)):
            np.testing.assert_array_equal(x.values, y.values)
            np.testing.assert_array_equal(x.log_time_ns, y.log_time_ns)
        assert fast.last == reference.last
