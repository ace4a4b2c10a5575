"""The commands' work below the command line, one module per command: ``modes``, ``simulate``,
``estimate``, ``study``, ``analyze``, ``oma``, ``inspection`` (``shm inspect``), ``daq``
(``shm import``), ``loads``, ``demo`` and ``reprocess`` (``shm reprocess`` and ``shm baseline
learn``), with what they share (``_common``: the user error, JSON output, the rig, estimator and
analysis settings from the arguments). ``shm_service.cli`` parses the arguments and calls these;
``shm serve`` lives with the service (``shm_service.service``). They may import ``contract``,
``estimator``, ``analytics`` and every package of ``shm_service`` except ``cli``; nothing below
imports them.
"""
