"""Where a structure's samples come from: the virtual rig, a replayed or followed recording, HTTP
ingest (``_ingest``: the validation of ``POST /api/ingest`` bodies against the recording contract),
and sensor faults injected into a live source (``_faults``). A new source subclasses a source of
``_sources``. May import ``contract``, ``shm_service.recording`` and ``shm_service.virtual_rig``;
never the stages or the runtime.
"""
