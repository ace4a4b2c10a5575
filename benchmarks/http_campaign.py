"""The HTTP part of the fault campaign: generated requests against the real
server (uvicorn on a free loopback port, an ingest service on a real SQLite file), half to an
API bound as on loopback, half to one that requires the token everywhere (as off loopback), with
and without the token: mutated query parameters and path ids, ingest bodies with NaN, Infinity,
huge integers, deep nesting, wrong types, random bytes, truncated JSON, chunked bodies below and
above the limits, odd Host and Authorization headers, odd methods. Every answer must be a 2xx,
3xx or 4xx with a JSON ``detail`` (never a 5xx, never a dropped connection).

``python -m benchmarks.http_campaign --requests 10000`` prints the status counts;
``tests/shm_service/service/test_open_doors.py`` runs a short seeded part.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

TOKEN = "campaign-token-0123"
_T0 = 1_767_225_600_000_000_000
_PATHS = ("/healthz", "/api/status", "/api/trends", "/api/alarms", "/api/spectra/latest", "/metrics", "/openapi.json",
          "/docs", "/redoc", "/docs-static/swagger-ui.css")
_ODD = ("", " ", "NaN", "Infinity", "-1", "0", "1e400", "9" * 40, "-9" * 20, "\u00e9\u4e2d", "%00", "'; DROP TABLE trends; --",
        "2026-01-01T00:00:00", "2026-13-45T99:99:99Z", "x" * 5000, "null", "[]", "{}", "true")


def _imu(rng: random.Random, i: int) -> dict:
    return {"accel": [-9.81, rng.uniform(-1, 1), 0.0], "gyro": [0.0, 0.0, rng.uniform(-0.01, 0.01)]}


def _number(rng: random.Random) -> Any:
    return rng.choice([float("nan"), float("inf"), -float("inf"), 10**29, -(10**40), 2**63, 2**64 + 1, 1e308, -1e-320,
                       True, None, "1.0", [], {}, 0])


def _ingest_body(rng: random.Random, n: int) -> bytes:
    kind = rng.randrange(12)
    t = _T0 + n * 10_000_000 + rng.randrange(10**6)
    if kind == 0:  # NaN / Infinity literals (orjson refuses them; the parser must answer 400 or count them)
        return ('{"messages": [{"topic": "/imu/D", "log_time_ns": %d, "payload": {"accel": [NaN, Infinity, -Infinity], '
                '"gyro": [0, 0, 0]}}]}' % t).encode()
    if kind == 1:  # huge integers anywhere
        big = "9" * rng.choice([20, 30, 400, 5000])
        return ('{"messages": [{"topic": "/tof/s1", "log_time_ns": %s, "payload": {"distance": %s}}]}'
                % (rng.choice([big, str(t)]), rng.choice([big, "0.5"]))).encode()
    if kind == 2:  # deep nesting
        depth = rng.choice([100, 1000, 5000, 100_000])
        return ('{"messages": ' + "[" * depth + "]" * depth + "}").encode()
    if kind == 3:  # random bytes
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 400)))
    if kind == 4:  # truncated valid JSON
        body = json.dumps({"messages": [{"topic": "/imu/D", "log_time_ns": t + i, "payload": _imu(rng, i)} for i in range(5)]})
        return body[: rng.randrange(1, len(body))].encode()
    if kind == 5:  # wrong types in every place
        msg = {"topic": rng.choice(["/imu/D", 5, None, "", "/nope", "/truth/state"]),
               "log_time_ns": rng.choice([t, -1, "x", 1.5, None, 2**70]),
               "payload": rng.choice([{"distance": _number(rng)}, {"accel": [_number(rng)] * 3, "gyro": [0, 0, 0]},
                                      "str", [], None, {"strain": _number(rng)}])}
        if rng.random() < 0.3:
            msg["extra"] = {"deep": [[[_number(rng)]]]}
        doc: Any = rng.choice([{"messages": [msg] * rng.randrange(1, 4)}, [msg], {"messages": msg}, {"messages": None}, msg])
        return json.dumps(doc, allow_nan=True, default=str).encode()
    if kind == 6:  # a valid batch (time moves on)
        return json.dumps({"messages": [{"topic": "/imu/D", "log_time_ns": t + i * 5_000_000, "payload": _imu(rng, i)}
                                        for i in range(rng.randrange(1, 50))]}).encode()
    if kind == 7:  # unicode and control characters in strings
        return json.dumps({"messages": [{"topic": "/imu/D\u0000\u202e", "log_time_ns": t, "payload": {"\ud800x": 1}}]},
                          ensure_ascii=rng.random() < 0.5).encode("utf-8", "surrogatepass")
    if kind == 8:  # duplicate keys, empty object
        return rng.choice([b'{"messages": [], "messages": [1]}', b"{}", b"", b"null", b'{"messages": []}'])
    if kind == 9:  # many messages
        return json.dumps({"messages": [{"topic": "/tof/s1", "log_time_ns": t + i, "payload": {"distance": 0.5}}
                                        for i in range(rng.choice([1000, 5000]))]}).encode()
    if kind == 10:  # implausible values and times
        return json.dumps({"messages": [{"topic": "/imu/D", "log_time_ns": t + rng.choice([10**18, -(10**17), 0]),
                                         "payload": {"accel": [1e6, 0, 0], "gyro": [0, 0, 0]}},
                                        {"topic": "/tof/s1", "log_time_ns": t, "payload": {"distance": -5.0}},
                                        {"topic": "/strain/g1", "log_time_ns": t, "payload": {"strain": 0.5}}]}).encode()
    return json.dumps({"messages": [{"topic": "/imu/D", "log_time_ns": t, "payload": _imu(rng, 0)}],
                       "pad": "x" * rng.choice([10, 70_000, 300_000])}).encode()


def _request(rng: random.Random, n: int, port: int, token: bool) -> dict[str, Any]:
    """One generated request as httpx.request keyword arguments."""
    headers: dict[str, str] = {}
    if token:
        headers["Authorization"] = f"Bearer {TOKEN}"
    roll = rng.random()
    if roll < 0.05:  # odd or guessed credentials
        headers["Authorization"] = rng.choice(["Bearer", "Basic !!!", "Basic " + "QQ==" * 2, "Negotiate x",
                                               "Bearer " + "x" * 3000, f"Bearer {TOKEN}x", f"bearer {TOKEN}"])
    elif roll < 0.1:
        headers["X-SHM-Token"] = rng.choice(["", TOKEN, "wrong-token", "\u00e9" * 10])
    if rng.random() < 0.1:  # odd Host headers
        headers["Host"] = rng.choice(["evil.example", f"evil.example:{port}", "localhost", f"127.0.0.1:{port}", "[::1]",
                                      "a" * 300, "xn--bcher-kva.example", "127.0.0.1:notaport", "[::1", "user@host",
                                      "localhost.", "LOCALHOST", "0.0.0.0", "169.254.169.254"])
    kind = rng.randrange(10)
    if kind <= 3:
        path = rng.choice(_PATHS)
        params = {rng.choice(["from", "to", "mode", "format", "limit", "source", "state", "x"]): rng.choice(_ODD)
                  for _ in range(rng.randrange(0, 4))}
        return {"method": "GET", "url": path, "params": params, "headers": headers}
    if kind <= 6:
        body = _ingest_body(rng, n)
        if rng.random() < 0.3:  # chunked (no Content-Length)
            step = rng.choice([7, 512, 16384])
            return {"method": "POST", "url": "/api/ingest", "headers": {**headers, "Content-Type": "application/json"},
                    "content": (body[i:i + step] for i in range(0, max(len(body), 1), step))}
        return {"method": "POST", "url": "/api/ingest", "headers": {**headers, "Content-Type": "application/json"},
                "content": body}
    if kind == 7:
        alarm = rng.choice(["1", "0", "-1", "9" * 30, "abc", "1.5", "%20", str(2**62), str(2**63)])
        return {"method": "POST", "url": f"/api/alarms/{alarm}/ack", "headers": headers,
                "content": rng.choice([b"", b"{}", b"x" * 70_000])}
    if kind == 8:
        size = rng.choice([0, 10, 65_536, 70_000])
        content: Any = b"y" * size
        if rng.random() < 0.5:
            content = (b"y" * 4096 for _ in range(size // 4096 + 1))
        return {"method": "POST", "url": "/api/baseline", "headers": headers, "content": content}
    return {"method": rng.choice(["PUT", "DELETE", "PATCH", "OPTIONS", "HEAD", "TRACE"]),
            "url": rng.choice([*_PATHS, "/api/ingest", "/api/baseline", "/nope", "/" + "a" * 2000, "/api/../etc/passwd"]),
            "headers": headers}


def campaign(requests: int, *, seed: int = 11, workdir: Path | None = None) -> dict[str, Any]:
    """Send ``requests`` generated requests; returns the counts by status and the 5xx examples."""
    import httpx

    from shm_service.service import ApiServer, MonitoringService, create_app, load_settings

    tmp = Path(workdir or tempfile.mkdtemp(prefix="shm-http-campaign-"))
    cfg = {"db": str(tmp / "shm.sqlite"), "source": {"spec": "ingest"}, "dashboard": {"enabled": False},
           "archive": {"enabled": False}, "server": {"port": 0}}
    service = MonitoringService(load_settings(None, cfg), environ={"SHM_TOKEN": TOKEN})
    service.start()
    apis = [ApiServer(create_app(service, loopback=True, max_ingest_bytes=256 * 1024), "127.0.0.1", 0).start(),
            ApiServer(create_app(service, loopback=False, host="0.0.0.0", max_ingest_bytes=256 * 1024,
                                 auth_failures_per_minute=1000), "127.0.0.1", 0).start()]
    rng = random.Random(seed)
    statuses: Counter = Counter()
    by_kind: Counter = Counter()
    server_errors: list[dict[str, Any]] = []
    dropped = not_sent = 0
    began = time.perf_counter()
    clients = [httpx.Client(base_url=api.url, timeout=30.0) for api in apis]
    try:
        for n in range(requests):
            which = n % 2
            kwargs = _request(rng, n, apis[which].port, token=rng.random() < 0.6)
            # header values as UTF-8 bytes: httpx sends str values only when they are ASCII
            kwargs["headers"] = {k: v.encode("utf-8") for k, v in kwargs["headers"].items()}
            try:
                r = clients[which].request(**kwargs)
            except httpx.LocalProtocolError:  # the client itself refused to send it (not the server's doing)
                not_sent += 1
                continue
            except httpx.HTTPError as exc:  # a dropped connection is a failure too
                dropped += 1
                server_errors.append({"request": _describe(kwargs), "error": repr(exc)[:200]})
                clients[which].close()
                clients[which] = httpx.Client(base_url=apis[which].url, timeout=30.0)
                continue
            statuses[r.status_code] += 1
            by_kind[f"{kwargs['method']} {kwargs['url'][:40]}"] += 1
            if r.status_code >= 500 and r.status_code != 503:  # 503 Retry-After: the pipeline is full, by design
                server_errors.append({"request": _describe(kwargs), "status": r.status_code, "body": r.text[:200]})
            elif r.status_code >= 400 and kwargs["method"] not in ("HEAD",):
                try:
                    assert isinstance(r.json().get("detail"), (str, list))
                except Exception:  # noqa: BLE001 - an error without a detail is reported, not fatal here
                    server_errors.append({"request": _describe(kwargs), "status": r.status_code, "body": r.text[:200],
                                          "problem": "no JSON detail"})
    finally:
        for c in clients:
            c.close()
        for api in apis:
            api.stop()
        service.stop(drain_s=0)
    return {"requests": requests, "seed": seed, "wall_s": round(time.perf_counter() - began, 1),
            "statuses": dict(sorted(statuses.items())), "server_errors": len(server_errors), "dropped": dropped, "not_sent": not_sent,
            "examples": server_errors[:10], "integrity": _integrity(tmp / "shm.sqlite")}


def _describe(kwargs: dict[str, Any]) -> str:
    content = kwargs.get("content")
    size = len(content) if isinstance(content, (bytes, bytearray)) else ("chunked" if content is not None else 0)
    return f"{kwargs['method']} {kwargs['url'][:80]} params={kwargs.get('params')} headers={kwargs.get('headers')} body={size}"


def _integrity(db: Path) -> str:
    import sqlite3

    con = sqlite3.connect(db)
    try:
        return str(con.execute("PRAGMA integrity_check").fetchone()[0])
    finally:
        con.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.http_campaign", description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=10_000, help="generated requests (default 10000)")
    ap.add_argument("--seed", type=int, default=11)
    args, _ = ap.parse_known_args(argv)
    result = campaign(args.requests, seed=args.seed)
    print(json.dumps(result, indent=1))
    return 1 if result["server_errors"] else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
