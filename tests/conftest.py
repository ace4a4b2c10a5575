"""The test tiers. ``make check`` runs the unit tier (``-m "not slow and not e2e and not browser"``:
lint, types and these in under two minutes on two cores); ``make test`` runs every tier.

- ``browser``: a real Chromium (the ``chromium`` fixture, or a module of browser tests);
- ``e2e``: a real service end to end — ``shm serve``/``shm demo`` as processes, a service run over
  a recording to its end, a dask cluster;
- ``slow``: longer physics checks (whole simulated recordings through the estimator or the study).

A module is put in a tier here by its path (one place to look), a test by its own marker.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

_HERE = Path(__file__).resolve().parent

# One BLAS/OpenMP thread per process, set before anything imports numpy (the xdist workers and the
# services and demos the tests start inherit it). The suite runs a worker per core beside service
# processes and Chromium: OpenBLAS's own threads on top of that oversubscribe the cores and spin,
# and a small identification then takes ~8x its single-threaded time (measured with
# analytics.identify_modes on 6000 samples, 2 cores under load: 11.1 s vs 1.4 s for 9 calls).
# The results do not depend on it: the tests assert the physics, never a kernel's last bits.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

#: modules of end-to-end tests (relative to tests/)
E2E = {
    "shm_service/test_demo.py",
    "shm_service/test_one_estimator.py",
    "shm_service/service/test_processes.py",
    "shm_service/service/test_serve_end_to_end.py",
    "shm_service/service/test_follow_faults.py",
    "shm_service/service/test_fleet.py",
    "shm_service/service/test_fleet_live_metrics.py",
    "shm_service/service/test_one_engine.py",
    "shm_service/service/test_reprocess.py",
    "shm_service/service/test_faults.py",
    "shm_service/service/test_storage_faults.py",
    "shm_service/service/test_open_doors.py",
    "shm_service/service/test_source_lag.py",
    "shm_service/service/test_sinks.py",
    "shm_service/service/test_api.py",
    "shm_service/service/test_api_docs.py",
    "shm_service/service/test_notify.py",
    "shm_service/service/test_retention.py",
    "shm_service/service/test_group_commit.py",
    "shm_service/service/test_inputs.py",
    "shm_service/service/test_export_streaming.py",
    "shm_service/service/test_loads_service.py",
    "shm_service/service/test_stop_under_backlog.py",
    "shm_service/service/test_db_lock.py",
    "shm_service/service/test_dropbear_rig.py",
    "docs/test_documentation.py",
}

#: modules of slow physics checks (those of more than ~5 s a test, measured with --durations)
SLOW = {
    "estimator/test_imms.py",
    "estimator/test_clamped.py",
    "estimator/test_fixed_support.py",
    "estimator/test_fixed_bearing_spectra.py",
    "estimator/test_combimode_error.py",
    "estimator/test_combimode_shape.py",
    "estimator/test_input_weights.py",
    "estimator/test_calibration.py",
    "analytics/test_dropbear.py",
    "analytics/test_curvature_chart_monitor.py",
    "analytics/test_location_and_chain.py",
    "analytics/test_frf.py",
    "analytics/test_engine.py",
    "analytics/test_ssi.py",
    "analytics/test_loads_monitor.py",
    "analytics/test_modes_physical.py",
    "analytics/test_mode_shape_curvature.py",
    "estimator/test_filterpy_reference.py",
    "estimator/test_damage_signatures.py",
    "shm_service/test_study.py",
    "shm_service/test_other_tool.py",
    "shm_service/test_daq_import.py",
    "shm_service/test_loads_cli.py",
    "shm_service/test_modes_any_beam.py",
    "shm_service/test_simulate_rig.py",
    "shm_service/test_virtual_rig.py",
    "shm_service/test_virtual_rig_sections.py",
    "shm_service/test_cli.py",
    "shm_service/test_oma_cli.py",
}


#: the longest indivisible units (a module fixture shared by the module's tests, measured with
#: --durations on a fresh clone): started first so no worker is left with one of them at the end
LONGEST_FIRST = ("shm_service/test_study.py",)


def _uses_module_fixture(item: pytest.Item) -> bool:
    info = getattr(item, "_fixtureinfo", None)
    return info is not None and any(defs and defs[-1].scope == "module" for defs in info.name2fixturedefs.values())


@pytest.hookimpl(tryfirst=True)  # before xdist's loadgroup reads the xdist_group marks
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    rank: dict[str, int] = {}
    for item in items:
        try:
            rel = Path(str(item.path)).resolve().relative_to(_HERE).as_posix()
        except ValueError:
            continue
        if "chromium" in getattr(item, "fixturenames", ()) or "browser" in Path(rel).name or rel == "web/test_dashboard_gate.py":
            item.add_marker(pytest.mark.browser)
        if rel in E2E:
            item.add_marker(pytest.mark.e2e)
        if rel in SLOW:
            item.add_marker(pytest.mark.slow)
        # make test distributes single tests (--dist loadgroup); the tests that share a module
        # fixture (a study, a served service, a recording) stay on one worker so it runs once
        if _uses_module_fixture(item):
            item.add_marker(pytest.mark.xdist_group(rel))
        tier = (0 if rel in LONGEST_FIRST else 1 if item.get_closest_marker("browser") else 2 if item.get_closest_marker("e2e")
                else 3 if item.get_closest_marker("slow") else 4)
        rank[rel] = min(rank.get(rel, tier), tier)
    # the long tiers first and the many short unit tests last, where they fill the workers' ends
    # evenly (modules stay whole and in their own order; xdist keeps this order with
    # --no-loadscope-reorder)
    def key(item: pytest.Item) -> int:
        try:
            return rank.get(Path(str(item.path)).resolve().relative_to(_HERE).as_posix(), 4)
        except ValueError:
            return 4

    items.sort(key=key)


class _GroupSuffix:
    """xdist's --dist loadgroup reads a test's group from a ``@group`` suffix of its node id, which
    xdist 3.8 writes to ``item._nodeid``; pytest 9.2's nodes keep their id in ``item._id``, so the
    suffix got lost and grouped tests were spread over the workers (their module fixture built on
    each). Write it where pytest reads it, after xdist's own hook; a no-op once xdist's suffix
    shows in the node id."""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, config: pytest.Config, items: list[pytest.Item]) -> None:
        if not getattr(config.option, "loadgroup", False):
            return
        for item in items:
            mark = item.get_closest_marker("xdist_group")
            node_id = getattr(item, "_id", None)
            if mark is None or node_id is None or "@" in item.nodeid.rsplit("]", 1)[-1]:
                continue
            item._id = type(node_id).parse(f"{item.nodeid}@{mark.args[0]}")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "browser: needs a real Chromium (make test only)")
    config.addinivalue_line("markers", "e2e: a real service end to end, processes or a whole run (make test only)")
    config.pluginmanager.register(_GroupSuffix(), "shm-xdist-group-suffix")


# -- real PostgreSQL and Mosquitto servers (a fleet across machines) ---------------------------------
# Started once per test process (an xdist worker each), on free loopback ports, from Debian's
# packages (make test installs them when missing: .ci/install-servers); they die with the process.


@pytest.fixture(scope="session")
def postgres_server():
    """A throwaway PostgreSQL (``shm_service.devservers.DevServer``) for the whole session."""
    from shm_service.devservers import start_postgres

    server = start_postgres()
    yield server
    server.stop()


@pytest.fixture(scope="session")
def postgres_url(postgres_server) -> str:
    """The URL of the session's PostgreSQL database ``shm`` (``postgresql://postgres@127.0.0.1:PORT/shm``)."""
    return postgres_server.url


@pytest.fixture
def fresh_postgres_url(postgres_server) -> str:
    """The URL of a database of its own for one test, in the session's PostgreSQL (dropped after it)."""
    import uuid

    import psycopg

    name = f"t_{uuid.uuid4().hex[:12]}"
    admin = postgres_server.url.rsplit("/", 1)[0] + "/postgres"
    with psycopg.connect(admin, autocommit=True) as db:
        db.execute(f'CREATE DATABASE "{name}"')
    yield postgres_server.url.rsplit("/", 1)[0] + "/" + name
    with psycopg.connect(admin, autocommit=True) as db:
        db.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture(scope="session")
def mqtt_server():
    """A throwaway Mosquitto (``shm_service.devservers.DevServer``) for the whole session."""
    from shm_service.devservers import start_mosquitto

    server = start_mosquitto()
    yield server
    server.stop()
