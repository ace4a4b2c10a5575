"""The shm command line: modes, simulate, inspect, estimate, and its errors."""

import importlib.util
import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from shm_service.cli import main


def run(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse refuses bad arguments with exit code 2
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_modes_json_has_the_contracted_keys(capsys):
    code, out, _ = run(capsys, "modes", "--json")
    data = json.loads(out)
    assert code == 0
    assert {"frequencies_hz", "table1_hz", "relative_error"} <= set(data)
    assert len(data["frequencies_hz"]) == 6 and data["table1_hz"][0] == 0.302
    assert all(abs(r) <= 0.02 for r in data["relative_error"][:4])
    assert (data["support"], data["orientation"], data["critical_load_factor"]) == ("pinned", "hanging", None)
    assert data["unit_deformations"] == [[1, 2], [3], [4], [5], [6]]


def _sheet(tmp_path, name, **overrides):
    """A bare 2 mm steel sheet as a rig file (the contract's keys only)."""
    description = {
        "beam": {"length": 1.5, "width": 0.2, "thickness": 0.002, "youngs_modulus": 2.1e11, "density": 7850.0},
        "gravity": 9.81, "reflector_distance": 0.5, "support": "clamped",
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}],
    }
    for key, value in overrides.items():
        if key == "beam":
            description["beam"].update(value)
        else:
            description[key] = value
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(description))
    return path


