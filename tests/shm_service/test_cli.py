"""The shm command line: modes, simulate, inspect, estimate, and its errors."""

import json

import pytest

from shm_service.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_modes_json_has_the_contracted_keys(capsys):
    code, out, _ = run(capsys, "modes", "--json")
    data = json.loads(out)
    assert code == 0
    assert set(data) == {"frequencies_hz", "table1_hz", "relative_error"}
    assert len(data["frequencies_hz"]) == 6 and data["table1_hz"][0] == 0.302
    assert all(abs(r) <= 0.02 for r in data["relative_error"][:4])


def test_simulate_friction_is_opt_in_and_recorded(capsys, tmp_path):
    from shm_service.recording import read_recording

    for argv, torque in (([], 0.0), (["--friction", "0.03"], 0.03)):
        path = tmp_path / f"run{torque}.mcap"
        assert main(["simulate", "--duration", "2", "--out", str(path), *argv]) == 0
        truth = json.loads(read_recording(path).metadata["truth"]["friction_torque_nm"])
        assert truth == torque
    capsys.readouterr()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "run.mcap"
    assert main(["simulate", "--duration", "90", "--seed", "3", "--ideal", "--out", str(path)]) == 0
    return path


def test_inspect_reports_topics_and_rates(capsys, recording):
    code, out, _ = run(capsys, "inspect", str(recording), "--json")
    data = json.loads(out)
    assert code == 0
    assert not data["truncated"]
    rates = {topic: info["rate_hz"] for topic, info in data["topics"].items()}
    assert rates["/imu/D"] == pytest.approx(200.0, rel=1e-3)
    assert rates["/tof/s1"] == pytest.approx(33.33, rel=1e-3)


def test_estimate_writes_estimates_and_scores_them(capsys, recording, tmp_path):
    out_path = tmp_path / "est.mcap"
    code, out, _ = run(capsys, "estimate", str(recording), "--json", "--out", str(out_path), "--peripheral", "acc")
    data = json.loads(out)
    assert code == 0
    assert set(data["rmse"]) == {"phi_deg", "e_m", "d_m", "deflection_m", "curvature_per_m"}
    assert data["samples"] == 90 * 200 and data["rejected"] == 0 and data["realtime_factor"] > 0
    assert data["rmse"]["phi_deg"] < 0.05
    code, out, _ = run(capsys, "inspect", str(out_path), "--json")
    assert json.loads(out)["topics"]["/estimate/state"]["accepted"] == 90 * 200


def test_estimate_with_named_sensors_and_restricted_aiding(capsys, recording):
    code, out, _ = run(capsys, "estimate", str(recording), "--json", "--imus", "s1,s2,s3,s4", "--gauges", "2", "--tofs", "4")
    data = json.loads(out)
    assert code == 0 and data["selection"]["aided"] == [3, 4] and len(data["selection"]["gauges"]) == 2


@pytest.mark.parametrize(
    "argv, message",
    [
        (["estimate", "missing.mcap"], "missing.mcap"),
        (["estimate", "{rec}", "--modes", "5"], "Γ=5"),
        (["estimate", "{rec}", "--imus", "s1,zz"], "unknown sensor names"),
        (["estimate", "{rec}", "--aided", "x"], "--aided"),
        (["simulate", "--duration", "-1", "--out", "x.mcap"], "duration"),
        (["simulate", "--damage", "mass:abc", "--out", "x.mcap"], "damage"),
        (["simulate", "--friction", "-0.1", "--out", "x.mcap"], "friction_torque"),
    ],
)
def test_bad_input_gives_one_clear_error(capsys, recording, argv, message):
    code, _, err = run(capsys, *[a.replace("{rec}", str(recording)) for a in argv])
    assert code == 2
    assert message in err
