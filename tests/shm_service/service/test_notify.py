"""Notifications: webhook retries with back-off (every attempt logged), e-mail over SMTP
(a local aiosmtpd server)."""

from __future__ import annotations

import json
import time

from svc_helpers import Receiver, wait_for

from shm_service.service import AlarmChange, NotifySettings, Storage, WindowCommit
from shm_service.service.alarms._notify import Notifier, notify_targets


def _raise(storage):
    change = AlarmChange("raise", "mode2", "frequency", 2, "alarm", 1000.0, 6.0, 5.0, "mode 2 off")
    storage.commit_window(WindowCommit("src", 980.0, 1000.0, [], None, None, [change]))


def test_webhook_retries_with_backoff_and_logs_every_attempt(storage_target):
    rx = Receiver(fail_first=2)
    try:
        settings = NotifySettings(webhooks=(rx.url,), retry_initial_s=0.05, retry_max_s=0.2)
        st = Storage(storage_target, notify_targets=notify_targets(settings))
        _raise(st)
        n = Notifier(st, settings, environ={})
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not rx.posts:
            n.deliver_due()
            time.sleep(0.02)
        n.stop()
        assert len(rx.posts) == 1 and rx.posts[0]["event"] == "raised" and rx.keys[0] == rx.posts[0]["id"]
        log = st.notification_log()
        assert [r["ok"] for r in log] == [0, 0, 1] and [r["attempt"] for r in log] == [1, 2, 3]
        assert st.outbox()[0]["status"] == "sent"
    finally:
        rx.close()


def test_gives_up_after_max_attempts(storage_target):
    settings = NotifySettings(webhooks=("http://127.0.0.1:9/none",), retry_initial_s=0.01, retry_max_s=0.01, max_attempts=2,
                              webhook_timeout_s=0.5)
    st = Storage(storage_target, notify_targets=notify_targets(settings))
    _raise(st)
    n = Notifier(st, settings, environ={})
    for _ in range(20):
        n.deliver_due()
        time.sleep(0.02)
    n.stop()
    assert st.outbox()[0]["status"] == "failed" and len(st.notification_log()) == 2


def test_email_over_smtp(tmp_path):
    from aiosmtpd.controller import Controller

    received = []

    class Handler:
        async def handle_DATA(self, server, session, envelope):  # noqa: N802
            received.append(envelope)
            return "250 OK"

    import socket

    with socket.socket() as probe:  # a free loopback port
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    controller = Controller(Handler(), hostname="127.0.0.1", port=port)
    controller.start()
    try:
        settings = NotifySettings(smtp_host="127.0.0.1", smtp_port=port, mail_to=("ops@example.org",))
        st = Storage(tmp_path / "s.sqlite", notify_targets=notify_targets(settings))
        _raise(st)
        n = Notifier(st, settings, environ={})
        n.deliver_due()
        n.stop()
        assert len(received) == 1 and received[0].rcpt_tos == ["ops@example.org"]
        assert b"mode 2 off" in received[0].content
        assert st.outbox()[0]["status"] == "sent"
    finally:
        controller.stop()


# -- Alertmanager-like semantics ---------------------------------------------




def _change(action, at, chart="mode2", level="alarm"):
    return AlarmChange(action, chart, "frequency", int(chart[4:]), level, at, 6.0, 5.0, f"{chart} {action}")


def test_an_unparsable_webhook_url_is_a_configuration_error_naming_the_key():
    import pytest

    from shm_service.service import SettingsError, load_settings

    for url in ("http://[::1/hook", "http://example.org:99999/x", "ftp://example.org/x", "http:///x"):
        with pytest.raises(SettingsError, match=r"notify\.webhooks"):
            load_settings(None, {"notify": {"webhooks": [url]}})


