"""``shm import``: DAQ files into the recording contract.

- Round trip: a short seeded simulated recording exported to every format (text, .npy, .npz,
  MATLAB v5 and v7.3, HDF5) and imported back has the same channels and gives the same estimator
  RMSE (against the original's truth) to 1e-9.
- The real DROPBEAR LabVIEW export with the example rig and map: passes ``shm inspect`` without
  problems, ``shm oma`` finds on it what it finds on the text file.
- Independent readers: the python ``mcap`` library and the npm ``@mcap`` packages (installed with
  npm from the registry into ``.venv/node-mcap`` when node is there) read the imports.
- Bad input: every error names the value.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from estimator import build_model, estimate, load_rig
from shm_service.cli import main
from shm_service.formats.daq_import import MapError, import_recording, parse_channel_map
from shm_service.processing.estimation import measurements_from_recording, score_against_truth, truth_from_recording
from shm_service.recording import inspect_recording, read_recording
from shm_service.formats.tables import TableError, read_table
from shm_service.virtual_rig import SimulationSettings, simulate

sys.path.insert(0, str(Path(__file__).resolve().parent))
from daq_export import export  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DROPBEAR = ROOT / "tests" / "data" / "dropbear" / "random-dwell" / "test0.txt"
EXAMPLE = ROOT / "examples" / "dropbear"
FORMATS = ("text", "npy", "npz", "mat", "mat73", "hdf5")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# -- round trip ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A 50 s recording (10 s rest, then the paper's excitation), seed 5, its rig file and the
    estimator's RMSE on it."""
    folder = tmp_path_factory.mktemp("sim")
    path = folder / "sim.mcap"
    simulate(SimulationSettings(duration=50.0, rest=10.0, seed=5), path)
    rec = read_recording(path)
    rig_path = folder / "rig.json"
    rig_path.write_text(rec.rig.to_json())
    return rec, rig_path, _rmse(rec, truth_from_recording(rec))


def _rmse(rec, truth) -> dict:
    model = build_model(rec.rig, peripheral="gyro", modes=4, imus=4, tofs=4, gauges=4)
    result = estimate(measurements_from_recording(rec), model)
    scores = score_against_truth(result, truth, after=result.calibration.rest_end)
    assert scores["scored_samples"] > 5000  # the trip is scored on the motion, not on the rest
    return scores["rmse"]


@pytest.fixture(scope="module")
def import_of(simulated, tmp_path_factory):
    """The simulated recording exported to a format and imported back by ``shm import`` (each once)."""
    rec, rig_path, _ = simulated
    done: dict[str, Path] = {}

    def get(fmt: str) -> Path:
        if fmt not in done:
            folder = tmp_path_factory.mktemp(fmt)
            data, map_path = export(rec, fmt, folder)
            out = folder / "imported.mcap"
            code = main(["import", *map(str, data), "--rig", str(rig_path), "--map", str(map_path), "--out", str(out), "--json"])
            assert code == 0
            done[fmt] = out
        return done[fmt]

    return get


@pytest.fixture(params=FORMATS)
def imported(request, import_of):
    return request.param, import_of(request.param)


def test_round_trip_keeps_every_sample(simulated, imported):
    rec, _, _ = simulated
    fmt, out = imported
    back = read_recording(out)
    assert back.rig.model_dump() == rec.rig.model_dump()
    assert back.start_ns == rec.start_ns
    topics = sorted(t for t, c in rec.channels.items() if c.kind != "truth")
    assert sorted(back.channels) == topics
    for topic in topics:
        a, b = rec.channels[topic], back.channels[topic]
        np.testing.assert_array_equal(b.log_time_ns, a.log_time_ns, err_msg=f"{fmt} {topic}")
        np.testing.assert_array_equal(b.publish_time_ns, b.log_time_ns)
        if fmt == "text" and (topic.startswith("/strain/") or topic == "/env/temperature"):
            # written in µε and K, scaled back by the map: rounding of the last bit
            np.testing.assert_allclose(b.values, a.values, rtol=1e-13, atol=0, err_msg=f"{fmt} {topic}")
        else:
            np.testing.assert_array_equal(b.values, a.values, err_msg=f"{fmt} {topic}")
    summary = inspect_recording(out)
    assert summary["problems"] == []
    assert "import" in summary["metadata"]


