"""Isolation of the service's sinks (the dashboard, the notifier): a sink that fails never
stops the monitoring. Each failure is counted by what the sink was doing (its kind) for
``/api/status`` and ``/metrics``; the first failure of each kind is logged with its traceback,
later ones only counted (a broken dashboard would otherwise log at 15 Hz)."""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Callable
from typing import Any

from contract import SinkStatusDocument

__all__ = ["SinkGuard"]


class SinkGuard:
    """Failures of one sink (thread-safe)."""

    def __init__(self, name: str, logger: logging.Logger) -> None:
        self.name = name
        self.log = logger
        self._lock = threading.Lock()
        self._errors: Counter[str] = Counter()
        self._last: str | None = None

    def call(self, kind: str, fn: Callable[..., Any], *args: Any) -> bool:
        """``fn(*args)``; a failure is recorded under ``kind`` and swallowed. True when it worked."""
        try:
            fn(*args)
        except Exception as exc:  # noqa: BLE001 - whatever a sink raises, the pipeline goes on
            self.record(kind, exc)
            return False
        return True

    def record(self, kind: str, error: BaseException | str) -> None:
        """Count one failure of ``kind``; the first of each kind is logged."""
        text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
        with self._lock:
            self._errors[kind] += 1
            first = self._errors[kind] == 1
            self._last = f"{kind}: {text}"
        if first:
            exc_info = error if isinstance(error, BaseException) else None
            self.log.warning("%s %s failed (%s); the monitoring goes on, further %s failures are only counted",
                             self.name, kind, text, kind, exc_info=exc_info)

    @property
    def errors(self) -> int:
        with self._lock:
            return sum(self._errors.values())

    def status(self) -> SinkStatusDocument:
        with self._lock:
            return SinkStatusDocument(errors=sum(self._errors.values()), errors_by_kind=dict(self._errors), last_error=self._last)
