"""Delivery of alarm notifications from the outbox: webhooks (JSON POST) and e-mail (SMTP), with
Alertmanager-like semantics.

- The outbox rows are written in the same transaction as the alarm event that causes them, so a
  crash never loses one. A row is marked sent in the transaction that logs the successful
  attempt. Delivery is at-least-once: a crash between the receiver's answer and that commit
  repeats a notification; every notification carries an id that never repeats for another event
  (body ``id`` and the ``Idempotency-Key`` header: a random instance id and the event's UUID) and
  the alarm's event ``sequence`` number, by which a receiver recognises a repeat.
- Each target has a worker thread of its own: one slow or failing target never delays another.
- A target gets the events of one alarm in their order: an event waits while an earlier event
  of the same alarm is still pending for that target (``Storage.due_notifications``).
- An answer 2xx is success; 4xx other than 408 and 429 (and 3xx: redirects are not followed)
  is permanent: the notification fails at once, logged, counted and shown in the status. 5xx,
  408, 429 and network errors or timeouts are retried with exponential back-off times a random
  factor 0.5–1 (``Retry-After`` is honoured), until ``give_up_after_s`` (or ``max_attempts``).
"""

from __future__ import annotations

import json
import logging
import os
import random
import smtplib
import threading
import time
from collections import Counter
from email.message import EmailMessage
from typing import Any

import httpx
from pydantic import BaseModel, ConfigDict, Field, field_validator

from ._sinks import SinkGuard
from ..storage._storage import Storage

__all__ = ["DeliveryResult", "NotifySettings", "Notifier", "classify_http", "notify_targets", "retry_delay"]

log = logging.getLogger("shm.serve.notify")

#: Outcome kinds of one attempt (counted in /metrics): sent; retry (a temporary failure, tried
#: again later); permanent (refused for good by the target); given_up (retried too long).
OUTCOMES = ("sent", "retry", "permanent", "given_up")


