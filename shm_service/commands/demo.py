"""``shm demo`` (what ``make demo`` runs): a bounded monitoring scenario on the virtual rig.

It builds a service configuration (``shm serve`` with ``--source sim``) in a demo directory of its
own, rotated on every run (the previous run moves to ``DIR.previous``), so a run never inherits the
last run's baseline or alarms. Before it starts it prints where to look (dashboard and API URLs),
what happens when (the rest phase, the filter's warm-up, when the baseline is learnt, when the damage
appears, the earliest an alarm can be raised and the frequency changes the damage causes in the
simulated plant), how to stop it and where its data live; every figure is computed from the
scenario's configuration. It ends by itself when the scenario ends; Ctrl-C stops it early, exit 0.

``--structure`` picks what is simulated: the paper's sheet on its moving bearing (the default) or the
20 m tapered steel tubular mast of ``examples/mast/rig.json`` (clamped on a fixed foundation, IMUs and
strain gauges, no ToFs) under a storm that passes: the wind load, scaled to the mast, ramps up to
``--storm-peak`` times its ambient RMS and back down between 40 % and 80 % of the scenario after
its rest phase.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._argtypes import number

__all__ = ["DemoError", "add_demo_parser", "demo_overrides", "demo_timeline", "prepare_demo_directory", "run_demo"]

MARKER = ".shm-demo"
PIDFILE = "demo.pid"
CONFIG = "demo.toml"


class DemoError(Exception):
    """The demo cannot start (the message says why)."""


def add_demo_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser("demo", help="a bounded monitoring demo on the virtual rig (what make demo runs)",
                       description="Runs shm serve on the simulated rig in a fresh demo directory: a healthy period, "
                                   "a baseline, then a damage (an added tip mass) and its alarms. Prints what happens "
                                   "when; ends when the scenario ends; Ctrl-C stops it (exit 0).")
    p.add_argument("--dir", default="var/demo", metavar="DIR",
                   help="demo directory (default var/demo); an earlier run's moves to DIR.previous")
    p.add_argument("--structure", choices=tuple(STRUCTURES), default="sheet",
                   help="sheet: the paper's 4 m sheet on its moving bearing (default); mast: the 20 m tapered tubular "
                        "mast of examples/mast under a storm that passes")
    p.add_argument("--storm-peak", type=number(low=1, high=100), default=4.0, metavar="FACTOR",
                   help="mast: the wind load's RMS at the storm's peak over its ambient level (default 4: twice the "
                        "wind speed)")
    p.add_argument("--duration", type=number(low=60, high=7 * 24 * 3600, unit="s"), default=1800.0, metavar="S",
                   help="simulated length of the scenario, s (default 1800)")
    p.add_argument("--speed", default="4", metavar="N|max", help="pace, a factor of real time or max (default 4)")
    p.add_argument("--damage-at", type=number(low=0, unit="s"), default=900.0, metavar="S",
                   help="simulated time the damage appears, s (default 900; after the baseline)")
    p.add_argument("--no-damage", action="store_true", help="a healthy scenario: no damage, no alarm expected")
    p.add_argument("--damage", default=None, metavar="SPEC",
                   help="the damage: mass:KG@POS or stiffness:FACTOR@A-B (default 1 %% of the beam's mass at its tip: "
                        "mass:0.126@4.0 on the sheet, mass:14.4@20 on the mast)")
    p.add_argument("--temperature-swing", type=number(low=0, high=100, unit="K"), default=4.0, metavar="K",
                   help="peak-to-peak temperature cycle over the scenario, K (default 4)")
    p.add_argument("--seed", type=number(int, low=0), default=1)
    p.add_argument("--port", type=number(int, low=0, high=65535), default=8600, help="API port (default 8600)")
    p.add_argument("--dashboard-port", type=number(int, low=0, high=65535), default=8080, help="dashboard port (default 8080)")
    p.add_argument("--no-dashboard", action="store_true", help="no dashboard (API only)")
    p.add_argument("--keep-running", action="store_true", help="keep the API and dashboard up after the scenario ends")
    p.add_argument("--config", metavar="FILE", help="a shm serve TOML file for everything else (the options above win)")
    from ..service._cli import add_process_arguments

    add_process_arguments(p)
    p.set_defaults(func=run_demo)
    return p


#: The mast's rig description (shipped with the examples a user starts from).
MAST_RIG = Path(__file__).resolve().parents[2] / "examples" / "mast" / "rig.json"
#: The storm on the mast: it begins and has passed at these fractions of the scenario after the rest
#: phase (after the default baseline, so the baseline is the mast in ambient wind; the damage comes
#: as the storm builds up).
STORM_SPAN = (0.4, 0.8)
STRUCTURES = ("sheet", "mast")


def _mast_rig() -> Path:
    if not MAST_RIG.is_file():
        raise DemoError(f"the mast's rig description {MAST_RIG} is missing (it ships in the repository's examples/)")
    return MAST_RIG


def default_damage(structure: str) -> str:
    """1 % of the beam's own mass at its tip, the issue's damage (mass:KG@POS)."""
    if structure == "sheet":
        return "mass:0.126@4.0"
    if structure == "mast":
        from estimator import load_rig

        beam = load_rig(_mast_rig()).beam
        return f"mass:{0.01 * beam.mass:.3g}@{beam.length:g}"
    raise DemoError(f"unknown structure {structure!r}: one of {', '.join(STRUCTURES)}")


def demo_overrides(args: argparse.Namespace, directory: Path) -> dict[str, Any]:
    """The service configuration of the demo (a nested dict for ``load_settings``)."""
    structure = getattr(args, "structure", "sheet")
    damage = args.damage or default_damage(structure)
    sim: dict[str, Any] = {"duration_s": float(args.duration), "seed": int(args.seed),
                           "damage": [] if args.no_damage else [damage],
                           "damage_at_s": None if args.no_damage else float(args.damage_at),
                           "temperature_swing_k": float(args.temperature_swing)}
    overrides: dict[str, Any] = {
        "data_dir": str(directory),
        "source": {"spec": "sim", "speed": args.speed, "keep_running": bool(args.keep_running)},
        "sim": sim,
        "server": {"port": int(args.port)},
        "dashboard": {"enabled": not args.no_dashboard, "port": int(args.dashboard_port)},
        # A demo of hours keeps all it records: the retention defaults are sized for a week.
    }
    if structure == "mast":
        from ..virtual_rig import SimulationSettings

        rest = SimulationSettings.model_fields["rest"].default  # the wind blows after the rest phase
        start, end = (rest + f * max(0.0, float(args.duration) - rest) for f in STORM_SPAN)
        # ambient: the wind load alone (a rig file's ambient excitation), scaled to the mast
        sim.update(rig=str(_mast_rig()), excitation="ambient",
                   storm_start_s=start, storm_end_s=end, storm_peak=float(args.storm_peak))
        # examples/mast/serve.toml's estimator: Γ = 4, the four IMUs and four gauges, no ToFs
        overrides["estimator"] = {"peripheral": "gyro", "modes": 4, "imus": 4, "tofs": 0, "gauges": 4}
    elif structure != "sheet":
        raise DemoError(f"unknown structure {structure!r}: one of {', '.join(STRUCTURES)}")
    return overrides


@dataclass(frozen=True)
class Timeline:
    """When things happen in a sim scenario (simulated seconds from the start)."""

    rest_s: float
    first_window_s: tuple[float, float]
    step_s: float
    baseline_s: float
    damage_s: float | None
    first_damaged_window_end_s: float | None
    earliest_alarm_s: float | None
    #: when a change large against the baseline's scatter is raised: hold_windows windows wholly after the damage
    expected_alarm_s: float | None
    duration_s: float
    #: (begins s, peak s, has passed s, peak factor) of a storm that passes, or None
    storm: tuple[float, float, float, float] | None = None


def demo_timeline(settings: Any) -> Timeline:
    """The scenario's timeline from its configuration: the simulator's rest phase, the estimator's
    warm-up, the analysis grid, the baseline period and the alarm hysteresis."""
    from ..service.sources._sources import simulation_settings

    sim = simulation_settings(settings)
    a, est = settings.engine_config(), settings.estimator  # the analytics with the service's alarm hysteresis
    step = a.window_s * (1.0 - a.overlap)
    rest = sim.rest
    # windows start on multiples of the step (data time from the start, which is on the grid)
    first_start = math.ceil((rest + est.warmup_s) / step) * step
    # the baseline is learnt at the end of the first window ending baseline_s after the first one's start
    k = max(0, math.ceil((first_start + a.baseline_s - a.window_s - first_start) / step))
    baseline = first_start + k * step + a.window_s
    damage = sim.damage_at if sim.damage else None
    first_damaged_end = earliest = expected = None
    if damage is not None:
        # the first analysed window that holds damaged data (it ends after the damage appears)
        first_damaged_end = max((math.floor((damage - a.window_s) / step) + 1) * step, first_start) + a.window_s
        # an alarm (or a warning) is raised after hold_windows consecutive windows at or beyond its line
        earliest = first_damaged_end + (a.hold_windows - 1) * step
        # the first window that holds only damaged data; a window half healthy shifts by half as much
        expected = max(math.ceil(damage / step) * step, first_start) + a.window_s + (a.hold_windows - 1) * step
    storm = None
    if sim.wind_storm is not None:
        w = sim.wind_storm
        storm = (w.start_s, 0.5 * (w.start_s + w.end_s), w.end_s, w.peak)
    return Timeline(rest, (first_start, first_start + a.window_s), step, baseline, damage, first_damaged_end, earliest,
                    expected, sim.duration, storm)


def _clock(data_s: float, speed: float | None) -> str:
    if speed is None:
        return "as fast as the machine runs"
    wall = round(data_s / speed)
    return f"{wall // 60}:{wall % 60:02d} wall"


def simulated_truth(settings: Any) -> dict[str, str]:
    """The simulated plant's ``truth`` metadata (its exact modal figures, wind load and damage)."""
    from ..service.sources._sources import simulated_rig, simulation_settings
    from ..virtual_rig import VirtualRig

    return VirtualRig(simulation_settings(settings), simulated_rig(settings)).truth_metadata()


