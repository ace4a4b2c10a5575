"""The contract package: layouts by hand, labels, documents, and that it stands alone."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from contract import (
    IMU_PLANAR_COLUMNS,
    PAYLOAD_FIELDS,
    AlarmDocument,
    ChartDocument,
    EstimateDocument,
    ModeDocument,
    ModeMap,
    PipelineStatusDocument,
    SpectrumDocument,
    StateLayout,
    StatusDocument,
    chart_name,
    estimate_payloads,
    row_layout,
)

ROOT = Path(__file__).resolve().parents[2]


def test_gyro_layout_by_hand():
    layout = StateLayout("gyro", 4, 4, imu_names=("s1", "s2", "s3", "s4"))
    assert layout.names == ("d", "h", "d_rate", "h_rate", "phi", "b1", "b2", "b3", "b4",
                            "gyro_bias_s1", "gyro_bias_s2", "gyro_bias_s3", "gyro_bias_s4", "gyro_bias_D")
    assert (layout.size, layout.d, layout.h, layout.d_rate, layout.h_rate, layout.phi) == (14, 0, 1, 2, 3, 4)
    assert layout.b == slice(5, 9) and layout.v is None and layout.peripheral_bias == slice(9, 13) and layout.bias_d == 13
    assert layout.position("b2") == 6 and layout.position("gyro_bias_D") == 13
    ix = layout.index
    assert (ix.size, ix.phi, ix.b, ix.v, ix.peripheral_bias, ix.bias_d, ix.gamma, ix.nu) == (14, 4, 5, -1, 9, 13, 4, 4)


def test_acc_layout_and_a_layout_without_attitude_by_hand():
    acc = StateLayout("acc", 3, 2)
    assert acc.names == ("d", "h", "d_rate", "h_rate", "phi", "b1", "b2", "b3", "v1", "v2", "v3", "gyro_bias_D")
    assert acc.v == slice(8, 11) and acc.peripheral_bias is None and acc.bias_d == 11
    # A support that fixes φ ≡ 0 (clamped): neither φ nor β_D take room.
    fixed = StateLayout("gyro", 2, 3, attitude=False)
    assert fixed.names == ("d", "h", "d_rate", "h_rate", "b1", "b2", "gyro_bias_1", "gyro_bias_2", "gyro_bias_3")
    assert fixed.phi is None and fixed.bias_d is None and fixed.b == slice(4, 6) and fixed.size == 9
    assert fixed.index.phi == -1 and fixed.index.bias_d == -1
    x = np.arange(18.0).reshape(2, 9)
    np.testing.assert_array_equal(fixed.phi_of(x), [0.0, 0.0])
    np.testing.assert_array_equal(fixed.b_of(x), [[4, 5], [13, 14]])
    np.testing.assert_array_equal(acc.phi_of(np.arange(12.0)), 4.0)


def test_layouts_with_residual_modes_by_hand():
    # Clamped gyro, Γ = 4, one residual mode: r1 right after b (the modal block the aiding sees), its rate next.
    gyro = StateLayout("gyro", 4, 4, attitude=False, residual=1)
    assert gyro.names == ("d", "h", "d_rate", "h_rate", "b1", "b2", "b3", "b4", "r1", "vr1",
                          "gyro_bias_1", "gyro_bias_2", "gyro_bias_3", "gyro_bias_4")
    assert gyro.b == slice(4, 8) and gyro.residual_modes == slice(8, 9) and gyro.modal == slice(4, 9)
    assert gyro.residual_rates == slice(9, 10) and gyro.peripheral_bias == slice(10, 14) and gyro.size == 14
    assert (gyro.index.residual, gyro.index.residual_rate) == (1, 9)
    acc = StateLayout("acc", 2, 3, attitude=False, residual=2)
    assert acc.names == ("d", "h", "d_rate", "h_rate", "b1", "b2", "r1", "r2", "v1", "v2", "vr1", "vr2")
    assert acc.v == slice(8, 10) and acc.residual_rates == slice(10, 12) and acc.index.residual_rate == 10
    none = StateLayout("gyro", 2, 3)
    assert none.residual_modes == slice(7, 7) and none.residual_rates == slice(0, 0) and none.index.residual_rate == -1
    with pytest.raises(ValueError, match="residual=-1 must be >= 0"):
        StateLayout("gyro", 2, 3, residual=-1)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"peripheral": "laser", "gamma": 4, "nu": 4}, "peripheral='laser'"),
    ({"peripheral": "gyro", "gamma": 0, "nu": 4}, "gamma=0"),
    ({"peripheral": "gyro", "gamma": 2.5, "nu": 4}, "gamma=2.5"),
    ({"peripheral": "gyro", "gamma": 4, "nu": -1}, "nu=-1"),
    ({"peripheral": "gyro", "gamma": 4, "nu": 2, "imu_names": ("a",)}, "1 names for nu=2"),
    ({"peripheral": "gyro", "gamma": 4, "nu": 2, "attitude": 1}, "attitude=1"),
])
def test_bad_layouts_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        StateLayout(**kwargs)


def test_a_state_of_another_layout_is_refused_naming_the_states():
    with pytest.raises(ValueError, match="needs 13 entries: d, h, d_rate, h_rate, phi, b1, b2, b3"):
        StateLayout("gyro", 3, 4).check(np.zeros(9))
    with pytest.raises(KeyError, match="no state 'v1'"):
        StateLayout("gyro", 3, 4).position("v1")


def test_row_layouts_by_hand():
    truth = row_layout("shm.TruthState", stations=3)
    assert truth.names() == ("d", "h", "phi", "e", "deflection[0]", "deflection[1]", "deflection[2]",
                             "curvature[0]", "curvature[1]", "curvature[2]")
    assert truth.width == 10 and truth.columns("deflection") == slice(4, 7) and truth.columns("curvature") == slice(7, 10)
    est = row_layout("shm.EstimateState", stations=2, free={"b": 4, "covariance_diagonal": 14})
    assert est.width == 4 + 4 + 2 + 2 + 14 and est.columns("b") == slice(4, 8) and est.column("covariance_diagonal", 13) == 25
    assert row_layout("shm.TruthState", stations=0).width == 4  # a rig without truth stations
    # The planar model's IMU columns: accel x, accel y and gyro z of [accel x, y, z, gyro x, y, z].
    assert IMU_PLANAR_COLUMNS == (0, 1, 5)
    with pytest.raises(ValueError, match="truth station"):
        row_layout("shm.TruthState")
    with pytest.raises(ValueError, match="free length"):
        row_layout("shm.EstimateState", stations=2, free={"b": 4})
    with pytest.raises(KeyError, match="unknown payload schema"):
        row_layout("shm.Nothing")
    with pytest.raises(KeyError, match="no payload key 'x'"):
        truth.columns("x")
    with pytest.raises(IndexError, match="no index 3"):
        truth.column("deflection", 3)


def test_mode_labels_of_the_pinned_and_a_clamped_beam():
    pinned = ModeMap.of(((1, 2), (3,), (4,), (5,)))
    assert pinned.gamma == 4 and pinned.modes == (1, 2, 3, 4, 5)
    assert pinned.unit_label(1) == "b1 · mode 1+2" and pinned.unit_label(4) == "b4 · mode 5"
    assert [pinned.mode_label(m) for m in (1, 2, 3)] == ["mode 1 (b1)", "mode 2 (b1)", "mode 3 (b2)"]
    clamped = ModeMap.of(((1,), (2,), (3,)))  # no combimode: one mode per unit deformation
    assert clamped.unit_label(1) == "b1 · mode 1" and clamped.mode_label(3) == "mode 3 (b3)"
    for bad in ((), ((),), ((2,),), ((1,), (1,)), ((1, 3),)):
        with pytest.raises(ValueError, match="unit_modes"):
            ModeMap.of(bad)
    with pytest.raises(KeyError, match="mode 6"):
        pinned.unit_of(6)


def test_chart_names_are_structured_fields():
    assert chart_name("frequency", 3) == "mode3" and chart_name("curvature") == "curvature"
    for args, message in ((("frequency", None), "1-based"), (("curvature", 2), "no mode"), (("strain", 1), "kind=")):
        with pytest.raises(ValueError, match=message):
            chart_name(*args)
    ok = dict(name="mode2", kind="frequency", mode=2, unit=1, level="warning", score_sigma=3.2, warning_sigma=3.0, alarm_sigma=5.0)
    assert ChartDocument(**ok).name == "mode2"
    with pytest.raises(ValidationError, match="does not match"):
        ChartDocument(**{**ok, "name": "mode3"})
    with pytest.raises(ValidationError, match="does not match"):
        AlarmDocument(id=1, source="s", chart="mode2", kind="curvature", level="alarm", state="active", raised_at_s=1.0, message="m")


def test_documents_turn_undefined_numbers_into_none_and_refuse_unknown_keys():
    m = ModeDocument(mode=1, unit=1, frequency_hz=float("nan"), amplitude=np.float64(np.inf), damping_ratio=np.float32(0.25))
    assert m.frequency_hz is None and m.amplitude is None and m.damping_ratio == 0.25
    assert "NaN" not in m.model_dump_json() and "Infinity" not in m.model_dump_json()
    with pytest.raises(ValidationError, match="extra"):
        ModeDocument(mode=1, unit=1, frequency=0.3)
    with pytest.raises(ValidationError):
        ModeDocument(mode=0, unit=1)
    alarm = AlarmDocument(id=1, source="s", chart="curvature", kind="curvature", level="alarm", state="active",
                          raised_at_s=1.0, acknowledged_at_s=2.0, message="m")
    assert alarm.acknowledged and alarm.active
    with pytest.raises(ValidationError, match="frozen"):
        alarm.state = "cleared"


def test_spectrum_shapes_are_checked():
    f = np.linspace(0.0, 10.0, 5)
    doc = SpectrumDocument.from_arrays(source="s", window_start_s=0.0, window_end_s=60.0, frequencies_hz=f,
                                       amplitudes=np.ones((5, 2)), tracked_hz=[[0.3, 0.86], [1.9]], baseline_hz=None)
    freqs, amps = doc.arrays()
    np.testing.assert_array_equal(freqs, f)
    assert amps.shape == (5, 2)
    for bad, message in (({"amplitudes": np.ones((5, 3))}, r"\(5, 2\)"), ({"frequencies_hz": f[::-1]}, "increasing"),
                         ({"baseline_hz": [[0.3]]}, "1 entries for Γ=2")):
        kwargs = dict(source="s", window_start_s=0.0, window_end_s=60.0, frequencies_hz=f, amplitudes=np.ones((5, 2)),
                      tracked_hz=[[0.3, 0.86], [1.9]], baseline_hz=None)
        with pytest.raises(ValidationError, match=message):
            SpectrumDocument.from_arrays(**{**kwargs, **bad})


def test_estimate_payloads_by_hand():
    layout = StateLayout("gyro", 2, 1)  # [d, h, ḋ, ḣ, φ, b1, b2, β1, β_D]
    x = np.array([[0.1, 0.2, 9.0, 9.0, 0.03, 0.5, -0.25, 7.0, 8.0]])
    P = np.full((1, 9), 1e-6)
    (row,) = estimate_payloads(layout, x, P, [0.125], [[0.0, 0.0625]], [[1.0, 2.0]])
    assert row == {"d": 0.1, "h": 0.2, "phi": 0.03, "e": 0.125, "b": [0.5, -0.25], "deflection": [0.0, 0.0625],
                   "curvature": [1.0, 2.0], "covariance_diagonal": [1e-6] * 9}
    assert list(EstimateDocument.model_validate(row).model_dump()) == [f.name for f in PAYLOAD_FIELDS["shm.EstimateState"]]
    fixed = StateLayout("acc", 1, 0, attitude=False)  # [d, h, ḋ, ḣ, b1, v1]: φ reported as 0
    (row,) = estimate_payloads(fixed, np.arange(6.0)[None], np.zeros((1, 6)), [0.0], [[0.0]], [[0.0]])
    assert row["phi"] == 0.0 and row["b"] == [4.0]
    with pytest.raises(ValueError, match="one row per estimate"):
        estimate_payloads(layout, np.vstack([x, x]), P, [0.1], [[0.0, 0.0]], [[0.0, 0.0]])
    with pytest.raises(ValueError, match="needs 9 entries"):
        estimate_payloads(layout, x[:, :8], P, [0.1], [[0.0, 0.0]], [[0.0, 0.0]])


def test_the_status_document_keeps_its_field_names():
    assert {"samples", "estimates", "queue_depth", "estimator", "windows", "windows_committed"} <= set(PipelineStatusDocument.model_fields)
    assert {"service", "sources", "pipeline", "sensors", "degraded_sensors", "baseline", "alarms", "notifications", "storage",
            "sinks", "thresholds", "model"} == set(StatusDocument.model_fields)


def _modules_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted({{m.split('.')[0] for m in sys.modules}})))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return set(out.split())


def test_contract_imports_no_other_package_of_the_project():
    loaded = _modules_after("import contract")
    assert not loaded & {"estimator", "analytics", "shm_service", "web", "benchmarks", "numba", "scipy"}, loaded


def test_the_recording_reader_does_not_load_the_estimator():
    loaded = _modules_after("import shm_service.recording")
    assert "contract" in loaded and not loaded & {"estimator", "numba", "analytics", "web"}, loaded


@pytest.mark.parametrize("pattern", ["5 + gamma", "[0, 1, 5]", "5:5 +", "(shape[1] - 4) // 2"])
def test_no_layout_arithmetic_outside_the_contract(pattern):
    hits = []
    for package in ("estimator", "analytics", "shm_service", "web", "benchmarks", "tests"):
        for path in (ROOT / package).rglob("*.py"):
            if pattern in path.read_text(encoding="utf-8") and path != Path(__file__).resolve():
                hits.append(str(path.relative_to(ROOT)))
    assert not hits, f"{pattern!r} in {hits}: read the offsets from contract.StateLayout / row_layout"


def test_finite_check_of_required_numbers():
    with pytest.raises(ValidationError, match="finite"):
        ChartDocument(name="curvature", kind="curvature", level="ok", warning_sigma=math.nan, alarm_sigma=6.0)
