"""``shm serve``: the command-line entry (argument parser and handler)."""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Mapping
from typing import Any

from .._argtypes import number
from .storage._url import redact

__all__ = ["add_serve_parser", "run_serve"]


def add_serve_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser("serve", help="run the continuous monitoring service (sources, trends, alarms, HTTP API)")
    p.add_argument("--config", metavar="FILE", help="TOML configuration (see --print-config for every key and default)")
    p.add_argument("--print-config", action="store_true", help="print the effective configuration as TOML and exit")
    p.add_argument("--source", help="sim | replay:FILE.mcap | follow:FILE.mcap | ingest (default sim)")
    p.add_argument("--speed", help="sim/replay pace: factor of real time or 'max' (default 1)")
    p.add_argument("--keep-running", action="store_true", default=None, help="keep serving after a replay ends")
    p.add_argument("--data-dir", metavar="DIR", help="directory of all the service's files (default: the directory of --db, else ./var)")
    p.add_argument("--db", help="SQLite database (default DATA_DIR/shm.sqlite)")
    p.add_argument("--host", help="API address (default 127.0.0.1; others need a token)")
    p.add_argument("--port", type=number(int, low=0, high=65535), help="API port, 0-65535 (default 8600; 0 = a free port)")
    p.add_argument("--dashboard-port", type=number(int, low=0, high=65535), help="dashboard port, 0-65535 (default 8080; 0 = a free port)")
    p.add_argument("--no-dashboard", action="store_true", default=None, help="do not start the dashboard")
    p.add_argument("--token-file", help="file with the API token (else env SHM_TOKEN)")
    p.add_argument("--rig", help="rig description (.json/.toml) for ingest or to replace a recording's rig.json")
    p.add_argument("--source-id", help="source id of the trend rows")
    p.add_argument("--webhook", action="append", metavar="URL", help="webhook for alarm notifications (repeatable)")
    p.add_argument("--recordings", metavar="DIR", help="directory of the rotating recordings (default DATA_DIR/recordings)")
    p.add_argument("--no-archive", action="store_true", default=None, help="do not write recordings")
    p.add_argument("--json", action="store_true", help="print the final summary as JSON")
    p.add_argument("--workers", type=number(int, low=1, high=64),
                   help="worker processes hosting the [[structures]] (default: one per core, at most one per structure; "
                   "1: all in this process)")
    p.add_argument("--worker-of", metavar="I/N", help=argparse.SUPPRESS)  # internal: a worker process of a fleet
    p.add_argument("--node", metavar="NAME",
                   help="run as node NAME of a fleet across machines: the nodes with this configuration share its "
                   "[[structures]] through leases in the PostgreSQL database storage.url (one process per node)")
    add_process_arguments(p)
    p.set_defaults(func=run_serve)
    return p


def add_process_arguments(p: argparse.ArgumentParser) -> None:
    """The options by which a program that starts ``shm serve`` learns it is ready and ends it with itself."""
    p.add_argument("--ready-file", metavar="FILE",
                   help="write a JSON document (api, docs, dashboard, pid, state) here once the API answers")
    p.add_argument("--parent-pid", type=number(int, low=1), metavar="PID",
                   help="end (gracefully, then hard) when process PID, the one that started this, ends")


def _ready(args: argparse.Namespace, **document: Any) -> None:
    path = getattr(args, "ready_file", None)
    if path:
        from .runtime._processes import write_ready

        write_ready(path, document)


def overrides_from_args(args: argparse.Namespace) -> dict[str, Any]:
    o: dict[str, Any] = {}

    def put(path: str, value: Any) -> None:
        if value is None:
            return
        node = o
        *parents, leaf = path.split(".")
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = value

    put("source.spec", args.source)
    put("source.speed", args.speed)
    put("source.keep_running", args.keep_running)
    put("source.rig", args.rig)
    put("source.id", args.source_id)
    put("data_dir", args.data_dir)
    put("db", args.db)
    put("server.host", args.host)
    put("server.port", args.port)
    put("server.token_file", args.token_file)
    put("dashboard.port", args.dashboard_port)
    put("dashboard.enabled", False if args.no_dashboard else None)
    put("archive.directory", args.recordings)
    put("archive.enabled", False if args.no_archive else None)
    put("workers", getattr(args, "workers", None))
    if args.webhook:
        put("notify.webhooks", tuple(args.webhook))
    return o


