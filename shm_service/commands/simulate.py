"""``shm simulate``: the virtual rig into a recording, from the options and a rig file's ``simulator`` settings."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import CliError, _print_json, _pydantic_message, _rig_from_args

__all__ = ['cmd_simulate']


def _simulation_settings(args: argparse.Namespace):
    from pydantic import ValidationError

    from ..virtual_rig import SimulationSettings

    try:
        return SimulationSettings(
            duration=args.duration,
            seed=args.seed,
            plant_seed=args.plant_seed,
            excitation=args.excitation,
            layout=args.layout,
            support=args.support or "pinned",
            orientation=args.orientation or "hanging",
            length=4.0 if args.length is None else args.length,
            ideal=args.ideal,
            damage=tuple(args.damage or ()),
            damage_at=args.damage_at,
            temperature_swing=args.temperature_swing,
            temperature_mean=args.temperature_mean,
            plant={"friction_torque": args.friction},
            wind_load_rms=args.wind_load,
            wind_correlation=args.wind_correlation,
        )
    except (ValidationError, ValueError) as exc:
        raise CliError(str(exc).splitlines()[0] if not isinstance(exc, ValidationError) else _pydantic_message(exc)) from None


# (settings field, option, the option's default) of ``shm simulate``: what a rig file's simulator settings yield to.
_SIMULATE_OPTIONS = (
    ("duration", "duration", 300.0), ("seed", "seed", 1), ("plant_seed", "plant_seed", None),
    ("excitation", "excitation", "paper"), ("ideal", "ideal", False),
    ("damage", "damage", None), ("damage_at", "damage_at", None), ("temperature_swing", "temperature_swing", 0.0),
    ("temperature_mean", "temperature_mean", 20.0), ("plant", "friction", 0.0), ("wind_load_rms", "wind_load", None),
    ("wind_correlation", "wind_correlation", None),
)


def cmd_simulate(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from ..virtual_rig import settings_for_rig, simulate

    settings = _simulation_settings(args)
    rig = None
    if args.rig:
        rig = _rig_from_args(args)
        # The rig file's ``simulator`` settings, then what the command line sets (options left at
        # their defaults do not override the file).
        given = {field for field, option, default in _SIMULATE_OPTIONS if getattr(args, option) != default}
        try:
            settings = settings_for_rig(rig, settings, given)
        except (ValidationError, ValueError) as exc:
            raise CliError(f"{args.rig}: simulator: " + (_pydantic_message(exc) if isinstance(exc, ValidationError) else str(exc))) from None
    summary = simulate(settings, Path(args.out), rig=rig)
    if args.json:
        _print_json(summary.as_dict())
    else:
        data = summary.as_dict()
        print(f"wrote {data['path']}: {data['duration_s']:.1f} s, {data['total_messages']} messages "
              f"in {data['wall_time_s']:.1f} s")
        print("plant eigenfrequencies [Hz]: " + ", ".join(f"{f:.4f}" for f in data["eigenfrequencies_hz"][:6]))
        if data["eigenfrequencies_after_damage_hz"]:
            print("after damage [Hz]:           " + ", ".join(f"{f:.4f}" for f in data["eigenfrequencies_after_damage_hz"][:6]))
    return 0
