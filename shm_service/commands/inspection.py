"""``shm inspect``: the topics, counts, rates, gaps and problems of a recording, or its rig description."""

from __future__ import annotations

import argparse
from ._common import _print_json

__all__ = ['cmd_inspect']


def cmd_inspect(args: argparse.Namespace) -> int:
    from ..recording import format_inspection, inspect_recording

    if args.print_rig:  # the recording's rig description (rig.json), to edit or to reuse with shm import --rig
        from ..recording import read_recording

        print(read_recording(args.recording, rig=args.rig).rig.to_json())
        return 0
    report = inspect_recording(args.recording, rig=args.rig)
    if args.json:
        _print_json(report)
    else:
        print(format_inspection(report))
    return 0
