"""``shm oma``: operational modal analysis (SSI-cov) of measured channels, cleaned first, whole and in windows."""

from __future__ import annotations

import argparse
from typing import Any

from ._common import CliError, _print_json, _pydantic_message

__all__ = ['cmd_oma']


def cmd_oma(args: argparse.Namespace) -> int:
    table, clean, config, result = _oma_identify(args)
    if args.json:
        _print_json(_oma_document(table, clean, config, result))
        return 0
    _print_oma(table, clean, result)
    return 0


def _oma_identify(args: argparse.Namespace) -> tuple[Any, Any, Any, Any]:
    """Read, clean and identify (``shm oma``): the table, its cleaning, the configuration, the result."""
    from pydantic import ValidationError

    from analytics import OmaConfig, OperationalModalAnalysis

    from ..formats.oma_input import clean_for_identification
    from ..formats.tables import TableError, read_table, select_channels

    try:
        table = read_table(args.data, fs=args.fs, nonfinite="keep")
        names = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
        if args.channels is not None and not names:
            raise CliError(f"--channels {args.channels!r} names no channel")
        input_names = None
        if args.inputs:
            input_names = list(select_channels(table, [c.strip() for c in args.inputs.split(",") if c.strip()]).channels)
            if names is None:  # the inputs are not outputs too
                names = [c for c in table.channels if c not in input_names]
        output_names = list(select_channels(table, names).channels)
        clean = clean_for_identification(table, output_names, input_names, outlier_factor=args.outlier_factor,
                                         max_abs=args.max_abs, max_fill=args.max_fill)
        table = select_channels(table, output_names)
        inputs = clean.inputs
        config = OmaConfig(fmin_hz=args.fmin or 0.0, fmax_hz=args.fmax)
        window = args.window
        step = args.step if args.step is not None else window
        if step is not None and window is None:
            raise CliError("--step needs --window")
        if table.fs_hz is None:
            raise CliError(f"{args.data}: no sample rate (give --fs)")
        result = OperationalModalAnalysis(config, window_s=window, step_s=step).run(clean.outputs, table.fs_hz, inputs=inputs)
    except ValidationError as exc:
        raise CliError(_pydantic_message(exc)) from None
    except (TableError, ValueError) as exc:
        raise CliError(str(exc)) from None
    return table, clean, config, result


def _oma_modes(ident) -> list[dict]:
    return [m.as_dict() for m in ident.modes]


def _oma_io(ident) -> dict:
    if ident.excitation is None:
        return {}
    e = ident.excitation
    return {"excitation": {"kind": e.kind, "line_hz": e.line_hz, "line_fraction": e.line_fraction, "nearest_mode_hz": e.nearest_mode_hz},
            "frf_modes": [{"frequency_hz": m.frequency_hz, "damping_ratio": m.damping_ratio, "frequency_std_hz": m.frequency_std_hz,
                           "damping_std": m.damping_std, "coherence": m.coherence, "shape": list(m.shape)} for m in ident.frf_modes]}


def _oma_document(table: Any, clean: Any, config: Any, result: Any) -> dict:
    """``shm oma --json``."""
    rec = result.record
    return {
        "fs_hz": table.fs_hz,
        "channels": list(table.channels),
        "format": table.format,
        "band_hz": [config.fmin_hz, config.fmax_hz if config.fmax_hz is not None else 0.4 * table.fs_hz],
        "analysed_fs_hz": rec.fs_hz,
        "modes": _oma_modes(rec),
        "rejected": [{"frequency_hz": f, "reason": why} for f, why in rec.rejected],
        **_oma_io(rec),
        "windows": [{"start_s": w.start_s, "end_s": w.end_s, "modes": _oma_modes(w.identification),
                     "rejected": [{"frequency_hz": f, "reason": why} for f, why in w.identification.rejected],
                     **_oma_io(w.identification)} for w in result.windows],
        "tracks": [t.as_dict() for t in result.tracks],
        **clean.as_dict(table.fs_hz),
        "recording_problems": list(table.problems),
    }


def _print_oma(table: Any, clean: Any, result: Any) -> None:
    rec = result.record
    print(f"{table.path}: {table.data.shape[0]} samples of {len(table.channels)} channel(s) at {table.fs_hz:g} Hz "
          f"({table.format}); SSI-cov at {rec.fs_hz:g} Hz, {rec.block_rows} block rows, orders {rec.orders[0]}-{rec.orders[-1]}")
    print(f"{'f [Hz]':>10} {'± [Hz]':>8} {'zeta [%]':>9} {'± [%]':>7} {'MPC':>5} {'share':>6}  shape")
    for m in rec.modes:
        sf = f"{m.frequency_std_hz:8.4f}" if m.frequency_std_hz is not None else f"{'-':>8}"
        sz = f"{100 * m.damping_std:7.3f}" if m.damping_std is not None else f"{'-':>7}"
        print(f"{m.frequency_hz:10.4f} {sf} {100 * m.damping_ratio:9.3f} {sz} "
              f"{m.mpc:5.2f} {m.contribution:6.2f}  " + " ".join(f"{v:+.2f}" for v in m.shape))
        for note in dict.fromkeys(n for n in (m.frequency_std_note, m.damping_std_note) if n):
            print(f"  ± of {m.frequency_hz:.4f} Hz: {note}")
    for f, why in rec.rejected:
        print(f"  not a mode: {f:.4f} Hz ({why})")
    for line in [*clean.format(table.fs_hz), *(f"problem: {p}" for p in table.problems)]:
        print(line)
    if result.windows:
        print(f"{len(result.windows)} windows:")
        for w in result.windows:
            print(f"  {w.start_s:8.2f}-{w.end_s:8.2f} s: " + (", ".join(
                f"#{m.track} {m.frequency_hz:.3f} Hz ({100 * m.damping_ratio:.2f} %)"
                + (f" moving {m.start_hz:.2f} → {m.end_hz:.2f} Hz" if m.moving else "") for m in w.modes) or "-"))
        print("tracks: " + ", ".join(f"#{t.track} {t.min_hz:.2f}–{t.max_hz:.2f} Hz ({t.windows} windows)" for t in result.tracks))
