"""What the API serves while ``shm serve`` cannot build its service yet: a ``follow:`` source
whose file (and its ``rig.json``, which the model needs) is not there yet. The API is up and
authenticated as usual; ``/healthz`` answers "degraded" with the reason, every other route 503
with ``Retry-After`` (``ServiceStarting``), until the service replaces this stand-in in the
``ServiceSlot`` the app was built on.
"""

from __future__ import annotations

import hmac
import time
from collections.abc import Mapping
from typing import Any

from contract import HealthDocument

from .._config import ServiceSettings, resolve_token

__all__ = ["ServiceSlot", "ServiceStarting", "StartingService"]


class ServiceStarting(RuntimeError):
    """The service is not built yet (the message says what it waits for): retry later (503)."""


class StartingService:
    """The API's service before the real one exists (see the module docstring)."""

    def __init__(self, settings: ServiceSettings, waiting_for: str, *, environ: Mapping[str, str] | None = None) -> None:
        self.settings = settings
        self.token = resolve_token(settings, environ)
        self.waiting_for = waiting_for
        self.started_at = time.time()

    def check_token(self, token: str | None) -> None:
        if self.token is None:
            raise PermissionError("no API token is configured (server.token_file or SHM_TOKEN); this action is disabled")
        if not token or not hmac.compare_digest(token.encode(), self.token.encode()):
            raise PermissionError("missing or wrong token")

    def health(self) -> HealthDocument:
        return HealthDocument(status="degraded", uptime_s=round(time.time() - self.started_at, 1),
                              reasons=[f"starting: {self.waiting_for}"])

    def _starting(self, *args: Any, **kwargs: Any) -> Any:
        raise ServiceStarting(f"the service is starting: {self.waiting_for}")

    status = trends = alarms = acknowledge = request_baseline = spectra = ingest = _starting
    trends_page = alarms_page = structure_trends_page = structure_alarms_page = _starting


class ServiceSlot:
    """The service the API calls: first a ``StartingService``, then the real one (``current``)."""

    def __init__(self, current: Any) -> None:
        self.current = current

    def __getattr__(self, name: str) -> Any:
        return getattr(self.__dict__["current"], name)
