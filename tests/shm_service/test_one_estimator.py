"""One estimator policy: a raw recording with faults in it (a 7 s silence of the reference IMU D,
which restarts the filter, and a ToF reading 0.5 m off for 3 s, which the gate refuses) gives the
same b(t) through ``shm serve`` (a replay, its archived estimates), ``shm estimate``, the path of
``shm analyze`` on a raw file, and ``estimator.estimate()``."""

from __future__ import annotations

import json

import numpy as np
import orjson
import pytest
from mcap.reader import make_reader

from estimator import StreamingSettings, build_model, estimate
from shm_service.cli import main
from shm_service.processing.estimation import deformation_record, measurements_from_recording
from shm_service.recording import ESTIMATE_TOPIC, RecordingWriter, read_recording
from shm_service.service import MonitoringService, load_settings
from shm_service.virtual_rig import SimulationSettings, simulate

_NS = 1_000_000_000
SILENT_D = (70.0, 77.0)  # s after the start: longer than the 5 s gap reset
TOF_OFF = (30.0, 33.0)


@pytest.fixture(scope="module")
def faulty(tmp_path_factory):
    """110 s of the simulated rig (10 s rest), the faults written into the file itself."""
    tmp = tmp_path_factory.mktemp("one_estimator")
    clean, path = tmp / "clean.mcap", tmp / "faulty.mcap"
    simulate(SimulationSettings(duration=110.0, rest=10.0, excitation="ambient", seed=5), clean)
    rec = read_recording(clean)
    start = rec.start_ns
    tof = sorted(t for t in rec.channels if t.startswith("/tof/"))[0]
    with open(clean, "rb") as f, RecordingWriter(path, rec.rig) as out:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            s = (message.log_time - start) / _NS
            if channel.topic == "/imu/D" and SILENT_D[0] <= s < SILENT_D[1]:
                continue
            data = message.data
            if channel.topic == tof and TOF_OFF[0] <= s < TOF_OFF[1]:
                payload = orjson.loads(data)
                payload["distance"] = payload["distance"] + 0.5
                data = orjson.dumps(payload)
            out.write(channel.topic, message.log_time, data, message.publish_time)
    return tmp, path


def _b(rec) -> tuple[np.ndarray, np.ndarray]:
    ch = rec.channels[ESTIMATE_TOPIC]
    columns = [i for i, name in enumerate(ch.fields) if name.startswith("b[")]
    return ch.log_time_ns, ch.values[:, columns]


def test_the_same_faulty_recording_gives_the_same_b_through_every_entry_point(faulty, capsys):
    tmp, path = faulty
    rec = read_recording(path)
    assert "/imu/D" in rec.channels

    # shm serve: a replay at full speed, every estimate archived
    settings = load_settings(None, {"db": str(tmp / "shm.sqlite"), "dashboard": {"enabled": False},
                                    "source": {"spec": f"replay:{path}", "speed": "max"},
                                    "archive": {"directory": str(tmp / "recordings"), "raw": "never",
                                                "estimate_decimation": 1}})
    service = MonitoringService(settings, environ={})
    service.start()
    assert service.wait(300)
    status = service.status()
    service.stop(drain_s=0)
    est = status.pipeline.estimator
    assert est.filter_restarts_by_reason.get("gap", 0) >= 1, est  # the silence restarted the filter
    (archive,) = sorted((tmp / "recordings").glob("*.mcap"))
    served_t, served_b = _b(read_recording(archive))
    assert len(served_t) > 15_000

    # shm estimate --out
    out = tmp / "estimated.mcap"
    assert main(["estimate", str(path), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["diagnostics"]["filter_restarts"] == est.filter_restarts
    cli_t, cli_b = _b(read_recording(out))
    np.testing.assert_array_equal(cli_t, served_t)
    np.testing.assert_array_equal(cli_b, served_b)

    # shm analyze on the raw file: its b(t)
    data = deformation_record(rec, model_args={})
    assert data.estimated_here
    np.testing.assert_array_equal(data.b, served_b)
    np.testing.assert_allclose(rec.start_ns + data.times * 1e9, served_t, rtol=0, atol=1e3)

    # estimator.estimate() on the planar measurements
    result = estimate(measurements_from_recording(rec), build_model(rec.rig))
    assert result.diagnostics["filter_restarts"] == est.filter_restarts
    np.testing.assert_allclose(result.b, served_b, rtol=0, atol=1e-9 * max(1.0, float(np.abs(served_b).max())))
    # no estimate from inside the silence: the filter restarted after it
    inside = (served_t - rec.start_ns) / _NS
    assert not np.any((inside > SILENT_D[0] + 0.1) & (inside < SILENT_D[1] - 0.1))


def test_the_streaming_settings_refuse_a_bad_value():
    with pytest.raises(ValueError, match="chunk_s"):
        StreamingSettings(chunk_s=0.0)
