"""The port between the monitoring service and the dashboard (package ``web``).

The dashboard is built against this file and the ``contract`` package only. The service
implements :class:`DashboardService` and hands it to ``web.Dashboard``; the dashboard calls it
from its own thread (viser runs its own thread and asyncio loop), so every method here is
thread-safe and returns the contract's frozen documents.

Agreed dashboard interface (implemented in ``web``; the service only calls it)::

    Dashboard(*, host: str, port: int, rig, units, layout: contract.StateLayout, stations,
              service: DashboardService)
    .url -> str
    .push_estimate(t_s: float, x: np.ndarray, sensor_states: dict[str, str],
                   truth_deflection: np.ndarray | None)      # >= 10 Hz, decimated by the service
    .push_spectra(spectrum: contract.SpectrumDocument)        # after every committed window
    .push_window(window: contract.WindowDocument)             # every committed window
    .push_alarm(alarm: contract.AlarmDocument)                # raised, escalated, cleared, acknowledged
    .stop()

``sensor_states`` maps a topic (``/imu/s1``) to one of ``contract.SENSOR_STATES``. ``x`` is the
estimator state vector read through ``layout`` (``contract.StateLayout``); ``units`` are the
model's unit deformations, whose ``modes`` label trends and spectra (``contract.ModeMap``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from contract import SENSOR_STATES, AlarmDocument, StatusDocument, TrendRow

__all__ = ["DashboardService", "SENSOR_STATES"]


@runtime_checkable
class DashboardService(Protocol):
    """What the running service offers the dashboard. All methods are thread-safe."""

    def status(self) -> StatusDocument:
        """The same document as ``GET /api/status`` (thresholds, baseline, sensors, sources…)."""
        ...

    def trends(self, from_s: float | None, to_s: float | None) -> list[TrendRow]:
        """Trend rows (one per window and eigenmode) with ``from_s <= window_start_s < to_s``
        (UNIX seconds; None = open)."""
        ...

    def alarms(self) -> list[AlarmDocument]:
        """All alarms, newest first."""
        ...

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        """Acknowledge an alarm as ``by`` (who: shown with the alarm); same rules as ``POST /api/alarms/{id}/ack``.

        Raises ``PermissionError`` on a missing or wrong token (or when no token is configured),
        ``KeyError`` when the alarm does not exist. Returns the updated alarm.
        """
        ...

    def set_paused(self, paused: bool) -> None:
        """Pause or resume the pushes to the dashboard (the monitoring itself never pauses)."""
        ...
