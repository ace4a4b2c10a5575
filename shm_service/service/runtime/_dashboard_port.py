"""Where the monitoring service starts its dashboard (package ``web``).

The dashboard is built against the ``contract`` package only: it reads the running service
through its ``contract.ServicePort`` (one structure or a fleet alike, nothing is pushed into
it). It polls ``structures_document()`` every few seconds for the overview and, for each
structure a browser shows (only those), ``live()`` a few times a second, its status, alarms,
new trend rows, latest window and spectra after a new window, and (a rig with hot spots) its
fatigue. The service behind the port may be the structures in this process or the front of
worker processes (which forwards ``live``, status, the window and spectra to the structure's
worker and reads the rows from the database): the dashboard cannot tell.
"""

from __future__ import annotations

import logging
from typing import Any

from contract import SENSOR_STATES, ServicePort, StructureModel

__all__ = ["SENSOR_STATES", "StructureModel", "start_dashboard"]

log = logging.getLogger("shm.serve")


def start_dashboard(service: ServicePort, settings: Any, token: str | None) -> Any:
    """``web.Dashboard`` on ``settings.dashboard`` reading ``service``; None (logged) when it
    cannot start: the monitoring runs without it."""
    try:
        import web

        Dashboard = web.Dashboard
    except (ImportError, AttributeError):
        log.warning("dashboard: web.Dashboard is not available; running without the dashboard")
        return None
    d = settings.dashboard
    try:
        dashboard = Dashboard(host=d.host, port=d.port, service=service, token=token)
    except Exception as exc:
        log.warning("dashboard failed to start (%s); running without it", exc)
        return None
    log.info("dashboard at %s", getattr(dashboard, "url", "?"))
    return dashboard