def expected_changes(settings: Any, truth: dict[str, str] | None = None) -> list[tuple[int, float, float]]:
    """(mode, healthy Hz, relative change) of the simulated plant's eigenfrequencies due to the
    scheduled damage (its exact linear figures), modes 1-5."""
    truth = simulated_truth(settings) if truth is None else truth
    if "eigenfrequencies_after_damage_hz" not in truth:
        return []
    before = json.loads(truth["eigenfrequencies_hz"])
    after = json.loads(truth["eigenfrequencies_after_damage_hz"])
    return [(m + 1, before[m], after[m] / before[m] - 1.0) for m in range(min(5, len(before), len(after)))]


def describe(settings: Any, timeline: Timeline, changes: list[tuple[int, float, float]],
             truth: dict[str, str] | None = None) -> str:
    """The banner: where to look, what happens when, how to stop it, where the data live. ``truth``
    (the simulated plant's metadata) adds the structure's eigenfrequencies and wind load."""
    speed = None if settings.source.speed == "max" else float(settings.source.speed)
    pace = "max speed" if speed is None else f"{speed:g}x real time"
    t, a = timeline, settings.engine_config()
    what = f"the mast of {settings.sim.rig}" if settings.sim.rig else "the virtual rig"
    lines = [f"shm demo: {what} at {pace}, {t.duration_s:g} s of simulated data ({_clock(t.duration_s, speed)}).", ""]
    free = "on a free port, printed below when it starts"
    if settings.dashboard.enabled:
        d = settings.dashboard
        lines.append(f"  dashboard  {f'http://{d.host}:{d.port}' if d.port else free}")
    api = f"http://{settings.server.host}:{settings.server.port}" if settings.server.port else None
    lines += [f"  API        {f'{api}/api/status' if api else free}  (trends /api/trends, alarms /api/alarms, "
              "documents /docs)", "", "What happens when (simulated time" + (")" if speed is None else
                                                                           ", and wall-clock time at this pace):")]
    if speed is not None:
        lines.append("  (wall-clock times hold while the machine keeps the pace: /api/status sources[0].lag_s is how many "
                     "simulated seconds the data are behind it)")
    events: list[tuple[float, int, str, tuple[str, ...]]] = []  # printed in time order (ties: as added)

    def at(data_s: float, text: str, *more: str) -> None:
        events.append((data_s, len(events), text, more))

    truth = truth or {}
    modes = json.loads(truth["eigenfrequencies_hz"])[:4] if "eigenfrequencies_hz" in truth else []
    wind = json.loads(truth["wind_load"]) if "wind_load" in truth else None
    at(0, f"the beam rests for {t.rest_s:g} s: the estimator learns the sensors' biases and noise",
       *([f"(its first modes: {', '.join(f'{f:.3g}' for f in modes)} Hz)"] if modes and settings.sim.rig else []))
    ambient = (f"ambient wind, {wind['rms_n_per_m']:.3g} N/m RMS along the beam" if wind else "ambient excitation")
    at(t.rest_s, f"{ambient}; the filter converges ({settings.estimator.warmup_s:g} s are not analysed)")
    at(t.first_window_s[1], f"the first analysis window ({t.first_window_s[0]:g}-{t.first_window_s[1]:g} s); "
       f"a {a.window_s:g} s window every {t.step_s:g} s")
    at(t.baseline_s, f"the baseline is learnt from {a.baseline_s:g} s of healthy windows")
    if t.storm is not None:
        begins, peak, passed, factor = t.storm
        level = f" ({factor * wind['rms_n_per_m']:.3g} N/m RMS)" if wind else ""
        at(begins, "a storm begins: the wind load ramps up",
           "(the response and the stress ranges at the hot spots grow; the simulated plant is linear, so its "
           "eigenfrequencies do not change)")
        at(peak, f"the storm peaks: the wind load is {factor:g} x its ambient RMS{level}")
        at(passed, "the storm has passed: the wind load is back at its ambient level")
    # a damage comes with the times of its alarms (DemoTimeline sets them together)
    if t.damage_s is not None and t.earliest_alarm_s is not None and t.expected_alarm_s is not None:
        shifts = ", ".join(f"mode {m} {100 * r:+.2f} %" for m, _, r in changes)
        at(t.damage_s, f"the damage appears: {', '.join(settings.sim.damage)}",
           *([f"the simulated plant's eigenfrequencies change by {shifts}"] if changes else []))
        at(t.earliest_alarm_s, "the earliest an alarm can be raised: the first window holding the damage ends at "
           f"{t.first_damaged_window_end_s:g} s", f"and a chart needs {a.hold_windows} consecutive windows at or beyond a line")
        at(t.expected_alarm_s, f"a shift large against the baseline's scatter is raised: {a.hold_windows} windows wholly after the "
           f"damage (the first ends at {t.expected_alarm_s - (a.hold_windows - 1) * t.step_s:g} s);",
           "a warning first, an alarm when the chart goes on to its alarm line; smaller shifts take longer",
           f"(EWMA charts, λ = {a.ewma_lambda:g}, warning {a.warning_sigma:g} σ, alarm {a.alarm_sigma:g} σ, "
           f"curvature alarm {a.curvature_alarm_sigma:g} σ)")
    at(t.duration_s, "the scenario ends; " + ("the API and dashboard stay up (--keep-running)"
                                              if settings.source.keep_running else "so does the demo"))
    later = [e for e in events if e[0] > t.duration_s]
    for data_s, _, text, more in sorted(e for e in events if e[0] <= t.duration_s):
        wall = "" if speed is None else f"  [{_clock(data_s, speed):>9}]"
        lines.append(f"  {data_s:7g} s{wall}  {text}")
        lines.extend(f"  {'':{9 + len(wall)}}  {m}" for m in more)
    if later:
        lines.append(f"  (after the end: {'; '.join(e[2] for e in sorted(later))}: give a longer --duration)")
    if t.damage_s is None:
        lines.append("  (no damage: no alarm is expected)")
    elif t.expected_alarm_s is not None and t.expected_alarm_s > t.duration_s:
        lines.append("  NOTE: the scenario ends before an alarm can be raised; give a longer --duration")
    lines += ["", "Stop it at any time with Ctrl-C (exit status 0).",
              f"Its data: {settings.data_dir}/ (database {Path(settings.db).name}, recordings "
              f"{Path(settings.archive.directory).name}/, configuration {CONFIG}); the next run moves them to "
              f"{settings.data_dir}.previous/", ""]
    return "\n".join(lines)


