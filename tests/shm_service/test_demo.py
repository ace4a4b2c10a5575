"""``shm demo`` / ``make demo``: the timeline it prints is the configuration's, every run starts in a
fresh directory (the previous one rotated), it ends by itself when the scenario ends, and Ctrl-C
stops it with exit status 0 (``make demo`` then prints no error)."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from shm_service.commands.demo import MARKER, DemoError, demo_timeline, prepare_demo_directory
from shm_service.service import Storage, load_settings

ROOT = Path(__file__).resolve().parents[2]

#: A short scenario: small windows and a 40 s baseline, so it learns, damages and alarms in ~200 s of data.
SHORT_CONFIG = """
[analytics]
window_s = 20.0
overlap = 0.5
baseline_s = 40.0
baseline_min_windows = 3
hold_windows = 1
warning_sigma = 0.5
alarm_sigma = 1.0
clear_sigma = 0.2
curvature_alarm_sigma = 1.0
[estimator]
calibration_s = 10.0
warmup_s = 5.0
chunk_s = 1.0
[alarms]
raise_windows = 1
"""


def test_timeline_is_computed_from_the_configuration():
    t = demo_timeline(load_settings(None, {"sim": {"duration_s": 1800.0, "damage_at_s": 900.0}}))
    # rest 60 s + warm-up 120 s; 60 s windows every 30 s; baseline 480 s from the first window
    assert (t.rest_s, t.first_window_s, t.step_s, t.baseline_s) == (60.0, (180.0, 240.0), 30.0, 660.0)
    # the window 870-930 s is the first to hold damaged data; the charts hold 3 windows: 930 + 2·30
    assert (t.damage_s, t.first_damaged_window_end_s, t.earliest_alarm_s, t.duration_s) == (900.0, 930.0, 990.0, 1800.0)
    # the first window wholly after the damage is 900-960 s: three of them raise a large shift at 1020 s
    assert t.expected_alarm_s == 1020.0
    t = demo_timeline(load_settings(None, {"sim": {"damage_at_s": None}}))
    assert t.damage_s is None and t.earliest_alarm_s is None
    t = demo_timeline(load_settings(None, {"sim": {"damage_at_s": 333.0}, "estimator": {"warmup_s": 5.0},
                                          "analytics": {"window_s": 20.0, "overlap": 0.5, "baseline_s": 40.0,
                                                        "hold_windows": 2}}))
    # first window starts at ceil(65/10)·10 = 70; baseline at 70 + 40 = 110; damage window 320-340
    assert (t.first_window_s, t.baseline_s, t.first_damaged_window_end_s, t.earliest_alarm_s) == ((70.0, 90.0), 110.0, 340.0, 350.0)
    assert t.expected_alarm_s == 340.0 + 20.0 + 10.0  # the window 340-360 s is the first wholly damaged one


def test_each_run_gets_a_fresh_directory_and_the_last_one_is_kept_once(tmp_path):
    demo = tmp_path / "demo"
    assert prepare_demo_directory(demo) is None and (demo / MARKER).exists()
    (demo / "demo.pid").unlink()
    (demo / "shm.sqlite").write_text("run 1")
    assert prepare_demo_directory(demo) == tmp_path / "demo.previous"
    assert (tmp_path / "demo.previous" / "shm.sqlite").read_text() == "run 1"
    assert sorted(p.name for p in demo.iterdir()) == [MARKER, "demo.pid"]
    (demo / "demo.pid").unlink()
    (demo / "shm.sqlite").write_text("run 2")
    prepare_demo_directory(demo)
    assert (tmp_path / "demo.previous" / "shm.sqlite").read_text() == "run 2"  # only one generation is kept


def test_a_directory_that_is_not_a_demos_or_is_in_use_is_refused(tmp_path):
    other = tmp_path / "home"
    other.mkdir()
    (other / "thesis.tex").write_text("precious")
    with pytest.raises(DemoError, match="not a demo directory"):
        prepare_demo_directory(other)
    assert (other / "thesis.tex").read_text() == "precious"
    demo = tmp_path / "demo"
    prepare_demo_directory(demo)
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (demo / "demo.pid").write_text(f"{sleeper.pid}\n")
        with pytest.raises(DemoError, match=f"a demo is running in {demo} \\(pid {sleeper.pid}\\)"):
            prepare_demo_directory(demo)
    finally:
        sleeper.kill()
        sleeper.wait()


def _shm(*args: str) -> list[str]:
    return [sys.executable, "-m", "shm_service.cli", *args]


def test_a_short_demo_runs_to_its_end_and_says_what_happened(tmp_path):
    config = tmp_path / "short.toml"
    config.write_text(SHORT_CONFIG)
    demo = tmp_path / "demo"
    args = ["demo", "--dir", str(demo), "--config", str(config), "--duration", "200", "--speed", "max",
            "--damage-at", "120", "--no-dashboard", "--port", "0"]
    result = subprocess.run(_shm(*args), capture_output=True, text=True, timeout=600, cwd=tmp_path)
    out = result.stdout + result.stderr
    assert result.returncode == 0, out
    assert "Traceback" not in out
    assert "API        on a free port, printed below" in out and re.search(r"shm serve: API at http://127\.0\.0\.1:\d+", out)
    assert "Ctrl-C" in out and f"Its data: {demo}/" in out
    assert re.search(r"120 s\s+the damage appears: mass:0\.126@4\.0", out)
    assert re.search(r"the simulated plant's eigenfrequencies change by mode 1 -0\.\d+ %", out)
    assert "shm demo: done (exit 0)" in out
    storage = Storage(demo / "shm.sqlite")
    try:
        assert storage.count("trends") > 0
        alarms = storage.alarms()
    finally:
        storage.close()
    assert (f"{len(alarms)} alarm" if alarms else "no alarms raised") in out  # the summary is the database's
    assert (demo / "demo.toml").exists() and list((demo / "recordings").glob("*.mcap"))
    assert not (demo / "demo.pid").exists() and not (tmp_path / "var").exists()
    # shm analyze reads the demo's recording (its estimates are archived at 50 Hz, a quarter of the
    # estimator's rate) and analyses its windows, as the service did
    (recording,) = (demo / "recordings").glob("*.mcap")
    analysed = subprocess.run(_shm("analyze", str(recording), "--config", str(config), "--json"), capture_output=True,
                              text=True, timeout=600, cwd=tmp_path)
    assert analysed.returncode == 0, analysed.stderr
    assert len(json.loads(analysed.stdout)["windows"]) > 0
    # a second run starts afresh: the first run's data move aside (a minute of healthy data will do)
    second = subprocess.run(_shm("demo", "--dir", str(demo), "--duration", "60", "--no-damage", "--speed", "max",
                                 "--no-dashboard", "--port", "0"), capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert second.returncode == 0, second.stdout + second.stderr
    assert f"the previous run's data are in {demo}.previous/" in second.stdout
    assert (tmp_path / "demo.previous" / "shm.sqlite").exists()


class _Running:
    """A command in a process group of its own (a terminal's Ctrl-C goes to the whole foreground
    group), its output collected by a thread."""

    def __init__(self, cmd: list[str], cwd: Path) -> None:
        self.proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=lambda: self.lines.extend(iter(self.proc.stdout.readline, "")), daemon=True)
        self._reader.start()

    @property
    def output(self) -> str:
        return "".join(self.lines)

    def wait_for(self, text: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while text not in self.output:
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.kill()
                raise AssertionError(f"{text!r} not seen:\n{self.output}")
            time.sleep(0.1)

    def interrupt(self, timeout: float = 120) -> int:
        os.killpg(self.proc.pid, signal.SIGINT)
        try:
            code = self.proc.wait(timeout)
        finally:
            self.kill()
        self._reader.join(10)
        self.proc.stdout.close()
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(30)


def test_ctrl_c_stops_the_demo_with_exit_status_0(tmp_path):
    run = _Running(_shm("demo", "--dir", str(tmp_path / "demo"), "--no-dashboard", "--port", "0"), tmp_path)
    run.wait_for("shm serve: API at", 300)
    time.sleep(2.0)  # running
    code = run.interrupt()
    out = run.output
    assert code == 0, out
    assert "shm demo: done (exit 0)" in out and "Traceback" not in out


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_ctrl_c_in_make_demo_prints_no_make_error(tmp_path):
    venv_shm = ROOT / ".venv" / "bin" / "shm"
    if not venv_shm.exists():
        pytest.skip("make demo runs .venv/bin/shm, which this checkout has not built (make test builds it)")
    args = f"--dir {tmp_path / 'demo'} --no-dashboard --port 0"
    # -o: do not rebuild the venv from this test (its stamp may be older than a just-edited pyproject.toml)
    run = _Running(["make", "-s", "-C", str(ROOT), "-o", ".venv/.installed", "demo", f"DEMO_ARGS={args}"], tmp_path)
    run.wait_for("shm serve: API at", 300)
    time.sleep(1.0)
    code = run.interrupt()
    out = run.output
    assert "shm demo: done (exit 0)" in out, out
    assert "make: ***" not in out, out
    # make itself dies of the SIGINT it got too (status 130 in a shell, -2 here): that is make's way, not an error
    assert code in (0, -signal.SIGINT, 128 + signal.SIGINT), (code, out)


def test_the_mast_demo_has_its_storm_and_its_damage_in_the_timeline():
    import argparse

    from shm_service.commands.demo import add_demo_parser, demo_overrides

    parser = argparse.ArgumentParser()
    add_demo_parser(parser.add_subparsers())
    args = parser.parse_args(["demo", "--structure", "mast", "--storm-peak", "3"])
    settings = load_settings(None, demo_overrides(args, Path("unused")))
    assert settings.sim.rig.endswith("examples/mast/rig.json") and settings.estimator.tofs == 0
    # both planes in one filter: Γ = Γξ = 4 and the four gauge pairs (0° and 90°)
    assert (settings.estimator.modes, settings.estimator.modes_xi, settings.estimator.gauges) == (4, 4, 8)
    # 1 % of the mast's own mass (1443.4 kg: tapered tubes, 7850 kg/m³) at its 20 m tip
    assert settings.sim.damage == ("mass:14.4@20",)
    t = demo_timeline(settings)
    # the storm begins and has passed at 40 % and 80 % of the 1740 s after the 60 s rest
    assert t.storm == pytest.approx((60.0 + 0.4 * 1740, 60.0 + 0.6 * 1740, 60.0 + 0.8 * 1740, 3.0))
    assert t.baseline_s < t.storm[0]  # the baseline is the mast in ambient wind
    sheet = parser.parse_args(["demo"])
    assert demo_timeline(load_settings(None, demo_overrides(sheet, Path("unused")))).storm is None


def test_a_short_mast_demo_under_a_storm_runs_at_max_speed(tmp_path):
    config = tmp_path / "short.toml"
    config.write_text(SHORT_CONFIG)
    demo = tmp_path / "demo"
    args = ["demo", "--structure", "mast", "--dir", str(demo), "--config", str(config), "--duration", "150",
            "--speed", "max", "--damage-at", "115", "--no-dashboard", "--port", "0"]
    result = subprocess.run(_shm(*args), capture_output=True, text=True, timeout=600, cwd=tmp_path)
    out = result.stdout + result.stderr
    assert result.returncode == 0, out
    assert "Traceback" not in out and "shm demo: done (exit 0)" in out
    assert "examples/mast/rig.json at max speed" in out
    # storm: 60 s rest, then 40 %-80 % of the 90 s after it, peaking halfway; the wind is scaled to the mast
    assert re.search(r"\n\s+96 s\s+a storm begins", out) and re.search(r"\n\s+114 s\s+the storm peaks: the wind load is 4 x", out)
    assert re.search(r"\n\s+132 s\s+the storm has passed", out)
    assert re.search(r"ambient wind, [\d.]+ N/m RMS along the beam", out)
    assert "its direction veering 25° ± 30° from ζ towards ξ (period 600 s): the beam bends in both planes" in out
    assert re.search(r"115 s\s+the damage appears: mass:14\.4@20", out)
    storage = Storage(demo / "shm.sqlite")
    try:
        assert storage.count("trends") > 0
    finally:
        storage.close()
    # the recording is the mast's: its rig has the tubes' sections and no ToF, and it bends in both planes
    from mcap.reader import make_reader

    (recording,) = (demo / "recordings").glob("*.mcap")
    with recording.open("rb") as f:
        attachments = {a.name: a.data for a in make_reader(f).iter_attachments()}
    rig = json.loads(attachments["rig.json"])
    assert rig["beam"]["sections"][0]["shape"] == "tube"
    assert not any(s["kind"] == "tof" for s in rig["sensors"])
    assert rig["beam"]["bending"] == "biaxial"
    assert [s.get("angle_deg", 0) for s in rig["sensors"] if s["kind"] == "strain"] == [0, 90] * 4
