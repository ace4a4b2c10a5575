"""The routers of the HTTP API, one module per resource: health and status, trends, alarms,
structures (live), fatigue and ingest. ``ROUTERS`` lists them in the order the app mounts them; a
new resource is a module here and an entry there. A router may import ``contract`` and the
conventions of its parent package (``_common``, ``_deps``, ``_pages``).
"""

from __future__ import annotations

from . import _alarms, _fatigue, _health, _ingest, _structures, _trends

#: every router of the API, in the order the app mounts them
ROUTERS = (_health.router, _trends.router, _alarms.router, _structures.router, _fatigue.router, _ingest.router)

__all__ = ["ROUTERS"]
