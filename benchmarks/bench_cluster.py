"""Structures per node when the data come from an MQTT broker (a benchmark, not a test).

One node (``shm serve --config fleet.toml --node bench``) on a throwaway PostgreSQL and Mosquitto
(``shm_service.devservers``) runs N structures with ``source = "mqtt"`` and the mast's rig
description (``examples/mast/rig.json``: its two hot spots, so the loads are counted). A separate
publisher process (this module with ``--publish``, a field gateway) replays virtual-rig recordings
made beforehand (``shm simulate``, operational excitation; no simulation inside the node) at real
time in 1 s bodies with QoS 1, each stamped with the wall clock, to ``<prefix>/<id>/ingest``. The
node's ``/api/structures`` is polled: the worst lag of every structure (now minus its newest
processed data) over the run. PostgreSQL's own counters (``pg_stat_database``) give the database
writes per second: transactions committed and rows written (inserted + updated + deleted).

N grows along a ladder (``--ladder``) until a run's worst lag exceeds ``--bound`` (5 s): the
largest N within it is the figure of this machine. In the same run, bench_fleet's single-machine
fleet (``shm serve`` of N simulated structures on one SQLite file) runs at that N for the
side-by-side line.

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.bench_cluster [--quick] [--ladder 50,100,150,200,250,300]
     [--seconds 300] [--bound 5] [--recordings 4] [--skip-single]
(``--quick``: 2 and 4 structures, 60 s each.)
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

ROOT = Path(__file__).resolve().parent.parent
RIG = ROOT / "examples" / "mast" / "rig.json"
_SENSOR_KINDS = ("imu", "tof", "strain", "bearing", "temperature")


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def make_recordings(directory: Path, count: int, duration_s: float) -> list[Path]:
    """``count`` recordings of the mast (operational excitation, seeds 1..count), ``duration_s`` each."""
    paths = []
    for k in range(count):
        path = directory / f"mast-{k + 1}.mcap"
        subprocess.run([sys.executable, "-m", "shm_service.cli", "simulate", "--rig", str(RIG), "--excitation", "operational",
                        "--duration", f"{duration_s:g}", "--seed", str(k + 1), "--out", str(path)],
                       check=True, stdout=subprocess.DEVNULL)
        paths.append(path)
    return paths


class _Replay:
    """One recording as ingest bodies of 1 s: the contract payloads encoded once, each body's
    stamps made at publish time (the recording loops when the run is longer)."""

    def __init__(self, path: Path) -> None:
        import numpy as np
        import orjson

        from shm_service.recording import read_recording
        from shm_service.virtual_rig._record import encode_payloads

        rec = read_recording(path, kinds=_SENSOR_KINDS)
        self.seconds = int(rec.duration_s)
        offsets, topics, payloads = [], [], []
        for topic, ch in rec.channels.items():
            offsets.append(ch.log_time_ns - rec.start_ns)
            topics += [topic] * len(ch)
            payloads += [orjson.loads(p) for p in encode_payloads(topic, ch.values)]
        off = np.concatenate(offsets)
        order = np.argsort(off, kind="stable")
        self.offsets = off[order]
        self.topics = [topics[i] for i in order.tolist()]
        self.payloads = [payloads[i] for i in order.tolist()]
        self.edges = np.searchsorted(self.offsets, np.arange(self.seconds + 1) * 1_000_000_000)

    def body(self, k: int, start_ns: int) -> bytes:
        """The body of second ``k`` of the run (wall clock ``start_ns`` at its beginning)."""
        import orjson

        j = k % self.seconds
        lo, hi = int(self.edges[j]), int(self.edges[j + 1])
        base = start_ns + k * 1_000_000_000 - j * 1_000_000_000
        return orjson.dumps({"messages": [{"topic": self.topics[i], "log_time_ns": base + int(self.offsets[i]),
                                           "payload": self.payloads[i]} for i in range(lo, hi)]})


def publish(url: str, prefix: str, ids: list[str], recordings: list[Path], seconds: float) -> int:
    """The publisher process: every second, one body per structure (structure i replays recording
    i mod len), stamped with the second just ended, QoS 1; it prints how far behind it fell."""
    from urllib.parse import urlsplit

    import paho.mqtt.client as mqtt
    from paho.mqtt.enums import MQTTProtocolVersion

    replays = [_Replay(p) for p in recordings]
    parts = urlsplit(url)
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"bench-gateway-{os.getpid()}",
                         protocol=MQTTProtocolVersion.MQTTv5)
    client.max_inflight_messages_set(1000)
    client.connect(parts.hostname or "127.0.0.1", parts.port or 1883)
    client.loop_start()
    start_ns = time.time_ns()
    late = 0.0
    pending: list = []
    k = 0
    try:
        while k < seconds:
            due = start_ns / 1e9 + k + 1  # the body of second k is complete at its end
            wait = due - time.time()
            if wait > 0:
                time.sleep(wait)
            late = max(late, -wait)
            bodies = [r.body(k, start_ns) for r in replays]
            pending = [info for info in pending if not info.is_published()]
            for i, sid in enumerate(ids):
                pending.append(client.publish(f"{prefix}/{sid}/ingest", bodies[i % len(bodies)], qos=1))
            k += 1
        for info in pending:
            info.wait_for_publish(30)
    finally:
        client.disconnect()
        client.loop_stop()
    print(json.dumps({"bodies": k * len(ids), "publisher_worst_late_s": round(late, 2)}), flush=True)
    return 0


def _fleet_toml(ids: list[str], storage_url: str, mqtt_url: str, prefix: str) -> str:
    lines = ["[storage]", f'url = "{storage_url}"', "", "[mqtt]", f'url = "{mqtt_url}"', f'topic_prefix = "{prefix}"', "",
             "[nodes]", "lease_s = 15.0", ""]
    for sid in ids:
        lines += ["[[structures]]", f'id = "{sid}"', 'source = "mqtt"', f'rig = "{RIG}"', ""]
    return "\n".join(lines)


def _db_counters(url: str) -> tuple[int, int]:
    """(transactions committed, rows inserted + updated + deleted) of the database of ``url``."""
    import psycopg

    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("SELECT pg_stat_force_next_flush()") if conn.info.server_version >= 150000 else None
        row = conn.execute("SELECT xact_commit, tup_inserted + tup_updated + tup_deleted FROM pg_stat_database "
                           "WHERE datname = current_database()").fetchone()
    assert row is not None
    return int(row[0]), int(row[1])


def _fresh_database(base_url: str, name: str) -> str:
    import psycopg

    with psycopg.connect(base_url, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    return base_url.rsplit("/", 1)[0] + "/" + name


def run_node(n: int, *, postgres_url: str, mqtt_url: str, recordings: list[Path], seconds: float, bound_s: float,
             poll_s: float = 5.0, after_s: float = 30.0) -> dict:
    """One node with ``n`` mqtt structures for ``seconds`` of published data: worst lag, writes/s, CPU."""
    import httpx
    import psutil

    from shm_service.service import ServeStartError, start_serve

    ids = [f"mast-{k + 1:03d}" for k in range(n)]
    prefix = f"bench{n}x{os.getpid()}"
    url = _fresh_database(postgres_url, f"bench_{n}_{os.getpid()}")
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "fleet.toml"
        cfg.write_text(_fleet_toml(ids, url, mqtt_url, prefix), encoding="utf-8")
        log = open(Path(tmp) / "node.log", "w")
        try:
            serve = start_serve(["--config", str(cfg), "--node", "bench", "--no-archive", "--no-dashboard", "--port", "0", "--json"],
                                stdout=subprocess.DEVNULL, stderr=log, timeout=600, ready_file=Path(tmp) / "ready.json")
        except ServeStartError as exc:
            raise RuntimeError(f"the node did not start ({exc}): {(Path(tmp) / 'node.log').read_text()[-2000:]}") from None
        node = psutil.Process(serve.process.pid)
        worst: dict[str, float] = {}
        worst_after = -1e9
        series: list[float | None] = []  # the fleet's worst lag at each poll
        last: dict[str, dict] = {}
        publisher = None
        try:
            with httpx.Client(timeout=30) as client:
                deadline = time.monotonic() + 300
                while time.monotonic() < deadline:  # every structure held and subscribed before the first body
                    rows = client.get(f"{serve.url}/api/structures").json()["structures"]
                    # "running": its source connected to the broker (its subscription follows at once)
                    if len(rows) == n and all(r.get("node") == "bench" and r["state"] == "running" for r in rows):
                        break
                    time.sleep(1.0)
                else:
                    raise RuntimeError(f"the node did not hold and connect its {n} structures within 300 s: "
                                       f"{sorted({(r.get('node'), r['state']) for r in rows})}")
                time.sleep(3.0)
                load = _load()
                commits0, rows0 = _db_counters(url)
                procs = [node, *node.children(recursive=True)]
                cpu0 = sum(q.cpu_times().user + q.cpu_times().system for q in procs)
                started = time.monotonic()
                publisher = subprocess.Popen([sys.executable, "-m", "benchmarks.bench_cluster", "--publish", mqtt_url, prefix,
                                              ",".join(ids), ",".join(map(str, recordings)), f"{seconds:g}"],
                                             cwd=ROOT, stdout=subprocess.PIPE, text=True)
                # measured while data arrive: once the publisher has ended, the lag only grows with the wall clock
                while True:
                    ended = publisher.poll() is not None
                    if not ended:
                        try:  # back at once when it ends, so that no poll falls after the data stopped
                            publisher.wait(poll_s)
                        except subprocess.TimeoutExpired:
                            pass
                    polled = client.get(f"{serve.url}/api/structures").json()["structures"]
                    for s in polled:
                        last[s["id"]] = s
                        if s["lag_s"] is not None:
                            worst[s["id"]] = max(worst.get(s["id"], -1e9), s["lag_s"])
                            if time.monotonic() - started >= after_s:
                                worst_after = max(worst_after, s["lag_s"])
                    series.append(max((s["lag_s"] for s in polled if s["lag_s"] is not None), default=None))
                    if ended or time.monotonic() - started > seconds + 120:
                        break
                wall = time.monotonic() - started
                procs = [node, *node.children(recursive=True)]
                cpu = sum(q.cpu_times().user + q.cpu_times().system for q in procs) - cpu0
                commits1, rows1 = _db_counters(url)
            published = json.loads((publisher.communicate(timeout=60)[0] or "{}").strip().splitlines()[-1] or "{}")
        finally:
            if publisher is not None and publisher.poll() is None:
                publisher.kill()
                publisher.wait()
            serve.process.send_signal(signal.SIGINT)
            try:
                serve.process.wait(90)
            except subprocess.TimeoutExpired:
                serve.process.kill()
                serve.process.wait()
            log.close()
    lags = [worst.get(i) for i in ids]
    windows = [last.get(i, {}).get("windows", 0) for i in ids]
    result = {"structures": n, "seconds": seconds, "worst_lag_s": None if None in lags else round(max(lags), 2),
              f"worst_lag_after_{after_s:g}s": round(worst_after, 2) if worst_after > -1e9 else None,
              "lag_per_poll_s": [None if x is None else round(x, 1) for x in series],
              "structures_lag_over_bound": sum(1 for x in lags if x is None or x > bound_s),
              "min_windows": min(windows), "states": sorted({last.get(i, {}).get("state", "?") for i in ids}),
              "db_commits_per_s": round((commits1 - commits0) / wall, 1), "db_rows_per_s": round((rows1 - rows0) / wall, 1),
              "cpu_cores": round(cpu / wall, 2), **published, "load_before": load, "load_after": _load()}
    result["at_real_time"] = result["worst_lag_s"] is not None and result["structures_lag_over_bound"] == 0
    print(f"[cluster] {result}", flush=True)
    return result


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--publish"]:
        url, prefix, ids, recordings, seconds = argv[1:6]
        return publish(url, prefix, ids.split(","), [Path(p) for p in recordings.split(",")], float(seconds))
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--quick", action="store_true", help="2 and 4 structures, 60 s each")
    p.add_argument("--ladder", default=None, help="structure counts to try, ascending (default 50,100,150,200,250,300)")
    p.add_argument("--seconds", type=float, default=None, help="published data per run, s (default 300; --quick 60)")
    p.add_argument("--bound", type=float, default=5.0, help="the worst lag at real time, s")
    p.add_argument("--recordings", type=int, default=4, help="distinct recordings the structures replay")
    p.add_argument("--skip-single", action="store_true", help="leave out the single-machine fleet")
    args, _ = p.parse_known_args(argv)
    ladder = [int(x) for x in (args.ladder or ("2,4" if args.quick else "50,100,150,200,250,300")).split(",")]
    seconds = args.seconds or (60.0 if args.quick else 300.0)
    from shm_service.devservers import start_mosquitto, start_postgres

    print(f"[cluster] this machine: {os.cpu_count()} cores, load {_load()}; ladder {ladder}, {seconds:g} s each, "
          f"bound {args.bound:g} s", flush=True)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        recordings = make_recordings(Path(tmp), args.recordings if not args.quick else 2, min(seconds + 30.0, 600.0))
        with start_postgres() as postgres, start_mosquitto() as broker:
            for n in ladder:
                r = run_node(n, postgres_url=postgres.url, mqtt_url=broker.url, recordings=recordings, seconds=seconds,
                             bound_s=args.bound)
                results.append(r)
                if not r["at_real_time"]:
                    break
    passing = [r for r in results if r["at_real_time"]]
    best = passing[-1] if passing else None
    single = None
    if not args.skip_single:
        from benchmarks.bench_fleet import bench_live_fleet

        single = bench_live_fleet(best["structures"] if best else ladder[0], seconds=seconds + 60.0, after_s=60.0)
    print("[cluster] side by side (one node on PostgreSQL + Mosquitto | the single-machine fleet on SQLite, simulated):")
    if best is None:
        print(f"[cluster]   no rung of {ladder} ran at real time (worst lag {results[0]['worst_lag_s']} s)")
    else:
        print(f"[cluster]   {best['structures']} structures at real time from the broker: worst lag {best['worst_lag_s']} s, "
              f"{best['db_commits_per_s']} commits/s, {best['db_rows_per_s']} rows written/s, {best['cpu_cores']} cores")
    if single is not None:
        print(f"[cluster]   {single['structures']} simulated structures on one machine (bench_fleet): worst lag "
              f"{single['worst_lag_s']} s ({single['structures_lag_over_5s']} over 5 s), {single['cpu_cores']} cores")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