def test_round_trip_gives_the_same_estimator_rmse(simulated, imported):
    rec, _, original = simulated
    fmt, out = imported
    again = _rmse(read_recording(out), truth_from_recording(rec))
    assert set(again) == set(original)
    for key, value in original.items():
        assert value is not None and abs(again[key] - value) <= 1e-9, (fmt, key, value, again[key])


# -- DROPBEAR --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def dropbear(tmp_path_factory):
    out = tmp_path_factory.mktemp("dropbear") / "dropbear.mcap"
    code = main(["import", str(DROPBEAR), "--rig", str(EXAMPLE / "rig.json"), "--map", str(EXAMPLE / "channels.toml"),
                 "--out", str(out)])
    assert code == 0
    return out


def test_dropbear_import_passes_inspect_without_problems(dropbear, capsys):
    summary = inspect_recording(dropbear)
    assert summary["problems"] == [] and not summary["truncated"]
    assert set(summary["topics"]) == {"/imu/low_g", "/imu/high_g", "/strain/SG_300_a", "/strain/SG_306_b"}
    for topic, info in summary["topics"].items():
        assert info["messages"] == info["accepted"] == 60000, topic
        assert info["rate_hz"] == pytest.approx(5000.0, rel=1e-9) and info["gaps"] == 0
        assert info["first_s"] == 0.0 and info["last_s"] == pytest.approx(11.9998, abs=1e-9)
    code, out, _ = run(capsys, "inspect", dropbear)
    assert code == 0 and "problems" not in out
    rec = read_recording(dropbear)
    table = read_table(DROPBEAR)
    # the values are the file's (volts; the high-g accelerometer turned by scale = -1), on sensor y
    np.testing.assert_array_equal(rec.channels["/imu/low_g"].values[:, 1], table.data[:, table.channels.index("Low G Accel")])
    np.testing.assert_array_equal(rec.channels["/imu/high_g"].values[:, 1], -table.data[:, table.channels.index("Accel")])
    np.testing.assert_array_equal(rec.channels["/strain/SG_306_b"].values[:, 0], table.data[:, table.channels.index("SG_306_b")])
    assert not np.any(rec.channels["/imu/low_g"].values[:, [0, 2, 3, 4, 5]])  # not measured: 0.0
    np.testing.assert_array_equal(np.diff(rec.channels["/imu/low_g"].log_time_ns), 200_000)
    sensors = {s.name: s for s in rec.rig.sensors}
    assert sensors["low_g"].model_extra["axes"] == ["accel_y"] and rec.rig.support == "clamped"
    assert json.loads(rec.metadata["import"]["files"]) == ["test0.txt"]


def test_shm_oma_finds_on_the_import_what_it_finds_on_the_file(dropbear, capsys):
    band = ["--fmin", "5", "--fmax", "200", "--json"]
    code, out, err = run(capsys, "oma", dropbear, *band)
    assert code == 0, err
    doc = json.loads(out)
    # the rig's axes: one accelerometer axis each, not the five zero-filled ones
    assert doc["channels"] == ["high_g.accel_y", "low_g.accel_y", "SG_300_a.strain", "SG_306_b.strain"]
    code, out, err = run(capsys, "oma", DROPBEAR, "--channels", "Accel,Low G Accel,SG_300_a,SG_306_b", *band)
    assert code == 0, err
    direct = json.loads(out)
    f = [m["frequency_hz"] for m in doc["modes"]]
    assert f and f == pytest.approx([m["frequency_hz"] for m in direct["modes"]], rel=1e-9)
    assert [m["damping_ratio"] for m in doc["modes"]] == pytest.approx([m["damping_ratio"] for m in direct["modes"]], rel=1e-6)
    # the beam's first bending mode with the roller somewhere between its ends (25-42 Hz)
    assert any(25.0 <= x <= 42.0 for x in f), f


