"""The service's bars (``shm serve``): end-to-end replay speed of a one-hour recording with
the dashboard off and on (under 3 minutes on 2 cores with it on, every window
committed, nothing in the log), and flat memory over a long simulated run at maximum speed.

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.bench_service [--replay FILE] [--hours H] [--skip-replay] [--skip-sim]
     [--skip-dashboard] [--compare TREE [--rounds N]]
``--compare TREE`` (another checkout, e.g. ``git worktree add ../old COMMIT``) runs its code and this
tree's side by side: the one-hour replay with ``--no-archive`` and with the default archive, and
the sim source's peak RSS with the raw archive.
(``main()`` is the entry for ``python -m benchmarks``.)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


_THREAD_CPU: dict[int, list[float]] = {}  # pid -> CPU seconds of its busiest threads (set by _run_measured)


def _run_measured(cmd: list[str], **kwargs) -> tuple[subprocess.CompletedProcess, float, int]:
    """Run ``cmd``; returns the completed process, its CPU seconds and its peak RSS (bytes,
    sampled every 0.2 s). The CPU seconds of its three busiest threads are left in
    ``_THREAD_CPU[pid]`` (the busiest thread bounds the wall time on an idle machine)."""
    import psutil

    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        popen = subprocess.Popen(cmd, stdout=out, stderr=err, text=True, **kwargs)
        handle = psutil.Process(popen.pid)
        peak, cpu = 0, 0.0
        threads: dict[int, float] = {}
        while popen.poll() is None:
            try:
                peak = max(peak, handle.memory_info().rss)
                times = handle.cpu_times()
                cpu = times.user + times.system
                for th in handle.threads():
                    threads[th.id] = th.user_time + th.system_time
            except psutil.Error:
                pass
            time.sleep(0.2)
        out.seek(0)
        err.seek(0)
        _THREAD_CPU[popen.pid] = sorted(threads.values(), reverse=True)[:3]
        proc = subprocess.CompletedProcess(cmd, popen.returncode, out.read(), err.read())
        proc.pid = popen.pid  # type: ignore[attr-defined]
        return proc, cpu, peak


def bench_replay(recording: Path, *, dashboard: bool, tree: Path | None = None, archive: bool = True) -> dict:
    """``shm serve --source replay:FILE --speed max`` as a subprocess, timed, with its dashboard on
    (a free port, no browser) or off; the log is counted for warnings and errors. ``tree``: run
    another checkout's code (``--compare``: before/after side by side); ``archive=False``: with
    ``--no-archive``. CPU seconds and peak RSS of the process are reported too."""
    if not recording.exists():
        print(f"simulating {recording} (one hour, ambient) ...", flush=True)
        subprocess.run([sys.executable, "-m", "shm_service.cli", "simulate", "--duration", "3600", "--excitation", "ambient",
                        "--out", str(recording)], check=True)
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "shm_service.cli", "serve", "--source", f"replay:{recording}", "--speed", "max",
               "--port", "0", "--db", f"{tmp}/shm.sqlite", "--recordings", f"{tmp}/rec", "--json"]
        cmd += ["--dashboard-port", "0"] if dashboard else ["--no-dashboard"]
        cmd += [] if archive else ["--no-archive"]
        env = dict(os.environ, PYTHONPATH=str(tree)) if tree is not None else None
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
        started = time.perf_counter()
        proc, cpu_s, peak_rss = _run_measured(cmd, cwd=tree, env=env)
        wall = time.perf_counter() - started
        load += " → " + " ".join(f"{x:.2f}" for x in os.getloadavg())
    if proc.returncode != 0:
        print(proc.stderr[-3000:], flush=True)
    levels = [line.split()[2] for line in proc.stderr.splitlines() if len(line.split()) > 2]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    result = {"tree": str(tree or "."), "dashboard": dashboard, "archive": archive, "wall_s": round(wall, 1),
              "cpu_s": round(cpu_s, 1), "busiest_threads_cpu_s": [round(c, 1) for c in _THREAD_CPU.get(proc.pid, [])],
              "peak_rss_mib": round(peak_rss / 2**20, 1), "load": load, "exit": proc.returncode, "messages": summary["messages"],
              "estimates": summary["estimates"], "windows": summary["windows"], "windows_committed": summary["windows_committed"],
              "trend_rows": summary["trend_rows"], "realtime_factor": round(summary["processed_data_s"] / wall, 1),
              "pipeline_errors": summary["pipeline_errors"], "sink_errors": summary["sink_errors"],
              "log_warnings": levels.count("WARNING"), "log_errors": levels.count("ERROR") + proc.stderr.count("Traceback")}
    print(f"[replay] {recording}: {result}", flush=True)
    return result


def bench_memory(hours: float, sample_s: float = 30.0) -> dict:
    """The sim source at max speed for ``hours`` of simulated time, in process; RSS sampled."""
    import psutil

    from shm_service.service import MonitoringService, load_settings

    proc = psutil.Process()
    with tempfile.TemporaryDirectory() as tmp:
        settings = load_settings(None, {
            "db": f"{tmp}/shm.sqlite", "source": {"spec": "sim", "speed": "max"},
            "sim": {"duration_s": hours * 3600.0}, "dashboard": {"enabled": False},
            "archive": {"directory": f"{tmp}/rec"},
        })
        service = MonitoringService(settings, environ={})
        samples: list[tuple[float, float, float]] = []
        started = time.perf_counter()
        service.start()
        done = threading.Event()

        def sample() -> None:
            while not done.wait(sample_s):
                st = service.status().pipeline
                data_h = (st.processed_data_s or 0.0) / 3600
                rss = proc.memory_info().rss / 2**20
                samples.append((round(time.perf_counter() - started, 1), round(data_h, 3), round(rss, 1)))
                print(f"[memory] wall {samples[-1][0]:8.1f} s  data {data_h:7.3f} h  RSS {rss:7.1f} MiB", flush=True)

        thread = threading.Thread(target=sample, daemon=True)
        thread.start()
        service.wait()
        done.set()
        st = service.status()
        service.stop(drain_s=0)
    wall = time.perf_counter() - started
    rss = [s[2] for s in samples]
    later = rss[len(rss) // 4:] or rss
    result = {"simulated_h": hours, "wall_s": round(wall, 1), "samples": samples,
              "rss_first_mib": rss[0] if rss else None, "rss_max_mib": max(rss) if rss else None,
              "rss_growth_after_first_quarter_mib": round(max(later) - min(later), 1) if later else None,
              "windows": st.pipeline.windows, "trend_rows": st.storage.trend_rows}
    print(f"[memory] {json.dumps({k: v for k, v in result.items() if k != 'samples'})}", flush=True)
    return result


def bench_sim_memory(seconds: float, tree: Path | None = None) -> dict:
    """Peak RSS of ``shm serve --source sim --speed max`` with the raw archive on (the queued
    batches carry every sample's payload) for ``seconds`` of simulated data; ``tree`` as for
    ``bench_replay``."""
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "sim.toml"
        config.write_text(f"[sim]\nduration_s = {seconds}\n")
        cmd = [sys.executable, "-m", "shm_service.cli", "serve", "--config", str(config), "--source", "sim", "--speed", "max",
               "--port", "0", "--db", f"{tmp}/shm.sqlite", "--recordings", f"{tmp}/rec", "--no-dashboard", "--json"]
        env = dict(os.environ, PYTHONPATH=str(tree)) if tree is not None else None
        started = time.perf_counter()
        proc, cpu_s, peak = _run_measured(cmd, cwd=tree, env=env)
        wall = time.perf_counter() - started
    result = {"tree": str(tree or "."), "simulated_s": seconds, "wall_s": round(wall, 1), "cpu_s": round(cpu_s, 1),
              "peak_rss_mib": round(peak / 2**20, 1), "exit": proc.returncode}
    print(f"[sim-memory] {result}", flush=True)
    return result


def warm_up(tree: Path | None, seconds: float = 300.0) -> None:
    """A short replay of ``tree``'s code (None: this one), untimed: a tree's first run compiles its
    numba kernels into its cache, which would count against the first timed run of that tree."""
    with tempfile.TemporaryDirectory() as tmp:
        short = Path(tmp) / "short.mcap"
        subprocess.run([sys.executable, "-m", "shm_service.cli", "simulate", "--duration", str(seconds), "--excitation",
                        "ambient", "--out", str(short)], check=True, capture_output=True)
        env = dict(os.environ, PYTHONPATH=str(tree)) if tree is not None else None
        started = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "shm_service.cli", "serve", "--source", f"replay:{short}", "--speed",
                               "max", "--port", "0", "--db", f"{tmp}/shm.sqlite", "--no-archive", "--no-dashboard", "--json"],
                              cwd=tree, env=env, capture_output=True, text=True)
    print(f"[warm-up] {tree or 'this tree'}: {seconds:g} s replayed untimed in {time.perf_counter() - started:.1f} s "
          f"(exit {proc.returncode}; its kernels compiled and cached)", flush=True)
    if proc.returncode != 0:
        print(proc.stderr[-2000:], flush=True)


def compare(recording: Path, tree: Path, rounds: int, sim_s: float = 1200.0) -> dict:
    """Before/after in one run: the one-hour replay of ``tree``'s code and this tree's, with
    ``--no-archive`` and with the default archive, alternately for ``rounds`` rounds (best wall
    and CPU of each), then the sim source's peak RSS with the raw archive (``sim_s`` of simulated data)."""
    runs: dict[tuple[str, bool], list[dict]] = {(k, a): [] for k in ("before", "after") for a in (False, True)}
    warm_up(tree)
    warm_up(None)
    for _ in range(rounds):
        for archive in (False, True):
            runs["before", archive].append(bench_replay(recording, dashboard=False, tree=tree, archive=archive))
            runs["after", archive].append(bench_replay(recording, dashboard=False, archive=archive))
    best = {k: {"wall_s": min(r["wall_s"] for r in v), "cpu_s": min(r["cpu_s"] for r in v),
                "peak_rss_mib": max(r["peak_rss_mib"] for r in v),
                "busiest_thread_cpu_s": min((r["busiest_threads_cpu_s"] or [float("nan")])[0] for r in v), "windows": sorted({r["windows_committed"] for r in v}),
                "trend_rows": sorted({r["trend_rows"] for r in v})} for k, v in runs.items()}
    for archive in (False, True):
        b, a = best["before", archive], best["after", archive]
        print(f"[compare] one hour replayed, {'default archive' if archive else '--no-archive'}, no dashboard "
              f"(best of {rounds}): before {b['wall_s']} s wall / {b['cpu_s']} s CPU (busiest thread {b['busiest_thread_cpu_s']} s) / "
              f"{b['peak_rss_mib']} MiB peak RSS, after {a['wall_s']} s / {a['cpu_s']} s ({a['busiest_thread_cpu_s']} s) / "
              f"{a['peak_rss_mib']} MiB; {b['wall_s'] / a['wall_s']:.2f}x faster; "
              f"windows committed {b['windows']} / {a['windows']}, trend rows {b['trend_rows']} / {a['trend_rows']}", flush=True)
    sim_before = bench_sim_memory(sim_s, tree)
    sim_after = bench_sim_memory(sim_s)
    print(f"[compare] sim source, {sim_s:g} simulated s at max speed, raw archive on: peak RSS before "
          f"{sim_before['peak_rss_mib']} MiB, after {sim_after['peak_rss_mib']} MiB", flush=True)
    result = {"replay": {f"{k}/{'archive' if a else 'no-archive'}": v for (k, a), v in best.items()},
              "sim_memory": {"before": sim_before, "after": sim_after}}
    print(f"[compare] {json.dumps(result)}", flush=True)
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--replay", default="/tmp/hour.mcap", help="one-hour recording (simulated if missing)")
    p.add_argument("--hours", type=float, default=24.0, help="simulated hours of the memory run")
    p.add_argument("--skip-replay", action="store_true")
    p.add_argument("--skip-sim", action="store_true")
    p.add_argument("--skip-dashboard", action="store_true", help="replay with the dashboard off only")
    p.add_argument("--quick", action="store_true", help="a 2-hour memory run instead of --hours")
    p.add_argument("--compare", default=None, metavar="TREE",
                   help="another checkout (e.g. the tree before a change): its replay with and without --no-archive "
                        "(no dashboard) and this tree's, alternately (--rounds), and the sim source's memory, before the usual runs")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--sim-seconds", type=float, default=1200.0, help="simulated seconds of --compare's sim memory run")
    # `python -m benchmarks` passes the same arguments to every benchmark: ignore the others' flags.
    args, _ = p.parse_known_args(argv)
    if args.quick:
        args.hours = min(args.hours, 2.0)
    if args.compare:
        compare(Path(args.replay), Path(args.compare).resolve(), args.rounds, args.sim_seconds)
    if not args.skip_replay:
        bench_replay(Path(args.replay), dashboard=False)
        if not args.skip_dashboard:
            bench_replay(Path(args.replay), dashboard=True)
    if not args.skip_sim:
        bench_memory(args.hours)
    return 0


if __name__ == "__main__":
    sys.exit(main())
