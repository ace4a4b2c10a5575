"""``shm study``: the paper's sensor-configuration study, and its design mode with ``--target-*``."""

from __future__ import annotations

import argparse
from ._common import CliError, _pydantic_message

__all__ = ['cmd_study']


def _int_list(text: str, option: str) -> tuple[int, ...]:
    """'1,2,3' or '4-13' (or a mix) → integers."""
    values: list[int] = []
    try:
        for part in text.split(","):
            part = part.strip()
            if "-" in part[1:]:
                lo, hi = part.split("-", 1)
                values.extend(range(int(lo), int(hi) + 1))
            elif part:
                values.append(int(part))
    except ValueError:
        raise CliError(f"{option} {text!r} must list integers, e.g. 1,2,3 or 4-13") from None
    return tuple(values)


def cmd_study(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from ..study import DesignTargets, StudyError, StudySettings, run_command

    fields = {
        "seeds": _int_list(args.seeds, "--seeds") if args.seeds else None,
        "duration": args.duration, "rest": args.rest, "ideal": args.ideal or None, "workers": args.workers,
        "tofs": _int_list(args.tofs, "--tofs") if args.tofs else None,
        "modes": args.modes,
        # a rig file: its wind load (the ambient excitation scaled to the structure), no bearing friction
        **({"rig": args.rig, "excitation": "ambient", "friction_torque": 0.0} if args.rig else {}),
    }
    fields = {k: v for k, v in fields.items() if v is not None}
    targets = None
    try:
        settings = StudySettings.quick(**fields) if args.quick else StudySettings(**fields)
        if args.target_phi_deg is not None or args.target_e_m is not None:
            targets = DesignTargets(phi_deg=args.target_phi_deg, e_m=args.target_e_m)
    except ValidationError as exc:
        raise CliError(_pydantic_message(exc)) from None
    try:
        return run_command(settings, args.out, targets=targets, keep_recordings=args.keep_recordings)
    except StudyError as exc:
        raise CliError(str(exc)) from None