# -- independent readers -----------------------------------------------------------------------
def _python_mcap(path: Path) -> dict:
    from mcap.decoder import DecoderFactory
    from mcap.reader import make_reader

    class JsonDecoders(DecoderFactory):
        def decoder_for(self, message_encoding, schema):
            return json.loads if message_encoding == "json" and schema is not None and schema.encoding == "jsonschema" else None

    topics: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[JsonDecoders()])
        summary = reader.get_summary()
        for schema, channel, message, payload in reader.iter_decoded_messages(log_time_order=False):
            topics.setdefault(channel.topic, []).append((message.log_time, schema.name, payload))
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    return {"summary": summary, "topics": topics, "attachments": attachments, "metadata": metadata}


def _row(payload: dict) -> list[float]:
    return [x for v in payload.values() for x in (v if isinstance(v, list) else [v])]


def test_the_python_mcap_library_reads_the_imports(dropbear, import_of):
    for path in (dropbear, import_of("text")):
        ours = read_recording(path)
        other = _python_mcap(path)
        assert other["summary"].statistics.message_count == sum(len(c) for c in ours.channels.values())
        assert json.loads(other["attachments"]["rig.json"]) == json.loads(json.dumps(ours.rig.model_dump(mode="json", exclude_unset=True)))
        assert "map" in other["metadata"]["import"]
        assert sorted(other["topics"]) == sorted(ours.channels)
        for topic, messages in other["topics"].items():
            channel = ours.channels[topic]
            np.testing.assert_array_equal([m[0] for m in messages], channel.log_time_ns)
            np.testing.assert_array_equal(np.array([_row(m[2]) for m in messages]), channel.values)


NPM_PACKAGES = Path(__file__).resolve().parent / "mcap_js"