class NotifySettings(BaseModel):
    """Notifications of alarm events: webhooks and e-mail, through a persistent outbox. Each target
    gets an alarm's events in their order; a 4xx answer other than 408/429 is permanent (the
    notification fails at once, reported), 5xx, 408, 429 and network errors are retried with
    jittered exponential back-off; targets are served independently."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    webhooks: tuple[str, ...] = Field((), description="URLs that receive a JSON POST per alarm event")
    webhook_timeout_s: float = Field(5.0, gt=0, description="timeout of one webhook attempt, s")
    retry_initial_s: float = Field(1.0, gt=0, description="first retry delay, s (doubles each attempt, times a random 0.5-1)")
    retry_max_s: float = Field(300.0, gt=0, description="longest retry delay, s")
    max_attempts: int | None = Field(None, ge=1, description="attempts before a notification is given up (None: no limit)")
    give_up_after_s: float = Field(
        7 * 86400.0, gt=0, description="a notification still failing this long after its event is given up (logged and "
        "counted as failed), s")
    smtp_host: str | None = Field(None, description="SMTP server for e-mail (None: no e-mail)")
    smtp_port: int = Field(25, ge=1, le=65535, description="SMTP port")
    smtp_starttls: bool = Field(False, description="use STARTTLS")
    smtp_user: str | None = Field(None, description="SMTP user (password from env SHM_SMTP_PASSWORD)")
    mail_from: str = Field("shm@localhost", description="sender address")
    mail_to: tuple[str, ...] = Field((), description="recipients")

    @field_validator("webhooks")
    @classmethod
    def _urls(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        # Parsed here, once, as the notifier will use them: a URL the HTTP client cannot use is a
        # configuration error at start, not a notification failing for ever.
        import httpx

        for url in value:
            try:
                parsed = httpx.URL(url)
            except (httpx.InvalidURL, TypeError, ValueError) as exc:
                raise ValueError(f"webhook {url!r} is not a valid URL: {exc}") from None
            if parsed.scheme not in ("http", "https"):
                raise ValueError(f"webhook {url!r} must be an http:// or https:// URL")
            if not parsed.host:
                raise ValueError(f"webhook {url!r} has no host")
            if parsed.port is not None and not 0 < parsed.port < 65536:
                raise ValueError(f"webhook {url!r}: port {parsed.port} is not within 1-65535")
        if len(set(value)) != len(value):
            raise ValueError(f"webhooks {list(value)} name a URL twice")
        return value


def notify_targets(settings: NotifySettings) -> list[tuple[str, str]]:
    targets = [("webhook", url) for url in settings.webhooks]
    if settings.smtp_host and settings.mail_to:
        targets.append(("email", ",".join(settings.mail_to)))
    return targets


def retry_delay(attempt: int, initial_s: float, max_s: float, rng: random.Random | None = None) -> float:
    """Delay before the next attempt after ``attempt`` failed ones (1-based): exponential
    (``initial_s`` · 2^(attempt−1), at most ``max_s``) times a random factor in [0.5, 1) so that
    many notifications failing together do not retry in step."""
    if attempt < 1:
        raise ValueError(f"{attempt=} must be >= 1")
    if not (initial_s > 0 and max_s > 0):
        raise ValueError(f"{initial_s=} and {max_s=} must be > 0")
    nominal = min(initial_s * 2.0 ** min(attempt - 1, 60), max_s)
    return nominal * (rng or random).uniform(0.5, 1.0)


class DeliveryResult:
    """What one attempt gave: ``outcome`` is "sent", "retry" or "permanent"; ``retry_after_s``
    what the target asked for (Retry-After), if anything."""

    __slots__ = ("outcome", "detail", "retry_after_s")

    def __init__(self, outcome: str, detail: str, retry_after_s: float | None = None) -> None:
        if outcome not in ("sent", "retry", "permanent"):
            raise ValueError(f"{outcome=} must be sent, retry or permanent")
        self.outcome = outcome
        self.detail = detail
        self.retry_after_s = retry_after_s


def classify_http(status: int) -> str:
    """sent (2xx), retry (5xx, 408, 429) or permanent (every other answer: 4xx, and 3xx, as
    redirects are not followed)."""
    if not 100 <= status <= 599:
        raise ValueError(f"{status=} is not an HTTP status code")
    if 200 <= status < 300:
        return "sent"
    if status >= 500 or status in (408, 429):
        return "retry"
    return "permanent"


def _retry_after(value: str | None) -> float | None:
    if not value:
        return None
    try:
        seconds = float(value)
    except ValueError:
        from email.utils import parsedate_to_datetime

        try:
            seconds = parsedate_to_datetime(value).timestamp() - time.time()
        except (TypeError, ValueError, IndexError):
            return None
    return max(0.0, seconds) if seconds == seconds else None


class Notifier:
    """Delivers the outbox: one worker thread per configured target."""

    def __init__(self, storage: Storage, settings: NotifySettings, environ: dict[str, str] | None = None,
                 *, rng: random.Random | None = None) -> None:
        self.storage = storage
        self.settings = settings
        self.environ = dict(os.environ if environ is None else environ)
        self.targets = notify_targets(settings)
        self._rng = rng or random.Random()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._wakes = {target: threading.Event() for target in self.targets}
        self._threads: list[threading.Thread] = []
        self._clients = {target: httpx.Client(timeout=settings.webhook_timeout_s, follow_redirects=False)
                         for target in self.targets if target[0] == "webhook"}
        self.outcomes: Counter = Counter()  # attempts this run by outcome kind
        self.by_target: dict[str, Counter] = {target: Counter() for _, target in self.targets}
        self.last_error: str | None = None
        # Failed deliveries by channel and errors of the loops themselves: counted, logged once per kind.
        self.guard = SinkGuard("notifier", log)

    # -- counters (the status document's names) -------------------------------------------------

    @property
    def sent(self) -> int:
        return self.outcomes["sent"]

    def snapshot(self) -> tuple[Counter, Any]:
        """(outcomes of this run, the notifier sink's status) read at one instant."""
        with self._lock:
            return Counter(self.outcomes), self.guard.status()

    # -- lifecycle ------------------------------------------------------------------------------

    def start(self) -> None:
        configured = set(self.targets)
        for channel, target in self.storage.pending_targets():
            if (channel, target) not in configured:
                n = self.storage.fail_pending(channel, target, "target no longer configured (notify settings)")
                log.warning("%d pending notification(s) to %s %s failed: the target is no longer configured", n, channel, target)
        for channel_target in self.targets:
            thread = threading.Thread(target=self._worker, args=(channel_target,), name=f"notify-{channel_target[0]}",
                                      daemon=True)
            thread.start()
            self._threads.append(thread)

    def wake(self) -> None:
        for event in self._wakes.values():
            event.set()

    def stop(self, drain_s: float = 0.0) -> None:
        deadline = time.monotonic() + drain_s
        while drain_s and time.monotonic() < deadline and self.storage.due_notifications(time.time(), 1):
            time.sleep(0.05)
        self._stop.set()
        self.wake()
        for thread in self._threads:
            thread.join(self.settings.webhook_timeout_s + 5.0)
        for client in self._clients.values():
            client.close()

    # -- delivery -------------------------------------------------------------------------------

    def _worker(self, target: tuple[str, str]) -> None:
        wake = self._wakes[target]
        while not self._stop.is_set():
            try:
                self.deliver_target(target)
                due = self.storage.next_due(channel=target[0], target=target[1])
            except Exception as exc:  # never let a worker die (the database may be unavailable for a while)
                self.guard.record("loop", exc)
                due = None
            wait = 1.0 if due is None else min(max(due - time.time(), 0.01), 1.0)
            wake.wait(wait)
            wake.clear()

    def deliver_due(self) -> int:
        """One pass over every target (in this thread); returns the notifications sent."""
        return sum(self.deliver_target(target) for target in self.targets)

    def deliver_target(self, target: tuple[str, str]) -> int:
        channel, address = target
        done = 0
        while not self._stop.is_set():
            rows = self.storage.due_notifications(time.time(), 20, channel=channel, target=address)
            if not rows:
                break
            for row in rows:
                if self._stop.is_set():
                    break
                done += self._attempt(target, row)
        return done

    def _attempt(self, target: tuple[str, str], row: dict[str, Any]) -> int:
        # The nodes of a fleet share one outbox: the row is taken first, for longer than an
        # attempt lasts, or another node's notifier would send it too (a no-op on a SQLite file).
        if not self.storage.claim_notification(row["id"], self.settings.webhook_timeout_s + 30.0):
            return 0
        result = self._send(row)
        attempt = int(row["attempts"]) + 1
        s = self.settings
        give_up = result.outcome == "permanent"
        kind = result.outcome
        if result.outcome == "retry":
            too_old = time.time() - float(row["created_at"]) > s.give_up_after_s
            too_many = s.max_attempts is not None and attempt >= s.max_attempts
            if too_old or too_many:
                give_up, kind = True, "given_up"
        delay = retry_delay(attempt, s.retry_initial_s, s.retry_max_s, self._rng)
        if result.retry_after_s is not None:
            delay = min(max(delay, result.retry_after_s), s.retry_max_s)
        self.storage.record_attempt(row["id"], result.outcome == "sent", result.detail, next_attempt_at=time.time() + delay,
                                    give_up=give_up, permanent=result.outcome == "permanent")
        text = None if result.outcome == "sent" else f"notification {row['id']} to {row['target']} (attempt {attempt}): {result.detail}"
        with self._lock:  # the outcome and the sink error together: a status reads both at once (snapshot)
            self.outcomes[kind] += 1
            self.by_target[target[1]][kind] += 1
            if text is not None:
                self.last_error = text
                self.guard.record(str(row["channel"]), text)
        if text is None:
            return 1
        if give_up:
            log.error("%s: %s", "refused for good" if kind == "permanent" else "given up", text)
        return 0

    def _send(self, row: dict[str, Any]) -> DeliveryResult:
        try:
            payload = json.loads(row["payload"])
            if row["channel"] == "webhook":
                return self._post(row, payload)
            if row["channel"] == "email":
                return self._mail(row["target"].split(","), payload)
            return DeliveryResult("permanent", f"unknown channel {row['channel']!r}")
        except (httpx.TimeoutException, httpx.TransportError) as exc:
            # network errors and timeouts pass (or not): retried, never blocking another target
            if isinstance(exc, (httpx.UnsupportedProtocol,)):
                return DeliveryResult("permanent", f"{type(exc).__name__}: {exc}")
            return DeliveryResult("retry", f"{type(exc).__name__}: {exc}")
        except smtplib.SMTPResponseException as exc:
            code = int(getattr(exc, "smtp_code", 0) or 0)
            return DeliveryResult("permanent" if 500 <= code < 600 else "retry", f"SMTP {code}: {exc}")
        except smtplib.SMTPRecipientsRefused as exc:
            codes = [int(c) for c, _ in exc.recipients.values()]
            return DeliveryResult("permanent" if codes and all(500 <= c < 600 for c in codes) else "retry", f"SMTP: {exc}")
        except (OSError, smtplib.SMTPException) as exc:
            return DeliveryResult("retry", f"{type(exc).__name__}: {exc}")
        except Exception as exc:  # a bad stored row, an unusable URL: this row fails, not the others
            return DeliveryResult("permanent", f"{type(exc).__name__}: {exc}")

    def _post(self, row: dict[str, Any], payload: dict[str, Any]) -> DeliveryResult:
        client = self._clients.get((row["channel"], row["target"]))
        if client is None:
            return DeliveryResult("permanent", "target no longer configured")
        r = client.post(row["target"], content=row["payload"].encode(),
                        headers={"Content-Type": "application/json", "Idempotency-Key": payload["id"]})
        outcome = classify_http(r.status_code)
        detail = f"HTTP {r.status_code}"
        if outcome != "sent":
            text = r.text[:200].strip()
            if text:
                detail += f": {text}"
        return DeliveryResult(outcome, detail, _retry_after(r.headers.get("retry-after")) if outcome == "retry" else None)

    def _mail(self, to: list[str], payload: dict[str, Any]) -> DeliveryResult:
        s = self.settings
        if s.smtp_host is None:  # start() failed every e-mail left pending when the settings had no server
            return DeliveryResult("permanent", "no smtp_host configured")
        alarm = payload["alarm"]
        msg = EmailMessage()
        msg["Subject"] = f"[shm] {payload['level']} {payload['event']}: {alarm['message']}"
        msg["From"] = s.mail_from
        msg["To"] = ", ".join(to)
        msg["Message-ID"] = f"<{payload['id']}@shm>"
        msg.set_content(json.dumps(payload, indent=2))
        with smtplib.SMTP(s.smtp_host, s.smtp_port, timeout=s.webhook_timeout_s) as smtp:
            if s.smtp_starttls:
                smtp.starttls()
            if s.smtp_user:
                smtp.login(s.smtp_user, self.environ.get("SHM_SMTP_PASSWORD", ""))
            smtp.send_message(msg)
        return DeliveryResult("sent", "SMTP accepted")