def run_serve(args: argparse.Namespace, *, environ: Mapping[str, str] | None = None) -> int:
    """``shm serve`` under the database's lock (``storage.sqlite._lock``: one service per database; a fleet's
    workers run under their front process's)."""
    from ._config import SettingsError, load_settings
    from .storage.sqlite._lock import DatabaseBusy, DatabaseLock

    try:
        settings = load_settings(args.config, overrides_from_args(args))
    except SettingsError:
        settings = None  # _run_serve says what is wrong
    if settings is None or args.print_config or getattr(args, "worker_of", None) is not None:
        return _run_serve(args, environ=environ)
    if settings.storage.url is not None:  # a shared PostgreSQL: nodes are fenced by their leases, not by a file
        return _run_serve(args, environ=environ)
    try:
        lock = DatabaseLock.acquire(settings.db_path)
    except (DatabaseBusy, OSError) as exc:
        print(f"shm serve: error: {exc}", file=sys.stderr)
        return 3
    if lock.took_over:
        print(f"shm serve: {lock.took_over} ({lock.path})", file=sys.stderr, flush=True)
    try:
        return _run_serve(args, environ=environ)
    finally:
        lock.release()


def _worker_part(settings: Any, worker_of: str) -> tuple[Any, Any] | None:
    """A worker's part of the fleet (``--worker-of I/N``) and its worker lock (held for the
    process's life: a later front knows this worker still runs on the database); None: bad value."""
    from .runtime._processes import hold_worker_lock
    from .runtime._workers import part_of

    try:
        index, count = (int(x) for x in worker_of.split("/"))
        settings = part_of(settings, index, count)
    except ValueError as exc:
        print(f"shm serve: error: --worker-of {worker_of!r}: {exc}", file=sys.stderr)
        return None
    return settings, hold_worker_lock(settings.lock_path)


def _wait_for_rig(args: argparse.Namespace, settings: Any, slot: Any, api: Any, stop: threading.Event, *,
                  environ: Mapping[str, str] | None, deliver: bool) -> Any:
    """follow: the API serves (healthz degraded, the rest 503 "starting") until the file's rig.json
    is readable; returns the service, or the exit code (0 stopped meanwhile, 2 an error)."""
    from ._config import SettingsError
    from .runtime._service import MonitoringService, RigPending, ServiceError

    if getattr(args, "worker_of", None) is None:
        print(f"shm serve: API at {api.url}; {slot.waiting_for}", flush=True)
    _ready(args, state="waiting", api=api.url, docs=f"{api.url}/docs", dashboard=None, waiting_for=slot.waiting_for)
    logging.getLogger("shm.serve").info("%s", slot.waiting_for)
    while True:
        if stop.wait(settings.source.follow_poll_s):
            return 0
        try:
            return MonitoringService(settings, environ=environ, deliver=deliver)
        except RigPending:
            continue
        except (ServiceError, SettingsError, OSError) as exc:
            print(f"shm serve: error: {exc}", file=sys.stderr)
            return 2


def _run_serve(args: argparse.Namespace, *, environ: Mapping[str, str] | None = None) -> int:
    from .http._app import create_app
    from ._config import SettingsError, load_settings, render_toml
    from .http._server import ApiServer
    from .runtime._service import MonitoringService, RigPending, ServiceError
    from .runtime._starting import ServiceSlot, StartingService

    try:
        settings = load_settings(args.config, overrides_from_args(args))
    except SettingsError as exc:
        print(f"shm serve: error: {exc}", file=sys.stderr)
        return 2
    if args.print_config:
        print(render_toml(settings))
        return 0
    logging.basicConfig(level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)
    worker_of = getattr(args, "worker_of", None)
    node = getattr(args, "node", None)
    if settings.worker_count > 1 and worker_of is None and node is None:
        return _run_workers(settings, args, environ)
    if worker_of is not None:
        part = _worker_part(settings, worker_of)
        if part is None:
            return 2
        settings, worker_lock = part  # the lock is held for this process's life  # noqa: F841
    deliver = worker_of is None  # worker processes leave the notifications to the front process
    stop = threading.Event()

    def on_signal(signum: int, frame: Any) -> None:
        stop.set()

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, on_signal)
        signal.signal(signal.SIGTERM, on_signal)
    _watch_parent(args)
    s = settings.server
    api = None
    try:
        if node is not None:
            from .runtime._node import NodeService

            service: MonitoringService | None = NodeService(settings, node, environ=environ)
        else:
            service = MonitoringService(settings, environ=environ, deliver=deliver)
        slot = ServiceSlot(service)
    except RigPending as pending:
        # follow: the file is not there yet. The API comes up now (healthz: degraded, the other
        # routes 503 "starting"); the service is built once the file's rig.json is readable.
        slot = ServiceSlot(StartingService(settings, str(pending), environ=environ))
        service = None
    except (ServiceError, SettingsError, OSError) as exc:
        print(f"shm serve: error: {exc}", file=sys.stderr)
        return 2
    app = create_app(slot, loopback=s.loopback, max_body_bytes=s.max_body_bytes, max_ingest_bytes=s.max_ingest_bytes,
                     host=s.host, allowed_hosts=s.allowed_hosts, auth_failures_per_minute=s.auth_failures_per_minute)
    try:
        api = ApiServer(app, s.host, s.port).start()
    except (OSError, TimeoutError) as exc:
        print(f"shm serve: error: HTTP API on {s.host}:{s.port}: {exc}", file=sys.stderr)
        if service is not None:
            service.stop()
        return 2
    if service is None:
        service = _wait_for_rig(args, settings, slot, api, stop, environ=environ, deliver=deliver)
        if not isinstance(service, MonitoringService):
            api.stop()
            return service
        slot.current = service
    if worker_of is None:  # a worker's front says where things are
        _print_where(service, settings, api)
    return _serve_until_stopped(args, settings, service, api, stop)


