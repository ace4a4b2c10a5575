"""A fleet (``[[structures]]``) in one service: the configuration, the /api/structures routes on a
real server, and isolation with faults injected for real — a replay of a missing file, of a
corrupt file, an exception in one structure's analysis — while the others commit every window
they would commit alone."""

from __future__ import annotations

import shutil
import time

import httpx
import pytest
from svc_helpers import fast_overrides, wait_for

from shm_service.service import ApiServer, MonitoringService, SettingsError, create_app, load_settings, render_toml, start_serve

TOKEN = "fleet-token-123"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def _fleet(tmp_path, structures, **extra):
    return load_settings(None, {**fast_overrides(tmp_path, **{"archive.enabled": False, **extra}), "structures": structures})


# -- configuration ------------------------------------------------------------------------------


def test_structures_take_their_own_source_and_overrides(tmp_path):
    settings = _fleet(tmp_path, [
        {"id": "mast-01", "source": "sim", "sim": {"seed": 7}, "estimator": {"modes": 3}},
        {"id": "mast-02", "source": "ingest", "alarms": {"raise_windows": 4}},
    ], **{"source.speed": 2.0, "sim.seed": 1})
    assert settings.fleet and [s.id for s in settings.structures] == ["mast-01", "mast-02"]
    one, two = (settings.for_structure(s) for s in settings.structures)
    assert (one.source.spec, one.source.id, one.sim.seed, one.estimator.modes) == ("sim", "mast-01", 7, 3)
    assert (two.source.spec, two.source.id, two.sim.seed, two.estimator.modes) == ("ingest", "mast-02", 1, 4)
    # --speed applies to every structure; the service's tables are the base of each structure's
    assert one.source.speed == two.source.speed == 2.0
    assert one.analytics.window_s == two.analytics.window_s == 20.0
    assert (one.alarms.raise_windows, two.alarms.raise_windows) == (1, 4)
    # only the keys set are carried: a count left at its default stays a default (capped to the rig)
    assert "imus" not in one.estimator.model_fields_set and "modes" in one.estimator.model_fields_set
    assert one.db == two.db == settings.db  # one database, rows keyed by the structure id
    # the rendered configuration reads back to the same structures
    path = tmp_path / "fleet.toml"
    path.write_text(render_toml(settings), encoding="utf-8")
    again = load_settings(path)
    assert again.structures == settings.structures


def test_without_structures_the_service_is_one_structure(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path))
    assert not settings.fleet and settings.structures == ()
    settings.for_structure  # noqa: B018 - exists, unused without a list


def test_a_fleet_takes_one_worker_process_per_core_unless_told(tmp_path, monkeypatch):
    """``workers = "auto"`` (the default): one worker process per core the service may run on, at
    most one per structure; a number is taken as given; a single structure has no workers."""
    import os

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    three = [{"id": f"m{k}"} for k in range(3)]
    assert _fleet(tmp_path, three).workers == "auto" and _fleet(tmp_path, three).worker_count == 2
    assert _fleet(tmp_path, three[:1]).worker_count == 1  # one structure: no second process
    assert _fleet(tmp_path, three, workers=1).worker_count == 1
    assert _fleet(tmp_path, three, workers=3).worker_count == 3
    assert load_settings(None, fast_overrides(tmp_path)).worker_count == 1
    for bad in (0, "two"):
        with pytest.raises(SettingsError, match="workers"):
            _fleet(tmp_path, three, workers=bad)


@pytest.mark.parametrize("structures, words", [
    ([{"id": "Mast_1"}], ["id"]),
    ([{"id": "a"}, {"id": "a"}], ["'a'", "more than once"]),
    ([{"id": "a", "source": "replay"}], ["replay"]),
    ([{"id": "a", "sim": {"seed": -1}}], ["structure 'a'", "sim.seed"]),
    ([{"id": "a", "estimator": {"no_such_key": 1}}], ["structure 'a'", "estimator.no_such_key"]),
    ([{"id": "a", "colour": "red"}], ["colour"]),
])
def test_bad_structures_are_refused_naming_the_key(tmp_path, structures, words):
    with pytest.raises(SettingsError) as info:
        _fleet(tmp_path, structures)
    for word in words:
        assert word in str(info.value)


