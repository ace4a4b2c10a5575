"""What the commands share, below the command line: the user error, JSON output, the rig of
--rig/--layout, a settings error in one line, the estimator model and sensor counts of
--modes/--imus/--tofs/--gauges, and b(t) of a recording as ``shm analyze`` takes it. The command
modules call these; none of them imports ``cli`` (no cycle).

The functions take the parsed options as an object with the options' attributes (an
``argparse.Namespace`` or ``reprocess.AnalysisOptions.namespace()``).
"""

from __future__ import annotations

import argparse
import json
from typing import TypedDict

__all__ = ["DEFAULT_SENSOR_COUNT", "CliError", "add_model_arguments"]


class CliError(Exception):
    """A user error: printed as one line, exit code 2."""


def _print_json(data: object) -> None:
    print(json.dumps(data, indent=2, allow_nan=False))


DEFAULT_SENSOR_COUNT = 4


def _count_or_names(text: str | None, default: int) -> int | tuple[str, ...]:
    """'4' → 4; 's1,s3' → ('s1', 's3')."""
    if text is None:
        return default
    text = text.strip()
    if text.lstrip("+-").isdigit():
        return int(text)
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise CliError(f"sensor list {text!r} is empty")
    return names


def add_model_arguments(p: argparse.ArgumentParser, *, aided: bool = True) -> None:
    """The estimator model's options, one definition for ``shm estimate``, ``analyze``, ``reprocess``,
    ``baseline learn`` and ``loads``: --rig, --peripheral, --modes, --modes-xi, --imus, --tofs, --gauges
    and (``aided``: where the command builds the model with it) --aided."""
    from .._argtypes import number

    p.add_argument("--rig", help="rig description to use instead of the attached rig.json")
    p.add_argument("--peripheral", choices=("gyro", "acc"), default="gyro")
    p.add_argument("--modes", type=number(int, low=1, high=5), default=4, metavar="Γ", help="unit deformations (1-5)")
    p.add_argument("--modes-xi", type=number(int, low=1, high=5), default=None, metavar="Γξ",
                   help="unit deformations in ξ of a biaxial beam (beam.bending = 'biaxial'; 1-5, default: as --modes)")
    p.add_argument("--imus", default=None,
                   help="peripheral IMUs: a count Γ..(the rig's) chosen by EfI, or names s1,s2,... (default 4, or all if fewer)")
    p.add_argument("--tofs", default=None, help="ToFs: a count 0..(the rig's) or names (default 4, or all if fewer)")
    p.add_argument("--gauges", default=None, help="strain gauges: a count 0..(the rig's) or names (default 4, or all if fewer; "
                                                  "a biaxial beam's default 8, four per plane)")
    if aided:
        p.add_argument("--aided", default=None, help="unit deformations aided by the gauges, e.g. 2,3,4 (Eq. 22)")


def _model_from_args(rig, args: argparse.Namespace):
    from estimator import build_model

    aided = None
    if args.aided:
        try:
            aided = tuple(int(a) for a in args.aided.split(","))
        except ValueError:
            raise CliError(f"--aided {args.aided!r} must list unit deformations, e.g. 2,3,4") from None
        bad = [a for a in aided if not 1 <= a <= args.modes]
        if bad:
            raise CliError(f"--aided {args.aided}: unit deformations {bad} are outside 1..{args.modes} (Γ = --modes)")
    try:
        return build_model(rig, aided=aided, **model_kwargs(rig, args))
    except ValueError as exc:
        raise CliError(str(exc)) from None


def model_kwargs(rig, args: argparse.Namespace) -> dict:
    """``estimator.build_model``'s keywords of the options: --peripheral, --modes, the sensor counts
    and, given, --modes-xi (a planar beam refuses it there)."""
    kwargs = dict(peripheral=args.peripheral, modes=args.modes, **_sensor_counts(rig, args))
    if getattr(args, "modes_xi", None) is not None:
        kwargs["modes_xi"] = args.modes_xi
    return kwargs