def _print_where(service: Any, settings: Any, api: Any) -> None:
    what = (f"{len(service.structures)} structures" if service.fleet
            else f"source {settings.source.spec} as '{service.source.id}'")
    if getattr(service, "node", None) is not None:
        what = f"node {service.node!r} of a fleet of {len(settings.structures)} structures (shared by leases)"
    print(f"shm serve: API at {api.url} (docs {api.url}/docs); {what}; "
          f"data in {settings.data_dir} (db {redact(str(settings.db))}, recordings "
          f"{settings.archive.directory if settings.archive.enabled else 'off'})", flush=True)
    if service.dashboard is not None:
        print(f"shm serve: dashboard at {getattr(service.dashboard, 'url', '?')}", flush=True)


def _serve_until_stopped(args: argparse.Namespace, settings: Any, service: Any, api: Any, stop: threading.Event) -> int:
    """Start the service (after compiling the filter's kernels), say it is ready, serve until it is
    done or stopped (SIGTERM, SIGINT, the parent's end), stop it and print its summary."""
    from .runtime._progress import ProgressLog, compile_first

    started = time.monotonic()
    progress = ProgressLog(service)
    if compile_first(service, stop):
        service.start()
        _ready(args, state="serving", api=api.url, docs=f"{api.url}/docs",
               dashboard=getattr(service.dashboard, "url", None) if service.dashboard is not None else None,
               structures=[s_.id for s_ in settings.structures] if service.fleet else [service.source.id], db=redact(str(settings.db)))
    try:
        while not stop.is_set():
            if service.wait(0.2) and not settings.source.keep_running:
                break
            progress.poll()
    finally:
        elapsed = time.monotonic() - started
        if not service.done:
            logging.getLogger("shm.serve").info("stopping")
        if service.fleet:
            fleet = _fleet_summary(service, elapsed)
        else:
            status = service.status()
        service.stop(drain_s=5.0 if service.done else 1.0)
        api.stop()
    try:
        return _print_fleet(fleet, as_json=args.json) if service.fleet else _print_summary(status, elapsed, args)
    except BrokenPipeError:
        # the reader of this output (a fleet's front) ended first: the summary has no one to go to
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1


def _print_summary(status: Any, elapsed: float, args: argparse.Namespace) -> int:
    code = 0
    p = status.pipeline
    src = status.sources[0]
    # A batch that failed was skipped: the run is not clean even if later batches succeeded.
    if src.state == "failed" or status.service.pipeline_errors:
        code = 1
    summary = {
        "source": src.id, "state": src.state, "error": src.error, "messages": src.messages,
        "rejected": src.rejected, "dropped": src.dropped, "estimates": p.estimates, "windows": p.windows,
        "windows_committed": p.windows_committed, "trend_rows": status.storage.trend_rows,
        "processed_data_s": p.processed_data_s, "wall_s": round(elapsed, 2),
        "realtime_factor": None if not p.processed_data_s else round(p.processed_data_s / max(elapsed, 1e-9), 1),
        "pipeline_errors": status.service.pipeline_errors,
        "sink_errors": {name: sink.errors_by_kind for name, sink in status.sinks.items() if sink.errors},
        "active_alarms": status.alarms.active, "problems": src.problems[-5:],
    }
    if args.json:
        print(json.dumps(summary), flush=True)
    else:
        # a run stopped before its first estimate processed no data: no pace to report
        pace = "no data processed" if summary["realtime_factor"] is None else f"{summary['realtime_factor']}x real time"
        print(f"shm serve: {summary['state']}: {summary['messages']} samples, {summary['estimates']} estimates, "
              f"{summary['windows']} windows, {summary['trend_rows']} trend rows in {summary['wall_s']} s "
              f"({pace})", flush=True)
    return code