def test_source_of_the_service_and_structures_do_not_mix(tmp_path):
    with pytest.raises(SettingsError, match="source.spec cannot be set with"):
        _fleet(tmp_path, [{"id": "a"}], **{"source.spec": "ingest"})


# -- a running fleet ------------------------------------------------------------------------------




def test_a_fleet_isolates_faults_and_serves_each_structure(tmp_path, short_recording):
    # reference: the recording alone, as a single-structure service
    alone = MonitoringService(load_settings(None, fast_overrides(
        tmp_path / "alone", **{"source.spec": f"replay:{short_recording}", "source.speed": "max", "source.id": "good",
                               "archive.enabled": False})), environ={})
    alone.start()
    assert alone.wait(240)
    reference = alone.trends(None, None, source="good")
    alone.stop(drain_s=0)
    assert len(reference) > 0

    corrupt = tmp_path / "corrupt.mcap"
    data = short_recording.read_bytes()
    corrupt.write_bytes(data[: len(data) // 3] + b"\x00garbage" * 4000)
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not a recording at all\n" * 100)
    twin = tmp_path / "twin.mcap"
    shutil.copyfile(short_recording, twin)
    settings = _fleet(tmp_path, [
        {"id": "good", "source": f"replay:{short_recording}"},
        {"id": "broken-analysis", "source": f"replay:{twin}"},
        {"id": "missing", "source": f"replay:{tmp_path / 'no-such-file.mcap'}"},
        {"id": "corrupt", "source": f"replay:{corrupt}"},
        {"id": "live", "source": "ingest"},
        {"id": "garbage", "source": f"replay:{garbage}"},
    ], **{"source.speed": "max"})
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    assert set(service.structures) == {"good", "broken-analysis", "missing", "corrupt", "live", "garbage"}

    broken = service.structure("broken-analysis").pipeline.analytics

    def exploding(*args, **kwargs):
        raise RuntimeError("injected analysis fault")

    broken.add = exploding  # every window of this structure raises in its analysis
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    service.start()
    try:
        with httpx.Client(base_url=api.url, timeout=30) as c:
            for sid in ("good", "broken-analysis", "corrupt"):
                wait_for(lambda: service.structure(sid).done, 240, f"{sid} to end")  # noqa: B023
            doc = c.get("/api/structures").json()
            by_id = {s["id"]: s for s in doc["structures"]}
            assert list(by_id) == ["good", "broken-analysis", "missing", "corrupt", "live", "garbage"]
            for s in doc["structures"]:
                assert set(s) >= {"id", "state", "data_time_s", "lag_s", "windows", "active_alarms"}
            # the healthy structure committed every window it commits alone, the same rows
            good = by_id["good"]
            assert good["state"] == "finished" and good["error"] is None
            rows = c.get("/api/structures/good/trends").json()["rows"]
            assert [(r["window_start_s"], r["mode"]) for r in rows] == [(r.window_start_s, r.mode) for r in reference]
            nan = float("nan")
            assert [nan if r["frequency_hz"] is None else r["frequency_hz"] for r in rows] == pytest.approx(
                [nan if r.frequency_hz is None else r.frequency_hz for r in reference], rel=1e-9, nan_ok=True)
            assert {r["source"] for r in rows} == {"good"}
            assert good["windows"] == alone.pipeline.windows_committed
            # the faults show on their own structures
            bad = by_id["broken-analysis"]
            assert bad["windows"] == 0 and "injected analysis fault" in (bad["error"] or "")
            st = c.get("/api/structures/broken-analysis/status").json()
            assert st["service"]["pipeline_errors"] > 0 and st["pipeline"]["samples"] > 0
            assert by_id["missing"]["state"] == "failed" and "no-such-file.mcap" in by_id["missing"]["error"]
            # a file damaged a third of the way in: its valid part is monitored, the damage shown
            corrupt = by_id["corrupt"]
            assert corrupt["state"] == "finished" and corrupt["error"], corrupt
            assert 0 < corrupt["windows"] < good["windows"]
            assert by_id["garbage"]["state"] == "failed" and "garbage.mcap" in by_id["garbage"]["error"]
            assert by_id["live"]["state"] == "running" and by_id["live"]["data_time_s"] is None
            health = c.get("/healthz").json()
            assert health["status"] == "degraded"
            assert any(r.startswith("missing: ") for r in health["reasons"])
            assert any(r.startswith("broken-analysis: ") for r in health["reasons"])

            # each structure's routes; an unknown id is a 404 naming it
            assert c.get("/api/structures/good/spectra/latest").json()["source"] == "good"
            r = c.get("/api/structures/nope/status")
            assert r.status_code == 404 and "'nope'" in r.json()["detail"]
            assert c.get("/api/structures/nope/trends").status_code == 404
            r = c.get("/api/structures/missing/status")
            assert r.status_code == 409 and "no-such-file.mcap" in r.json()["detail"]
            assert c.get("/api/structures/missing/alarms").json()["count"] == 0
            assert all(a["source"] == "good" for a in c.get("/api/structures/good/alarms").json()["alarms"])
            # the single-structure routes say where to go
            r = c.get("/api/status")
            assert r.status_code == 409 and "/api/structures" in r.json()["detail"]

            # ingest into the live structure only, with the token
            batch = {"messages": [{"topic": "/imu/D", "log_time_ns": int(time.time() * 1e9) + i * 5_000_000,
                                   "payload": {"accel": [-9.81, 0.0, 0.0], "gyro": [0.0, 0.0, 1e-4]}} for i in range(50)]}
            assert c.post("/api/structures/live/ingest", json=batch).status_code == 401
            r = c.post("/api/structures/live/ingest", json=batch, headers=AUTH)
            assert r.status_code == 200 and r.json()["accepted"] == 50, r.text
            r = c.post("/api/structures/good/ingest", json=batch, headers=AUTH)
            assert r.status_code == 409 and "not ingest" in r.json()["detail"]
            assert c.post("/api/structures/nope/ingest", json=batch, headers=AUTH).status_code == 404
            live = wait_for(lambda: next((s for s in c.get("/api/structures").json()["structures"]
                                       if s["id"] == "live" and s["data_time_s"] is not None), None), 30, "ingested data")
            assert live["lag_s"] is not None and live["lag_s"] > -61  # wall clock minus data time

            # a new baseline of one structure, with the token
            assert c.post("/api/structures/good/baseline").status_code == 401
            r = c.post("/api/structures/good/baseline", headers=AUTH)
            assert r.status_code == 202 and r.json()["source"] == "good" and r.json()["state"] == "learning"
            assert service.storage.baselines("good")[0]["state"] == "learning"
            assert service.storage.baselines("broken-analysis") == [] or \
                service.storage.baselines("broken-analysis")[0]["state"] != "learning"
            assert c.post("/api/structures/nope/baseline", headers=AUTH).status_code == 404
    finally:
        api.stop()
        service.stop(drain_s=0)


def test_sim_structures_run_side_by_side_with_their_lag(tmp_path):
    """Two simulated structures at real time: both deliver, each at its pace (lag a number)."""
    settings = _fleet(tmp_path, [{"id": "mast-01", "sim": {"seed": 1}}, {"id": "mast-02", "sim": {"seed": 2}}],
                      **{"source.speed": 1.0, "sim.duration_s": 3600.0})
    service = MonitoringService(settings, environ={})
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    service.start()
    try:
        with httpx.Client(base_url=api.url, timeout=30) as c:
            first = wait_for(lambda: (lambda d: d if all(s["data_time_s"] for s in d) else None)(
                c.get("/api/structures").json()["structures"]), 60, "data of both")
            time.sleep(3.0)
            later = c.get("/api/structures").json()["structures"]
        for a, b in zip(first, later):
            assert b["state"] == "running" and b["data_time_s"] > a["data_time_s"]
            assert isinstance(b["lag_s"], float)
        # two seeds: two different structures' data
        s1, s2 = (service.structure(i).pipeline for i in ("mast-01", "mast-02"))
        assert s1.newest_ns is not None and s2.newest_ns is not None
    finally:
        api.stop()
        service.stop(drain_s=0)


def test_shm_serve_of_a_fleet_prints_each_structure(tmp_path, short_recording, capsys):
    """``shm serve --config fleet.toml --json``: one summary row per structure; a structure that
    could not start makes the run not clean (exit 1) while the other is monitored to its end."""
    import json

    from shm_service.cli import main

    config = tmp_path / "fleet.toml"
    config.write_text(
        "[estimator]\ncalibration_s = 10.0\nwarmup_s = 5.0\n[analytics]\nwindow_s = 20.0\nbaseline_s = 40.0\n"
        "baseline_min_windows = 3\n"
        f'[[structures]]\nid = "blade-1"\nsource = "replay:{short_recording}"\n'
        f'[[structures]]\nid = "blade-2"\nsource = "replay:{tmp_path / "gone.mcap"}"\n', encoding="utf-8")
    code = main(["serve", "--config", str(config), "--speed", "max", "--no-archive", "--no-dashboard", "--port", "0",
                 "--db", str(tmp_path / "shm.sqlite"), "--json"])
    out = capsys.readouterr().out.strip().splitlines()
    assert "2 structures" in out[0]
    doc = json.loads(out[-1])
    rows = {r["id"]: r for r in doc["structures"]}
    assert code == 1
    assert rows["blade-1"]["state"] == "finished" and rows["blade-1"]["windows_committed"] > 0
    assert rows["blade-2"]["state"] == "failed" and "gone.mcap" in rows["blade-2"]["error"]


def test_a_fleet_on_worker_processes_behind_one_api(tmp_path, short_recording, storage_target):
    """``workers = 2``: two worker processes host every other structure on one database; the
    front answers /api/structures for all, forwards a structure's live routes to its worker,
    serves the stored rows itself; a structure's fault stays on it."""
    import json
    import subprocess

    config = tmp_path / "fleet.toml"
    config.write_text(
        "workers = 2\n[estimator]\ncalibration_s = 10.0\nwarmup_s = 5.0\n[analytics]\nwindow_s = 20.0\nbaseline_s = 40.0\n"
        "baseline_min_windows = 3\n[dashboard]\nenabled = false\n[archive]\nenabled = false\n"
        f'[[structures]]\nid = "a"\nsource = "replay:{short_recording}"\n'
        '[[structures]]\nid = "b"\nsource = "ingest"\n'
        f'[[structures]]\nid = "c"\nsource = "replay:{tmp_path / "gone.mcap"}"\n', encoding="utf-8")
    db = storage_target if not storage_target.endswith(".sqlite") else str(tmp_path / "shm.sqlite")  # --db: a file or a URL
    args = ["--config", str(config), "--port", "0", "--speed", "max", "--db", db, "--data-dir", str(tmp_path),
            "--keep-running", "--json"]
    env = {**__import__("os").environ, "SHM_TOKEN": TOKEN}
    serve = start_serve(args, env=env, stdout=subprocess.PIPE, timeout=300, ready_file=tmp_path / "ready.json")
    proc = serve.process
    try:
        assert serve.ready["state"] == "serving" and serve.ready["structures"] == ["a", "b", "c"]
        assert len(serve.ready["workers"]) == 2
        url = serve.url
        with httpx.Client(base_url=url, timeout=60) as c:
            done = wait_for(lambda: (lambda d: d if d["a"]["state"] == "finished" else None)(
                {s["id"]: s for s in c.get("/api/structures").json()["structures"]}), 300, "structure a to finish")
            assert list(done) == ["a", "b", "c"]
            assert done["a"]["windows"] > 0 and done["b"]["state"] == "running"
            assert done["c"]["state"] == "failed" and "gone.mcap" in done["c"]["error"]
            # a's worker (0) and b's worker (1) answer through the front
            st = c.get("/api/structures/a/status").json()
            assert st["sources"][0]["id"] == "a" and st["pipeline"]["windows_committed"] == done["a"]["windows"]
            assert c.get("/api/structures/a/spectra/latest").json()["source"] == "a"
            rows = c.get("/api/structures/a/trends").json()["rows"]
            assert rows and {r["source"] for r in rows} == {"a"}
            assert c.get("/api/trends", params={"source": "a"}).json()["count"] == len(rows)
            batch = {"messages": [{"topic": "/imu/D", "log_time_ns": int(time.time() * 1e9) + i * 5_000_000,
                                   "payload": {"accel": [-9.81, 0.0, 0.0], "gyro": [0.0, 0.0, 1e-4]}} for i in range(20)]}
            r = c.post("/api/structures/b/ingest", json=batch, headers=AUTH)
            assert r.status_code == 200 and r.json()["accepted"] == 20, r.text
            assert c.post("/api/structures/a/ingest", json=batch, headers=AUTH).status_code == 409
            r = c.post("/api/structures/a/baseline", headers=AUTH)
            assert r.status_code == 202 and r.json()["source"] == "a"
            r = c.get("/api/structures/zzz/status")
            assert r.status_code == 404 and "'zzz'" in r.json()["detail"]
            assert c.get("/api/structures/c/status").status_code == 409
            assert c.get("/api/status").status_code == 409
            health = c.get("/healthz").json()
            assert health["status"] == "degraded" and any(x.startswith("c: ") for x in health["reasons"])
    finally:
        proc.send_signal(__import__("signal").SIGTERM)
        out, _ = proc.communicate(timeout=120)
    summary = json.loads(out.strip().splitlines()[-1])
    assert [r["id"] for r in summary["structures"]] == ["a", "b", "c"] and summary["workers"] == 2
    assert proc.returncode == 1  # c could not start


def test_a_fleet_on_worker_processes_with_its_dashboard_on(tmp_path, short_recording):
    """The default invocation of a fleet (``workers = "auto"`` on this machine's cores, the
    dashboard on): worker 0 serves the dashboard (whatever it prints before its API line is not
    taken for a failed start), the front serves every structure's state."""
    import os
    import subprocess

    config = tmp_path / "fleet.toml"
    config.write_text(
        "workers = 2\n[estimator]\ncalibration_s = 10.0\nwarmup_s = 5.0\n[analytics]\nwindow_s = 20.0\nbaseline_s = 40.0\n"
        "baseline_min_windows = 3\n[dashboard]\nport = 0\n[archive]\nenabled = false\n"
        f'[[structures]]\nid = "a"\nsource = "replay:{short_recording}"\n'
        f'[[structures]]\nid = "b"\nsource = "replay:{short_recording}"\n', encoding="utf-8")
    args = ["--config", str(config), "--port", "0", "--speed", "max", "--db", str(tmp_path / "shm.sqlite"), "--keep-running"]
    serve = start_serve(args, env={**os.environ, "SHM_TOKEN": TOKEN}, stdout=subprocess.DEVNULL, timeout=300,
                        ready_file=tmp_path / "ready.json")
    try:
        assert len(serve.ready["workers"]) == 2 and serve.dashboard_url
        url = serve.url
        dashboard = "dashboard at " + serve.dashboard_url
        page = httpx.get(dashboard.split("dashboard at ")[1].split()[0], timeout=30)
        assert page.status_code == 200
        with httpx.Client(base_url=url, timeout=60) as c:
            done = wait_for(lambda: (lambda d: d if all(s["state"] == "finished" for s in d.values()) else None)(
                {s["id"]: s for s in c.get("/api/structures").json()["structures"]}), 300, "both structures to finish")
            assert list(done) == ["a", "b"] and done["a"]["windows"] == done["b"]["windows"] > 0
    finally:
        serve.stop(timeout=120)


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended but not yet reaped by its new parent, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            stat = f.read()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(not __import__("os").path.isdir("/proc"), reason="reads /proc")
def test_kill_9_of_the_front_ends_its_workers_and_a_new_front_starts_clean(tmp_path):
    """A supervisor's SIGKILL of the front (the OOM killer does the same): within 10 s no worker of
    it runs; a front started again on the database finds none and starts its own."""
    import os
    import signal
    import subprocess

    config = tmp_path / "fleet.toml"
    config.write_text(
        "workers = 2\n[dashboard]\nenabled = false\n[archive]\nenabled = false\n"
        '[[structures]]\nid = "a"\nsource = "sim"\n[[structures]]\nid = "b"\nsource = "sim"\n', encoding="utf-8")
    args = ["--config", str(config), "--port", "0", "--db", str(tmp_path / "shm.sqlite"), "--data-dir", str(tmp_path)]
    serve = start_serve(args, env={**os.environ, "SHM_TOKEN": TOKEN}, stdout=subprocess.DEVNULL, timeout=300,
                        ready_file=tmp_path / "ready.json")
    workers = serve.ready["workers"]
    assert len(workers) == 2 and all(_alive(pid) for pid in workers)
    os.kill(serve.pid, signal.SIGKILL)
    serve.process.wait(10)
    killed = time.monotonic()
    while any(_alive(pid) for pid in workers) and time.monotonic() - killed < 10.0:
        time.sleep(0.1)
    assert not any(_alive(pid) for pid in workers), [pid for pid in workers if _alive(pid)]
    again = start_serve(args, env={**os.environ, "SHM_TOKEN": TOKEN}, stdout=subprocess.DEVNULL, timeout=300,
                        ready_file=tmp_path / "ready.json")
    try:
        assert set(again.ready["workers"]).isdisjoint(workers)
        with httpx.Client(base_url=again.url, timeout=30) as c:
            states = {s["id"]: s["state"] for s in c.get("/api/structures").json()["structures"]}
            assert states == {"a": "running", "b": "running"}, states
    finally:
        assert again.stop(timeout=120) in (0, 1)


def test_paced_structures_start_one_after_the_other_over_a_window_step():
    """The starts of a fleet's paced structures are spread over one window step of wall time (so
    their calibrations and windows do not all fall due at once), at most 0.5 s apart."""
    from types import SimpleNamespace

    def paced(n, speed, window_s=60.0, overlap=0.5):
        analytics = SimpleNamespace(window_s=window_s, overlap=overlap)
        return [SimpleNamespace(settings=SimpleNamespace(analytics=analytics), speed=speed) for _ in range(n)]

    stagger = MonitoringService.start_stagger_s
    assert stagger(paced(1, 1.0)) == 0.0  # nothing to spread
    assert stagger(paced(50, 2.0)) == pytest.approx(15.0 / 50)  # 30 s of data per step = 15 s of wall time
    assert stagger(paced(100, 1.0)) == pytest.approx(30.0 / 100)
    assert stagger(paced(25, 2.0)) == stagger(paced(2, 1.0)) == 0.5  # at most half a second apart
    assert stagger(paced(100, 0.5)) == pytest.approx(30.0 / 100)  # over at most 30 s
