"""The figures for archives and structures (benchmarks, not tests):

- ``shm reprocess`` of eight one-hour recordings on 1 and 2 workers of a LocalCluster (the
  scaling ratio), each run into a fresh database;
- the scheduler's overhead per task, from a few hundred small tasks;
- on paper, what N machines would give (the measured per-file time and overhead);
- memory per structure: RSS of one process as it adds simulated structures (each a
  ``MonitoringService`` of its own, ``--no-archive``, no dashboard) at real time.

- the CPU per structure-second of one simulated structure (the virtual rig's generation and the
  pipeline, apart), and how many one core hosts at real time;
- live fleets: ``shm serve --workers 1|2`` of N simulated structures (all in one process, or in
  two worker processes behind one API on one database), the worst lag of each structure (overall
  and after the first minute), windows committed (and any analysed but not written at the end),
  RSS of all processes, CPU. By default 100 at real time for 690 s: the budget's ten minutes after
  the start-up.
- ``--compare TREE`` (another checkout, e.g. ``git worktree add ../before COMMIT``): each live
  fleet of ``--live`` on the tree's ``shm serve`` and on this one's, alternately, with a side-by-side
  line per fleet (the fleet budget no slower than before, in one run). ``--skip-live``
  then leaves out the usual live runs, which the comparison already made.

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.bench_fleet [--replay FILE] [--files 8] [--skip-reprocess]
     [--skip-memory] [--structures 4] [--skip-live] [--live 100] [--live-s 690] [--live-speed 1] [--live-dashboard]
     [--live-processes 1 2] [--live-hog] [--live-only]
(``main()`` is the entry for ``python -m benchmarks``; the eight files are the one-hour recording
under eight names, hard links: the work per file is that of eight different hours.)
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import IO, Any


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def bench_reprocess(recording: Path, files: int, workers: tuple[int, ...] = (1, 2)) -> dict:
    """``shm reprocess`` of ``files`` copies on each worker count, as a subprocess (wall and
    CPU of the whole run, the cluster's start included)."""
    if not recording.exists():
        print(f"simulating {recording} (one hour, ambient) ...", flush=True)
        subprocess.run([sys.executable, "-m", "shm_service.cli", "simulate", "--duration", "3600", "--excitation", "ambient",
                        "--out", str(recording)], check=True)
    results = {}
    with tempfile.TemporaryDirectory(dir=recording.parent) as tmp:
        paths = []
        for i in range(files):
            path = Path(tmp) / f"hour-{i + 1:02d}.mcap"
            os.link(recording, path)
            paths.append(str(path))
        for n in workers:
            db = Path(tmp) / f"reprocess-{n}.sqlite"
            cmd = [sys.executable, "-m", "shm_service.cli", "reprocess", *paths, "--db", str(db), "--workers", str(n), "--json"]
            load = _load()
            started = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True)
            wall = time.perf_counter() - started
            if proc.returncode != 0:
                print(proc.stderr[-2000:], flush=True)
            doc = json.loads(proc.stdout)
            statuses = [f["status"] for f in doc["files"]]
            results[n] = {"workers": n, "files": files, "wall_s": round(wall, 1), "done": statuses.count("done"),
                          "windows": sum(f["windows"] or 0 for f in doc["files"]), "load_before": load, "load_after": _load(),
                          "data_hours_per_wall_hour": round(files * 3600 / wall, 1)}
            print(f"[reprocess] {results[n]}", flush=True)
    if len(workers) > 1:
        a, b = results[workers[0]]["wall_s"], results[workers[-1]]["wall_s"]
        print(f"[reprocess] scaling {workers[0]} -> {workers[-1]} workers: {a / b:.2f}x faster "
              f"(ideal {workers[-1] / workers[0]:.0f}x; this machine has {os.cpu_count()} cores, load {_load()})", flush=True)
    return results


def _noop(x: int) -> int:
    return x + 1


