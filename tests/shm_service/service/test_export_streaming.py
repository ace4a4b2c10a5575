"""A long export streams: a real ``shm serve`` over 200,000 stored trend rows
sends them in one request, as JSON (54 MB) and as CSV (15 MB), while its resident memory grows by
far less than the JSON's size. Built whole, as before, the same answers grew the server by 510 and
357 MB (measured side by side with the tree before). The million-row figures are
``python -m benchmarks.bench_export``'s."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import httpx
import pytest

from benchmarks.bench_export import PeakMemory, fill
from shm_service.service import start_serve

ROWS = 200_000
#: the most the server may grow while it sends them: under half the JSON's size
BOUND_MB = 25.0


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    db = tmp_path_factory.mktemp("export") / "shm.sqlite"
    fill(db, ROWS)
    with start_serve(["--source", "ingest", "--db", str(db), "--port", "0", "--no-dashboard", "--no-archive"],
                     stdout=sys.stderr, timeout=600, until=lambda doc: doc.get("state") == "serving") as process:
        yield process


@pytest.mark.parametrize("format", ["json", "csv"])
def test_a_long_export_streams_in_bounded_memory(served, format):
    with httpx.Client(base_url=served.url, timeout=600) as client:
        # first use (imports, the thread pool, a chunk's buffers) is not what the bound is about
        client.get("/api/trends", params={"limit": 4000, "format": format}).raise_for_status()
        size = 0
        body = bytearray()
        with PeakMemory(served.pid) as memory, client.stream("GET", "/api/trends",
                                                             params={"limit": ROWS, "format": format}) as r:
            assert r.status_code == 200 and r.headers["x-total-count"] == str(ROWS)
            assert r.headers["x-truncated"] == "false" and r.headers["x-count"] == str(ROWS)
            for chunk in r.iter_bytes():
                size += len(chunk)
                body += chunk
    if format == "json":
        doc = json.loads(body)
        assert (doc["count"], doc["total"], doc["truncated"], len(doc["rows"])) == (ROWS, ROWS, False, ROWS)
        starts = [row["window_start_s"] for row in doc["rows"]]
        assert starts == sorted(starts)
    else:
        assert body.count(b"\n") == ROWS + 1
    # the server holds a chunk of rows at a time, not the answer
    assert size > (50e6 if format == "json" else 14e6)
    assert memory.growth_mb < BOUND_MB, (memory.growth_mb, size)
    assert Path(f"/proc/{served.pid}").exists()
