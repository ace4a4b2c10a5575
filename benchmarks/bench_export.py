"""Trend exports of a long history from a real ``shm serve``: a million stored
trend rows exported at once as CSV and as JSON, and paged through with the cursor; the server's
memory while it sends them.

The database is filled through the storage API (``Storage.commit_reprocessed``, 4 modes per
window, in recordings of 50,000 rows); ``shm serve --source ingest`` serves it as a child process
(``start_serve``); the exports are fetched with httpx, streamed (the client holds one chunk at a
time). The server's peak resident memory during each export is its ``VmHWM`` after resetting it
(``/proc/PID/clear_refs``) just before, cross-checked by sampling ``VmRSS`` every 20 ms; its growth
is that peak minus its resident memory before the export. The bar: a million-row export raises
the server's memory by no more than 100 MB.

``python -m benchmarks.bench_export [--rows 1000000] [--before TREE]`` (``--before``: the same
exports from ``shm serve`` of another source tree, side by side).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

from contract import TrendRow

BAR_MB = 100.0
MODES = 4


def fill(db: Path, rows: int, *, source: str = "mast-1", chunk: int = 50_000) -> float:
    """``rows`` trend rows (``MODES`` per 60 s window from t = 1.7e9 s) in ``db``; seconds taken."""
    from shm_service.service import Storage

    t0 = time.monotonic()
    storage = Storage(db)
    try:
        windows = -(-rows // MODES)
        for start in range(0, windows, chunk // MODES):
            stop = min(windows, start + chunk // MODES)
            batch = [TrendRow(source=source, window_start_s=1.7e9 + 60.0 * w, window_end_s=1.7e9 + 60.0 * w + 60.0,
                              mode=m, unit=m, kind="ambient", frequency_hz=1.5 * m + 1e-6 * w, damping_ratio=0.01,
                              amplitude=1e-3, confidence=0.9, temperature_c=12.5)
                     for w in range(start, stop) for m in range(1, MODES + 1) if w * MODES + m <= rows]
            storage.commit_reprocessed(key=f"bench-{start}", path=f"bench-{start}.mcap", source=source,
                                       content_sha256="0" * 64, configuration="bench", windows=stop - start,
                                       start_s=batch[0].window_start_s, end_s=batch[-1].window_end_s, rows=batch)
    finally:
        storage.close()
    return time.monotonic() - t0


def _kib(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"/proc/{pid}/status has no {field}")


class PeakMemory:
    """The peak resident memory of process ``pid`` while the block runs, and its growth over the
    resident memory at the start (MB)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.sampled_kib = 0
        self._stop = threading.Event()

    def __enter__(self) -> PeakMemory:
        self.before_kib = _kib(self.pid, "VmRSS")
        try:
            Path(f"/proc/{self.pid}/clear_refs").write_text("5")  # resets VmHWM to the current RSS
            self.hwm = True
        except OSError:
            self.hwm = False
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def _sample(self) -> None:
        while not self._stop.wait(0.02):
            self.sampled_kib = max(self.sampled_kib, _kib(self.pid, "VmRSS"))

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.sampled_kib = max(self.sampled_kib, _kib(self.pid, "VmRSS"))
        self.peak_kib = max(self.sampled_kib, _kib(self.pid, "VmHWM") if self.hwm else 0)

    @property
    def growth_mb(self) -> float:
        return (self.peak_kib - self.before_kib) / 1024.0


def export(client: httpx.Client, pid: int, params: dict) -> dict:
    """One export, streamed; its rows, bytes, seconds, headers and the server's memory growth."""
    t0 = time.monotonic()
    size = lines = 0
    with PeakMemory(pid) as memory, client.stream("GET", "/api/trends", params=params) as r:
        r.raise_for_status()
        for chunk in r.iter_bytes():
            size += len(chunk)
            lines += chunk.count(b"\n")
        headers = dict(r.headers)
    return {"bytes": size, "lines": lines, "s": time.monotonic() - t0, "headers": headers,
            "before_mb": memory.before_kib / 1024, "peak_mb": memory.peak_kib / 1024, "growth_mb": memory.growth_mb}