def bench_scheduler(tasks: int = 400, workers: int = 2) -> dict:
    """Overhead per task: ``tasks`` tasks that do nothing, on a fresh LocalCluster, wall per task."""
    import logging

    from distributed import Client, LocalCluster, wait

    with LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=":0", silence_logs=logging.CRITICAL) as cluster, \
            Client(cluster) as client:
        client.submit(_noop, -1).result()  # workers up
        best = None
        for _ in range(3):
            started = time.perf_counter()
            futures = client.map(_noop, range(tasks), pure=False)
            wait(futures)
            elapsed = time.perf_counter() - started
            best = elapsed if best is None else min(best, elapsed)
            del futures
    result = {"tasks": tasks, "workers": workers, "wall_s": round(best, 3), "overhead_ms_per_task": round(1e3 * best / tasks, 3),
              "load": _load()}
    print(f"[scheduler] {result}", flush=True)
    return result


def bench_commit(rows_per_file: int = 560, files: int = 20) -> float:
    """Seconds the client spends committing one reprocessed hour (its trend rows and ledger row)."""
    from contract import TrendRow
    from shm_service.service import Storage

    with tempfile.TemporaryDirectory() as tmp:
        storage = Storage(Path(tmp) / "c.sqlite")
        started = time.perf_counter()
        for f in range(files):
            rows = [TrendRow(source=f"s{f}", window_start_s=30.0 * (i // 5), window_end_s=30.0 * (i // 5) + 60, mode=i % 5 + 1,
                             unit=1, kind="ambient", frequency_hz=1.0) for i in range(rows_per_file)]
            storage.commit_reprocessed(key=f"k{f}", path=f"/f{f}", source=f"s{f}", content_sha256="0" * 64, configuration="{}",
                                       windows=rows_per_file // 5, start_s=0.0, end_s=3600.0, rows=rows)
        per_file = (time.perf_counter() - started) / files
        storage.close()
    print(f"[commit] {1e3 * per_file:.1f} ms per reprocessed hour ({rows_per_file} trend rows)", flush=True)
    return per_file


_PROBE = """
import sqlite3, sys, time
db = sqlite3.connect(sys.argv[1], isolation_level=None, timeout=60)
waits = []
deadline = time.monotonic() + float(sys.argv[2])
while time.monotonic() < deadline:
    a = time.perf_counter()
    db.execute("BEGIN IMMEDIATE")
    waits.append(time.perf_counter() - a)
    db.execute("UPDATE meta SET value = value WHERE key = 'instance'")
    db.execute("COMMIT")
    time.sleep(0.02)
waits.sort()
print(len(waits), waits[len(waits) // 2], waits[int(0.99 * len(waits))], waits[-1])
"""


def bench_lock_hold(busy_threads: int = 20, group: int = 19, seconds: float = 20.0) -> dict:
    """What another process waits for the write lock (``BEGIN IMMEDIATE``, every 20 ms) while this
    one, its CPU taken by ``busy_threads`` pure-Python threads, commits windows ``group`` at a time
    (30 kB monitor states, 5 trend rows each): with the plain windows moved in one statement (as
    shipped) and with every window in a savepoint of one transaction (the path of windows with
    alarm changes, and of every window before). The other process's median, 99th percentile and
    longest wait, in ms."""
    import threading

    from contract import TrendRow
    from shm_service.service import Storage, WindowCommit

    results = {}
    for path in ("one statement", "transaction"):
        with tempfile.TemporaryDirectory() as tmp:
            st = Storage(Path(tmp) / "s.sqlite")
            if path == "transaction":
                st._write_plain = lambda batch: False  # type: ignore[method-assign]
            stop = threading.Event()

            def spin() -> None:
                x = 0
                while not stop.is_set():  # noqa: B023  (the threads end before the loop moves on)
                    x += 1

            def commits(i: int) -> None:
                k = 0
                while not stop.is_set():  # noqa: B023
                    rows = [TrendRow(source=f"s{i}", window_start_s=30.0 * k, window_end_s=30.0 * k + 60, mode=m, unit=m,
                                     kind="ambient", frequency_hz=1.0) for m in range(1, 6)]
                    st.commit_window(WindowCommit(f"s{i}", 30.0 * k, 30.0 * k + 60, rows, {"monitor": "y" * 30000}, None))  # noqa: B023
                    k += 1
                    time.sleep(0.05)

            threads = [threading.Thread(target=spin, daemon=True) for _ in range(busy_threads)]
            threads += [threading.Thread(target=commits, args=(i,), daemon=True) for i in range(group)]
            for t in threads:
                t.start()
            out = subprocess.run([sys.executable, "-c", _PROBE, str(st.path), str(seconds)], capture_output=True, text=True,
                                 check=True).stdout.split()
            stop.set()
            for t in threads:
                t.join(30)
            n, median, p99, worst = int(out[0]), *(1e3 * float(x) for x in out[1:])
            results[path] = {"probe_writes": n, "median_wait_ms": round(median, 2), "p99_wait_ms": round(p99, 1),
                             "worst_wait_ms": round(worst, 1), "windows_written": st.grouped_windows, "groups": st.groups}
            st.close()
    print(f"[lock] {busy_threads} busy threads, {group} committing: {json.dumps(results)}", flush=True)
    return results


def on_paper(per_file_s: float, overhead_s: float, commit_s: float, files: int = 1000, cores: int = 2) -> None:
    """What N machines of ``cores`` cores would give for ``files`` one-hour recordings: the
    files run in parallel on N·cores workers; the scheduler's per-task overhead and the
    client's commits (one SQLite writer) are serial."""
    print(f"[paper] {files} one-hour files, {per_file_s:.1f} s per file on one core, "
          f"{1e3 * overhead_s:.1f} ms scheduler overhead and {1e3 * commit_s:.0f} ms commit per file (serial):")
    for n in (1, 2, 4, 8, 16, 64):
        parallel = files * per_file_s / (n * cores)
        serial = files * (overhead_s + commit_s)
        wall = max(parallel, serial)  # the client commits while the workers compute
        print(f"[paper]   {n:3d} machine(s): {wall / 3600:7.2f} h ({files * 3600 / wall:8.0f} data-hours per hour); "
              f"serial part {serial:.0f} s")
    print("[paper]   (reading the files is the other shared resource: 600 MB per one-hour file from the shared disk)")


def bench_memory_per_structure(structures: int = 4, settle_s: float = 90.0) -> dict:
    """RSS of this process with 1..``structures`` simulated structures at real time, each a
    MonitoringService (its own database, no archive, no dashboard), sampled after ``settle_s``."""
    import psutil

    from shm_service.service import MonitoringService, load_settings

    proc = psutil.Process()
    services = []
    samples = []
    with tempfile.TemporaryDirectory() as tmp:
        try:
            for k in range(structures):
                settings = load_settings(None, {
                    "db": f"{tmp}/s{k}.sqlite", "source": {"spec": "sim", "speed": 1.0, "id": f"mast-{k:02d}"},
                    "sim": {"duration_s": 3600.0, "seed": k + 1}, "dashboard": {"enabled": False},
                    "archive": {"enabled": False},
                })
                service = MonitoringService(settings, environ={})
                service.start()
                services.append(service)
                time.sleep(settle_s)
                rss = proc.memory_info().rss / 2**20
                samples.append(round(rss, 1))
                print(f"[memory] {k + 1} structure(s): RSS {rss:7.1f} MiB", flush=True)
        finally:
            for service in services:
                service.stop(drain_s=0)
    increments = [round(b - a, 1) for a, b in zip(samples, samples[1:])]
    result = {"rss_mib": samples, "per_additional_structure_mib": increments, "load": _load()}
    print(f"[memory] {json.dumps(result)}", flush=True)
    return result


def bench_structure_cost(data_s: float = 300.0, block_s: tuple[float, ...] = (1.0, 2.0)) -> dict:
    """CPU per structure-second of one simulated structure (benchmark layout, Gamma = 4, 200 Hz),
    split into the virtual rig's generation and the pipeline (estimator, analysis, commits), run
    unpaced in this thread (``time.process_time``: the machine's load does not count)."""
    from shm_service.service import Storage, load_settings
    from shm_service.service.runtime._service import SinkGuard, Structure, _ModelCache

    class _Host:  # what a Structure asks of its service
        fleet = False

    results = {}
    for block in block_s:
        with tempfile.TemporaryDirectory() as tmp:
            settings = load_settings(None, {"db": f"{tmp}/s.sqlite", "sim": {"duration_s": data_s, "seed": 1, "block_s": block},
                                            "dashboard": {"enabled": False}, "archive": {"enabled": False},
                                            "source": {"speed": "max"}})
            structure = Structure(_Host(), settings, models=_ModelCache())
            storage = Storage(settings.db)
            structure.attach(storage, SinkGuard("dashboard", None))
            sim_s = pipeline_s = 0.0
            batches = structure.source.batches(block)
            while True:
                a = time.process_time()
                batch = next(batches, None)
                b = time.process_time()
                if batch is None:
                    break
                structure.pipeline.process(batch)
                sim_s += b - a
                pipeline_s += time.process_time() - b
            a = time.process_time()
            structure.pipeline.finish()
            pipeline_s += time.process_time() - a
            storage.close()
        r = {"block_s": block, "sim_ms_per_s": round(1e3 * sim_s / data_s, 2), "pipeline_ms_per_s": round(1e3 * pipeline_s / data_s, 2),
             "total_ms_per_s": round(1e3 * (sim_s + pipeline_s) / data_s, 2),
             "windows_committed": structure.pipeline.windows_committed, "load": _load()}
        r["structures_per_core_at_real_time"] = round(1e3 / r["total_ms_per_s"], 1)
        results[block] = r
        print(f"[cost] {r}", flush=True)
    return results


#: ``--compare``: the checkout whose ``shm serve`` the live fleet runs (None: this one's).
_SERVE_TREE: Path | None = None


def _start_tree_serve(tree: Path, args: list[str], log: IO[str], tmp: Path) -> tuple[subprocess.Popen, str]:
    """``shm serve ARGS`` of ``tree``'s code (its directory on PYTHONPATH, as its cwd) and its API's
    URL: from its ready file when that tree writes one, else from its "API at" banner (the trees
    before the ready file)."""
    import threading

    from shm_service.service import read_ready

    help_text = subprocess.run([sys.executable, "-m", "shm_service.cli", "serve", "--help"], cwd=tree, capture_output=True,
                               text=True, env={**os.environ, "PYTHONPATH": str(tree)}).stdout
    ready = tmp / "ready.json"
    extra = ["--ready-file", str(ready), "--parent-pid", str(os.getpid())] if "--ready-file" in help_text else []
    proc = subprocess.Popen([sys.executable, "-m", "shm_service.cli", "serve", *args, *extra], cwd=tree,
                            env={**os.environ, "PYTHONPATH": str(tree)}, stdout=subprocess.PIPE, stderr=log, text=True)
    assert proc.stdout is not None
    if extra:
        deadline = time.monotonic() + 600
        while (doc := read_ready(ready)) is None:
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                raise RuntimeError(f"{tree}: shm serve did not start: {(tmp / 'serve.log').read_text()[-2000:]}")
            time.sleep(0.1)
        url = str(doc["api"])
    else:
        line = proc.stdout.readline()
        if "API at " not in line:
            proc.kill()
            proc.wait(30)
            raise RuntimeError(f"{tree}: shm serve did not start: {(tmp / 'serve.log').read_text()[-2000:]}")
        url = line.split("API at ")[1].split()[0]
    # keep its stdout drained (a full pipe would stall it)
    threading.Thread(target=proc.stdout.read, daemon=True).start()
    return proc, url


def compare_cost(tree: Path, rounds: int = 2) -> dict:
    """``bench_structure_cost`` of ``tree`` (before) and of this tree (after), each in a process of
    its own, alternately ``rounds`` times: the CPU per structure-second of one simulated structure
    split into the virtual rig's generation and the pipeline (``time.process_time``, so the
    machine's load does not count). A live fleet's CPU is both: this says which one changed."""
    code = ("import json, benchmarks.bench_fleet as b; r = b.bench_structure_cost(block_s=(2.0,)); "
            "print('COST', json.dumps(r[2.0]))")
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    here = Path(__file__).resolve().parents[1]
    for k in range(rounds):
        order = [("before", tree), ("after", here)]
        for label, where in (order[::-1] if k % 2 else order):
            out = subprocess.run([sys.executable, "-c", code], cwd=where, capture_output=True, text=True, check=True,
                                 env={**os.environ, "PYTHONPATH": str(where)}).stdout
            runs[label].append(json.loads(out.split("COST ", 1)[1]))
    mean = {label: {key: round(sum(r[key] for r in rs) / len(rs), 2) for key in ("sim_ms_per_s", "pipeline_ms_per_s")}
            for label, rs in runs.items()}
    b, a = mean["before"], mean["after"]
    print(f"[compare] one structure, block 2 s, mean of {rounds}: the virtual rig {b['sim_ms_per_s']} / {a['sim_ms_per_s']} ms, "
          f"the pipeline (estimator, analysis, commits) {b['pipeline_ms_per_s']} / {a['pipeline_ms_per_s']} ms of CPU per "
          f"structure-second (before / after)", flush=True)
    return mean


def compare_live(tree: Path, structures: list[int], *, speed: float, seconds: float, dashboard: bool,
                 processes: tuple[int, ...] = (1, 2), repeats: int = 1, **options: Any) -> list[dict]:
    """Each live fleet on ``tree``'s ``shm serve`` (before) and on this tree's (after), one after
    the other on the same machine, and a line comparing the two: worst lag (overall and after the
    first minute), structures over 5 s, CPU per structure-second, RSS. ``repeats`` > 1: the pairs
    again in alternating order (before-after, after-before, ...: a drift of the machine over the
    run, its clock or its neighbours, falls on both trees alike) and the mean CPU of each tree."""
    global _SERVE_TREE
    out = []
    for n in structures:
        for workers in processes:
            cpu: dict[str, list[float]] = {"before": [], "after": []}
            for repeat in range(repeats):
                pair = _compare_pair(tree, n, workers, speed=speed, seconds=seconds, dashboard=dashboard,
                                     reverse=repeat % 2 == 1, **options)
                out.append(pair)
                for label in cpu:
                    cpu[label].append(pair[label]["cpu_ms_per_structure_second"])
            if repeats > 1:
                mb, ma = sum(cpu["before"]) / repeats, sum(cpu["after"]) / repeats
                print(f"[compare] {n} structures on {workers} process(es), {repeats} pairs in alternating order: CPU before "
                      f"{' '.join(map(str, cpu['before']))} (mean {mb:.2f}) / after {' '.join(map(str, cpu['after']))} "
                      f"(mean {ma:.2f}) ms per structure-second, after/before {ma / mb:.3f}", flush=True)
    return out


def _compare_pair(tree: Path, n: int, workers: int, *, speed: float, seconds: float, dashboard: bool, reverse: bool,
                  **options: Any) -> dict:
    """One fleet on each tree (``reverse``: this tree's first) and the line comparing them."""
    global _SERVE_TREE
    pair = {}
    order = [("before", tree), ("after", None)]
    for label, which in (order[::-1] if reverse else order):
        _SERVE_TREE = which
        try:
            print(f"[compare] {label}: {n} structures, {workers} process(es), {which or 'this tree'}", flush=True)
            pair[label] = bench_live_fleet(n, speed=speed, seconds=seconds, processes=workers, dashboard=dashboard,
                                           **options)
        finally:
            _SERVE_TREE = None
    b, a = pair["before"], pair["after"]
    after_key = next(k for k in a if k.startswith("worst_lag_after_"))
    print(f"[compare] {n} structures at speed {speed:g} on {workers} process(es), {seconds:g} s each: worst lag "
          f"before {b['worst_lag_s']} s / after {a['worst_lag_s']} s ({after_key}: {b[after_key]} / {a[after_key]} s), "
          f"over 5 s {b['structures_lag_over_5s']} / {a['structures_lag_over_5s']}, CPU "
          f"{b['cpu_ms_per_structure_second']} / {a['cpu_ms_per_structure_second']} ms per structure-second, "
          f"peak RSS {b['peak_rss_mib']} / {a['peak_rss_mib']} MiB, windows not committed "
          f"{b['windows_not_committed']} / {a['windows_not_committed']}", flush=True)
    return pair


def _fleet_toml(ids: list[str], block_s: float, duration_s: float) -> str:
    lines = ["[sim]", f"duration_s = {duration_s}", f"block_s = {block_s}", ""]
    for k, sid in enumerate(ids):
        lines += ["[[structures]]", f'id = "{sid}"', 'source = "sim"', "[structures.sim]", f"seed = {k + 1}", ""]
    return "\n".join(lines)


def _run_fleet(tmp: str, ids: list[str], workers: int, speed: float, seconds: float, block_s: float, poll_s: float,
               dashboard: bool, worst: dict, last: dict, first: dict, after_s: float,
               uncommitted: dict, threads: dict) -> tuple[float, float, float, str, dict]:
    """One ``shm serve`` of the fleet on ``workers`` worker processes (``--workers``; 1: all in the
    process started), polled at its one API; RSS and CPU of that process and its workers, and the
    most threads each process had (``threads``: pid -> (name, threads))."""
    import httpx
    import psutil

    cfg = Path(tmp) / "fleet.toml"
    cfg.write_text(_fleet_toml(ids, block_s, max(3600.0, 2 * speed * seconds)), encoding="utf-8")
    from shm_service.service import ServeStartError, start_serve

    args = ["--config", str(cfg), "--speed", str(speed), "--no-archive", "--port", "0", "--db", f"{tmp}/shm.sqlite",
            "--workers", str(workers), "--json"]
    args += ["--dashboard-port", "0"] if dashboard else ["--no-dashboard"]
    log = open(Path(tmp) / "serve.log", "w")
    if _SERVE_TREE is not None:  # --compare: the other tree's shm serve (it may predate the ready file)
        proc, url = _start_tree_serve(_SERVE_TREE, args, log, Path(tmp))
    else:
        try:
            serve = start_serve(args, stdout=subprocess.DEVNULL, stderr=log, timeout=600, ready_file=Path(tmp) / "ready.json")
        except ServeStartError as exc:
            raise RuntimeError(f"shm serve did not start ({exc}): {(Path(tmp) / 'serve.log').read_text()[-2000:]}") from None
        proc, url = serve.process, serve.url
    front = psutil.Process(proc.pid)
    load = _load()
    started = time.monotonic()
    peak_rss = 0.0
    cpu0 = None
    worst_after: dict[str, float] = {}
    with httpx.Client(timeout=30) as client:
        while time.monotonic() - started < seconds:
            time.sleep(poll_s)
            ps = [front, *front.children(recursive=True)]
            if cpu0 is None and len(ps) >= workers:  # the workers are up: CPU from here
                cpu0, cpu_started = sum(q.cpu_times().user + q.cpu_times().system for q in ps), time.monotonic()
            for s in client.get(f"{url}/api/structures").json()["structures"]:
                if s["id"] not in first and s["data_time_s"] is not None:  # its first poll with data (starts are staggered)
                    first[s["id"]] = s["data_time_s"]
                last[s["id"]] = s
                if s["lag_s"] is not None:
                    worst[s["id"]] = max(worst.get(s["id"], -1e9), s["lag_s"])
                    if time.monotonic() - started >= after_s:
                        worst_after[s["id"]] = max(worst_after.get(s["id"], -1e9), s["lag_s"])
            peak_rss = max(peak_rss, sum(q.memory_info().rss for q in ps) / 2**20)
            for q in ps:
                try:
                    n = q.num_threads()
                except psutil.NoSuchProcess:
                    continue
                role = "front" if q.pid == front.pid else "worker"
                threads[q.pid] = (role, max(n, threads.get(q.pid, (role, 0))[1]))
        # every window analysed is committed: what each structure analysed and wrote, at the end
        for sid in ids:
            p = client.get(f"{url}/api/structures/{sid}/status").json()["pipeline"]
            uncommitted[sid] = p["windows"] - p["windows_committed"]
    ps = [front, *front.children(recursive=True)]
    wall = time.monotonic() - cpu_started if cpu0 is not None else time.monotonic() - started
    cpu = sum(q.cpu_times().user + q.cpu_times().system for q in ps) - (cpu0 or 0.0)
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(90)
    except subprocess.TimeoutExpired:
        proc.kill()
    return wall, cpu, peak_rss, load, worst_after


def bench_live_fleet(structures: int, *, speed: float = 1.0, seconds: float = 240.0, processes: int = 1,
                     block_s: float = 2.0, poll_s: float = 5.0, dashboard: bool = False, after_s: float = 60.0,
                     hog: bool = False) -> dict:
    """``shm serve`` of ``structures`` simulated structures (``--no-archive``, with or without the
    dashboard) on ``processes`` worker processes (``--workers``: each hosts every n-th structure,
    one database, one API), for ``seconds`` of wall time at ``--speed``: the worst lag of every
    structure from ``/api/structures`` (polled every ``poll_s``; overall and after ``after_s``),
    windows committed, the RSS of all processes together and the CPU per structure-second.
    ``hog``: a CPU-bound process at ``nice 10`` runs beside the fleet for the whole run (the fleet budget's
    acceptance: ``nice -n 10 python -c "while True: pass"``)."""
    ids = [f"mast-{k + 1:03d}" for k in range(structures)]
    worst: dict[str, float] = {}
    last: dict[str, dict] = {}
    first: dict[str, float] = {}  # data time at the first poll with data
    uncommitted: dict[str, int] = {}  # windows analysed but not (yet) written, at the end
    threads: dict[int, tuple[str, int]] = {}
    spinner = subprocess.Popen(["nice", "-n", "10", sys.executable, "-c", "while True: pass"]) if hog else None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            wall, cpu, peak_rss, load, worst_after = _run_fleet(tmp, ids, processes, speed, seconds, block_s, poll_s,
                                                                dashboard, worst, last, first, after_s, uncommitted, threads)
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait()
    lags = [worst.get(i) for i in ids]
    windows = [last.get(i, {}).get("windows", 0) for i in ids]
    states = sorted({last.get(i, {}).get("state", "?") for i in ids})
    # the data the structures processed while measured (the CPU's denominator: a fleet that
    # falls behind processes less than speed x wall)
    data_s = sum((last[i]["data_time_s"] or first[i]) - first[i] for i in ids if i in first)
    result = {"structures": structures, "processes": processes, "dashboard": dashboard, "hog": hog, "speed": speed,
              "block_s": block_s,
              "wall_s": round(wall, 1), "worst_lag_s": None if None in lags else round(max(lags), 2),
              f"worst_lag_after_{after_s:g}s": round(max(worst_after.values()), 2) if worst_after else None,
              "structures_lag_over_5s": sum(1 for x in lags if x is None or x > 5.0),
              "min_windows": min(windows), "structures_without_windows": sum(1 for w in windows if w == 0),
              "windows_not_committed": sum(uncommitted.values()), "states": states,
              "peak_rss_mib": round(peak_rss, 1), "rss_per_structure_mib": round(peak_rss / structures, 1),
              "budget_mib": 1024 + 150 * structures,
              "cpu_cores": round(cpu / wall, 2),
              "data_s_processed": round(data_s, 1), "data_s_due": round(structures * speed * wall, 1),
              "cpu_ms_per_structure_second": round(1e3 * cpu / max(data_s, 1e-9), 2),
              "threads": sorted(threads.values()), "load_before": load,
              "load_after": _load()}
    print(f"[live] {result}", flush=True)
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--replay", default="/tmp/hour.mcap", help="one-hour recording (simulated if missing)")
    p.add_argument("--files", type=int, default=8)
    p.add_argument("--compare", default=None, metavar="TREE",
                   help="another checkout (e.g. the tree before a change): each live fleet on its shm serve and on this "
                        "one's, alternately, side by side (with --skip-live no second set of this tree's live runs)")
    p.add_argument("--compare-repeats", type=int, default=1, metavar="K",
                   help="--compare: K pairs in alternating order (before-after, after-before, ...) and the mean of each")
    p.add_argument("--structures", type=int, default=4)
    p.add_argument("--skip-reprocess", action="store_true")
    p.add_argument("--skip-memory", action="store_true")
    p.add_argument("--skip-live", action="store_true")
    p.add_argument("--live", type=int, nargs="*", default=[100], metavar="N",
                   help="live fleets of N simulated structures (one and two worker processes each)")
    p.add_argument("--live-s", type=float, default=690.0,
                   help="wall time of each live fleet, s (the budget: ten minutes at real time after the start-up)")
    p.add_argument("--live-speed", type=float, default=1.0)
    p.add_argument("--live-dashboard", action="store_true", help="live fleets with the dashboard on (worker 0 serves it)")
    p.add_argument("--live-processes", type=int, nargs="*", default=[1, 2], metavar="P",
                   help="worker processes of each live fleet (--workers of shm serve)")
    p.add_argument("--live-hog", action="store_true",
                   help='a CPU-bound process at nice 10 beside each live fleet (nice -n 10 python -c "while True: pass")')
    p.add_argument("--live-only", action="store_true", help="only the live fleets (no memory, cost, lock, scheduler, reprocess)")
    args, _ = p.parse_known_args(argv)
    if args.live_only:
        for n in args.live:
            for processes in args.live_processes:
                bench_live_fleet(n, speed=args.live_speed, seconds=args.live_s, processes=processes,
                                 dashboard=args.live_dashboard, hog=args.live_hog)
        return 0
    if not args.skip_memory:  # first: before this process imports the cluster's libraries
        bench_memory_per_structure(args.structures)
    bench_structure_cost()
    bench_lock_hold()
    if args.compare:  # with --live-processes and --live-hog where this tree has them
        compare_cost(Path(args.compare).resolve())
        compare_live(Path(args.compare).resolve(), args.live, speed=args.live_speed, seconds=args.live_s,
                     dashboard=args.live_dashboard, processes=tuple(getattr(args, "live_processes", (1, 2))),
                     repeats=args.compare_repeats,
                     **({"hog": True} if getattr(args, "live_hog", False) else {}))
    if not args.skip_live:
        for n in args.live:
            for processes in args.live_processes:
                bench_live_fleet(n, speed=args.live_speed, seconds=args.live_s, processes=processes,
                                 dashboard=args.live_dashboard, hog=args.live_hog)
    scheduler = bench_scheduler()
    if not args.skip_reprocess:
        results = bench_reprocess(Path(args.replay), args.files)
        one = results[1]
        on_paper(one["wall_s"] / args.files, scheduler["overhead_ms_per_task"] / 1e3, bench_commit())
    return 0


if __name__ == "__main__":
    sys.exit(main())
