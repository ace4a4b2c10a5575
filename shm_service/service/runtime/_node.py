"""A node of a fleet across machines: ``shm serve --config fleet.toml --node NAME``.

Every node reads the same configuration and the same PostgreSQL database (``storage.url``); the
structures are shared through the database's leases (``storage.postgres.Leases``): a holder, an
expiry on the database's clock and a fencing token. Every third of ``nodes.lease_s`` a node

1. renews its own leases and its presence (a lease of its own, ``@node/NAME``, that tells the others
   it is alive even while it holds no structure);
2. stops at once every structure whose lease it no longer holds (taken after a pause of this node);
3. counts the nodes alive (their presence unexpired) and its fair share, ceil(structures / nodes);
4. takes free or expired structures up to its share, or hands back (stops, then releases) what it
   holds beyond it when a node joined.

A structure it takes resumes from its committed state in the database (the pipeline loads it), its
source from the broker's session of that structure. Each window's transaction checks the lease's
token (``WindowCommit.fencing_token``), so a node that lost a lease without noticing yet writes
nothing more of that structure. A node that cannot renew for a whole lease stops its structures:
the others may have them by then.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Mapping
from typing import Any

from contract import StructureSummaryDocument, StructureUnavailable, StructuresDocument

from .._config import ServiceSettings, SettingsError
from ._service import MonitoringService
from ._structure import ServiceError, Structure, _FailedStructure

__all__ = ["NodeService", "PRESENCE"]

log = logging.getLogger("shm.serve.node")

PRESENCE = "@node/"  # lease ids of the nodes' presence (a structure id is [a-z0-9-]: never one of these)


class NodeService(MonitoringService):
    """One node of a fleet: runs the structures whose leases it holds (see the module)."""

    def __init__(self, settings: ServiceSettings, node: str, *, environ: Mapping[str, str] | None = None) -> None:
        if not node or len(node) > 64 or not all(c.isalnum() or c in "-_." for c in node):
            raise SettingsError(f"--node {node!r} must be 1-64 letters, digits, '-', '_' or '.'")
        if not settings.fleet:
            raise SettingsError("--node needs a fleet: the structures the nodes share ([[structures]] tables)")
        if settings.storage.url is None:
            raise SettingsError("--node needs storage.url (PostgreSQL): the nodes share the structures through leases "
                                "in that database")
        self.node = node
        self.lease_s = settings.nodes.lease_s
        self.order = [st.id for st in settings.structures]
        self.configs = {st.id: st for st in settings.structures}
        self.view: dict[str, Any] = {}  # structure id -> its Lease as last read (the fleet's view)
        self.node_error: str | None = None
        self._renewed = time.monotonic()
        self._node_stop = threading.Event()
        self._node_thread: threading.Thread | None = None
        self._changing = threading.Lock()
        from ..storage.postgres import Leases

        try:
            self.leases = Leases(settings.storage.url, lease_s=self.lease_s)
            self.leases.register(self.order)
        except Exception as exc:
            raise ServiceError(f"leases in {settings.storage.url.split('@')[-1]}: {type(exc).__name__}: {exc}") from None
        super().__init__(settings, environ=environ)

    def _build_structures(self, settings: ServiceSettings) -> dict[str, Structure | _FailedStructure]:
        return {}  # the leases decide (``_take``)

    # -- running ------------------------------------------------------------------------------

    def start(self) -> None:
        super().start()
        self._node_thread = threading.Thread(target=self._node_loop, name=f"node-{self.node}", daemon=True)
        self._node_thread.start()

    def _watch_done(self) -> None:
        self._stopping.wait()  # a node serves until it is stopped (its structures come and go)
        for structure in list(self.structures.values()):
            structure.wait()
        self._done.set()

    def stop(self, *, drain_s: float = 2.0) -> None:
        self._node_stop.set()
        if self._node_thread is not None:
            self._node_thread.join(30.0)
        with self._changing:
            super().stop(drain_s=drain_s)
        try:
            released = self.leases.release_all(self.node)  # the others take them at once, not after lease_s
            log.info("node %s: released %d lease(s)", self.node, released)
        except Exception as exc:  # the database gone: they expire by themselves
            log.warning("node %s: releasing its leases failed (they expire within %g s): %s", self.node, self.lease_s, exc)
        self.leases.close()

    def _node_loop(self) -> None:
        first = True
        while not self._node_stop.is_set():
            try:
                with self._changing:
                    if self._stopping.is_set():
                        return
                    self.step(share=not first)
                self.node_error = None
                first = False
            except Exception as exc:  # the database unreachable: said in /healthz, tried again
                self.node_error = f"leases: {type(exc).__name__}: {exc}"
                log.error("node %s: %s", self.node, self.node_error)
                if time.monotonic() - self._renewed >= self.lease_s and self.running_structures():
                    log.error("node %s: no renewal for %g s: its structures stop (other nodes may hold them now)",
                              self.node, self.lease_s)
                    with self._changing:
                        for sid in list(self.structures):
                            self._drop(sid, lost=True)
            self._node_stop.wait(self.lease_s / 3)

    def step(self, *, share: bool = True) -> None:
        """One round of the node's leases (see the module); ``share`` False: only renew and look
        (the first round, so that nodes starting together see each other before they take)."""
        leases, me = self.leases, self.node
        leases.acquire(PRESENCE + me, me)  # its presence: a renewal once it has it
        held = {lease.structure_id: lease for lease in leases.renew_all(me) if lease.structure_id in self.configs}
        self._renewed = time.monotonic()
        for sid in list(self.structures):
            if sid not in held:
                log.warning("node %s: the lease of %s is no longer its own: stopping it", me, sid)
                self._drop(sid, lost=True)
        for sid in self.order:
            if sid in held and sid not in self.structures:
                self._take(sid, held[sid])  # held from before (this node restarted within its lease)
        rows = leases.all()
        alive = {r.holder for r in rows if r.structure_id.startswith(PRESENCE) and not r.expired and r.holder} | {me}
        self.view = {r.structure_id: r for r in rows if r.structure_id in self.configs}
        if not share:
            return
        fair = math.ceil(len(self.order) / len(alive))
        if len(held) > fair:
            for sid in [s for s in reversed(self.order) if s in held][: len(held) - fair]:
                log.info("node %s: hands %s back (%d nodes alive: its share is %d)", me, sid, len(alive), fair)
                self._drop(sid, lost=False)
                leases.release(held.pop(sid))
        free = [sid for sid in self.order if sid not in held and (self.view[sid].holder is None or self.view[sid].expired)]
        for sid in free[: max(0, fair - len(held))]:
            lease = leases.acquire(sid, me)
            if lease is not None:
                held[sid] = lease
                self._take(sid, lease)
        self.view.update({sid: lease for sid, lease in held.items()})

    def _take(self, sid: str, lease: Any) -> None:
        """Start ``sid`` under ``lease``: from its committed state, its windows fenced by the lease's token."""
        structure = self.build_structure(self.configs[sid])
        if isinstance(structure, Structure):
            try:
                structure.attach(self.storage, self.dashboard_guard)
                structure.pipeline.commits.fencing_token = lease.token
                structure.start()
            except Exception as exc:  # noqa: BLE001 - shown on the structure, the node goes on
                log.exception("node %s: structure %s cannot start", self.node, sid)
                structure = _FailedStructure(sid, structure.kind, f"{type(exc).__name__}: {exc}")
        log.info("node %s: took %s (token %d)%s", self.node, sid, lease.token,
                 "" if isinstance(structure, Structure) else f": it failed: {structure.error}")
        self.structures = {s: (structure if s == sid else self.structures[s]) for s in self.order
                           if s == sid or s in self.structures}

    def _drop(self, sid: str, *, lost: bool) -> None:
        """Stop ``sid`` (``lost``: at once, its backlog set aside: another node holds it)."""
        structure = self.structures.get(sid)
        if structure is None:
            return
        structure.stop_source()
        if lost and isinstance(structure, Structure) and structure.attached:
            structure.pipeline.stop_deadline = time.monotonic()
        if structure.started:
            structure.wait(30.0)
        self.structures = {s: v for s, v in self.structures.items() if s != sid}

    # -- what it answers ----------------------------------------------------------------------

    def structure(self, structure_id: str) -> Structure:
        if structure_id in self.configs and structure_id not in self.structures:
            lease = self.view.get(structure_id)
            where = f"node {lease.holder!r}" if lease is not None and lease.holder and not lease.expired else "no node now"
            raise StructureUnavailable(f"structure {structure_id!r} runs on {where}, not on {self.node!r}: its live "
                                       "routes are there; its stored trends, alarms and fatigue are answered here too")
        return super().structure(structure_id)

    def _known(self, structure_id: str) -> None:
        if structure_id not in self.configs:
            super()._known(structure_id)

    def structures_document(self) -> StructuresDocument:
        """Every structure of the fleet in its configured order: those of this node with their
        state, the others with the node that holds them."""
        here = dict(self.structures)
        rows = []
        for sid in self.order:
            if sid in here:
                rows.append(here[sid].summary().model_copy(update={"node": self.node}))
                continue
            lease = self.view.get(sid)
            kind = self.configs[sid].source.partition(":")[0]
            if lease is not None and lease.holder and not lease.expired:
                rows.append(StructureSummaryDocument(id=sid, kind=kind, state="running", node=lease.holder))
            else:
                rows.append(StructureSummaryDocument(id=sid, kind=kind, state="starting", node=None,
                                                     error="no node holds it: one takes it within nodes.lease_s"))
        return StructuresDocument(structures=rows)

    def fleet_metrics(self) -> str:
        """``/metrics`` of this node: its own structures (each node is scraped for its own)."""
        from ..http._metrics import fleet_metrics

        own = [s for s in self.structures_document().structures if s.node == self.node]
        return fleet_metrics(StructuresDocument(structures=own), self.statuses())

    def health(self) -> Any:
        doc = super().health()
        if self.node_error is None:
            return doc
        return doc.model_copy(update={"status": "degraded", "reasons": [f"node {self.node}: {self.node_error}", *doc.reasons]})