def page_through(client: httpx.Client, pid: int, limit: int) -> dict:
    """Every row by pages of ``limit`` following ``next_cursor``: pages, rows, distinct keys."""
    t0 = time.monotonic()
    keys: set[tuple] = set()
    pages = rows = 0
    cursor = None
    with PeakMemory(pid) as memory:
        while True:
            doc = client.get("/api/trends", params={"limit": limit, **({"cursor": cursor} if cursor else {})}).json()
            pages += 1
            rows += len(doc["rows"])
            keys.update((r["window_start_s"], r["source"], r["mode"]) for r in doc["rows"])
            total = doc["total"]
            cursor = doc["next_cursor"]
            if not doc["truncated"]:
                break
    return {"pages": pages, "rows": rows, "distinct": len(keys), "total": total, "s": time.monotonic() - t0,
            "growth_mb": memory.growth_mb}


def before(tree: Path, db: Path, rows: int) -> None:
    """The one-request exports from ``shm serve`` of another source tree (its own code: run from it)."""
    import os

    from shm_service.service import start_serve

    env = {**os.environ, "PYTHONPATH": str(tree)}
    with start_serve(["--source", "ingest", "--db", str(db), "--port", "0", "--no-dashboard", "--no-archive"], env=env,
                     cwd=tree, stdout=sys.stderr, timeout=600, until=lambda doc: doc.get("state") == "serving") as served, \
            httpx.Client(base_url=served.url, timeout=3600) as client:
        for name, params in (("JSON", {"limit": rows}), ("CSV", {"limit": rows, "format": "csv"})):
            out = export(client, served.pid, params)
            print(f"| {name}, one request, from {tree} | {rows} | {out['bytes'] / 1e6:.1f} | {out['s']:.1f} | "
                  f"{out['before_mb']:.0f} | {out['peak_mb']:.0f} | {out['growth_mb']:.1f} |", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_export", description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=1_000_000, help="trend rows stored and exported (default 1000000)")
    parser.add_argument("--page", type=int, default=100_000, help="page size of the paged read (default 100000)")
    parser.add_argument("--before", metavar="TREE", help="also export once from `shm serve` of this source tree (the "
                                                          "tree before a change), side by side on the same database")
    args, _ = parser.parse_known_args(argv)
    from shm_service.service import start_serve

    with tempfile.TemporaryDirectory(prefix="bench-export-") as tmp:
        db = Path(tmp) / "shm.sqlite"
        print(f"filling {args.rows} trend rows through the storage API: {fill(db, args.rows):.1f} s", flush=True)
        with start_serve(["--source", "ingest", "--db", str(db), "--port", "0", "--no-dashboard", "--no-archive"],
                         stdout=sys.stderr, timeout=600, until=lambda doc: doc.get("state") == "serving") as served, \
                httpx.Client(base_url=served.url, timeout=600) as client:
            small = client.get("/api/trends", params={"limit": 3}).json()
            print(f"/api/trends?limit=3: count {small['count']}, total {small['total']}, truncated {small['truncated']}, "
                  f"next_cursor {'set' if small['next_cursor'] else 'null'}")
            ok = small["truncated"] and small["total"] == args.rows
            print("\n| export | rows | MB sent | s | server RSS before (MB) | peak (MB) | growth (MB) |")
            print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
            for name, params in (("CSV, one request", {"limit": args.rows, "format": "csv"}),
                                 ("JSON, one request", {"limit": args.rows})):
                out = export(client, served.pid, params)
                total = int(out["headers"]["x-total-count"])
                rows = out["lines"] - 1 if "csv" in name else total
                print(f"| {name} | {rows} | {out['bytes'] / 1e6:.1f} | {out['s']:.1f} | {out['before_mb']:.0f} | "
                      f"{out['peak_mb']:.0f} | {out['growth_mb']:.1f} |", flush=True)
                ok &= out["growth_mb"] <= BAR_MB and total == args.rows and out["headers"]["x-truncated"] == "false"
                if "csv" in name:
                    ok &= rows == args.rows
            paged = page_through(client, served.pid, args.page)
            print(f"| JSON, {paged['pages']} pages of {args.page} by cursor | {paged['rows']} | | {paged['s']:.1f} | | | "
                  f"{paged['growth_mb']:.1f} |")
            ok &= paged["rows"] == paged["distinct"] == paged["total"] == args.rows and paged["growth_mb"] <= BAR_MB
        if args.before:
            before(Path(args.before), db, args.rows)
    print(f"\nbar: growth <= {BAR_MB:g} MB per export, every row exported once, the total and the cut said: "
          f"{'met' if ok else 'NOT MET'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
