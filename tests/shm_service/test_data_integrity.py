"""A bad value costs its channel that sample and nothing else, and is counted.

The faults are written into real files (text, .npz) and go through the real commands
(``shm import``, ``shm oma``); the kept samples are compared with the clean file sample by sample.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from shm_service.cli import main
from shm_service.formats.daq_faults import CELL_FAULTS, modal_response, write_faulted_csv
from shm_service.formats.daq_import import import_recording
from shm_service.recording import read_recording
from shm_service.formats.oma_input import clean_for_identification
from shm_service.formats.rejections import Rejections, fill_short_gaps, longest_clean_span, outliers
from shm_service.formats.tables import TableError, read_table

FS = 200.0
N_CH = 8

RIG = {
    "beam": {"length": 1.0, "width": 0.05, "thickness": 0.005, "youngs_modulus": 2.0e11, "density": 7850.0},
    "gravity": 9.81, "reflector_distance": 0.5, "support": "clamped",
    "sensors": [{"name": f"s{i}", "kind": "imu", "position": 0.1 * (i + 1)} for i in range(N_CH)],
}


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _write_csv(path: Path, columns: dict[str, np.ndarray], cells: dict[tuple[int, str], str] | None = None) -> Path:
    """A CSV of ``columns`` (values by repr) with some cells replaced by text (``cells``)."""
    names = list(columns)
    rows = [",".join(names)]
    cells = cells or {}
    for i in range(len(columns[names[0]])):
        rows.append(",".join(cells.get((i, n), repr(float(columns[n][i]))) for n in names))
    path.write_text("\n".join(rows) + "\n")
    return path


def _channels(n: int, seed: int = 1) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"time": np.arange(n) / FS, **{f"a{i}": rng.normal(size=n) for i in range(N_CH)}}


def _import_files(tmp_path: Path) -> tuple[Path, Path]:
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps(RIG))
    doc = {"clocks": {"daq": {"column": "time"}},
           "columns": {f"a{i}": {"topic": f"/imu/s{i}", "field": "accel", "index": 1} for i in range(N_CH)}}
    channel_map = tmp_path / "map.toml"
    channel_map.write_text(tomli_w.dumps(doc))
    return rig, channel_map


# -- the acceptance cases ----------------------------------------------------------------------
def test_one_blank_cell_costs_one_sample_of_one_channel(tmp_path, capsys):
    d = _channels(4000)
    csv = _write_csv(tmp_path / "blank.csv", d, {(3000, "a2"): ""})  # 15.000 s
    rig, channel_map = _import_files(tmp_path)
    code, out, err = run(capsys, "import", csv, "--rig", rig, "--map", channel_map, "--out", tmp_path / "o.mcap", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["rejected"] == 1 and doc["rejected_by_reason"] == {"blank": 1}
    entry = doc["topics"]["/imu/s2"]
    assert entry["messages"] == 3999 and entry["first_rejected_row"] == 3000
    assert entry["by_column"]["a2"]["first"] == [{"sample": 3000, "reason": "blank", "line": 3002}]
    rec = read_recording(tmp_path / "o.mcap")
    for i in range(N_CH):
        channel = rec.channels[f"/imu/s{i}"]
        kept = np.arange(4000) if i != 2 else np.delete(np.arange(4000), 3000)
        assert len(channel) == len(kept)
        np.testing.assert_array_equal(channel.values[:, 1], d[f"a{i}"][kept])
        np.testing.assert_array_equal(channel.log_time_ns, kept * 5_000_000)
    code, out, _ = run(capsys, "import", csv, "--rig", rig, "--map", channel_map, "--out", tmp_path / "p.mcap")
    assert "1 samples rejected (1 blank)" in out and "a2: 1 rejected (1 blank); first: line 3002 (blank)" in out


def test_every_kind_of_bad_cell_is_rejected_in_its_column_only(tmp_path):
    d = _channels(300)
    cells = {(10, "a0"): "", (20, "a1"): "ERR", (30, "a2"): "nan", (40, "a3"): "-inf", (50, "a4"): "1e30",
             (60, "time"): "", (70, "time"): repr(69 / FS)}  # a blank and a repeated time: the rows go
    csv = _write_csv(tmp_path / "bad.csv", d, cells)
    csv.write_text(csv.read_text() + "1.5,0.25,0.5")  # a last row cut short
    table = read_table(csv, nonfinite="keep")
    r = table.rejections.as_dict()
    assert r["channels"]["a0"]["reasons"] == {"blank": 1, "time": 2}
    assert r["channels"]["a1"]["reasons"] == {"unparsable": 1, "time": 2}
    assert r["channels"]["a2"]["reasons"] == {"nonfinite": 1, "time": 2, "truncated": 1}
    assert r["channels"]["a3"]["reasons"] == {"nonfinite": 1, "time": 2, "truncated": 1}
    # 1e30 is a number: the table keeps it, the limits of a sensor kind (import) or the outlier test (oma) judge it
    assert r["channels"]["a4"]["reasons"] == {"time": 2, "truncated": 1}
    assert table.data.shape == (301, N_CH)
    clean = np.column_stack([d[f"a{i}"] for i in range(N_CH)])
    clean[50, 4] = 1e30
    valid = np.isfinite(table.data[:300])
    np.testing.assert_array_equal(table.data[:300][valid], clean[valid])
    assert valid.sum() == 300 * N_CH - 4 - 2 * N_CH
    np.testing.assert_array_equal(table.data[300, :2], [0.25, 0.5])


def test_implausible_values_are_rejected_by_the_kind_limits_named_in_the_message(tmp_path, capsys):
    d = _channels(400)
    csv = _write_csv(tmp_path / "spike.csv", d, {(100, "a5"): "1e30", (200, "a6"): "2500"})
    rig, channel_map = _import_files(tmp_path)
    code, out, err = run(capsys, "import", csv, "--rig", rig, "--map", channel_map, "--out", tmp_path / "o.mcap")
    assert code == 0, err
    assert "a5: 1 rejected (1 implausible (|accel_y| <= 2000 m/s² (limits.accel_m_s2)))" in out
    rec = read_recording(tmp_path / "o.mcap")
    assert len(rec.channels["/imu/s5"]) == 399 and len(rec.channels["/imu/s6"]) == 399
    assert len(rec.channels["/imu/s0"]) == 400
    # the limits are the map's to set
    doc = {"clocks": {"daq": {"column": "time"}}, "limits": {"accel_m_s2": 3000.0},
           "columns": {f"a{i}": {"topic": f"/imu/s{i}", "field": "accel", "index": 1} for i in range(N_CH)}}
    channel_map.write_text(tomli_w.dumps(doc))
    report = import_recording([csv], rig, channel_map, tmp_path / "q.mcap")
    assert report.topics["/imu/s6"].rejected == 0 and report.topics["/imu/s5"].rejected == 1


def _modal_response(n: int) -> np.ndarray:
    return modal_response(n, FS, N_CH)


def _mac(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    return float(abs(a @ b) ** 2 / ((a @ a) * (b @ b)))


@pytest.fixture(scope="module")
def modal_files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("oma")
    y = _modal_response(int(120 * FS))
    columns = {"time": np.arange(len(y)) / FS, **{f"a{i}": y[:, i] for i in range(N_CH)}}
    clean = _write_csv(tmp / "clean.csv", columns)
    spike = _write_csv(tmp / "spike.csv", columns, {(9000, "a3"): "1e30"})
    blank = _write_csv(tmp / "blank.csv", columns, {(12000, "a5"): ""})
    return clean, spike, blank


def _oma(capsys, path) -> dict:
    code, out, err = run(capsys, "oma", path, "--fmax", 15, "--json")
    assert code == 0, err
    return json.loads(out)


def test_oma_with_one_absurd_value_finds_the_clean_modes_and_shapes(modal_files, capsys):
    clean, spike, blank = modal_files
    reference = _oma(capsys, clean)
    assert reference["rejected_samples"]["total"] == 0
    for path, reason, channel in ((spike, "implausible", "a3"), (blank, "blank", "a5")):
        doc = _oma(capsys, path)
        assert doc["rejected_samples"]["channels"][channel]["reasons"] == {reason: 1}
        assert doc["interpolated"] == {channel: 1}
        assert len(doc["modes"]) == len(reference["modes"])
        for m, r in zip(doc["modes"], reference["modes"]):
            assert m["frequency_hz"] == pytest.approx(r["frequency_hz"], rel=2e-3)
            assert _mac(m["shape"], r["shape"]) >= 0.99
            assert m["damping_ratio"] == pytest.approx(r["damping_ratio"], rel=0.1)


def test_oma_reports_what_it_rejected(modal_files, capsys):
    _, spike, _ = modal_files
    code, out, err = run(capsys, "oma", spike, "--fmax", 15)
    assert code == 0, err
    assert "1 sample(s) rejected" in out and "a3: 1 rejected (1 implausible" in out
    assert "1 filled by linear interpolation" in out


# -- the helpers ---------------------------------------------------------------------------------
def test_fill_short_gaps_fills_runs_up_to_the_limit_only():
    y = np.array([[0.0, 0.0], [np.nan, 1.0], [2.0, np.nan], [3.0, np.nan], [4.0, 4.0], [np.nan, 5.0]])
    filled, count = fill_short_gaps(y, 1)
    np.testing.assert_array_equal(filled[:, 0], [0, 1, 2, 3, 4, np.nan])  # the end stays NaN
    assert np.isnan(filled[2:4, 1]).all() and count.tolist() == [1, 0]
    filled, count = fill_short_gaps(y, 2)
    np.testing.assert_allclose(filled[:, 1], [0, 1, 2, 3, 4, 5])
    assert longest_clean_span(y) == (0, 1) and longest_clean_span(filled) == (0, 5)
    with pytest.raises(ValueError, match="max_run=-1"):
        fill_short_gaps(y, -1)


def test_outliers_and_rejections_bad_input():
    x = np.sin(np.arange(1000) / 7.0)
    x[500] = 1e30
    assert np.flatnonzero(outliers(x, 1000.0)).tolist() == [500]
    assert not outliers(np.zeros(10), 1000.0).any()
    with pytest.raises(ValueError, match="factor=0"):
        outliers(x, 0)
    with pytest.raises(ValueError, match="reason='odd'"):
        Rejections().add("a", "odd", [1])


def test_decimal_commas_and_a_units_row_are_read(tmp_path):
    d = _channels(50)
    text = ["time;a0;a1", "s;m/s^2;m/s^2"] + [f"{float(d['time'][i])!r};{float(d['a0'][i])!r};{float(d['a1'][i])!r}".replace(".", ",")
                                               for i in range(50)]
    (tmp_path / "dc.csv").write_text("\n".join(text) + "\n")
    table = read_table(tmp_path / "dc.csv")
    np.testing.assert_array_equal(table.data[:, 0], d["a0"])
    assert table.units == ("m/s^2", "m/s^2") and table.problems == ("decimal commas read as decimal points",)


def test_a_one_row_file_says_so(tmp_path):
    (tmp_path / "one.csv").write_text("time,a\n0.0,1.0\n")
    with pytest.raises(TableError, match="1 data row"):
        read_table(tmp_path / "one.csv")


def test_an_off_grid_stamp_between_valid_rows_costs_its_row_only(tmp_path):
    d = _channels(400)
    d["time"][150] += 0.4 / FS  # off the clock, which comes back at the next row
    d["time"][300] = d["time"][299]  # a backwards stamp followed by a row carrying its true stamp:
    d["time"][299] = d["time"][296]  # row 300 is stamped one step early, between valid rows
    table = read_table(_write_csv(tmp_path / "off.csv", d), nonfinite="keep")
    assert table.rejections.by_reason() == {"time": 3 * N_CH}
    lost = np.flatnonzero(np.isnan(table.data).any(axis=1))
    assert lost.tolist() == [150, 299, 300]
    kept = np.ones(400, bool)
    kept[lost] = False
    for j in range(N_CH):
        np.testing.assert_array_equal(table.data[kept, j], d[f"a{j}"][kept])
    assert table.time is not None and np.isnan(table.time[lost]).all() and table.start_s == 0.0


def test_a_clock_that_does_not_come_back_is_refused_naming_the_step(tmp_path):
    d = _channels(400)
    d["time"][150:] += 2.5 / FS  # samples missing without rows: every later row off the first rows' clock
    with pytest.raises(TableError, match=r"not a uniform clock \(step 0.017\d* s from sample 149 to 150"):
        read_table(_write_csv(tmp_path / "jump.csv", d), nonfinite="keep")


# -- property: any mix of faults costs exactly the faulted samples ------------------------------
_ROWS, _COLS = 300, 4


@st.composite
def _faults(draw):
    cells = draw(st.dictionaries(st.tuples(st.integers(0, _ROWS - 1), st.integers(0, _COLS - 1)),
                                 st.sampled_from(sorted(CELL_FAULTS)), max_size=8))
    return {
        "cells": cells,
        "repeated_times": tuple(draw(st.lists(st.integers(1, _ROWS - 1), max_size=3))),
        "backwards_times": tuple(draw(st.lists(st.integers(3, _ROWS - 1), max_size=3))),
        "cut_last_row": draw(st.none() | st.integers(1, _COLS)),
        "units_row": draw(st.booleans()),
        "decimal_comma": draw(st.booleans()),
    }


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(faults=_faults())
def test_every_valid_sample_is_kept_and_every_rejection_counted(tmp_path, faults):
    clean = np.random.default_rng(5).normal(size=(_ROWS, _COLS))
    f = write_faulted_csv(tmp_path / "f.csv", clean, FS, **faults)
    table = read_table(f.path, nonfinite="keep")
    assert table.channels == tuple(f.names) and table.data.shape == clean.shape
    expected = {}
    for i in range(_ROWS):
        for j in range(_COLS):
            if i in f.rows:
                reason = "time"
            elif i == _ROWS - 1 and j in f.truncated:
                reason = "truncated"
            else:
                reason = f.cells.get((i, j))
            if reason is None:
                assert table.data[i, j] == clean[i, j], (i, j)
            elif reason == "implausible":
                assert table.data[i, j] == 1e30
            else:
                assert np.isnan(table.data[i, j]), (i, j, reason)
                expected[reason] = expected.get(reason, 0) + 1
    assert table.rejections.by_reason() == expected
    # shm oma's view: 1e30 is rejected as implausible, nothing else is
    record = clean_for_identification(table, list(f.names))
    implausible = sum(1 for (i, j), r in f.cells.items() if r == "implausible")
    assert record.rejections.by_reason().get("implausible", 0) == implausible
    assert record.rejections.total == sum(expected.values()) + implausible


# -- cut recordings ------------------------------------------------------------------------------
def test_a_cut_recording_keeps_its_metadata_and_every_command_says_it_is_cut(tmp_path, capsys):
    d = _channels(2000)
    csv = _write_csv(tmp_path / "daq.csv", d)
    rig, channel_map = _import_files(tmp_path)
    out = tmp_path / "o.mcap"
    import_recording([csv], rig, channel_map, out)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(out.read_bytes()[: out.stat().st_size // 2])
    rec = read_recording(cut)
    assert rec.report.truncated and "import" in rec.metadata  # written at the start: the cut keeps it
    assert json.loads(rec.metadata["import"]["limits"])["accel_m_s2"] == 2000.0
    code, _, err = run(capsys, "analyze", cut)
    assert code == 2 and "the recording is cut off: file is cut off at byte" in err
    code, out_text, err = run(capsys, "oma", cut, "--json")
    assert code == 0, err
    assert any("file is cut off at byte" in p for p in json.loads(out_text)["recording_problems"])


def test_messages_name_what_is_wrong(tmp_path):
    np.savez(tmp_path / "two.npz", a=np.zeros((100, 2)), b=np.zeros((100, 3)), fs=100.0)
    with pytest.raises(TableError, match=r"numeric arrays \{'a': \(100, 2\), 'b': \(100, 3\)\} are not vectors"):
        read_table(tmp_path / "two.npz")
    (tmp_path / "t.csv").write_text("time,a\n0,1\n0.01,2\n0.02,3\n0.5,5\n")
    with pytest.raises(TableError, match=r"step 0.48 s from sample 2 to 3, median 0.01 s\)$") as info:
        read_table(tmp_path / "t.csv")
    assert "np.float64" not in str(info.value)
    (tmp_path / "dc.csv").write_text("time,a\n0,0,1,5\n0,01,2,5\n")
    with pytest.raises(TableError, match="decimal commas in a comma-separated file"):
        read_table(tmp_path / "dc.csv")