def _recording_problems(rec) -> dict:
    """``recording_problems`` (a cut, damage, gaps, rejected messages) and ``truncated`` of a recording, as
    ``shm inspect`` says them."""
    return {"truncated": rec.report.truncated, "recording_problems": list(rec.report.problems)}


def _cut_note(rec) -> str:
    """`` (the recording is cut off: ...)`` for a refused analysis of a cut recording, else ``""``."""
    if not rec.report.truncated:
        return ""
    cut = next((p for p in rec.report.problems if "cut off" in p or "damaged" in p), "damaged")
    return f" (the recording is cut off: {cut})"



class SensorCounts(TypedDict):
    """--imus/--tofs/--gauges as ``estimator.build_model`` takes them: a count or the sensors' names."""

    imus: int | tuple[str, ...]
    tofs: int | tuple[str, ...]
    gauges: int | tuple[str, ...]


def _sensor_counts(rig, args: argparse.Namespace) -> SensorCounts:
    """--imus/--tofs/--gauges as the estimator takes them. A count the user gave must exist on the
    rig; the default (4 each) is capped to what the rig has, as the help says."""
    from ..processing.estimation import sensor_count_problem

    counts = {kind: _count_or_names(getattr(args, kind), DEFAULT_SENSOR_COUNT) for kind in ("imus", "tofs", "gauges")}
    if args.gauges is None and getattr(rig.beam, "biaxial", False):
        counts["gauges"] = 2 * DEFAULT_SENSOR_COUNT  # a biaxial beam's gauges hold two planes: four per plane
    for kind, wanted in counts.items():
        if getattr(args, kind) is not None and isinstance(wanted, int):
            problem = sensor_count_problem(rig, kind, wanted, modes=args.modes)
            if problem:
                raise CliError(f"--{kind} {wanted}: {problem} (or give names)")
    return SensorCounts(imus=counts["imus"], tofs=counts["tofs"], gauges=counts["gauges"])


def _analysis_settings(args: argparse.Namespace):
    """(AnalysisConfig, warm-up s) of --config (a `shm serve` TOML: its analytics, alarm hysteresis
    and estimator warm-up), else the defaults, which are serve's."""
    from ..processing.analysis import DEFAULT_WARMUP_S

    if not args.config:
        return None, DEFAULT_WARMUP_S
    from ..service._config import SettingsError, load_settings

    try:
        settings = load_settings(args.config)
    except SettingsError as exc:
        raise CliError(f"--config {args.config}: {exc}") from None
    return settings.engine_config(), settings.estimator.warmup_s


def _deformations_of(path: str, args: argparse.Namespace):
    from ..processing.estimation import deformation_record
    from ..recording import read_recording

    rec = read_recording(path, rig=args.rig)
    model_args = model_kwargs(rec.rig, args)
    streaming = None
    if getattr(args, "config", None):  # a raw file is estimated as the service with this configuration would
        from ..service._config import load_settings

        streaming = load_settings(args.config).streaming_settings()
    try:
        return rec, deformation_record(rec, model_args=model_args, settings=streaming)
    except ValueError as exc:
        raise CliError(f"{exc}{_cut_note(rec)}") from None


def _rig_from_args(args: argparse.Namespace):
    """The rig of --rig (with --support/--orientation overriding its keys) or of --layout
    (with --length, --support, --orientation)."""
    from estimator import RigError, load_rig, parse_rig

    from ..rig_layouts import build_rig

    if getattr(args, "rig", None):
        if args.length is not None:
            raise CliError("--length scales a --layout rig; with --rig set beam.length in the file")
        rig = load_rig(args.rig)
        overrides = {k: v for k, v in (("support", args.support), ("orientation", args.orientation)) if v is not None}
        return parse_rig({**rig.model_dump(mode="json"), **overrides}, source=args.rig) if overrides else rig
    try:
        return build_rig(args.layout, length=args.length, support=args.support or "pinned",
                         orientation=args.orientation or "hanging")
    except ValueError as exc:
        if isinstance(exc, RigError):
            raise
        raise CliError(str(exc)) from None


def _pydantic_message(exc) -> str:
    return "; ".join(f"{'.'.join(str(p) for p in e['loc']) or 'settings'}: {e['msg']}" for e in exc.errors())
