"""``shm oma`` on every file format ``shm_service.formats.tables`` reads, and its errors."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy import io

from shm_service.cli import main
from shm_service.recording import RecordingWriter
from shm_service.formats.tables import TableError, read_table, select_channels

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "analytics"))
from oma_systems import ambient_response, three_dof  # noqa: E402

FS = 50.0
SYSTEM = three_dof()
BAND = ["--fmin", "1", "--fmax", "15"]


@pytest.fixture(scope="module")
def response() -> np.ndarray:
    return ambient_response(SYSTEM, FS, 9000, seed=11, noise_rel=0.05)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def check_modes(doc: dict, channels: list[str]) -> None:
    assert set(doc) >= {"fs_hz", "channels", "modes", "windows"}
    assert doc["channels"] == channels
    f = np.array([m["frequency_hz"] for m in doc["modes"]])
    assert f.size == 3, f
    np.testing.assert_allclose(f, SYSTEM.frequencies_hz, rtol=0.01)
    for m in doc["modes"]:
        assert set(m) >= {"frequency_hz", "damping_ratio", "frequency_std_hz", "damping_std", "mpc", "shape"}
        assert len(m["shape"]) == len(channels) and m["frequency_std_hz"] > 0


def write_text(path: Path, y: np.ndarray, sep: str, *, time: bool, names=("a", "b", "c")) -> None:
    cols = ([np.arange(y.shape[0]) / FS] if time else []) + [y[:, j] for j in range(y.shape[1])]
    header = (["Time"] if time else []) + list(names)
    rows = [sep.join(header)] + [sep.join(f"{v:.9e}" for v in row) for row in np.column_stack(cols)]
    path.write_text("\n".join(rows) + "\n")


def test_npy_needs_fs_and_names_columns_by_index(tmp_path, capsys, response):
    p = tmp_path / "y.npy"
    np.save(p, response)
    code, out, _ = run(capsys, "oma", p, "--fs", FS, *BAND, "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["fs_hz"] == FS
    check_modes(doc, ["0", "1", "2"])
    code, out, _ = run(capsys, "oma", p, "--fs", FS, "--channels", "2,0", *BAND, "--json")
    assert json.loads(out)["channels"] == ["2", "0"]


@pytest.mark.parametrize("suffix, sep, time", [(".csv", ",", True), (".tsv", "\t", False), (".txt", " ", True)])
def test_text_files_with_a_header(tmp_path, capsys, response, suffix, sep, time):
    p = tmp_path / f"y{suffix}"
    write_text(p, response, sep, time=time)
    extra = [] if time else ["--fs", FS]
    code, out, err = run(capsys, "oma", p, *extra, *BAND, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["fs_hz"] == pytest.approx(FS, rel=1e-9)
    check_modes(doc, ["a", "b", "c"])


def test_labview_export_with_preamble_units_and_padding(tmp_path, capsys, response):
    p = tmp_path / "labview.txt"
    lines = ["C:\\rig\\trial data\\test0.txt", "Programmer - None", "Striker Velocity - 0.0", "Sampling Frequency - 50", "Mon, Jun 6, 2022",
             "a\tb\tc\tTime", "Voltage (unscaled)\tVoltage (unscaled)\tVoltage (unscaled)\tSec", "0.0 0.0 0\t\t\t", ""]
    t = np.arange(response.shape[0]) / FS
    lines += ["\t".join(f"{v:.5E}" for v in row) for row in np.column_stack([response, t])]
    p.write_text("\n".join(lines) + "\n")
    table = read_table(p)
    assert table.format == "labview" and table.units == ("Voltage (unscaled)",) * 3
    code, out, err = run(capsys, "oma", p, *BAND, "--json")
    assert code == 0, err
    check_modes(json.loads(out), ["a", "b", "c"])


def test_the_real_dropbear_export_reads():
    p = Path(__file__).resolve().parents[1] / "data" / "dropbear" / "random-dwell" / "test0.txt"
    table = read_table(p)
    assert table.channels == ("Low G Accel", "SG_300_a", "SG_306_b", "Accel", "PinLoc")
    assert table.fs_hz == pytest.approx(5000.0, rel=1e-9) and table.data.shape == (60000, 5)
    assert table.format == "labview"


def test_npz_mat_and_hdf5(tmp_path, capsys, response):
    np.savez(tmp_path / "y.npz", a=response[:, 0], b=response[:, 1], c=response[:, 2], fs=FS)
    io.savemat(tmp_path / "y.mat", {"a": response[:, 0], "b": response[:, 1], "c": response[:, 2], "time": np.arange(response.shape[0]) / FS})
    with h5py.File(tmp_path / "y.h5", "w") as h:
        h["data"] = response
        h.attrs["fs"] = FS
    for name, channels in (("y.npz", ["a", "b", "c"]), ("y.mat", ["a", "b", "c"]), ("y.h5", ["0", "1", "2"])):
        code, out, err = run(capsys, "oma", tmp_path / name, *BAND, "--json")
        assert code == 0, (name, err)
        check_modes(json.loads(out), channels)


RIG = {
    "beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, "youngs_modulus": 2.1e11, "density": 7850.0},
    "gravity": 9.81, "reflector_distance": 0.5,
    "sensors": [{"name": "D", "kind": "imu", "position": 0.0}, {"name": "s1", "kind": "imu", "position": 2.0},
                {"name": "g1", "kind": "strain", "position": 0.9}],
}


def test_contract_recording(tmp_path, capsys):
    fs = 200.0
    y = ambient_response(SYSTEM, fs, int(180 * fs), seed=12, noise_rel=0.05)
    path = tmp_path / "rec.mcap"
    t0 = 1_700_000_000_000_000_000
    with RecordingWriter(path, RIG) as w:
        for k in range(y.shape[0]):
            t = t0 + k * 5_000_000
            w.write("/imu/D", t, {"accel": [-9.81, float(y[k, 1]), 0.0], "gyro": [0.0, 0.0, 0.0]})
            w.write("/imu/s1", t, {"accel": [-9.81, float(y[k, 0]), 0.0], "gyro": [0.0, 0.0, 0.0]})
            w.write("/strain/g1", t, {"strain": float(y[k, 2]) * 1e-6})
    table = read_table(path)
    assert "s1.accel_y" in table.channels and "g1.strain" in table.channels and table.fs_hz == pytest.approx(fs)
    code, out, err = run(capsys, "oma", path, "--channels", "s1.accel_y,D.accel_y,g1.strain", *BAND, "--json")
    assert code == 0, err
    check_modes(json.loads(out), ["s1.accel_y", "D.accel_y", "g1.strain"])


def test_windows_are_listed_with_times_from_the_first_sample(tmp_path, capsys, response):
    p = tmp_path / "y.npy"
    np.save(p, response)
    code, out, _ = run(capsys, "oma", p, "--fs", FS, *BAND, "--window", 60, "--step", 30, "--json")
    doc = json.loads(out)
    assert code == 0
    np.testing.assert_allclose([(w["start_s"], w["end_s"]) for w in doc["windows"]], [(30.0 * k, 30.0 * k + 60) for k in range(5)], atol=0.1)
    first = set()
    for w in doc["windows"]:
        f = [m["frequency_hz"] for m in w["modes"]]
        assert any(abs(x / SYSTEM.frequencies_hz[0] - 1) < 0.02 for x in f), f
        first |= {m["track"] for m in w["modes"] if abs(m["frequency_hz"] / SYSTEM.frequencies_hz[0] - 1) < 0.02}
        assert all(set(r) == {"frequency_hz", "reason"} for r in w["rejected"])
    # the first mode is one track through the record, and the document lists it with its range
    assert len(first) == 1
    (track,) = [t for t in doc["tracks"] if t["track"] in first]
    assert track["windows"] == 5 and track["min_hz"] <= SYSTEM.frequencies_hz[0] * 1.02 and track["max_hz"] >= SYSTEM.frequencies_hz[0] * 0.98
    code, out, _ = run(capsys, "oma", p, "--fs", FS, *BAND)
    assert code == 0 and "f [Hz]" in out


def test_measured_input_channel(tmp_path, capsys):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "analytics"))
    from test_frf import base_excited

    ag, acc, _ = base_excited(seconds=600.0)
    p = tmp_path / "io.npz"
    np.savez(p, support=ag, mass=acc, fs=100.0)
    code, out, err = run(capsys, "oma", p, "--inputs", "support", "--fmin", "1", "--fmax", "8", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["channels"] == ["mass"]
    assert doc["excitation"]["kind"] == "broadband"
    assert [round(m["frequency_hz"], 1) for m in doc["frf_modes"]] == [3.0]
    assert [round(m["frequency_hz"], 1) for m in doc["modes"]] == [3.0]


def test_bad_input_is_refused_with_a_message_naming_the_value(tmp_path, capsys, response):
    one = tmp_path / "one.npy"
    np.save(one, response[:, 0])
    code, _, err = run(capsys, "oma", one)
    assert code == 2 and "--fs" in err and "1-D" in err
    nohead = tmp_path / "nohead.csv"
    nohead.write_text("\n".join(",".join(f"{v:.4f}" for v in row) for row in response[:100]) + "\n")
    code, _, err = run(capsys, "oma", nohead, "--fs", FS)
    assert code == 2 and "no header row names the 3 columns" in err
    blank = tmp_path / "blank.csv"
    blank.write_text("a,,c\n" + "\n".join(",".join(f"{v:.4f}" for v in row) for row in response[:100]) + "\n")
    code, _, err = run(capsys, "oma", blank, "--fs", FS)
    assert code == 2 and "without a name" in err
    short = tmp_path / "y.npy"
    np.save(short, response)
    code, _, err = run(capsys, "oma", short, "--fs", FS, *BAND, "--window", 1000)
    assert code == 2 and "shorter than one window" in err and "window_s=1000.0" in err
    bad = response.copy()
    bad[123, 1] = np.nan
    nan = tmp_path / "nan.csv"
    write_text(nan, bad, ",", time=True)
    code, out, err = run(capsys, "oma", nan, *BAND)  # a NaN costs one sample, counted and filled
    assert code == 0 and "b: 1 rejected (1 nonfinite); first: line 125 (nonfinite)" in out, err
    code, _, err = run(capsys, "oma", short, "--fs", FS, "--channels", "0,zz")
    assert code == 2 and "unknown channel 'zz'" in err
    code, _, err = run(capsys, "oma", tmp_path / "missing.csv")
    assert code == 2 and "no such file" in err
    code, _, err = run(capsys, "oma", short, "--fs", FS, "--fmin", "20", "--fmax", "10")
    assert code == 2 and "fmax_hz" in err
    with pytest.raises(TableError, match="unknown format"):
        read_table(tmp_path / "x.xyz") if (tmp_path / "x.xyz").write_text("1") else None
    with pytest.raises(TableError, match="unknown channel"):
        select_channels(read_table(short, fs=FS), ["nope"])