def _watch_parent(args: argparse.Namespace) -> None:
    parent = getattr(args, "parent_pid", None)
    if parent is not None:
        from .runtime._processes import end_with_parent

        end_with_parent(parent)


def _fleet_summary(service: Any, elapsed: float) -> dict[str, Any]:
    """The final summary of a fleet: one row per structure (as ``/api/structures`` lists it, with
    its samples, windows and errors)."""
    rows = []
    for summary in service.structures_document().structures:
        row = summary.model_dump()
        if summary.id in {s.id for s in service.running_structures()}:  # (not one that failed, nor another node's)
            st = service.status(summary.id)
            p, src = st.pipeline, st.sources[0]
            row.update(messages=src.messages, estimates=p.estimates, windows=p.windows, windows_committed=p.windows_committed,
                       processed_data_s=p.processed_data_s, pipeline_errors=st.service.pipeline_errors)
        rows.append(row)
    return {"structures": rows, "wall_s": round(elapsed, 2)}


def _print_fleet(fleet: dict[str, Any], *, as_json: bool) -> int:
    rows = fleet["structures"]
    if as_json:
        print(json.dumps(fleet), flush=True)
    else:
        for r in rows:
            print(f"shm serve: {r['id']}: {r['state']}{' (' + r['error'] + ')' if r['error'] else ''}, "
                  f"{r.get('windows_committed', 0)} windows committed, lag {r['lag_s']} s", flush=True)
    # Like a single structure: a failed source or a failed batch makes the run not clean.
    return 1 if any(r["state"] == "failed" or r.get("pipeline_errors") for r in rows) else 0


def _run_workers(settings: Any, args: argparse.Namespace, environ: Mapping[str, str] | None) -> int:
    """A fleet on ``settings.worker_count`` worker processes behind one API (this process)."""
    from .http._app import create_app
    from .http._server import ApiServer
    from .runtime._service import ServiceError
    from .runtime._workers import WorkerFleet

    try:
        front = WorkerFleet(settings, environ=environ, json_summary=args.json)
    except (ServiceError, OSError) as exc:
        print(f"shm serve: error: {exc}", file=sys.stderr)
        return 2
    s = settings.server
    try:
        api = ApiServer(create_app(front, loopback=s.loopback, max_body_bytes=s.max_body_bytes,
                                   max_ingest_bytes=s.max_ingest_bytes), s.host, s.port).start()
    except (OSError, TimeoutError) as exc:
        print(f"shm serve: error: HTTP API on {s.host}:{s.port}: {exc}", file=sys.stderr)
        return 2
    print(f"shm serve: API at {api.url} (docs {api.url}/docs); {len(settings.structures)} structures in "
          f"{settings.worker_count} worker processes; data in {settings.data_dir} (db {redact(str(settings.db))}, recordings "
          f"{settings.archive.directory if settings.archive.enabled else 'off'})", flush=True)
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, lambda *a: stop.set())
        signal.signal(signal.SIGTERM, lambda *a: stop.set())
    _watch_parent(args)
    started = time.monotonic()
    try:
        front.start()
        if front.dashboard is not None:
            print(f"shm serve: dashboard at {getattr(front.dashboard, 'url', '?')}", flush=True)
        _ready(args, state="serving", api=api.url, docs=f"{api.url}/docs",
               dashboard=getattr(front.dashboard, "url", None) if front.dashboard is not None else None,
               structures=list(front.order), db=redact(str(settings.db)), workers=[w.process.pid for w in front.workers])
        while not stop.is_set():
            if front.wait(0.2) and not settings.source.keep_running:
                break
    except ServiceError as exc:
        print(f"shm serve: error: {exc}", file=sys.stderr)
        return 2
    finally:
        fleet = front.structures_document() if front.workers and not front.done else None
        code = front.stop(drain_s=5.0 if front.done else 1.0)
        api.stop()
    if args.json:
        rows: list[dict[str, Any]] = []
        for worker in front.workers:
            try:
                rows.extend(json.loads(worker.summary or "{}").get("structures", []))
            except ValueError:
                pass
        known = {r["id"] for r in rows}
        if fleet is not None:
            rows.extend(r.model_dump() for r in fleet.structures if r.id not in known)
        order = {sid: k for k, sid in enumerate(s_.id for s_ in settings.structures)}
        rows.sort(key=lambda r: order.get(r["id"], len(order)))
        print(json.dumps({"structures": rows, "wall_s": round(time.monotonic() - started, 2),
                          "workers": settings.worker_count}), flush=True)
    return code