def _running_pid(directory: Path) -> int | None:
    try:
        pid = int((directory / PIDFILE).read_text().strip())
    except (OSError, ValueError):
        return None
    if pid == os.getpid():
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except PermissionError:
        return pid
    return pid


def prepare_demo_directory(directory: Path) -> Path | None:
    """Make ``directory`` a fresh, empty demo directory. An earlier demo's directory moves to
    ``DIR.previous`` (replacing an older one); a directory that is not a demo's and not empty is
    refused, as is one a running demo uses. Returns where the earlier run went, or None."""
    directory = Path(directory)
    previous = directory.with_name(directory.name + ".previous")
    moved = None
    if directory.exists():
        if not directory.is_dir():
            raise DemoError(f"{directory} exists and is not a directory")
        pid = _running_pid(directory)
        if pid is not None:
            raise DemoError(f"a demo is running in {directory} (pid {pid}); stop it first (Ctrl-C there, or kill {pid})")
        if not (directory / MARKER).exists() and any(directory.iterdir()):
            raise DemoError(f"{directory} is not empty and not a demo directory: give another --dir")
        if any(directory.iterdir()):
            if previous.exists():
                if not (previous / MARKER).exists():
                    raise DemoError(f"{previous} exists and is not a demo directory: move it away first")
                shutil.rmtree(previous)
            directory.rename(previous)
            moved = previous
    directory.mkdir(parents=True, exist_ok=True)
    (directory / MARKER).write_text("made by shm demo: removed or rotated by the next run\n")
    (directory / PIDFILE).write_text(f"{os.getpid()}\n")
    return moved


