"""Helpers of the service tests: fast analytics settings, a webhook receiver."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path


#: Small analytics windows and sensitive charts so that a short recording gives windows,
#: a baseline and alarms within seconds of data.
FAST = {
    "analytics": {"window_s": 20.0, "overlap": 0.5, "baseline_s": 40.0, "baseline_min_windows": 3, "hold_windows": 1,
                  "warning_sigma": 0.5, "alarm_sigma": 1.0, "clear_sigma": 0.2, "curvature_alarm_sigma": 1.0,
                  "curvature_memory_windows": 2.0},
    "estimator": {"calibration_s": 10.0, "warmup_s": 5.0, "chunk_s": 1.0},
    "alarms": {"raise_windows": 1, "clear_windows": 2},
    "dashboard": {"enabled": False},
    "server": {"port": 0},
}


def fast_overrides(tmp: Path, **extra) -> dict:
    out = json.loads(json.dumps(FAST))
    out["db"] = str(tmp / "shm.sqlite")
    out["archive"] = {"directory": str(tmp / "recordings")}
    for key, value in extra.items():
        node = out
        *parents, leaf = key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return out


class Receiver:
    """A tiny webhook receiver: records every POST; ``fail_first`` answers 500 that many times."""

    def __init__(self, fail_first: int = 0) -> None:
        self.posts: list[dict] = []
        self.keys: list[str] = []
        self.fail_first = fail_first
        self.lock = threading.Lock()
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                with receiver.lock:
                    if receiver.fail_first > 0:
                        receiver.fail_first -= 1
                        self.send_response(500)
                        self.end_headers()
                        return
                    receiver.posts.append(json.loads(body))
                    receiver.keys.append(self.headers.get("Idempotency-Key", ""))
                self.send_response(200)
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


