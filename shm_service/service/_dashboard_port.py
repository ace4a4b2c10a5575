"""The port between the monitoring service and the dashboard (package ``web``).

The dashboard is built against this file only. The service implements
:class:`DashboardService` and hands it to ``web.Dashboard``; the dashboard calls it from its own
thread (viser runs its own thread and asyncio loop), so every method here is thread-safe and
returns plain JSON-like data (dicts, lists, str, float, int, bool, None).

Agreed dashboard interface (implemented in ``web``; the service only calls it)::

    Dashboard(*, host: str, port: int, rig, units, stations, service: DashboardService)
    .url -> str
    .push_estimate(t_s: float, x: np.ndarray, sensor_states: dict[str, str],
                   truth_deflection: np.ndarray | None)      # >= 10 Hz, decimated by the service
    .push_spectra(frequencies_hz: np.ndarray, amplitudes: np.ndarray,     # (n_freq, Γ)
                  tracked_hz: list[list[float]], baseline_hz: list[list[float]] | None)
    .push_window(window: dict)   # one trend window, same keys as a row of GET /api/trends
    .push_alarm(alarm: dict)     # same keys as an item of GET /api/alarms
    .stop()

``sensor_states`` maps a topic (``/imu/s1``) to ``"ok"``, ``"degraded"`` or ``"rejected"``.
``x`` is the estimator state vector in the order of ``model.state_names``.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

__all__ = ["DashboardService", "SENSOR_STATES"]

SENSOR_STATES = ("ok", "degraded", "rejected")


@runtime_checkable
class DashboardService(Protocol):
    """What the running service offers the dashboard. All methods are thread-safe."""

    def status(self) -> dict[str, Any]:
        """The same document as ``GET /api/status``.

        Keys: ``service`` (version, started_at, uptime_s, paused), ``sources`` (list of
        {id, kind, state, messages, rate_hz, latency_s, data_time_s, dropped, rejected}),
        ``pipeline`` (queue depths, estimator/analytics rates), ``degraded_sensors`` (list of
        topics), ``sensors`` (topic -> "ok"|"degraded"|"rejected"), ``baseline`` (state, modes),
        ``alarms`` (active counts by level), ``storage`` (db path, rows, recordings dir).
        """
        ...

    def trends(self, from_s: float | None, to_s: float | None) -> list[dict[str, Any]]:
        """Trend rows with ``from_s <= window_start_s < to_s`` (UNIX seconds; None = open).

        Each row: ``source``, ``window_start_s``, ``window_end_s``, ``mode`` (1-based unit
        deformation), ``frequency_hz``, ``damping_ratio``, ``amplitude``, ``confidence``,
        ``temperature_c``, ``curvature_index``, ``flags`` (list of str). Values may be None.
        """
        ...

    def alarms(self) -> list[dict[str, Any]]:
        """All alarms, newest first: ``id``, ``source``, ``kind``, ``mode``, ``level``
        ("warning"|"alarm"), ``state`` ("active"|"cleared"), ``raised_at_s``, ``cleared_at_s``,
        ``acknowledged_at_s``, ``acknowledged_by``, ``message``, ``value``, ``threshold``."""
        ...

    def acknowledge(self, alarm_id: int, token: str) -> dict[str, Any]:
        """Acknowledge an alarm; same rules as ``POST /api/alarms/{id}/ack``.

        Raises ``PermissionError`` on a missing or wrong token (or when no token is configured),
        ``KeyError`` when the alarm does not exist. Returns the updated alarm.
        """
        ...

    def set_paused(self, paused: bool) -> None:
        """Pause or resume the pushes to the dashboard (the monitoring itself never pauses)."""
        ...
