"""The DROPBEAR rig (examples/dropbear/rig.json) as the contract reads it, and ``shm serve`` on it:
no IMU at D (the clamp does not move and carries none), so the service refuses at once naming it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from estimator import load_rig
from shm_service.cli import main

ROOT = Path(__file__).resolve().parents[3]
RIG = ROOT / "examples" / "dropbear" / "rig.json"


def test_the_rig_describes_what_dropbear_has():
    rig = load_rig(RIG)
    assert rig.support == "clamped" and rig.gravity == 0.0 and not rig.truth_stations
    assert sorted(s.name for s in rig.sensors_of("imu")) == ["high_g", "low_g"]  # no IMU at D
    assert not rig.sensors_of("tof") and rig.reflector_distance is None  # no ToF: no reflector (the contract)
    assert not rig.sensors_of("bearing")  # the clamp is fixed to the ground
    assert sorted(s.name for s in rig.sensors_of("strain")) == ["SG_300_a", "SG_306_b"]
    assert all((s.model_extra or {}).get("axes") == ["accel_y"] for s in rig.sensors_of("imu"))  # single-axis


def test_shm_modes_works_on_it(capsys):
    assert main(["modes", "--rig", str(RIG), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    # the bare clamped-free steel beam of 0.35 m: f1 = 1.875²/(2π L²)·√(EI/ρA) = 39.94 Hz
    # (the sheet's 6 mm: I/A = t²/12; E = 200 GPa, ρ = 7850 kg/m³)
    assert doc["support"] == "clamped" and doc["frequencies_hz"][0] == pytest.approx(39.94, rel=2e-3)


def test_shm_serve_refuses_it_at_once_naming_the_missing_imu(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-m", "shm_service.cli", "serve", "--source", "ingest", "--rig", str(RIG),
                           "--db", str(tmp_path / "shm.sqlite"), "--port", "0", "--no-dashboard", "--no-archive"],
                          capture_output=True, text=True, env=env, timeout=180)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "no IMU named 'D'" in proc.stderr and "'sensors'" in proc.stderr and "the rig's IMUs: low_g, high_g" in proc.stderr
    assert "API at" not in proc.stdout  # refused before serving anything
