"""Loads in ``shm serve``: the mast's hot spots counted by the service's engine, their rows
in SQLite, ``/api/fatigue`` and ``/api/structures/{id}/fatigue`` (JSON, CSV, OpenAPI), the
Prometheus gauges; a SIGKILL in the middle neither loses nor double-counts a cycle (the rainflow
residue is committed with each window); ``shm reprocess`` of the service's archive accumulates the
same damage as the live service did."""

from __future__ import annotations

import csv
import io
import os
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import httpx
import pytest
import tomli_w
from example_mast import write_planar_mast
from svc_helpers import fast_overrides, wait_for

from contract import FatigueDocument
from shm_service.cli import main
from shm_service.service import start_serve

SPOTS = ("base_flange_weld", "door_opening")


@pytest.fixture(scope="module")
def mast_rig(tmp_path_factory) -> Path:
    """The mast of examples/mast bending in ζ alone (its four 0° gauges for the service's Γ = 4)."""
    return write_planar_mast(tmp_path_factory.mktemp("rig"))


@pytest.fixture(scope="module")
def mast_recording(mast_rig, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("mast") / "mast.mcap"
    # a storm (145 N/m RMS, ten times the mast's everyday wind, which consumes nothing): the hot spots consume life
    assert main(["simulate", "--rig", str(mast_rig), "--excitation", "operational", "--duration", "150", "--seed", "11",
                 "--wind-load", "145", "--out", str(path)]) == 0
    return path


def _config(tmp: Path, rig: Path, recording: Path, db: Path, speed: str = "max") -> Path:
    o = fast_overrides(tmp)
    o.pop("archive")
    o["db"] = str(db)
    o["estimator"].update({"peripheral": "gyro", "modes": 4, "imus": 4, "tofs": 0, "gauges": 4})
    o["source"] = {"spec": f"replay:{recording}", "rig": str(rig), "speed": speed, "keep_running": True}
    o["archive"] = {"directory": str(tmp / "recordings"), "estimate_decimation": 1}
    toml = tmp / "serve.toml"
    toml.write_text(tomli_w.dumps(o))
    return toml


def _status(url: str) -> dict:
    return httpx.get(f"{url}/api/status", timeout=30).json()




def _finished(url: str) -> bool:
    """The replay ended and its last window is committed (the count stays the same for 2 s: the
    analysis of the last data follows the source's end)."""
    def settled() -> tuple[bool, int]:
        st = _status(url)
        done = (st["sources"][0]["state"] == "finished" and st["pipeline"]["queue_depth"] == 0
                and st["storage"]["windows_waiting"] == 0 and st["pipeline"]["windows_committed"] > 0)
        return done, st["pipeline"]["windows_committed"]

    done, windows = settled()
    if not done:
        return False
    time.sleep(2.0)
    return settled() == (True, windows)


def _serve(toml: Path, tmp: Path):
    return start_serve(["--config", str(toml), "--port", "0"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       ready_file=tmp / "ready.json", timeout=120)


def _rows(db: Path) -> dict[tuple[float, str], tuple[float, float]]:
    con = sqlite3.connect(db)
    try:
        return {(round(s, 6), h): (inc, d) for s, h, inc, d in
                con.execute("SELECT window_start_s, hot_spot, damage_increment, consumed FROM fatigue_hot_spots")}
    finally:
        con.close()


@pytest.fixture(scope="module")
def served(mast_rig, mast_recording, tmp_path_factory):
    """The mast replayed through a real ``shm serve`` to its end; its fatigue and metrics over HTTP."""
    tmp = tmp_path_factory.mktemp("served")
    toml = _config(tmp, mast_rig, mast_recording, tmp / "shm.sqlite")
    serve = _serve(toml, tmp)
    try:
        sid = httpx.get(f"{serve.url}/api/structures", timeout=30).json()["structures"][0]["id"]
        live: list[dict] = []

        def finished() -> bool:  # watching the live view meanwhile (a read keeps the structure keeping estimates)
            doc = httpx.get(f"{serve.url}/api/structures/{sid}/live", timeout=30).json()
            if doc["t_s"]:
                live.append(doc)
            return _finished(serve.url)

        wait_for(finished, timeout=300)
        with httpx.Client(base_url=serve.url, timeout=30) as c:
            answers = {"sid": sid, "live": live, "status": c.get("/api/status").json(), "single": c.get("/api/fatigue"),
                       "structure": c.get(f"/api/structures/{sid}/fatigue"),
                       "csv": c.get(f"/api/structures/{sid}/fatigue", params={"format": "csv"}),
                       "limited": c.get(f"/api/structures/{sid}/fatigue", params={"limit": 2}),
                       "unknown": c.get("/api/structures/nope/fatigue"),
                       "bad_period": c.get("/api/fatigue", params={"from": "200", "to": "100"}),
                       "metrics": c.get("/metrics").text, "openapi": c.get("/openapi.json").json()}
    finally:
        serve.stop()
    return tmp, toml, answers


def test_the_service_counts_the_hot_spots_and_serves_their_fatigue(served):
    tmp, _, a = served
    assert a["single"].status_code == 200 and a["structure"].status_code == 200
    doc = FatigueDocument.model_validate(a["structure"].json())
    assert doc == FatigueDocument.model_validate(a["single"].json())
    assert doc.structure_id == a["sid"] and doc.design_life_years == 20.0
    committed = a["status"]["pipeline"]["windows_committed"]
    assert doc.total == len(doc.windows) == committed >= 5 and not doc.truncated
    assert [h.name for h in doc.hot_spots] == sorted(SPOTS, key=lambda n: {"base_flange_weld": 0.15, "door_opening": 2.0}[n])
    starts = [w.start_s for w in doc.windows]
    assert starts == sorted(starts) and len(set(starts)) == len(starts)
    for spot in doc.hot_spots:
        trend = [next(h for h in w.hot_spots if h.name == spot.name) for w in doc.windows]
        # D is the running sum of the closed cycles' increments plus the open residue as half cycles
        closed = sum(h.damage_increment for h in trend)
        assert spot.consumed == trend[-1].consumed and closed <= spot.consumed
        assert all(b.consumed >= a.consumed - 1e-18 for a, b in zip(trend, trend[1:]))
        assert spot.del_pa["3"] > 0 and spot.del_pa["5"] > 0 and spot.verdict in ("finite", "no_damage_below_cutoff")
        # each window counts its first step (10 s of the 20 s window): N_eq = 1 Hz × 10 s
        assert all(h.n_eq == pytest.approx(10.0) for h in trend)
        # the band of each window, judged at the mast's four strain gauges, with its method stated
        for h in trend:
            assert h.band_method.startswith("calibrated on the gauges' cross-validated residuals (g1 ")
            assert all(f"{g} " in h.band_method for g in ("g2", "g3", "g4"))
            for m, (low, high) in h.del_band_pa.items():
                assert low < h.del_pa[m] < high and high / h.del_pa[m] == pytest.approx(h.del_pa[m] / low, rel=1e-9)
                assert high / h.del_pa[m] >= 1.02  # at least the 2 % floor
            assert h.damage_band[0] <= h.damage_increment <= h.damage_band[1]
    # the strain envelope along the 20 m mast: 16 stations from the foundation, largest at the root
    env = doc.envelope
    assert len(env) == 16 and env[0].position_m == 0.0 and env[-1].position_m == pytest.approx(18.75)
    assert env[0].strain_range_max == max(e.strain_range_max for e in env)
    assert env[0].stress_range_max_pa == pytest.approx(env[0].strain_range_max * 2.1e11, rel=0.02)  # E(T), T near 20 °C
    # the status carries the latest hot spots; /metrics their gauges
    assert {h["name"] for h in a["status"]["pipeline"]["hot_spots"]} == set(SPOTS)
    for name in ("shm_fatigue_consumed_ratio", "shm_fatigue_del_pascals", "shm_fatigue_remaining_life_years"):
        assert f"# TYPE {name} gauge" in a["metrics"]
    line = next(x for x in a["metrics"].splitlines() if x.startswith('shm_fatigue_consumed_ratio{hot_spot="door_opening"}'))
    assert float(line.split()[-1]) == pytest.approx(next(h.consumed for h in doc.hot_spots if h.name == "door_opening"), rel=1e-12)
    assert 'shm_fatigue_del_pascals{hot_spot="base_flange_weld",m="5"}' in a["metrics"]


def test_fatigue_csv_limits_errors_and_openapi(served):
    _, _, a = served
    doc = FatigueDocument.model_validate(a["structure"].json())
    r = a["csv"]
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    assert r.headers["X-Total-Count"] == str(doc.total) and r.headers["X-Truncated"] == "false"
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert len(rows) == len(doc.windows) * len(SPOTS)
    assert {"del_m3_pa", "del_m5_pa", "consumed", "remaining_years", "verdict"} <= set(rows[0])
    last = [row for row in rows if row["hot_spot"] == "door_opening"][-1]
    assert float(last["consumed"]) == next(h.consumed for h in doc.hot_spots if h.name == "door_opening")
    limited = FatigueDocument.model_validate(a["limited"].json())
    assert len(limited.windows) == 2 and limited.truncated and limited.total == doc.total
    assert limited.windows == doc.windows[:2]
    assert a["unknown"].status_code == 404 and "nope" in a["unknown"].json()["detail"]
    assert a["bad_period"].status_code == 422 and "after" in a["bad_period"].json()["detail"]
    paths = a["openapi"]["paths"]
    for path in ("/api/fatigue", "/api/structures/{structure_id}/fatigue"):
        ok = paths[path]["get"]["responses"]["200"]["content"]
        assert ok["application/json"]["schema"]["$ref"].endswith("/FatigueDocument") and "text/csv" in ok
    assert "FatigueDocument" in a["openapi"]["components"]["schemas"]


def test_a_sigkill_neither_loses_nor_double_counts_a_cycle(served, mast_rig, mast_recording, tmp_path):
    """The same replay killed (SIGKILL) after a few windows and started again on its database: the
    same windows, each once, and the same consumed life as the uninterrupted run."""
    whole_tmp, _, a = served
    whole = _rows(whole_tmp / "shm.sqlite")
    db = tmp_path / "shm.sqlite"
    # paced (10x), so the kill lands mid-run: at max speed a fast machine committed every window
    # before the poll that saw the fourth could kill it
    serve = _serve(_config(tmp_path, mast_rig, mast_recording, db, speed="10"), tmp_path)
    try:
        wait_for(lambda: _status(serve.url)["pipeline"]["windows_committed"] >= 4, timeout=300)
        os.kill(serve.pid, signal.SIGKILL)
        serve.process.wait(10)
    finally:
        serve.kill()
    before = _rows(db)
    assert 0 < len(before) < len(whole)
    serve = _serve(_config(tmp_path, mast_rig, mast_recording, db), tmp_path)  # the rest at max speed
    try:
        wait_for(lambda: _finished(serve.url), timeout=300)
    finally:
        serve.stop()  # drains: every window is committed
    after = _rows(db)
    assert set(after) == set(whole)  # every window once (the rows are keyed by window and hot spot)
    for spot in SPOTS:
        last = max(k for k in whole if k[1] == spot)
        got = after[last][1]
        # the restarted estimator re-converges from the stored calibration: b differs by far less than a
        # window's damage (one lost or doubled window would be ~10 % of D here)
        assert got == pytest.approx(whole[last][1], rel=1e-3), spot
        # the windows committed before the kill were kept as written
        for key, value in before.items():
            assert after[key] == value


def test_the_fatigue_router_in_process(served, tmp_path):
    """The router against the service's own database, in process (the app on a loopback port)."""
    from shm_service.service import ApiServer, MonitoringService, create_app, load_settings

    whole_tmp, toml, a = served
    settings = load_settings(toml, {"db": str(whole_tmp / "shm.sqlite"), "source": {"spec": "ingest", "id": a["sid"]},
                                    "archive": {"enabled": False}})
    service = MonitoringService(settings, environ={})
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    try:
        with httpx.Client(base_url=api.url, timeout=30) as client:
            sid = next(iter(service.structures))
            got = client.get(f"/api/structures/{sid}/fatigue", params={"from": str(a["structure"].json()["windows"][2]["start_s"])})
            assert got.status_code == 200
            doc = FatigueDocument.model_validate(got.json())
            full = FatigueDocument.model_validate(a["structure"].json())
            assert doc.windows == full.windows[2:] and doc.total == full.total - 2 and doc.hot_spots == full.hot_spots
            assert client.get("/api/fatigue", params={"format": "xml"}).status_code == 422
            assert client.get("/api/fatigue", params={"limit": 0}).status_code == 422
            empty = client.get("/api/fatigue", params={"from": str(full.windows[-1].start_s + 1)}).json()
            assert empty["windows"] == [] and empty["hot_spots"] == [] and empty["total"] == 0
    finally:
        api.stop()
        service.storage.close()


@pytest.mark.slow
def test_reprocess_of_the_archive_accumulates_the_damage_the_live_service_did(served, mast_rig, tmp_path, capsys):
    """``shm reprocess`` of the service's own archive (its estimates at 200 Hz): the live service's
    windows again, with the same damage window by window and the same consumed life."""
    import json

    whole_tmp, toml, _ = served
    archives = sorted(str(p) for p in (whole_tmp / "recordings").glob("*.mcap"))
    assert archives
    db = tmp_path / "re.sqlite"
    assert main(["reprocess", *archives, "--db", str(db), "--config", str(toml), "--rig", str(mast_rig), "--workers", "1",
                 "--json"]) == 0
    assert all(f["status"] == "done" for f in json.loads(capsys.readouterr().out)["files"])
    live, again = _rows(whole_tmp / "shm.sqlite"), _rows(db)
    # the archive knows no rest phase, so reprocess also analyses the warm-up windows the live service
    # skipped (the mast at rest and the filter converging: next to no damage); every live window is there
    assert set(live) <= set(again) and len(again) - len(live) <= 4 * len(SPOTS)
    # the warm-up windows' open reversals close a few cycles in other windows: the increments move a
    # little between windows, D agrees (one window more or less would be several per cent of it)
    worst = max(abs(again[k][1] / v[1] - 1) for k, v in live.items() if v[1] > 0)
    print(f"reprocess vs live: consumed life differs by {worst:.1e} relative at most (over {len(live)} rows)")
    assert worst < 1e-4
    for spot in SPOTS:
        last = max(k for k in live if k[1] == spot)
        assert again[last][1] == pytest.approx(live[last][1], rel=1e-5)


def test_the_live_view_carries_virtual_strain_stress_and_moments(served, mast_rig):
    """Each live estimate carries ε = −c κ, σ = E ε, M = EI κ at the hot spots and the grid, and the
    clamped mast's root bending moment."""
    import numpy as np

    from contract import LiveEstimatesDocument, load_rig

    _, _, a = served
    assert a["live"], "the live view kept no estimate while watched"
    doc = LiveEstimatesDocument.model_validate(a["live"][-1])
    n, names = len(doc.t_s), doc.loads_station_names
    assert names[:2] == ["base_flange_weld", "door_opening"] and doc.loads_stations_m[:2] == [0.15, 2.0]
    assert len(doc.loads_stations_m) == 2 + 16 and set(names[2:]) == {""}
    strain, stress, moment = np.array(doc.strain), np.array(doc.stress_pa), np.array(doc.moment_nm)
    assert strain.shape == stress.shape == moment.shape == (n, 18) and len(doc.root_moment_nm) == n
    beam = load_rig(mast_rig).beam
    eta = np.array(doc.loads_stations_m)
    np.testing.assert_allclose(stress, strain * 2.1e11, rtol=1e-12)
    # M = EI κ and ε = −c κ: M = −EI ε / c at every station
    np.testing.assert_allclose(moment, -strain * beam.bending_stiffness(eta) / beam.fibre_distance(eta), rtol=1e-9, atol=1e-9)
    # the grid's first station is the root: the root moment is its moment
    np.testing.assert_allclose(doc.root_moment_nm, moment[:, 2], rtol=1e-12)
    assert np.max(np.abs(strain[:, 2])) > 1e-6  # the wind bends the mast
    # the status's hot spots, the live view's and the fatigue rows name the same hot spots
    assert set(names[:2]) == {h["name"] for h in a["status"]["pipeline"]["hot_spots"]}
