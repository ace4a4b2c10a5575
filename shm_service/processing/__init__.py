"""A recording through the estimator and the one analysis engine: what the commands, the service's
stages and the study share. ``estimation`` turns a recording's measurements into b(t), its
estimates and their scores against a truth; ``analysis`` runs a whole record's b(t) through
``analytics``' engine as ``shm analyze`` does. May import ``contract``, ``estimator``,
``analytics`` and ``shm_service.recording``; nothing of the commands or the service.
"""
