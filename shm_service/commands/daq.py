"""``shm import``: DAQ files and their channel map into a recording of the contract."""

from __future__ import annotations

from ..formats.daq_import import MapError, import_recording
from ..formats.tables import TableError
from ._common import CliError, _print_json

__all__ = ["cmd_import"]


def cmd_import(args) -> int:
    """``shm import`` (the parser is in ``cli.py``, which stays light)."""
    try:
        report = import_recording(args.data, args.rig, args.map, args.out)
    except (MapError, TableError) as exc:
        raise CliError(str(exc)) from None
    if args.json:
        _print_json(report.as_dict())
    else:
        print(report.format())
    return 0
