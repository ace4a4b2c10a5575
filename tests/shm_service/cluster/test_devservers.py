"""The throwaway servers of the tests and of ``make servers``: real PostgreSQL and Mosquitto on free
loopback ports that answer, and that die with the process that started them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import paho.mqtt.client as mqtt
import psycopg
import pytest

from shm_service.devservers import free_port, start_mosquitto, start_postgres

ROOT = Path(__file__).resolve().parents[3]


def test_postgres_answers_sql(postgres_url):
    with psycopg.connect(postgres_url) as db:
        db.execute("CREATE TABLE IF NOT EXISTS probe (k int PRIMARY KEY, v text)")
        db.execute("INSERT INTO probe VALUES (1, 'one') ON CONFLICT (k) DO UPDATE SET v = excluded.v")
        assert db.execute("SELECT v FROM probe WHERE k = 1").fetchone() == ("one",)
        assert db.execute("SHOW server_version").fetchone()[0].split(".")[0].isdigit()


def test_fresh_database_is_empty_and_its_own(fresh_postgres_url, postgres_url):
    assert fresh_postgres_url != postgres_url
    with psycopg.connect(fresh_postgres_url) as db:
        tables = db.execute("SELECT count(*) FROM information_schema.tables WHERE table_schema = 'public'").fetchone()[0]
    assert tables == 0


def test_mosquitto_delivers_qos1_and_keeps_a_persistent_session(mqtt_server):
    """A QoS 1 message published while a persistent session's client is away is delivered when
    it comes back (what a structure's takeover relies on)."""
    port = mqtt_server.port
    got: list[bytes] = []
    arrived = threading.Event()

    def subscriber() -> mqtt.Client:
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="probe-session", protocol=mqtt.MQTTv5)
        c.on_message = lambda client, userdata, message: (got.append(message.payload), arrived.set())
        props = mqtt.Properties(mqtt.PacketTypes.CONNECT)
        props.SessionExpiryInterval = 3600
        c.connect("127.0.0.1", port, clean_start=False, properties=props)
        c.subscribe("probe/x", qos=1)
        return c

    sub = subscriber()
    sub.loop_start()
    time.sleep(0.5)
    sub.disconnect()
    sub.loop_stop()
    pub = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="probe-pub", protocol=mqtt.MQTTv5)
    pub.connect("127.0.0.1", port)
    pub.loop_start()
    pub.publish("probe/x", b"kept while away", qos=1).wait_for_publish(10)
    pub.disconnect()
    pub.loop_stop()
    sub = subscriber()
    sub.loop_start()
    try:
        assert arrived.wait(10), "the broker did not deliver the message kept for the session"
    finally:
        sub.disconnect()
        sub.loop_stop()
    assert got == [b"kept while away"]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is dead too
        return Path(f"/proc/{pid}/stat").read_text().split(") ", 1)[1][0] != "Z"
    except (OSError, IndexError):
        return False


def test_servers_die_with_a_killed_parent():
    """SIGKILL of the process that started them (no chance to clean up): both servers end, and
    the next start removes the directories it left."""
    code = ("import sys, time\n"
            "from shm_service.devservers import start_postgres, start_mosquitto\n"
            "p = start_postgres(); m = start_mosquitto()\n"
            "print(p.process.pid, m.process.pid, p.port, m.port, p.directory, m.directory, flush=True)\n"
            "time.sleep(600)\n")
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        line = parent.stdout.readline()
        assert line, "the parent printed nothing"
        *numbers, pg_dir, mq_dir = line.split()
        pg_pid, mq_pid, pg_port, mq_port = (int(x) for x in numbers)
        assert _alive(pg_pid) and _alive(mq_pid)
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        parent.stdout.close()
    deadline = time.monotonic() + 20
    while (_alive(pg_pid) or _alive(mq_pid)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(pg_pid), "PostgreSQL outlived its parent"
    assert not _alive(mq_pid), "Mosquitto outlived its parent"
    for port in (pg_port, mq_port):
        import socket
        with socket.socket() as s:
            assert s.connect_ex(("127.0.0.1", port)) != 0, f"port {port} still answers"
    assert Path(pg_dir).exists() and Path(mq_dir).exists()  # SIGKILL: nobody removed them
    start_mosquitto().stop()  # sweeps the stale directories of both kinds' prefix it owns
    start_postgres().stop()
    assert not Path(pg_dir).exists() and not Path(mq_dir).exists()


def test_a_taken_port_is_an_error_naming_the_server(postgres_server, mqtt_server):
    with pytest.raises(RuntimeError, match="mosquitto"):
        start_mosquitto(port=postgres_server.port, timeout_s=10)
    with pytest.raises(RuntimeError, match="postgres"):
        start_postgres(port=mqtt_server.port, timeout_s=10)
    mine = [d for d in Path(tempfile.gettempdir()).glob("shm-*-*") if (d / "started-by.pid").is_file()
            and (d / "started-by.pid").read_text().strip() == str(os.getpid())]
    assert sorted(mine) == sorted([postgres_server.directory, mqtt_server.directory]), "a failed start left its directory"


def test_free_port_is_bindable():
    import socket

    port = free_port()
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))
