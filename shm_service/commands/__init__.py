"""The commands' work below the command line: ``shm demo``, ``shm import``, ``shm loads`` and
``shm reprocess`` over a recording or an archive, with what they share (``_common``: the user
error, JSON output, the estimator and analysis settings from the arguments). ``shm_service.cli``
parses the arguments and calls these. They may import ``contract``, ``estimator``, ``analytics``
and every package of ``shm_service`` except ``cli``; nothing below imports them.
"""