def test_4xx_is_permanent_and_reported_5xx_and_429_are_retried(storage_target):
    rx = Receiver(script=[400, 503, 429, 200])
    try:
        settings = NotifySettings(webhooks=(rx.url,), retry_initial_s=0.02, retry_max_s=0.05)
        st = Storage(storage_target, notify_targets=notify_targets(settings))
        st.commit_window(WindowCommit("src", 0.0, 20.0, [], None, None, [_change("raise", 20.0, "mode1")]))
        st.commit_window(WindowCommit("src", 0.0, 40.0, [], None, None, [_change("raise", 40.0, "mode3")]))
        n = Notifier(st, settings, environ={})
        assert wait_for(lambda: (n.deliver_due() or True) and len(rx.posts) == 1)
        n.stop()
        first, second = st.outbox()
        # the 400 was not retried: one attempt, failed for good and said so
        assert (first["status"], first["attempts"], first["permanent"]) == ("failed", 1, 1) and "HTTP 400" in first["last_error"]
        # 503, then 429, then delivered
        assert (second["status"], second["attempts"]) == ("sent", 3)
        assert n.outcomes == {"permanent": 1, "retry": 2, "sent": 1}
    finally:
        rx.close()


def test_each_target_gets_an_alarms_events_in_order_whatever_the_retries(storage_target):
    # 'raised' fails once and backs off; 'cleared' (committed meanwhile) must not overtake it
    rx = Receiver(script=[lambda doc: 500 if doc["event"] == "raised" else 200])
    try:
        settings = NotifySettings(webhooks=(rx.url,), retry_initial_s=0.3, retry_max_s=0.3)
        st = Storage(storage_target, notify_targets=notify_targets(settings))
        st.commit_window(WindowCommit("src", 0.0, 20.0, [], None, None, [_change("raise", 20.0)]))
        n = Notifier(st, settings, environ={})
        n.deliver_due()  # raised: 500, due again in 0.15-0.3 s
        st.commit_window(WindowCommit("src", 20.0, 40.0, [], None, None, [_change("clear", 40.0)]))
        assert wait_for(lambda: (n.deliver_due() or True) and len(rx.posts) == 2)
        n.stop()
        assert [(p["event"], p["sequence"]) for p in rx.posts] == [("raised", 1), ("cleared", 2)]
        assert rx.posts[0]["alarm"]["id"] == rx.posts[1]["alarm"]["id"]
    finally:
        rx.close()


def test_a_target_that_hangs_does_not_delay_another(tmp_path):
    import socket

    hang = socket.socket()  # accepts connections (kernel backlog) and never answers
    hang.bind(("127.0.0.1", 0))
    hang.listen(16)
    rx = Receiver()
    try:
        slow = f"http://127.0.0.1:{hang.getsockname()[1]}/hook"
        # the hanging target's attempt lasts its whole timeout, far beyond the wait below
        settings = NotifySettings(webhooks=(slow, rx.url), webhook_timeout_s=60.0, retry_initial_s=10.0)
        st = Storage(tmp_path / "s.sqlite", notify_targets=notify_targets(settings))
        for k in range(3):
            st.commit_window(WindowCommit("src", 20.0 * k, 20.0 * k + 20, [], None, None,
                                          [_change("raise", 20.0 * k + 20, chart=f"mode{k + 1}")]))
        n = Notifier(st, settings, environ={})
        n.start()
        # the healthy target's three posts arrive while the hanging target's first attempt is open
        assert wait_for(lambda: len(rx.posts) == 3, timeout=10.0)
        assert n.outcomes["retry"] == 0 and n.outcomes["given_up"] == 0
        hang.close()  # its attempt ends now (connection reset), so stop does not wait for it
        n.stop()
        assert n.outcomes["sent"] == 3
    finally:
        rx.close()
        hang.close()


def test_retry_delays_grow_are_capped_and_jittered():
    import random

    import pytest

    from shm_service.service.alarms._notify import classify_http, retry_delay

    rng = random.Random(7)
    delays = [retry_delay(k, 1.0, 60.0, rng) for k in range(1, 11)]
    for k, d in enumerate(delays, start=1):
        nominal = min(2.0 ** (k - 1), 60.0)
        assert 0.5 * nominal <= d < nominal
    assert len({round(retry_delay(3, 1.0, 60.0, rng), 9) for _ in range(20)}) > 15  # not in step
    assert [classify_http(c) for c in (200, 204, 302, 400, 404, 408, 429, 500, 503)] == [
        "sent", "sent", "permanent", "permanent", "permanent", "retry", "retry", "retry", "retry"]
    with pytest.raises(ValueError, match="attempt"):
        retry_delay(0, 1.0, 60.0)
    with pytest.raises(ValueError, match="status"):
        classify_http(42)


