"""Where a structure's samples come from: the virtual rig, a replayed or followed recording, HTTP
ingest (``_ingest``: the validation of ``POST /api/ingest`` bodies against the recording contract),
an MQTT broker (``_mqtt``), sensor faults injected into a live source (``_faults``), and the
sources' settings (``_settings``: ``[sim]``, ``[mqtt]``, and ``[source]`` made of the merge's and
the checks' settings). A new source subclasses a
source of ``_sources``. May import ``contract``, ``shm_service.recording``,
``shm_service.virtual_rig`` and the stages (a source delivers the pipeline's batches, and its
section is made of the settings of the stages that judge them); never the runtime.
"""
