"""Recordings: writer/reader round trip and every kind of bad input the contract names."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from shm_service.recording import (
    RecordingError,
    RecordingWriter,
    format_inspection,
    inspect_recording,
    read_recording,
)

STATIONS = [0.5, 1.0, 2.0, 4.0]
RIG: dict[str, Any] = {
    "beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, "youngs_modulus": 2.1e11, "density": 7850.0},
    "gravity": 9.81,
    "reflector_distance": 0.5,
    "sensors": [
        {"name": "D", "kind": "imu", "position": 0.0},
        {"name": "s1", "kind": "imu", "position": 1.2},
        {"name": "s1", "kind": "tof", "position": 1.2},
        {"name": "g1", "kind": "strain", "position": 0.9},
        {"name": "bearing", "kind": "bearing"},
    ],
    "truth_stations": STATIONS,
}
T0 = 1_700_000_000_000_000_000  # ns
FAST, SLOW = 5_000_000, 30_000_000  # ns


def imu(i: int, k: float = 0.0) -> dict[str, list[float]]:
    return {"accel": [-9.81 + i * 1e-3, k, 0.5], "gyro": [0.0, 0.25, i * -1e-4]}


def truth(i: int) -> dict[str, Any]:
    return {"d": i * 1e-3, "h": 0.0, "phi": 1e-4 * i, "e": 0.01, "deflection": [0.1 * j for j in range(4)], "curvature": [i * 1e-5] * 4}


def write_demo(path: Path, *, seconds: float = 2.0, **kwargs: Any) -> None:
    """All channels of RIG for ``seconds``, written one channel after the other (not interleaved)."""
    fast, slow = int(seconds * 200), int(seconds * 1e9 / SLOW)
    with RecordingWriter(path, RIG, metadata={"truth": {"f1_hz": "0.42"}}, **kwargs) as writer:
        for i in range(fast):
            writer.write("/imu/D", T0 + i * FAST, imu(i))
        for i in range(fast):
            writer.write("/imu/s1", T0 + i * FAST, imu(i, 1.0), publish_time_ns=T0 + i * FAST + 2_000_000)
        for i in range(fast):
            writer.write("/strain/g1", T0 + i * FAST, {"strain": i * 1e-7})
        for i in range(slow):
            writer.write("/tof/s1", T0 + i * SLOW, {"distance": 0.5 + i * 1e-4})
            writer.write("/bearing/displacement", T0 + i * SLOW, {"distance": i * 1e-5})
        for i in range(fast):
            writer.write("/truth/state", T0 + i * FAST, truth(i))
        writer.add_metadata("notes", {"who": "test"})


def test_round_trip_exact_values_and_merged_order(tmp_path: Path) -> None:
    path = tmp_path / "demo.mcap"
    write_demo(path, chunk_size=8192)
    rec = read_recording(path)
    assert rec.report.truncated is False
    assert rec.report.problems == []
    assert set(rec.channels) == {"/imu/D", "/imu/s1", "/strain/g1", "/tof/s1", "/bearing/displacement", "/truth/state"}
    d = rec.channels["/imu/D"]
    assert d.kind == "imu" and d.name == "D" and d.position == 0.0
    assert d.fields == ("accel[0]", "accel[1]", "accel[2]", "gyro[0]", "gyro[1]", "gyro[2]")
    expected = np.array([imu(i)["accel"] + imu(i)["gyro"] for i in range(400)])
    np.testing.assert_array_equal(d.values, expected)
    np.testing.assert_array_equal(d.log_time_ns, T0 + np.arange(400) * FAST)
    np.testing.assert_array_equal(rec.channels["/imu/s1"].publish_time_ns - rec.channels["/imu/s1"].log_time_ns, 2_000_000)
    tof = rec.channels["/tof/s1"]
    assert tof.position == 1.2 and tof.values.shape == (66, 1)
    np.testing.assert_array_equal(tof.values[:, 0], [0.5 + i * 1e-4 for i in range(66)])
    t = rec.channels["/truth/state"]
    assert t.values.shape == (400, 4 + 2 * len(STATIONS))
    seventh = truth(7)
    np.testing.assert_array_equal(t.values[7], [7e-3, 0.0, 7e-4, 0.01, *seventh["deflection"], *seventh["curvature"]])
    assert rec.metadata == {"notes": {"who": "test"}, "truth": {"f1_hz": "0.42"}}
    assert rec.attachments == ("rig.json",)
    assert rec.rig.beam.length == 4.0 and rec.start_ns == T0 and rec.duration_s == pytest.approx(1.995)
    assert rec.channels["/imu/D"].time_s(rec.start_ns)[-1] == pytest.approx(1.995)
    report = rec.report.topics["/strain/g1"]
    assert (report.messages, report.accepted, report.gaps, report.silent_after_s) == (400, 400, 0, None)

    merged = list(rec.merged())
    assert len(merged) == sum(len(c) for c in rec.channels.values())
    keys = [(time, topic) for time, topic, _ in merged]
    assert keys == sorted(keys)
    assert merged[0][1] == "/bearing/displacement" and merged[0][2][0] == 0.0
    only = list(rec.merged(["/tof/s1"]))
    assert [row[0] for _, _, row in only] == list(tof.values[:, 0])

    # Any MCAP reader opens the file, with all its indexes and CRCs.
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 4 * 400 + 2 * 66
        assert sum(1 for _ in reader.iter_messages()) == summary.statistics.message_count
        assert [a.name for a in reader.iter_attachments()] == ["rig.json"]

    summary_dict = inspect_recording(path)
    assert summary_dict["topics"]["/imu/D"]["rate_hz"] == pytest.approx(200.0)
    assert summary_dict["topics"]["/tof/s1"]["rate_hz"] == pytest.approx(33.333, rel=1e-3)
    assert summary_dict["rig"]["sensors"] == {"imu": 2, "tof": 1, "strain": 1, "bearing": 1}
    json.dumps(summary_dict)
    assert "/truth/state" in format_inspection(summary_dict)


def test_write_batch_writes_the_bytes_of_one_write_per_message(tmp_path: Path) -> None:
    # Chunks of 2 kB: the batches are cut across several chunks, one message at a time would be cut the same way.
    import orjson

    stamps = T0 + np.arange(300, dtype=np.int64) * FAST
    payloads = [orjson.dumps(imu(i)) for i in range(300)]
    strain = [orjson.dumps({"strain": i * 1e-7}) for i in range(300)]
    one, many = tmp_path / "one.mcap", tmp_path / "many.mcap"
    with RecordingWriter(one, RIG, chunk_size=2048) as writer:
        writer.write("/strain/g1", T0, strain[0])
        for t, p in zip(stamps.tolist(), payloads):
            writer.write("/imu/D", t, p, t + 7)
        for t, p in zip(stamps.tolist()[1:], strain[1:]):
            writer.write("/strain/g1", t, p)
    with RecordingWriter(many, RIG, chunk_size=2048) as writer:
        writer.write("/strain/g1", T0, strain[0])
        writer.write_batch("/imu/D", stamps[:17], payloads[:17], stamps[:17] + 7)
        writer.write_batch("/imu/D", stamps[17:], payloads[17:], stamps[17:] + 7)
        writer.write_batch("/strain/g1", stamps[:0], [])
        writer.write_batch("/strain/g1", stamps[1:], strain[1:])
    assert many.read_bytes() == one.read_bytes()
    assert len(read_recording(many).channels["/imu/D"]) == 300
    with RecordingWriter(tmp_path / "bad.mcap", RIG) as writer:
        with pytest.raises(ValueError, match="log_times_ns must be 2 integers"):
            writer.write_batch("/imu/D", stamps[:3], payloads[:2])
        with pytest.raises(ValueError, match="publish_time_ns=.* is before log_time_ns"):
            writer.write_batch("/imu/D", stamps[:2], payloads[:2], stamps[:2] - 1)
        with pytest.raises(ValueError, match="negative"):
            writer.write_batch("/imu/D", -stamps[:2], payloads[:2])
        with pytest.raises(ValueError, match="not a topic of the recording contract"):
            writer.write_batch("/nope", stamps[:2], payloads[:2])


def test_topics_filter_and_other_json_formatting(tmp_path: Path) -> None:
    path = tmp_path / "spaced.mcap"
    with RecordingWriter(path, json.dumps(RIG)) as writer:
        for i in range(50):  # the stdlib's spacing and key order: still valid JSON of the schema
            writer.write("/imu/D", T0 + i * FAST, json.dumps({"gyro": imu(i)["gyro"], "accel": imu(i)["accel"]}).encode())
            writer.write("/imu/s1", T0 + i * FAST, imu(i))
    rec = read_recording(path, topics=["/imu/D"])
    assert list(rec.channels) == ["/imu/D"]
    np.testing.assert_array_equal(rec.channels["/imu/D"].values[3], imu(3)["accel"] + imu(3)["gyro"])
    assert rec.end_ns == T0 + 49 * FAST


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_truncated_file_keeps_everything_before_the_cut(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "full.mcap"
    write_demo(path, compression=compression, chunk_size=16384)
    full = read_recording(path)
    data = path.read_bytes()
    after_attachment = data.index(b"rig.json") + len(json.dumps(RIG, indent=2)) + 40
    for cut in (after_attachment, after_attachment + 5, len(data) // 2, int(len(data) * 0.9)):
        cut_path = tmp_path / f"cut{cut}.mcap"
        cut_path.write_bytes(data[:cut])
        rec = read_recording(cut_path)
        assert rec.report.truncated, cut
        assert any("cut off" in p for p in rec.report.problems)
        for topic, channel in rec.channels.items():
            n = len(channel)
            np.testing.assert_array_equal(channel.values, full.channels[topic].values[:n])
            np.testing.assert_array_equal(channel.log_time_ns, full.channels[topic].log_time_ns[:n])
        kept = sum(len(c) for c in rec.channels.values())
        if cut >= len(data) // 2:
            assert kept > 0
    # A cut in the summary section loses no data.
    (tmp_path / "summary_cut.mcap").write_bytes(data[:-100])
    rec = read_recording(tmp_path / "summary_cut.mcap")
    assert not rec.report.truncated
    assert all(len(rec.channels[t]) == len(full.channels[t]) for t in full.channels)
    # Only the magic, with the rig given separately.
    rig_path = tmp_path / "rig.json"
    rig_path.write_text(json.dumps(RIG))
    (tmp_path / "magic.mcap").write_bytes(data[:5])
    rec = read_recording(tmp_path / "magic.mcap", rig=rig_path)
    assert rec.report.truncated and rec.channels == {}


def test_partial_chunk_is_salvaged(tmp_path: Path) -> None:
    path = tmp_path / "one_chunk.mcap"
    write_demo(path, compression="none")  # a single 1 MiB chunk: the cut falls inside it
    data = path.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    rec = read_recording(tmp_path / "cut.mcap")
    assert rec.report.truncated
    assert len(rec.channels["/imu/D"]) == 400


def test_nonfinite_duplicate_backwards_and_malformed_are_skipped(tmp_path: Path) -> None:
    path = tmp_path / "bad.mcap"
    with RecordingWriter(path, RIG) as writer:
        for i in range(100):
            t = T0 + i * FAST
            payload: dict[str, Any] | bytes = {"strain": i * 1e-4}
            if i == 10:
                payload = json.dumps({"strain": math.nan}).encode()
            elif i == 11:
                payload = json.dumps({"strain": -math.inf}).encode()
            elif i == 12:
                payload = b'{"strain": 1e400}'
            elif i == 40:
                payload = {"strain": 1e30}  # no strain gauge reads that: implausible
            writer.write("/strain/g1", t, payload)
            if i == 20:
                writer.write("/strain/g1", t, {"strain": -1e-4})  # duplicate stamp
            if i == 30:
                writer.write("/strain/g1", t - 3 * FAST, {"strain": -2e-4})  # backwards
            imu_payload: dict[str, Any] | bytes = imu(i)
            if i == 5:
                imu_payload = {"accel": [1.0, 2.0, 3.0]}
            elif i == 6:
                imu_payload = {"accel": [1.0, 2.0], "gyro": [0.0, 0.0, 0.0]}
            elif i == 7:
                imu_payload = b"not json"
            elif i == 8:
                imu_payload = {"accel": [1.0, "2", 3.0], "gyro": [0.0, 0.0, 0.0]}
            elif i == 9:
                imu_payload = {"accel": [1.0, True, 3.0], "gyro": [0.0, 0.0, 0.0]}
            writer.write("/imu/D", t, imu_payload)
            truth_payload = truth(i)
            if i == 50:
                truth_payload["deflection"] = [0.0] * 3
            writer.write("/truth/state", t, truth_payload)
    rec = read_recording(path)
    strain = rec.report.topics["/strain/g1"]
    assert (strain.messages, strain.nonfinite, strain.implausible, strain.duplicate, strain.backwards, strain.accepted) == (
        102, 3, 1, 1, 1, 96)
    values = rec.channels["/strain/g1"].values[:, 0]
    np.testing.assert_allclose(values[:12], np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 13, 14]) * 1e-4, rtol=1e-12)
    assert -1e-4 not in values and -2e-4 not in values and 1e30 not in values and 20e-4 in values and 30e-4 in values
    assert np.all(np.diff(rec.channels["/strain/g1"].log_time_ns) > 0)
    d = rec.report.topics["/imu/D"]
    assert (d.malformed, d.accepted) == (5, 95)
    np.testing.assert_array_equal(rec.channels["/imu/D"].values[4:6], [imu(4)["accel"] + imu(4)["gyro"], imu(10)["accel"] + imu(10)["gyro"]])
    assert rec.report.topics["/truth/state"].malformed == 1
    text = "\n".join(rec.report.problems)
    assert "/imu/D: 5 malformed" in text and "missing key 'gyro'" in text
    assert "/strain/g1: 3 message(s) with NaN" in text
    assert "/strain/g1: 1 message(s) with values beyond what a strain sensor reads skipped" in text
    assert rec.report.truncated is False


def test_gaps_and_silent_sensor(tmp_path: Path) -> None:
    path = tmp_path / "gaps.mcap"
    dropped = set(range(100, 105)) | {300, 301}
    with RecordingWriter(path, RIG) as writer:
        for i in range(400):
            if i not in dropped:
                writer.write("/imu/D", T0 + i * FAST, imu(i))
            if i < 100:  # s1 stops after 0.5 s of a 2 s recording
                writer.write("/imu/s1", T0 + i * FAST, imu(i))
        for i in range(66):
            if i != 20:
                writer.write("/tof/s1", T0 + i * SLOW, {"distance": 0.5})
    rec = read_recording(path)
    d = rec.report.topics["/imu/D"]
    assert (d.gaps, d.missing_samples, d.silent_after_s) == (2, 7, None)
    tof = rec.report.topics["/tof/s1"]
    assert (tof.gaps, tof.missing_samples) == (1, 1)
    assert rec.report.topics["/imu/s1"].silent_after_s == pytest.approx(0.495)
    assert any("/imu/s1: silent after 0.495 s" in p for p in rec.report.problems)
    assert any("no /strain/g1" in p for p in rec.report.problems)


def raw_recording(path: Path, rig_json: bytes | None, channels: list[tuple[str, str, str, str]]) -> None:
    """A file written with the plain mcap writer: ``(topic, schema title, schema encoding,
    message encoding)`` channels with ten messages each."""
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start()
        if rig_json is not None:
            writer.add_attachment(0, 0, "rig.json", "application/json", rig_json)
        for topic, title, schema_encoding, message_encoding in channels:
            schema = writer.register_schema(title, schema_encoding, b"{}")
            channel = writer.register_channel(topic, message_encoding, schema)
            for i in range(10):
                writer.add_message(channel, T0 + i * FAST, json.dumps({"distance": 1.0, **imu(i)}).encode(), T0 + i * FAST)
        writer.finish()


def test_unknown_topic_and_sensor_not_in_rig_are_skipped(tmp_path: Path) -> None:
    with RecordingWriter(tmp_path / "x.mcap", RIG) as writer, pytest.raises(ValueError, match="/foo/bar"):
        writer.write("/foo/bar", T0, {"x": 1})
    path = tmp_path / "skip.mcap"
    raw_recording(
        path,
        json.dumps(RIG).encode(),
        [
            ("/imu/D", "shm.Imu", "jsonschema", "json"),
            ("/foo/bar", "whatever", "", "cbor"),
            ("/imu/x9", "shm.Imu", "jsonschema", "json"),
        ],
    )
    rec = read_recording(path)
    assert list(rec.channels) == ["/imu/D"] and len(rec.channels["/imu/D"]) == 10
    assert rec.report.skipped_topics == {"/foo/bar": 10, "/imu/x9": 10}
    text = "\n".join(rec.report.problems)
    assert "/foo/bar: not a topic of the recording contract" in text and "rig.json has no imu named 'x9'" in text


def test_schema_mismatch_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "schema.mcap"
    raw_recording(path, json.dumps(RIG).encode(), [("/tof/s1", "shm.Imu", "jsonschema", "json")])
    with pytest.raises(RecordingError, match="/tof/s1.*shm.Distance"):
        read_recording(path)
    raw_recording(path, json.dumps(RIG).encode(), [("/tof/s1", "shm.Distance", "jsonschema", "cbor")])
    with pytest.raises(RecordingError, match="/tof/s1.*message_encoding"):
        read_recording(path)


def bad_rig(**changes: Any) -> dict[str, Any]:
    rig = json.loads(json.dumps(RIG))
    rig.update(changes)
    return rig


@pytest.mark.parametrize(
    ("rig_json", "match"),
    [
        (None, "rig.json is missing"),
        (b"{not json", "rig.json.*not valid JSON"),
        (json.dumps({k: v for k, v in RIG.items() if k != "beam"}).encode(), "rig.json.*beam"),
        (json.dumps(bad_rig(sensors=[{"name": "w", "kind": "wind", "position": 1.0}])).encode(), "rig.json.*kind"),
        (json.dumps(bad_rig(sensors=[{"name": "s9", "kind": "imu", "position": 5.0}])).encode(), "position=5.0 is outside"),
    ],
)
def test_bad_rig_is_refused(tmp_path: Path, rig_json: bytes | None, match: str) -> None:
    path = tmp_path / "rig.mcap"
    raw_recording(path, rig_json, [("/imu/D", "shm.Imu", "jsonschema", "json")])
    with pytest.raises(RecordingError, match=match):
        read_recording(path)


def test_rig_given_as_json_or_toml_file(tmp_path: Path) -> None:
    path = tmp_path / "norig.mcap"
    raw_recording(path, None, [("/imu/D", "shm.Imu", "jsonschema", "json"), ("/imu/s1", "shm.Imu", "jsonschema", "json")])
    as_json = tmp_path / "rig.json"
    as_json.write_text(json.dumps(bad_rig(sensors=[{"name": "D", "kind": "imu", "position": 0.0}])))
    rec = read_recording(path, rig=as_json)
    assert list(rec.channels) == ["/imu/D"] and rec.report.skipped_topics == {"/imu/s1": 10}
    as_toml = tmp_path / "rig.toml"
    as_toml.write_text(
        "gravity = 9.81\nreflector_distance = 0.5\ntruth_stations = [1.0, 3.0]\n"
        "[beam]\nlength = 3.0\nwidth = 0.2\nthickness = 0.002\nyoungs_modulus = 2.1e11\ndensity = 7850.0\n"
        '[[sensors]]\nname = "D"\nkind = "imu"\nposition = 0.0\n'
        '[[sensors]]\nname = "s1"\nkind = "imu"\nposition = 2.5\n'
    )
    rec = read_recording(path, rig=as_toml)
    assert rec.rig.beam.length == 3.0 and rec.channels["/imu/s1"].position == 2.5
    with pytest.raises(RecordingError, match="cannot read rig description"):
        read_recording(path, rig=tmp_path / "missing.toml")