def _beam_column_reference():
    spec = importlib.util.spec_from_file_location(
        "beam_column_reference", Path(__file__).parents[1] / "estimator" / "beam_column_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_modes_of_a_clamped_sheet_without_gravity_meet_the_closed_form(capsys, tmp_path):
    path = _sheet(tmp_path, "clamped", gravity=0.0)
    code, out, _ = run(capsys, "modes", "--rig", str(path), "--count", "4", "--json")
    data = json.loads(out)
    assert code == 0 and "table1_hz" not in data and data["unit_deformations"][:2] == [[1], [2]]
    EI, mu = 2.1e11 * 0.2 * 0.002**3 / 12, 7850.0 * 0.2 * 0.002
    closed = np.array([1.87510407, 4.69409113, 7.85475744, 10.99554073]) ** 2 / (2 * np.pi * 1.5**2) * np.sqrt(EI / mu)
    np.testing.assert_allclose(data["frequencies_hz"], closed, rtol=1e-3)


@pytest.mark.parametrize("orientation", ["hanging", "standing"])
def test_modes_of_the_clamped_1_5_m_sheet_match_an_independent_beam_column_solution(capsys, tmp_path, orientation):
    path = _sheet(tmp_path, orientation, orientation=orientation)
    code, out, _ = run(capsys, "modes", "--rig", str(path), "--count", "5", "--json")
    assert code == 0
    EI, mu = 2.1e11 * 0.2 * 0.002**3 / 12, 7850.0 * 0.2 * 0.002
    reference = _beam_column_reference().clamped_frequencies(
        5, length=1.5, EI=EI, mu=mu, axial_gravity=9.81 if orientation == "hanging" else -9.81)
    np.testing.assert_allclose(json.loads(out)["frequencies_hz"], reference, rtol=1e-2)
    np.testing.assert_allclose(json.loads(out)["frequencies_hz"], reference, rtol=1e-4)  # in fact much closer


def test_modes_of_a_4_m_standing_sheet_exit_non_zero_because_it_buckles(capsys, tmp_path):
    path = _sheet(tmp_path, "mast", orientation="standing", beam={"length": 4.0})
    code, out, err = run(capsys, "modes", "--rig", str(path), "--json")
    assert code == 2 and out == ""
    assert "buckles" in err and "L_cr = 1.924 m" in err and "4 m long" in err


def test_modes_configuration_options(capsys):
    code, out, _ = run(capsys, "modes", "--support", "clamped", "--orientation", "standing", "--length", "1.5", "--json")
    data = json.loads(out)
    assert code == 0 and (data["support"], data["orientation"], data["length_m"]) == ("clamped", "standing", 1.5)
    assert 1 < data["critical_load_factor"] < 3
    code, _, err = run(capsys, "modes", "--support", "pinned", "--orientation", "standing")
    assert code == 2 and "inverted pendulum" in err
    code, _, err = run(capsys, "modes", "--length", "0")
    assert code == 2 and "--length: 0 is out of range" in err


def test_simulate_friction_is_opt_in_and_recorded(capsys, tmp_path):
    from shm_service.recording import read_recording

    for argv, torque in (([], 0.0), (["--friction", "0.03"], 0.03)):
        path = tmp_path / f"run{torque}.mcap"
        assert main(["simulate", "--duration", "2", "--out", str(path), *argv]) == 0
        truth = json.loads(read_recording(path).metadata["truth"]["friction_torque_nm"])
        assert truth == torque
    capsys.readouterr()


@pytest.mark.parametrize("excitation", ["paper", "ambient", "decay"])
def test_simulate_a_clamped_standing_mast_with_truth(capsys, tmp_path, excitation):
    from shm_service.recording import read_recording

    path = tmp_path / f"mast-{excitation}.mcap"
    code = main(["simulate", "--duration", "3", "--out", str(path), "--excitation", excitation, "--support", "clamped",
                 "--orientation", "standing", "--length", "1.5", "--json"])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0 and summary["eigenfrequencies_hz"][0] < 0.6  # compression softens mode 1 (0.87 Hz hanging)
    rec = read_recording(path)
    assert (rec.rig.support, rec.rig.orientation, rec.rig.beam.length) == ("clamped", "standing", 1.5)
    truth = rec.metadata["truth"]
    assert truth["support"] == "clamped" and json.loads(truth["critical_load_factor"]) > 1


def test_simulate_refuses_a_mast_that_buckles_and_a_pinned_standing_beam(capsys, tmp_path):
    path = tmp_path / "mast.mcap"
    code, _, err = run(capsys, "simulate", "--duration", "2", "--out", str(path), "--support", "clamped", "--orientation", "standing")
    assert code == 2 and "buckles" in err and "L_cr" in err and not path.exists()
    code, _, err = run(capsys, "simulate", "--duration", "2", "--out", str(path), "--orientation", "standing")
    assert code == 2 and "inverted pendulum" in err and not path.exists()
    code, _, err = run(capsys, "simulate", "--duration", "2", "--out", str(path), "--support", "clamped", "--friction", "0.03")
    assert code == 2 and "clamped support has none" in err


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
    # shm analyze of the estimates skips the warm-up after the same rest phase as of the raw recording
    from shm_service.processing.estimation import deformation_record
    from shm_service.recording import read_recording

    rest_end = deformation_record(read_recording(out_path)).rest_end_s
    assert rest_end is not None and 0 < rest_end < 90


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
        (["simulate", "--friction", "-0.1", "--out", "x.mcap"], "argument --friction: -0.1 is out of range (valid: a number from 0 to 10 N·m)"),
        (["simulate", "--duration", "nan", "--out", "x.mcap"], "argument --duration: 'nan' must be finite"),
        (["simulate", "--seed", "1.5", "--out", "x.mcap"], "argument --seed: '1.5' is not an integer"),
        (["modes", "--count", "21"], "argument --count: 21 is out of range (valid: an integer from 1 to 20)"),
        (["estimate", "{rec}", "--modes", "0"], "argument --modes: 0 is out of range (valid: an integer from 1 to 5)"),
        # counts the rig does not have are refused with the valid range, not capped
        (["estimate", "{rec}", "--imus", "7"], "--imus 7: the rig has 4 peripheral IMUs (s1, s2, s3, s4); Γ = 4 needs at least 4: valid counts: 4"),
        (["estimate", "{rec}", "--modes", "2", "--imus", "1"], "Γ = 2 needs at least 2: valid counts: 2..4"),
        (["estimate", "{rec}", "--tofs", "5"], "--tofs 5: the rig has 4 ToFs (s1, s2, s3, s4): valid counts: 0..4"),
        (["estimate", "{rec}", "--gauges", "9"], "--gauges 9: the rig has 4 strain gauges (g1, g2, g3, g4): valid counts: 0..4"),
        (["analyze", "{rec}", "--imus", "7"], "--imus 7: the rig has 4 peripheral IMUs"),
        (["estimate", "{rec}", "--aided", "2,7"], "unit deformations [7] are outside 1..4"),
        (["serve", "--port", "70000"], "argument --port: 70000 is out of range (valid: an integer from 0 to 65535)"),
        (["study", "--workers", "0"], "argument --workers: 0 is out of range (valid: an integer from 1 to 64)"),
    ],
)
def test_bad_input_gives_one_clear_error(capsys, recording, argv, message):
    code, _, err = run(capsys, *[a.replace("{rec}", str(recording)) for a in argv])
    assert code == 2
    assert message in err


