"""``shm simulate --rig``: any rig description, its simulator settings, the wind load scaled to the
structure, a support fixed to the ground, and recordings that the project's own reader accepts
(also the estimates of a rig without truth stations)."""

import json

import numpy as np
import pytest
import scipy.integrate

from contract import parse_rig
from shm_service.cli import main
from shm_service.recording import read_recording
from shm_service.virtual_rig._wind import scaled_wind_load, support_moment_factor


def run(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _mast(**simulator):
    """A 20 m standing clamped mast (uniform, a 300 × 6 mm tube's EI and μ as a rectangle): IMUs and
    gauges, no ToF, no bearing sensor, no truth stations."""
    return {
        "beam": {"length": 20.0, "width": 0.01539, "thickness": 0.3603, "youngs_modulus": 2.1e11, "density": 7850.0},
        "gravity": 9.81, "support": "clamped", "orientation": "standing",
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]
        + [{"name": f"s{j}", "kind": "imu", "position": p} for j, p in enumerate((6.0, 11.0, 15.5, 20.0), start=1)]
        + [{"name": f"g{j}", "kind": "strain", "position": p} for j, p in enumerate((0.5, 4.0, 8.5, 13.0), start=1)],
        "truth_stations": [],
        **({"simulator": simulator} if simulator else {}),
    }


def test_support_moment_factor_against_a_double_integral():
    # RMS support moment of a unit-RMS load: sqrt(∫∫ η ξ exp(−|η − ξ|/λ)) by adaptive quadrature.
    L, lam = 3.0, 0.7
    value, _ = scipy.integrate.dblquad(lambda y, x: x * y * np.exp(-abs(x - y) / lam), 0, L, 0, L, epsabs=1e-10)
    assert support_moment_factor(L, lam, points=2001) == pytest.approx(np.sqrt(value), rel=1e-4)
    assert support_moment_factor(L, 1e12) == pytest.approx(L**2 / 2, rel=1e-9)  # fully correlated: p L²/2
    with pytest.raises(ValueError, match="correlation_m=0"):
        support_moment_factor(L, 0.0)


def test_scaled_wind_load_gives_the_base_strain_of_the_statics():
    rig = parse_rig(_mast())
    b = rig.beam
    EI, c = b.youngs_modulus * b.width * b.thickness**3 / 12, b.thickness / 2
    p = scaled_wind_load(rig, 1e12, 5e-5)
    assert p * b.length**2 / 2 * c / EI == pytest.approx(5e-5, rel=1e-9)  # M(0) = p L²/2, ε = M c / EI
    with pytest.raises(ValueError, match="base_strain=0"):
        scaled_wind_load(rig, 5.0, 0.0)


def test_simulate_a_rig_file_with_a_fixed_support_and_no_truth_stations(capsys, tmp_path):
    rig_file = tmp_path / "mast.json"
    rig_file.write_text(json.dumps(_mast(rest=2.0, operational={"ramp": 1.0}, wind_load_rms=3.0)))
    out = tmp_path / "mast.mcap"
    code, stdout, err = run(capsys, "simulate", "--rig", str(rig_file), "--excitation", "operational", "--duration", "12",
                            "--json", "--out", str(out))
    assert code == 0, err
    summary = json.loads(stdout)
    assert "/bearing/displacement" not in summary["messages"] and not any(t.startswith("/tof/") for t in summary["messages"])
    rec = read_recording(out)
    assert rec.report.problems == []
    assert rec.rig.truth_stations == tuple(2.5 * k for k in range(1, 9))  # eight stations scaled to the beam
    assert rec.rig.reflector_distance is None
    settings = rec.rig.extra("simulator")
    assert settings["wind_load_rms"] == 3.0 and settings["rest"] == 2.0
    truth = rec.channels["/truth/state"]
    assert np.all(truth.values[:, truth.fields.index("d")] == 0.0)  # the foundation does not move
    tip = truth.values[:, truth.fields.index("e")]
    assert np.std(tip[truth.log_time_ns > truth.log_time_ns[0] + 4e9]) > 1e-4  # the wind moves the mast
    meta = json.loads(rec.metadata["truth"]["wind_load"])
    assert meta["rms_n_per_m"] == 3.0 and meta["correlation_m"] == 5.0  # a quarter of the 20 m mast
    # The command line overrides the file's settings; an unknown setting is refused by its key.
    code, stdout, err = run(capsys, "simulate", "--rig", str(rig_file), "--excitation", "ambient", "--duration", "4",
                            "--wind-load", "7", "--json", "--out", str(tmp_path / "b.mcap"))
    assert code == 0, err
    assert json.loads(read_recording(tmp_path / "b.mcap", kinds=()).metadata["truth"]["wind_load"])["rms_n_per_m"] == 7.0
    rig_file.write_text(json.dumps(_mast(windspeed=3.0)))
    code, _, err = run(capsys, "simulate", "--rig", str(rig_file), "--duration", "4", "--out", str(tmp_path / "c.mcap"))
    assert code == 2 and "simulator: windspeed: Extra inputs are not permitted" in err


def test_estimates_of_a_rig_without_truth_stations_read_back(capsys, tmp_path):
    rig_file = tmp_path / "mast.json"
    rig_file.write_text(json.dumps(_mast(rest=4.0, operational={"ramp": 1.0})))
    recording = tmp_path / "mast.mcap"
    assert run(capsys, "simulate", "--rig", str(rig_file), "--excitation", "operational", "--duration", "12",
               "--out", str(recording))[0] == 0
    estimates = tmp_path / "est.mcap"
    # The rig as the user wrote it: no truth stations, so the estimates carry empty deflection/curvature.
    code, stdout, err = run(capsys, "estimate", str(recording), "--rig", str(rig_file), "--out", str(estimates), "--json")
    assert code == 0, err
    rec = read_recording(estimates)
    state = rec.channels["/estimate/state"]
    assert rec.report.topics["/estimate/state"].malformed == 0
    assert state.values.shape[0] == json.loads(stdout)["samples"] > 0
    assert not any("deflection" in f or "curvature" in f for f in state.fields)
