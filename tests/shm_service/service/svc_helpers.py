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
    """A tiny webhook receiver: records every POST it answers 2xx (body, Idempotency-Key, arrival
    time). ``fail_first`` answers 500 that many times; ``script`` is a list of statuses (or
    callables body -> status) used one per request before the default 200; ``delay_s(body)`` is
    how long an answer waits (a slow receiver)."""

    def __init__(self, fail_first: int = 0, script=None, delay_s=None) -> None:
        import time

        self.posts: list[dict] = []
        self.keys: list[str] = []
        self.times: list[float] = []
        self.refused: list[tuple[int, dict]] = []  # (status, body) of the requests not answered 2xx
        self.fail_first = fail_first
        self.script = list(script or [])
        self.delay_s = delay_s
        self.lock = threading.Lock()
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                doc = json.loads(body)
                if receiver.delay_s is not None:
                    time.sleep(receiver.delay_s(doc))
                with receiver.lock:
                    status = 200
                    if receiver.fail_first > 0:
                        receiver.fail_first -= 1
                        status = 500
                    elif receiver.script:
                        step = receiver.script.pop(0)
                        status = step(doc) if callable(step) else step
                    if 200 <= status < 300:
                        receiver.posts.append(doc)
                        receiver.keys.append(self.headers.get("Idempotency-Key", ""))
                        receiver.times.append(time.monotonic())
                    else:
                        receiver.refused.append((status, doc))
                self.send_response(status)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def wait_for(predicate, timeout: float = 60.0, what: str = "condition", poll: float = 0.05):
    """The first truthy value of ``predicate()`` within ``timeout`` s (else AssertionError naming ``what``)."""
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