@pytest.fixture(scope="session")
def node_reader() -> list[str]:
    """``node read_mcap.mjs`` with the npm @mcap packages of ``mcap_js/package-lock.json``, installed
    by ``npm ci`` into ``.venv/node-mcap`` (kept between runs, remade when the lock changes)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
        if shutil.which("apt-get") and hasattr(os, "geteuid") and os.geteuid() == 0:
            for cmd in (["apt-get", "update"], ["apt-get", "install", "-y", "--no-install-recommends", "nodejs", "npm"]):
                subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env)
        node, npm = shutil.which("node"), shutil.which("npm")
        if node is None or npm is None:
            pytest.skip("node and npm are not available (apt-get install nodejs npm); the python mcap reader test still runs")
    home = ROOT / ".venv" / "node-mcap"
    lock = (NPM_PACKAGES / "package-lock.json").read_bytes()
    if not (home / "node_modules").is_dir() or (home / "package-lock.json").read_bytes() != lock:
        shutil.rmtree(home, ignore_errors=True)
        home.mkdir(parents=True)
        for name in ("package.json", "package-lock.json"):
            shutil.copy(NPM_PACKAGES / name, home / name)
        result = subprocess.run([npm, "ci", "--ignore-scripts", "--no-audit", "--no-fund"], cwd=home,
                                capture_output=True, text=True, timeout=600)
        if result.returncode != 0:
            shutil.rmtree(home, ignore_errors=True)
            pytest.fail(f"npm ci of the @mcap packages failed: {result.stderr.strip()[-800:]}")
    shutil.copy(NPM_PACKAGES / "read_mcap.mjs", home / "read_mcap.mjs")
    return [node, str(home / "read_mcap.mjs")]


def test_the_npm_mcap_reader_reads_the_imports(node_reader, dropbear, import_of):
    for path in (dropbear, import_of("text")):
        result = subprocess.run([*node_reader, str(path)], capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr[-2000:]
        doc = json.loads(result.stdout)
        ours = read_recording(path)
        assert doc["header"]["library"] == "imms-shm"
        assert int(doc["statistics"]["message_count"]) == sum(len(c) for c in ours.channels.values())
        assert doc["stream"]["footer"] and doc["stream"]["topics"] == {t: len(c) for t, c in ours.channels.items()}
        assert [a["name"] for a in doc["attachments"]] == ["rig.json"]
        assert load_rig_text(doc["attachments"][0]["data"]) == ours.rig.model_dump()
        assert set(doc["metadata"]) == {"import"} and doc["metadata"]["import"]["tool"] == "shm import"
        assert sorted(doc["topics"]) == sorted(ours.channels)
        for topic, t in doc["topics"].items():
            channel = ours.channels[topic]
            assert t["schema_encoding"] == "jsonschema" and t["message_encoding"] == "json" and t["in_order"]
            assert t["count"] == len(channel)
            assert int(t["first_log_time"]) == channel.log_time_ns[0] and int(t["last_log_time"]) == channel.log_time_ns[-1]
            assert int(t["log_time_sum"]) == sum(int(x) for x in channel.log_time_ns)
            assert t["first"] == channel.values[0].tolist() and t["last"] == channel.values[-1].tolist()
            np.testing.assert_allclose(t["sums"], channel.values.sum(axis=0), rtol=1e-9, atol=1e-9 * np.abs(channel.values).sum(axis=0).max())


def load_rig_text(text: str) -> dict:
    from estimator import parse_rig

    return parse_rig(text).model_dump()


# -- clocks and the map ----------------------------------------------------------------------
RIG = {
    "beam": {"length": 1.0, "width": 0.05, "thickness": 0.005, "youngs_modulus": 2.0e11, "density": 7850.0},
    "gravity": 9.81, "reflector_distance": 0.5, "support": "clamped",
    "sensors": [
        {"name": "a1", "kind": "imu", "position": 0.8},
        {"name": "g1", "kind": "strain", "position": 0.1},
        {"name": "t", "kind": "temperature"},
    ],
}


def _files(tmp_path, columns: dict, doc: dict, *, rig=RIG):
    rig_path = tmp_path / "rig.json"
    rig_path.write_text(json.dumps(rig))
    map_path = tmp_path / "map.toml"
    map_path.write_text(tomli_w.dumps(doc))
    return rig_path, map_path


def _csv(path: Path, columns: dict) -> Path:
    names = list(columns)
    rows = [",".join(names)] + [",".join(repr(float(v)) for v in row) for row in np.column_stack([columns[n] for n in names])]
    path.write_text("\n".join(rows) + "\n")
    return path


def _simple_map(**clock) -> dict:
    return {
        "clocks": {"daq": clock or {"column": "time"}},
        "columns": {
            "ax": {"topic": "/imu/a1", "field": "accel", "index": 0, "scale": 9.80665, "offset": -9.80665},
            "gz": {"topic": "/imu/a1", "field": "gyro", "index": 2, "scale": np.pi / 180},
            "eps": {"topic": "/strain/g1", "field": "strain", "scale": 1e-6},
            "T": {"topic": "/env/temperature", "field": "celsius"},
        },
    }


def _data(n=400, fs=200.0, seed=3):
    rng = np.random.default_rng(seed)
    return {"time": np.arange(n) / fs, "ax": rng.normal(size=n), "gz": rng.normal(size=n), "eps": rng.normal(size=n) * 50,
            "T": 20 + rng.normal(size=n) * 0.1, "unused": np.zeros(n)}


def test_scale_offset_time_column_and_zero_filled_axes(tmp_path):
    d = _data()
    csv = _csv(tmp_path / "daq.csv", d)
    doc = _simple_map(column="time", start=datetime.fromisoformat("2026-01-01T01:00:00+01:00"))  # a TOML date-time
    rig_path, map_path = _files(tmp_path, d, doc)
    report = import_recording([csv], rig_path, map_path, tmp_path / "out.mcap")
    rec = read_recording(tmp_path / "out.mcap")
    t0 = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z
    imu = rec.channels["/imu/a1"]
    np.testing.assert_array_equal(imu.log_time_ns, t0 + np.arange(400) * 5_000_000)
    np.testing.assert_allclose(imu.values[:, 0], 9.80665 * d["ax"] - 9.80665, rtol=1e-15)
    np.testing.assert_allclose(imu.values[:, 5], np.radians(d["gz"]), rtol=1e-15)
    assert not np.any(imu.values[:, [1, 2, 3, 4]])
    np.testing.assert_allclose(rec.channels["/strain/g1"].values[:, 0], 1e-6 * d["eps"], rtol=1e-15)
    sensor = {s.name: s for s in rec.rig.sensors}["a1"]
    assert sensor.model_extra["axes"] == ["accel_x", "gyro_z"]
    assert report.topics["/imu/a1"].zero_filled == ["accel_y", "accel_z", "gyro_x", "gyro_y"]
    assert report.unused_columns == {str(csv): ["unused"]}
    assert report.clocks["daq"].rate_hz == pytest.approx(200.0, rel=1e-12)


def test_rate_clock_with_a_start_and_a_time_column_in_ms(tmp_path):
    d = _data(n=50)
    npy = tmp_path / "daq.npy"
    np.save(npy, np.column_stack([d["ax"], d["eps"]]))
    doc = {"clocks": {"daq": {"rate_hz": 1000.0, "start_ns": 123}},
           "columns": {"0": {"topic": "/imu/a1", "field": "accel", "index": 1}, "1": {"topic": "/strain/g1", "field": "strain", "scale": 1e-6}}}
    rig = {**RIG, "sensors": RIG["sensors"][:2]}
    rig_path, map_path = _files(tmp_path, d, doc, rig=rig)
    import_recording([npy], rig_path, map_path, tmp_path / "a.mcap")
    rec = read_recording(tmp_path / "a.mcap")
    np.testing.assert_array_equal(rec.channels["/strain/g1"].log_time_ns, 123 + np.arange(50) * 1_000_000)
    assert rec.report.problems == []
    # the same in a text file with the time in ms
    csv = _csv(tmp_path / "ms.csv", {"stamp": np.arange(50) * 2.5, "a": d["ax"], "e": d["eps"]})
    doc = {"clocks": {"daq": {"column": "stamp", "unit": "ms"}},
           "columns": {"a": {"topic": "/imu/a1", "field": "accel", "index": 1}, "e": {"topic": "/strain/g1", "field": "strain", "scale": 1e-6}}}
    rig_path, map_path = _files(tmp_path, d, doc, rig=rig)
    report = import_recording([csv], rig_path, map_path, tmp_path / "b.mcap")
    np.testing.assert_array_equal(read_recording(tmp_path / "b.mcap").channels["/imu/a1"].log_time_ns, np.arange(50) * 2_500_000)
    assert report.clocks["daq"].rate_hz == pytest.approx(400.0, rel=1e-12)


def test_nan_samples_are_counted_rejections_and_the_rest_is_kept(tmp_path, capsys):
    d = _data()
    d["eps"][[5, 300]] = np.nan
    d["gz"][7] = np.inf
    csv = _csv(tmp_path / "daq.csv", d)
    rig_path, map_path = _files(tmp_path, d, _simple_map())
    code, out, err = run(capsys, "import", csv, "--rig", rig_path, "--map", map_path, "--out", tmp_path / "o.mcap", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["rejected"] == 3
    assert doc["topics"]["/strain/g1"]["rejected"] == 2 and doc["topics"]["/strain/g1"]["first_rejected_row"] == 5
    assert doc["topics"]["/imu/a1"]["rejected"] == 1 and doc["topics"]["/imu/a1"]["first_rejected_column"] == "gz"
    assert doc["topics"]["/env/temperature"]["rejected"] == 0
    rec = read_recording(tmp_path / "o.mcap")
    assert len(rec.channels["/strain/g1"]) == 398 and len(rec.channels["/imu/a1"]) == 399
    kept = np.delete(np.arange(400), [5, 300])
    np.testing.assert_array_equal(rec.channels["/strain/g1"].log_time_ns, kept * 5_000_000)
    assert sum(r.rejected for r in rec.report.topics.values()) == 0  # nothing malformed was written
    assert json.loads(rec.metadata["import"]["rejected_nonfinite"]) == {"/env/temperature": 0, "/imu/a1": 1, "/strain/g1": 2}
    code, out, _ = run(capsys, "import", csv, "--rig", rig_path, "--map", map_path, "--out", tmp_path / "p.mcap")
    assert code == 0 and "2 rejected (first: row 5 of 'eps')" in out


def test_several_files_and_clocks(tmp_path):
    d = _data()
    fast = _csv(tmp_path / "fast.csv", {"time": d["time"], "ax": d["ax"], "eps": d["eps"]})
    slow = _csv(tmp_path / "slow.csv", {"time": d["time"][::200], "T": d["T"][::200]})
    doc = {"clocks": {"fast": {"file": "fast.csv", "column": "time"}, "slow": {"file": str(slow), "column": "time"}},
           "columns": {"ax": {"topic": "/imu/a1", "field": "accel", "index": 0, "clock": "fast"},
                       "eps": {"topic": "/strain/g1", "field": "strain", "clock": "fast"},
                       "T": {"topic": "/env/temperature", "field": "celsius", "clock": "slow"}}}
    rig_path, map_path = _files(tmp_path, d, doc)
    report = import_recording([fast, slow], rig_path, map_path, tmp_path / "o.mcap")
    rec = read_recording(tmp_path / "o.mcap")
    np.testing.assert_array_equal(rec.channels["/env/temperature"].log_time_ns, [0, 1_000_000_000])
    assert report.clocks["slow"].samples == 2 and report.sensors_without_data == []


# -- bad input -------------------------------------------------------------------------------
def _refused(tmp_path, doc, d=None, *, rig=RIG, match, error=MapError, data=None):
    d = _data() if d is None else d
    csv = data or _csv(tmp_path / "daq.csv", d)
    rig_path, map_path = _files(tmp_path, d, doc, rig=rig)
    out = tmp_path / "bad.mcap"
    with pytest.raises(error) as info:
        import_recording([csv] if not isinstance(csv, list) else csv, rig_path, map_path, out)
    assert not out.exists() and not (tmp_path / "bad.mcap.part").exists()
    for text in ([match] if isinstance(match, str) else match):
        assert text in str(info.value), str(info.value)
    return str(info.value)


def test_unknown_column_names_the_map_key(tmp_path):
    doc = _simple_map()
    doc["columns"]["Lo G"] = {"topic": "/imu/a1", "field": "accel", "index": 1}
    _refused(tmp_path, doc, match=['columns."Lo G"', "unknown channel 'Lo G'", "'ax'"])


def test_topic_not_in_the_rig_names_column_and_topic(tmp_path):
    doc = _simple_map()
    doc["columns"]["eps"]["topic"] = "/strain/g9"
    _refused(tmp_path, doc, match=["columns.eps", "'/strain/g9'", "is not declared by the rig", "/strain/g1"])
    doc["columns"]["eps"]["topic"] = "/truth/state"
    _refused(tmp_path, doc, match=["columns.eps", "not a sensor topic"])
    doc["columns"]["eps"]["topic"] = "/weather/wind"
    _refused(tmp_path, doc, match=["columns.eps", "'/weather/wind'"])


@pytest.mark.parametrize("change, match", [
    ({"field": "stress"}, ["columns.eps", "field 'stress'", "['strain']"]),
    ({"index": 0}, ["columns.eps", "is a number: it takes no index"]),
    ({"scale": 0.0}, ["columns.eps.scale", "scale=0"]),
    ({"scal": 2.0}, ["columns.eps.scal", "Extra inputs are not permitted"]),
    ({"clock": "nope"}, ["columns.eps", "clock='nope'"]),
])
def test_bad_column_entries(tmp_path, change, match):
    doc = _simple_map()
    doc["columns"]["eps"].update(change)
    _refused(tmp_path, doc, match=match)


def test_vector_fields_need_an_index_and_each_value_one_column(tmp_path):
    doc = _simple_map()
    del doc["columns"]["ax"]["index"]
    _refused(tmp_path, doc, match=["columns.ax", "vector of 3", "index = 0..2"])
    doc = _simple_map()
    doc["columns"]["ax"]["index"] = 3
    _refused(tmp_path, doc, match=["columns.ax", "index=3"])
    doc = _simple_map()
    doc["columns"]["gz"].update(field="accel", index=0)
    _refused(tmp_path, doc, match=["columns.gz", "accel_x is already filled by column 'ax'"])


def test_rig_axes_must_be_what_the_map_fills(tmp_path):
    rig = json.loads(json.dumps(RIG))
    rig["sensors"][0]["axes"] = ["accel_x"]
    _refused(tmp_path, _simple_map(), rig=rig, match=["/imu/a1", "['accel_x']", "['gyro_z'] not in rig.json"])
    rig["sensors"][0]["axes"] = ["accel_x", "gyro_z", "accel_q"]
    _refused(tmp_path, _simple_map(), rig=rig, match=["imu 'a1'", "axes="])


@pytest.mark.parametrize("clock, match", [
    ({"column": "time", "rate_hz": 200.0}, ["clocks.daq", "exactly one"]),
    ({}, ["clocks.daq", "exactly one"]),
    ({"rate_hz": 200.0, "unit": "ms"}, ["clocks.daq", "unit='ms'"]),
    ({"column": "time", "unit": "min"}, ["clocks.daq.unit"]),
    ({"rate_hz": -5.0}, ["clocks.daq.rate_hz"]),
    ({"column": "time", "start_ns": 5, "start": "x"}, ["clocks.daq.start"]),
    ({"column": "time", "start": datetime(2026, 1, 1)}, ["clocks.daq.start", "timezone"]),
    ({"column": "when"}, ["clocks.daq", "column='when'", "no time column 'when'"]),
    ({"rate_hz": 100.0}, ["clocks.daq", "the given sample rate 100.0 Hz", "200 Hz"]),
    ({"column": "time", "file": "other.csv"}, ["clocks.daq", "file='other.csv'"]),
])
def test_bad_clocks(tmp_path, clock, match):
    doc = _simple_map()
    doc["clocks"]["daq"] = clock
    _refused(tmp_path, doc, match=match, error=(MapError, TableError))


def test_a_non_uniform_time_column_names_the_column_and_sample(tmp_path):
    d = _data()
    d["time"][200:] += 0.5  # a jump: half a second of samples missing
    _refused(tmp_path, _simple_map(), d, match=["time column 'time' is not a uniform clock", "sample 199 to 200"], error=TableError)


def test_a_repeated_or_backwards_stamp_costs_its_row_only(tmp_path):
    d = _data()
    d["time"][10] = d["time"][9]  # a repeated stamp
    d["time"][20] = d["time"][5]  # one stamp backwards
    csv = _csv(tmp_path / "daq.csv", d)
    rig_path, map_path = _files(tmp_path, d, _simple_map())
    report = import_recording([csv], rig_path, map_path, tmp_path / "o.mcap")
    assert report.topics["/strain/g1"].rejected == 2 and report.topics["/strain/g1"].reasons == {"time": 2}
    kept = np.delete(np.arange(400), [10, 20])
    rec = read_recording(tmp_path / "o.mcap")
    np.testing.assert_array_equal(rec.channels["/strain/g1"].log_time_ns, kept * 5_000_000)
    np.testing.assert_array_equal(rec.channels["/strain/g1"].values[:, 0], 1e-6 * d["eps"][kept])


def test_mismatched_lengths_are_refused(tmp_path):
    d = _data()
    npz = tmp_path / "daq.npz"
    np.savez(npz, time=d["time"], ax=d["ax"], gz=d["gz"][:-1], eps=d["eps"], T=d["T"])
    _refused(tmp_path, _simple_map(), data=npz, match=["differ in length", "'gz': 399", "'ax': 400"], error=TableError)
    np.savez(npz, time=d["time"][:-3], ax=d["ax"], gz=d["gz"], eps=d["eps"], T=d["T"])
    _refused(tmp_path, _simple_map(), data=npz, match=["the time array 'time' has 397 samples, the channels 400"], error=TableError)


def test_a_topic_on_two_clocks_and_unused_files_are_refused(tmp_path):
    doc = _simple_map()
    doc["clocks"]["other"] = {"column": "time"}
    doc["columns"] = {k: {**v, "clock": "daq"} for k, v in doc["columns"].items()}
    doc["columns"]["gz"]["clock"] = "other"
    _refused(tmp_path, doc, match=["columns.gz", "/imu/a1 takes column 'ax' on clock 'daq'", "share a clock"])
    doc = _simple_map()
    extra = _csv(tmp_path / "extra.csv", {"time": np.arange(3.0), "x": np.zeros(3)})
    d = _data()
    _refused(tmp_path, doc, data=[_csv(tmp_path / "daq.csv", d), extra], match=["clocks.daq", "give file = one of"])
    doc["clocks"]["daq"]["file"] = "daq.csv"
    _refused(tmp_path, doc, data=[tmp_path / "daq.csv", extra], match=["no clock reads", "extra.csv"])


def test_the_cli_reports_errors_in_one_line_and_exits_2(tmp_path, capsys):
    d = _data()
    csv = _csv(tmp_path / "daq.csv", d)
    doc = _simple_map()
    doc["columns"]["eps"]["topic"] = "/strain/nope"
    rig_path, map_path = _files(tmp_path, d, doc)
    code, out, err = run(capsys, "import", csv, "--rig", rig_path, "--map", map_path, "--out", tmp_path / "x.mcap")
    assert code == 2 and err.startswith("shm import: error: ") and "/strain/nope" in err and err.count("\n") == 1
    map_path.write_text("[clocks.daq\n")
    code, _, err = run(capsys, "import", csv, "--rig", rig_path, "--map", map_path, "--out", tmp_path / "x.mcap")
    assert code == 2 and "not valid TOML" in err
    code, _, err = run(capsys, "import", tmp_path / "none.csv", "--rig", rig_path, "--map", map_path, "--out", tmp_path / "x.mcap")
    assert code == 2 and "no such file" in err
    map_path.write_text(tomli_w.dumps(_simple_map()))
    code, _, err = run(capsys, "import", csv, "--rig", tmp_path / "none.json", "--map", map_path, "--out", tmp_path / "x.mcap")
    assert code == 2 and "none.json" in err
    assert not (tmp_path / "x.mcap").exists()


def test_parse_channel_map_names_missing_keys():
    with pytest.raises(MapError, match=r"columns\.a\.topic: Field required"):
        parse_channel_map({"clocks": {"c": {"rate_hz": 1.0}}, "columns": {"a": {"field": "strain"}}})
    with pytest.raises(MapError, match=r"clocks: .*at least 1"):
        parse_channel_map({"clocks": {}, "columns": {"a": {"topic": "/strain/g", "field": "strain"}}})
    with pytest.raises(MapError, match=r"columns.a: give clock = one of \['c', 'd'\]"):
        parse_channel_map({"clocks": {"c": {"rate_hz": 1.0}, "d": {"rate_hz": 2.0}},
                           "columns": {"a": {"topic": "/strain/g", "field": "strain"}}})


def test_example_files_are_valid():
    rig = load_rig(EXAMPLE / "rig.json")
    assert rig.support == "clamped" and rig.beam.length == 0.35
    assert sorted((s.kind, s.name) for s in rig.sensors) == [("imu", "high_g"), ("imu", "low_g"),
                                                            ("strain", "SG_300_a"), ("strain", "SG_306_b")]


def test_matlab_structs_groups_and_text_variables(tmp_path):
    from scipy import io

    d = _data(n=100)
    io.savemat(tmp_path / "v5.mat", {"daq": {"time": d["time"], "eps": d["eps"]}, "note": "volts", "other": np.ones(7)})
    table = read_table(tmp_path / "v5.mat", channels=["eps"], time_column="time")
    assert table.channels == ("eps",) and table.fs_hz == pytest.approx(200.0) and table.other_channels == ("other",)
    np.testing.assert_array_equal(table.data[:, 0], d["eps"])
    import hdf5storage

    hdf5storage.savemat(str(tmp_path / "v73.mat"), {"time": d["time"], "eps": d["eps"], "note": "volts"}, format="7.3",
                        matlab_compatible=True)
    table = read_table(tmp_path / "v73.mat")  # the text variable is not a channel
    assert table.format == "mat" and table.channels == ("eps",)
    np.testing.assert_array_equal(table.time, d["time"])


def test_a_nan_in_the_time_column_costs_its_row_only(tmp_path):
    d = _data()
    d["time"][42] = np.nan
    csv = _csv(tmp_path / "daq.csv", d)
    rig_path, map_path = _files(tmp_path, d, _simple_map())
    report = import_recording([csv], rig_path, map_path, tmp_path / "o.mcap")
    assert all(t.rejected == 1 and t.reasons == {"time": 1} and t.first_rejected_row == 42 for t in report.topics.values())
    assert report.topics["/imu/a1"].by_column["ax"]["first"] == [{"sample": 42, "reason": "time", "line": 44}]
