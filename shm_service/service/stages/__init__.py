"""A structure's pipeline, one small stage per module in data order: merge the sensors' streams on one
clock (``_merge``), plausibility and stuck-sensor checks (``_checks``), the streaming estimator
(``_estimate``), windowing and the analysis engine (``_analysis``), each window's commit (``_commit``)
and the outputs (``_outputs``: the recording and the rotating archive of ``_archive``); ``_pipeline``
wires them. May import ``contract``, ``estimator``,
``analytics``, ``shm_service.recording``, ``storage`` and ``alarms``; never the runtime or ``http``.
"""
