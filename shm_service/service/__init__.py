"""``shm serve``: the continuous monitoring service (sources, pipeline, storage, alarms, API)."""

from ._dashboard_port import SENSOR_STATES, DashboardService

__all__ = ["DashboardService", "SENSOR_STATES"]
