"""The crash part of the fault campaign: ``shm serve`` replaying a recording with
an alarm in it (a mass added at 90 s) is killed with SIGKILL at random instants, restarted each
time on the same database, while a webhook receiver delays some of its 2xx answers. After every
kill: ``PRAGMA integrity_check`` is ok and no committed row (trend rows, alarms, alarm events,
outbox rows) is gone. At the end (a last run to its end, every notification out): every
committed alarm event reached the receiver at least once, the events of each alarm arrived in
their sequence order (first arrivals), and the repeats are counted: the design promises
at-least-once delivery, a receiver deduplicates by ``id`` / ``Idempotency-Key``.

``python -m benchmarks.kill_campaign --kills 20`` prints the figures (JSON);
``tests/shm_service/service/test_serve_end_to_end.py`` kills once.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
FAST = {"analytics": {"window_s": 20.0, "overlap": 0.5, "baseline_s": 40.0, "baseline_min_windows": 3},
        "estimator": {"calibration_s": 10.0, "warmup_s": 5.0, "chunk_s": 1.0}, "archive": {"enabled": False}}


class Receiver:
    """Webhook receiver: answers 200, a share ``delay_share`` of the answers after 0.2-1.5 s."""

    def __init__(self, rng: random.Random, delay_share: float = 0.3) -> None:
        self.posts: list[dict[str, Any]] = []
        self.lock = threading.Lock()
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                with outer.lock:
                    delay = rng.uniform(0.2, 1.5) if rng.random() < delay_share else 0.0
                time.sleep(delay)
                doc = json.loads(body)
                with outer.lock:
                    outer.posts.append({"id": doc["id"], "key": self.headers.get("Idempotency-Key"),
                                        "alarm": doc["alarm"]["id"], "sequence": doc["sequence"], "event": doc["event"]})
                self.send_response(200)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def _snapshot(db: Path) -> dict[str, set]:
    con = sqlite3.connect(db, timeout=30)
    try:
        return {
            "trends": set(con.execute("SELECT source, window_start_s, mode FROM trends").fetchall()),
            "alarms": set(con.execute("SELECT id, chart, raised_at_s FROM alarms").fetchall()),
            "events": set(con.execute("SELECT id, alarm_id, seq, uuid FROM alarm_events").fetchall()),
            "outbox": set(con.execute("SELECT id, event_id FROM outbox").fetchall()),
        }
    finally:
        con.close()


def _integrity(db: Path) -> str:
    con = sqlite3.connect(db, timeout=30)
    try:
        return str(con.execute("PRAGMA integrity_check").fetchone()[0])
    finally:
        con.close()


def _start(tmp: Path, recording: Path, webhook: str) -> tuple[subprocess.Popen, str]:
    import tomli_w

    toml = tmp / "serve.toml"
    toml.write_text(tomli_w.dumps(FAST))
    from shm_service.service import start_serve

    args = ["--config", str(toml), "--source", f"replay:{recording}", "--speed", "max", "--no-dashboard", "--port", "0",
            "--db", str(tmp / "shm.sqlite"), "--webhook", webhook, "--keep-running", "--json"]
    serve = start_serve(args, cwd=tmp, env={**os.environ, "PYTHONPATH": str(ROOT)}, stdout=subprocess.DEVNULL,
                        stderr=subprocess.DEVNULL, timeout=120, ready_file=tmp / "ready.json")
    return serve.process, serve.url


def campaign(kills: int = 20, *, seed: int = 7, max_delay_s: float = 15.0, workdir: Path | None = None) -> dict[str, Any]:
    import httpx

    from shm_service.virtual_rig import SimulationSettings, simulate

    rng = random.Random(seed)
    tmp = Path(workdir or tempfile.mkdtemp(prefix="shm-kill-campaign-"))
    recording = tmp / "alarm.mcap"
    simulate(SimulationSettings(duration=150.0, rest=10.0, excitation="ambient", seed=3, damage=("mass:0.126@4.0",),
                                damage_at=90.0), recording)
    db = tmp / "shm.sqlite"
    receiver = Receiver(random.Random(seed + 1))
    previous: dict[str, set] | None = None
    lost: dict[str, int] = {"trends": 0, "alarms": 0, "events": 0, "outbox": 0}
    integrity: list[str] = []
    instants: list[float] = []
    began = time.perf_counter()
    try:
        for _ in range(kills):
            proc, _url = _start(tmp, recording, receiver.url)
            instant = rng.uniform(0.2, max_delay_s)
            instants.append(round(instant, 2))
            time.sleep(instant)
            proc.send_signal(signal.SIGKILL)
            proc.wait(30)
            integrity.append(_integrity(db))
            now = _snapshot(db)
            if previous is not None:
                for table in lost:
                    lost[table] += len(previous[table] - now[table])
            previous = now
        # the last run: to its end, and until every notification is out
        proc, url = _start(tmp, recording, receiver.url)
        deadline = time.monotonic() + 600
        with httpx.Client(base_url=url, timeout=10) as c:
            while time.monotonic() < deadline:
                st = c.get("/api/status").json()
                if st["service"]["done"] and st["notifications"]["pending"] == 0:
                    break
                time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
        integrity.append(_integrity(db))
        final = _snapshot(db)
        if previous is not None:
            for table in lost:
                lost[table] += len(previous[table] - final[table])
    finally:
        receiver.close()
    con = sqlite3.connect(db)
    outbox = con.execute("SELECT o.status, e.uuid FROM outbox o JOIN alarm_events e ON e.id = o.event_id").fetchall()
    con.close()
    posts = list(receiver.posts)
    received = {p["id"] for p in posts}
    committed = {f for _, f in outbox}
    undelivered = sum(1 for status, event_uuid in outbox if not any(r.endswith(event_uuid) for r in received))
    first_seen: dict[int, list[int]] = {}
    seen: set[str] = set()
    for p in posts:
        if p["id"] not in seen:
            seen.add(p["id"])
            first_seen.setdefault(p["alarm"], []).append(p["sequence"])
    out_of_order = sum(1 for seqs in first_seen.values() if seqs != sorted(seqs))
    return {
        "kills": kills, "instants_s": instants, "wall_s": round(time.perf_counter() - began, 1),
        "integrity_ok": sum(1 for i in integrity if i == "ok"), "integrity_checks": len(integrity),
        "committed_rows_lost": lost, "trend_rows": len(final["trends"]), "alarms": len(final["alarms"]),
        "alarm_events": len(final["events"]), "outbox_rows": len(outbox),
        "outbox_by_status": {s: sum(1 for st, _ in outbox if st == s) for s in {st for st, _ in outbox}},
        "events_committed": len(committed), "events_undelivered": undelivered, "posts": len(posts),
        "duplicates": len(posts) - len(received), "alarms_out_of_order": out_of_order,
        "keys_match_ids": all(p["key"] == p["id"] for p in posts),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.kill_campaign", description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--max-delay", type=float, default=15.0, help="latest kill instant after the API is up, s")
    args, _ = ap.parse_known_args(argv)
    result = campaign(args.kills, seed=args.seed, max_delay_s=args.max_delay)
    print(json.dumps(result, indent=1))
    bad = (any(result["committed_rows_lost"].values()) or result["events_undelivered"] or result["alarms_out_of_order"]
           or result["integrity_ok"] != result["integrity_checks"])
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