def test_output_into_a_missing_directory_is_refused_and_nothing_is_created(capsys, tmp_path):
    target = tmp_path / "missing" / "dir" / "x.mcap"
    code, _, err = run(capsys, "simulate", "--duration", "1", "--out", str(target))
    assert code == 2 and f"directory {target.parent} does not exist" in err
    assert not (tmp_path / "missing").exists()
    code, _, err = run(capsys, "simulate", "--duration", "1", "--out", str(tmp_path))
    assert code == 2 and "is a directory" in err


def test_help_and_argument_errors_import_no_numerics():
    # `shm --help` and argparse errors must not pay for numpy, scipy, pydantic or the estimator
    # (1.4 s on a fresh machine); what they import is checked, not how long it takes.
    probe = (
        "import sys\n"
        "from shm_service.cli import main\n"
        "for argv in (['--help'], ['serve', '--help'], ['estimate', 'x.mcap', '--modes', '9'], ['demo', '--help']):\n"
        "    try:\n"
        "        main(argv)\n"
        "    except SystemExit:\n"
        "        pass\n"
        "heavy = sorted(m for m in ('numpy', 'scipy', 'pydantic', 'estimator', 'analytics', 'fastapi', 'viser') if m in sys.modules)\n"
        "print('HEAVY', heavy)\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert "HEAVY []" in result.stdout, result.stdout + result.stderr


def test_modes_calibration_reports_what_table1_determines(capsys):
    code, out, _ = run(capsys, "modes", "--calibration", "--json")
    data = json.loads(out)["calibration"]
    assert code == 0 and "board_rotary_inertia" in data["undetermined"] and "youngs_modulus" not in data["undetermined"]
    assert set(data["parameters"]["youngs_modulus"]) == {"value", "std", "prior_std", "resolution"}
    code, out, _ = run(capsys, "modes", "--calibration")
    assert code == 0 and "board_rotary_inertia" in out and "not determined by the frequencies" in out
    code, _, err = run(capsys, "modes", "--calibration", "--layout", "dense")
    assert code == 2 and "benchmark layout" in err


# -- a reader that goes away (``shm … --json | head -1``) -----------------------------------------
def test_a_closed_pipe_ends_the_command_quietly_with_the_shells_status():
    """The reader closes the pipe before the command writes: no traceback, exit 141 (128 + SIGPIPE)."""
    import os

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from shm_service.cli import main; sys.exit(main())", "modes", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # as head does after its first line
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_a_closed_pipe_in_process_returns_141_and_writes_nothing_more(monkeypatch):
    import io
    import os

    r, w = os.pipe()
    os.close(r)
    stdout = io.TextIOWrapper(io.FileIO(w, "w"), encoding="utf-8")
    monkeypatch.setattr(sys, "stdout", stdout)
    try:
        assert main(["modes", "--json"]) == 141
        stdout.write("more")  # the descriptor now points at devnull: later writes and the exit flush pass
        stdout.flush()
    finally:
        monkeypatch.undo()
        stdout.close()


def test_analyze_says_why_no_window_is_usable_and_what_to_change(capsys, recording):
    # 90 s: rest phase, then the filter's 120 s warm-up covers every 60 s window on the grid
    code, out, _ = run(capsys, "analyze", str(recording), "--json")
    doc = json.loads(out)["usability"]
    assert code == 0 and doc["usable"] == 0 and doc["rejected"] == {"warmup": 2}
    assert doc["why_none"].startswith("no usable window: 2 warmup") and doc["change"][0].startswith("warmup: record longer")
    code, out, _ = run(capsys, "analyze", str(recording))
    assert code == 0 and "no usable window: 2 warmup" in out and "  change: warmup: record longer" in out