def run_demo(args: argparse.Namespace) -> int:
    from ..service._cli import run_serve
    from ..service._config import SettingsError, load_settings, render_toml

    directory = Path(args.dir)
    try:
        if not args.no_damage and args.damage_at >= args.duration:
            raise DemoError(f"--damage-at {args.damage_at:g} s must be before the end of the scenario (--duration {args.duration:g} s)")
        settings = load_settings(args.config, demo_overrides(args, directory))
        timeline = demo_timeline(settings)
        if timeline.damage_s is not None and timeline.damage_s < timeline.baseline_s:
            raise DemoError(f"--damage-at {args.damage_at:g} s comes before the baseline is learnt "
                            f"({timeline.baseline_s:g} s): the damage would be learnt as healthy")
        truth = simulated_truth(settings)
        changes = expected_changes(settings, truth) if timeline.damage_s is not None else []
        moved = prepare_demo_directory(directory)
    except SettingsError as exc:
        print(f"shm demo: error: {exc}", file=sys.stderr)
        return 2
    except DemoError as exc:
        print(f"shm demo: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\nshm demo: stopped before it started", file=sys.stderr)
        return 0
    config = directory / CONFIG
    config.write_text(render_toml(settings), encoding="utf-8")
    if moved is not None:
        print(f"shm demo: the previous run's data are in {moved}/")
    print(describe(settings, timeline, changes, truth), flush=True)
    serve_args = argparse.Namespace(
        config=str(config), print_config=False, source=None, speed=None, keep_running=None, data_dir=None, db=None,
        host=None, port=None, dashboard_port=None, no_dashboard=None, token_file=None, rig=None, source_id=None,
        webhook=None, recordings=None, no_archive=None, json=False,
        ready_file=getattr(args, "ready_file", None), parent_pid=getattr(args, "parent_pid", None),
    )
    try:
        code = run_serve(serve_args)
    except KeyboardInterrupt:  # Ctrl-C before shm serve took over the signal
        code = 0
    finally:
        try:
            (directory / PIDFILE).unlink()
        except OSError:
            pass
    print(happened(settings), flush=True)
    print(f"shm demo: done (exit {code}); its data are in {directory}/", flush=True)
    return code


