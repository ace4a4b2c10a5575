"""What runs a fleet: the monitoring service (``_service``) and its structures (``_structure``), their
status and progress documents, the scheduler that steps the pipelines on a small pool of threads,
the worker processes of a fleet, how a started process reports ready and ends with its parent
(``_processes``, ``_launch``), what the API serves while a source is still starting (``_starting``)
and the dashboard's side of the port. The runtime composes ``sources``, ``stages``, ``storage``,
``alarms`` and ``http``; none of those imports the runtime.
"""