def test_a_firing_alarm_is_renotified_and_a_silent_sources_alarms_go_stale(storage_target):
    rx = Receiver()
    try:
        settings = NotifySettings(webhooks=(rx.url,))
        st = Storage(storage_target, notify_targets=notify_targets(settings))
        st.touch_source("src", "sim", "sim", 1000.0)
        st.commit_window(WindowCommit("src", 0.0, 20.0, [], None, None, [_change("raise", 20.0)]))
        assert st.renotify_due(0.5) == []  # not yet
        time.sleep(0.6)
        assert len(st.renotify_due(0.5)) == 1
        assert st.renotify_due(0.5) == []  # once per interval
        # no data since 1000 s: the alarm goes stale once, and stale alarms are not re-notified
        assert st.mark_stale(silent_since=time.time() - 60) == [1] and st.mark_stale(silent_since=time.time()) == []
        time.sleep(0.6)
        assert st.alarm(1).stale and st.renotify_due(0.5) == []
        n = Notifier(st, settings, environ={})
        assert wait_for(lambda: (n.deliver_due() or True) and len(rx.posts) == 3)
        n.stop()
        assert [(p["event"], p["sequence"]) for p in rx.posts] == [("raised", 1), ("repeated", 2), ("stale", 3)]
        # the source delivers again: its next window un-stales the alarm
        st.commit_window(WindowCommit("src", 20.0, 40.0, [], None, None, []))
        assert not st.alarm(1).stale
    finally:
        rx.close()


def test_notification_ids_do_not_repeat_after_a_power_loss(tmp_path):
    """After a power loss the last transactions may be gone and an AUTOINCREMENT id is used again:
    the notification of the new event must still have a new id (a receiver deduplicating by it
    would otherwise drop a real alarm)."""
    import sqlite3

    db = tmp_path / "s.sqlite"
    st = Storage(db, notify_targets=[("webhook", "http://127.0.0.1:1/x")])
    st.commit_window(WindowCommit("src", 0.0, 20.0, [], None, None, [_change("raise", 20.0, "mode1")]))
    disk = tmp_path / "disk.sqlite"  # what reached the disk before the power went
    with sqlite3.connect(disk) as copy:
        st._db.backup(copy)
    st.commit_window(WindowCommit("src", 20.0, 40.0, [], None, None, [_change("raise", 40.0, "mode2")]))
    lost = json.loads(st.outbox()[-1]["payload"])["id"]
    st.close()
    after = Storage(disk, notify_targets=[("webhook", "http://127.0.0.1:1/x")])
    after.commit_window(WindowCommit("src", 20.0, 60.0, [], None, None, [_change("raise", 60.0, "mode3")]))
    row = after.outbox()[-1]
    assert row["event_id"] == 2  # the same event id as the lost one...
    assert json.loads(row["payload"])["id"] != lost  # ...but never the same notification id


def test_alarm_and_outbox_transactions_are_committed_with_synchronous_full(tmp_path):
    from shm_service.service import ServiceSettings

    assert ServiceSettings().storage_alarm_sync == "full"
    st = Storage(tmp_path / "s.sqlite", notify_targets=[("webhook", "http://127.0.0.1:1/x")])
    seen = []
    # a transaction: BEGIN, or the one statement that moves plain windows (SQLite's trace repeats it
    # for each statement of its trigger)
    starts = ("BEGIN", "INSERT INTO STAGE_FLUSH")
    st._db.set_trace_callback(lambda sql: seen.append(sql) if sql.upper().startswith(("PRAGMA SYNCHRONOUS", *starts))
                              and (not seen or seen[-1] != sql or sql.upper().startswith("BEGIN")) else None)
    st.commit_window(WindowCommit("src", 0.0, 20.0, [], {"monitor": None}, None, []))  # trend rows and state only
    st.commit_window(WindowCommit("src", 20.0, 40.0, [], None, None, [_change("raise", 40.0)]))
    st.record_attempt(1, True, "HTTP 200", next_attempt_at=None, give_up=False)
    begins = [i for i, sql in enumerate(seen) if sql.upper().startswith(starts)]
    modes = []
    for i in begins:  # the synchronous mode in force at each transaction
        pragmas = [sql.split("=")[1].strip().upper() for sql in seen[:i] if "=" in sql]
        modes.append(pragmas[-1] if pragmas else "NORMAL")
    assert modes == ["NORMAL", "FULL", "FULL"]