def happened(settings: Any) -> str:
    """What the run raised: its alarms, in simulated time, from the demo's database."""
    from ..service.sources._sources import simulation_settings
    from ..service.storage._storage import Storage

    start_s = simulation_settings(settings).start_time_ns / 1e9
    try:
        storage = Storage(settings.db)
        try:
            alarms = {a.id: a for a in storage.alarms()}
            events = storage.alarm_events()
            windows = storage.count("trends")
        finally:
            storage.close()
    except Exception as exc:  # the summary must not turn a good run into a failure
        return f"shm demo: cannot read {settings.db}: {exc}"
    lines = [f"shm demo: {windows} trend rows stored; {len(alarms) or 'no'} alarm{'s' if len(alarms) != 1 else ''} raised"
             + (" (simulated time, what each did):" if alarms else "")]
    # every event (raised as a warning, escalated to an alarm, cleared) in the order they came
    for e in sorted(events, key=lambda e: (e["at_s"], e["id"])):
        a = alarms.get(e["alarm_id"])
        if a is None:
            continue
        lines.append(f"  {e['at_s'] - start_s:7.0f} s  #{a.id} {a.chart:<10} {e['event']:<9} {e['level']}")
    for a in sorted(alarms.values(), key=lambda a: a.id):
        lines.append(f"  #{a.id} now {a.state}: {a.message}")
    return "\n".join(lines)
