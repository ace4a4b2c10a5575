"""The ``shm`` command line: modes, simulate, inspect, estimate, analyze, reprocess, baseline, oma, study, serve,
demo, import.

Building the parser imports nothing heavy (numpy, scipy, pydantic, the estimator are imported by
the command that needs them), so ``shm --help`` and argument errors answer at once.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Sequence

from ._argtypes import database_target, number, output_path
from .commands._common import (  # noqa: F401  (the commands' shared parts; reprocess, loads and import call them)
    DEFAULT_SENSOR_COUNT,
    CliError,
    _analysis_settings,
    _count_or_names,
    _cut_note,
    _deformations_of,
    _model_from_args,
    _print_json,
    _recording_problems,
    _sensor_counts,
    add_model_arguments,
)

__all__ = ["main"]


def _rig_from_args(args: argparse.Namespace):
    """The rig of --rig (with --support/--orientation overriding its keys) or of --layout
    (with --length, --support, --orientation)."""
    from estimator import RigError, load_rig, parse_rig

    from .rig_layouts import build_rig

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


# -- shm modes ---------------------------------------------------------------------------
def _plane_modes(rig, temperature_c, count: int, plane: str = "zeta"):
    """The FE model of one bending plane, its first ``count`` frequencies (Hz) and the unit
    deformation (1-based) each mode belongs to."""
    from estimator import assemble_beam, natural_modes, unit_deformations

    model = assemble_beam(rig, temperature_c=temperature_c, plane=plane)
    modes = natural_modes(model, max(count, 6))
    units = unit_deformations(modes, 5)
    unit_of_mode = {m: i + 1 for i, group in enumerate(units.modes) for m in group}
    return model, modes.frequencies_hz[:count], units, unit_of_mode


def _cmd_modes(args: argparse.Namespace) -> int:
    import numpy as np

    from estimator import TABLE1_HZ

    if args.calibration:
        return _print_calibration(args)
    rig = _rig_from_args(args)
    model, freqs, units, unit_of_mode = _plane_modes(rig, args.temperature, args.count)
    # A biaxial beam bends in ξ too: its own frequencies from EI_ξ (a round tube: the same as ζ's).
    xi = _plane_modes(rig, args.temperature, args.count, "xi") if rig.beam.biaxial else None
    # Table 1 is the paper's pinned, hanging sheet: only that configuration is compared with it.
    paper = rig.support == "pinned" and rig.orientation == "hanging"
    table = np.array(TABLE1_HZ)
    n = min(len(freqs), len(table)) if paper else 0
    relative = (freqs[:n] / table[:n] - 1).tolist()
    critical = model.critical_load_factor
    if args.json:
        _print_json({
            "frequencies_hz": [round(float(f), 6) for f in freqs],
            **({"table1_hz": list(TABLE1_HZ), "relative_error": [round(float(r), 6) for r in relative]} if paper else {}),
            "support": rig.support,
            "orientation": rig.orientation,
            "length_m": rig.beam.length,
            "gravity": rig.gravity,
            "critical_load_factor": None if not np.isfinite(critical) else round(float(critical), 6),
            "unit_deformations": [list(group) for group in units.modes],
            **({} if xi is None else _modes_xi_json(xi[0], xi[1], xi[2])),
        })
        return 0
    print(f"{rig.support}, {rig.orientation} beam of {rig.beam.length:g} m, g = {rig.gravity:g} m/s²"
          + (f"; critical load factor {critical:.4g} (it buckles under {critical:.4g} × its weight)" if np.isfinite(critical) else ""))
    if xi is not None:
        _print_biaxial_modes(freqs, unit_of_mode, xi[1], xi[3])
        return 0
    print(f"{'mode':>4} {'f [Hz]':>9}" + (f" {'Table 1':>8} {'error':>8}" if paper else "") + "  unit deformation")
    for k, f in enumerate(freqs, start=1):
        compared = ""
        if paper:
            t = f"{table[k - 1]:8.3f}" if k <= len(table) else " " * 8
            r = f"{100 * relative[k - 1]:+7.2f}%" if k <= n else " " * 8
            compared = f" {t} {r}"
        print(f"{k:4d} {f:9.4f}{compared}  {unit_of_mode.get(k, '-')}")
    return 0


def _modes_xi_json(model, freqs, units) -> dict:
    """The ξ plane's keys of ``shm modes --json`` for a biaxial beam."""
    import numpy as np

    critical = model.critical_load_factor
    return {
        "bending": "biaxial",
        "frequencies_xi_hz": [round(float(f), 6) for f in freqs],
        "critical_load_factor_xi": None if not np.isfinite(critical) else round(float(critical), 6),
        "unit_deformations_xi": [list(group) for group in units.modes],
    }


def _print_biaxial_modes(freqs, unit_of_mode: dict, freqs_xi, unit_of_mode_xi: dict) -> None:
    """Both planes' frequencies side by side, each mode with its plane's unit deformation."""
    print("biaxial: bending in ζ and in ξ")
    print(f"{'mode':>4} {'f ζ [Hz]':>10} {'unit ζ':>6} {'f ξ [Hz]':>10} {'unit ξ':>6}")
    for k, (f, f_xi) in enumerate(zip(freqs, freqs_xi), start=1):
        print(f"{k:4d} {f:10.4f} {unit_of_mode.get(k, '-')!s:>6} {f_xi:10.4f} {unit_of_mode_xi.get(k, '-')!s:>6}")


def _print_calibration(args: argparse.Namespace) -> int:
    """The frozen model update against Table 1 with what the frequencies determine of it."""
    if args.rig or args.layout != "benchmark":
        raise CliError("--calibration describes the shipped calibration of the benchmark layout; drop --rig/--layout")
    from .rig_layouts import CALIBRATED, CALIBRATION_PARAMETERS, frozen_calibration_identifiability

    ident = frozen_calibration_identifiability()
    if args.json:
        _print_json({"calibration": ident.as_dict()})
        return 0
    nominal = {p.name: p.nominal for p in CALIBRATION_PARAMETERS}
    print(f"Model update of the benchmark layout against Table 1 (frozen values; target σ = {100 * ident.frequency_std:.2f} %"
          f" from the residuals, cost {ident.cost:.4g})")
    print(f"{'parameter':<24} {'nominal':>10} {'calibrated':>11} {'± 1σ':>10} {'prior σ':>10} {'resolution':>10}")
    for name, std, prior, res in zip(ident.names, ident.std, ident.prior_std, ident.resolution):
        flag = "" if name not in ident.undetermined else "  not determined by the frequencies"
        print(f"{name:<24} {nominal[name]:10.4g} {CALIBRATED[name]:11.4g} {std:10.3g} {prior:10.3g} {res:10.3f}{flag}")
    print(f"effective parameters determined: {ident.effective_parameters:.2f} of {len(ident.names)}")
    print("singular values of the weighted relative sensitivities (1 % along a combination moves the weighted frequencies by s %):")
    for i, value in enumerate(ident.singular_values):
        print(f"  s{i + 1} = {value:.3g}: {ident.combination_text(i)}")
    return 0


# -- shm simulate ------------------------------------------------------------------------
def _simulation_settings(args: argparse.Namespace):
    from pydantic import ValidationError

    from .virtual_rig import SimulationSettings

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


def _pydantic_message(exc) -> str:
    return "; ".join(f"{'.'.join(str(p) for p in e['loc']) or 'settings'}: {e['msg']}" for e in exc.errors())


def _cmd_simulate(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from .virtual_rig import settings_for_rig, simulate

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


# -- shm estimate ------------------------------------------------------------------------
def _cmd_estimate(args: argparse.Namespace) -> int:
    from .processing.estimation import estimate_recording, score_against_truth, truth_from_recording, write_estimates
    from .recording import read_recording

    rec = read_recording(args.recording, rig=args.rig)
    model = _model_from_args(rec.rig, args)
    try:
        result = estimate_recording(rec, model)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if args.out:
        write_estimates(args.out, rec, result)
    summary = {
        "samples": int(result.t.size),
        # Samples the reader refused (NaN, malformed, duplicate, backwards) plus the filter's gate.
        "rejected": int(result.diagnostics["rejected"] + sum(r.rejected for r in rec.report.topics.values())),
        "realtime_factor": round(float((result.t[-1] - result.t[0]) / max(result.filter_seconds, 1e-9)), 1),
        "selection": result.model.selection.as_dict(),
        "modes": result.model.gamma,
        **({"modes_xi": result.model.gamma_xi} if result.model.biaxial else {}),
        "rest_end_s": round(float(result.calibration.rest_end), 3),
        "diagnostics": result.diagnostics,
        **_recording_problems(rec),
    }
    truth = truth_from_recording(rec)
    if truth is not None:
        scores = score_against_truth(result, truth, after=result.calibration.rest_end)
        summary = {"rmse": scores["rmse"], **summary, "nees": scores["nees"], "scored_samples": scores["scored_samples"]}
    if args.json:
        _print_json(summary)
    else:
        sel = result.model.selection
        print(f"{sel.peripheral}, Γ = {result.model.gamma}: IMUs {','.join(sel.imus)}; ToFs {','.join(sel.tofs) or '-'}; "
              f"gauges {','.join(sel.gauges) or '-'} (aiding b{','.join(map(str, sel.aided)) or '-'})")
        print(f"{summary['samples']} samples, {summary['rejected']} rejected, {summary['realtime_factor']}x real time")
        for problem in result.diagnostics.get("problems", ()):
            print(f"warning: {problem}")
        if "rmse" in summary:
            r = summary["rmse"]
            print(f"RMSE after the rest phase: phi {r['phi_deg']:.4f} deg, e {1000 * r['e_m']:.3f} mm, d {1000 * r['d_m']:.3f} mm, "
                  f"deflection {1000 * r['deflection_m']:.3f} mm, curvature {r['curvature_per_m']:.2e} 1/m")
        for problem in summary["recording_problems"]:
            print(f"problem: {problem}")
        if args.out:
            print(f"wrote {args.out}")
    return 0


# -- shm study ---------------------------------------------------------------------------
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


def _cmd_study(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from .study import DesignTargets, StudyError, StudySettings, run_command

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


# -- shm analyze -------------------------------------------------------------------------
def _cmd_analyze(args: argparse.Namespace) -> int:
    from analytics import BaselineError

    from .processing.analysis import analyze_deformations, baseline_from_deformations, recording_gauges

    config, warmup = _analysis_settings(args)
    baseline = None
    if args.baseline:
        rec_b, healthy = _deformations_of(args.baseline, args)
        try:
            baseline = baseline_from_deformations(rec_b.rig, healthy, config=config, warmup_s=warmup)
        except BaselineError as exc:
            raise CliError(f"{args.baseline}: {exc}") from None
    rec, data = _deformations_of(args.recording, args)
    try:
        result = analyze_deformations(rec.rig, data, config=config, baseline=baseline, warmup_s=warmup, not_before_s=args.not_before,
                                      gauges=recording_gauges(rec))
    except ValueError as exc:
        raise CliError(f"{args.recording}: {exc}{_cut_note(rec)}") from None
    output = {**result.as_dict(), **_recording_problems(rec)}
    if "loads" in output:
        output["loads_band"] = _loads_band_note(output["loads"])
    if data.truth_metadata and "eigenfrequencies_hz" in data.truth_metadata:
        exact = json.loads(data.truth_metadata["eigenfrequencies_hz"])
        zeta_key = next((k for k in ("modal_damping_ratios", "damping_ratios") if k in data.truth_metadata), None)
        zeta = json.loads(data.truth_metadata[zeta_key]) if zeta_key else None
        output["truth"] = {
            "eigenfrequencies_hz": exact,
            "relative_error": {
                str(m["mode"]): (m["frequency_hz"] / exact[m["mode"] - 1] - 1 if m.get("frequency_hz") else None)
                for m in output["modes"] if m.get("mode") and m["mode"] <= len(exact)
            },
            **({"damping_ratios": zeta,
                "damping_relative_error": {
                    str(m["mode"]): (m["damping_ratio"] / zeta[m["mode"] - 1] - 1 if m.get("damping_ratio") else None)
                    for m in output["modes"] if m.get("mode") and m["mode"] <= len(zeta)}} if zeta else {}),
        }
    if args.json:
        _print_json(output)
    else:
        skipped = ", ".join(f"{v} {k}" for k, v in output["skipped_windows"].items() if v)
        print(f"{rec.path}: {data.times[-1] - data.times[0]:.0f} s of b1..b{data.b.shape[1]}"
              f"{' (estimated here)' if data.estimated_here else ''}, {len(output['windows'])} windows"
              f"{f' ({skipped} skipped)' if skipped else ''}")
        print(f"{'unit':>4} {'mode':>4} {'f [Hz]':>9} {'± [Hz]':>8} {'zeta [%]':>9} {'± [%]':>7}  damping by")
        for m in output["modes"]:
            f = m.get("frequency_hz")
            z = m.get("damping_ratio")
            sf = m.get("frequency_std_hz")
            sz = m.get("damping_std")
            print(f"{m['unit']:4d} {m.get('mode') or '-':>4} {'-' if f is None else round(f, 4)!s:>9} "
                  f"{'-' if sf is None else round(sf, 4)!s:>8} {'-' if z is None else round(100 * z, 3)!s:>9} "
                  f"{'-' if sz is None else round(100 * sz, 3)!s:>7}  {m.get('damping_method') or '-'}")
        bl = output.get("baseline")
        if bl:
            for m in bl["modes"]:
                if not m["charted"]:
                    print(f"  mode {m['mode']} not charted: {m['reason']}")
        for problem in output["recording_problems"]:
            print(f"problem: {problem}")
        usability = output.get("usability") or {}
        if usability.get("why_none"):
            print(usability["why_none"])
            for change in usability["change"]:
                print(f"  change: {change}")
        print(f"flags: {len(output['flags'])}")
        for flag in output["flags"]:
            print("  " + ", ".join(f"{k}={v}" for k, v in flag.items()))
        if output.get("loads"):
            _print_loads(output["loads"][-1], output["loads_band"])
    return 0


def _loads_band_note(windows: list[dict]) -> str:
    """What the loads' DEL bands of ``shm analyze`` rest on: the method of the first band, or why there is none."""
    for w in windows:
        for h in w.get("hot_spots", []):
            if h.get("band_method"):
                return str(h["band_method"])
    return ("no band: no strain gauge measured over the analysed windows (none in the rig, or no samples in the recording), "
            "so the virtual strain's modal truncation cannot be judged")


def _print_loads(last: dict, note: str) -> None:
    """The hot spots at the last window: DEL (m = 3) with its band, consumed life, remaining life (withheld, with
    the reason and what to change, where the band is wider than ``analytics.WITHHOLD_HALF_WIDTH``); the band's basis."""
    from analytics import WITHHOLD_HALF_WIDTH

    from .commands.loads import WITHHOLD_REMEDY

    print(f"loads at the last window ({last['start_s']:.0f} s):")
    for h in last["hot_spots"]:
        dels = h.get("del_pa") or {}
        key = next(iter(dels), None)
        band = (h.get("del_band_pa") or {}).get(key) if key else None
        del_text = "-" if key is None else f"DEL{key} {dels[key] / 1e6:.3g} MPa" + (
            f" [{band[0] / 1e6:.3g}, {band[1] / 1e6:.3g}]" if band else " (no band)")
        remaining = h.get("remaining_years")
        if band and key and dels[key] > 0 and band[1] / dels[key] - 1.0 > WITHHOLD_HALF_WIDTH:
            # virtual and measured strain disagree beyond what a damage figure can carry: no life printed
            print(f"  {h['name']:>20} at {h['position_m']:g} m: {del_text}; damage and life withheld: the band is "
                  f"±{band[1] / dels[key] - 1.0:.0%}, wider than ±{WITHHOLD_HALF_WIDTH:.0%}; change: {WITHHOLD_REMEDY}")
            continue
        print(f"  {h['name']:>20} at {h['position_m']:g} m: {del_text}, consumed {h['consumed']:.3e}, "
              f"remaining {'-' if remaining is None else f'{remaining:.3g} years'} ({h.get('verdict')})")
    print(f"  band: {note}")


# -- shm reprocess, shm baseline learn ---------------------------------------------------
def _analysis_options(args: argparse.Namespace):
    from .commands.reprocess import AnalysisOptions

    return AnalysisOptions(rig=args.rig, peripheral=args.peripheral, modes=args.modes, modes_xi=args.modes_xi, imus=args.imus,
                           tofs=args.tofs, gauges=args.gauges, config=args.config)


def _cmd_reprocess(args: argparse.Namespace) -> int:
    import time

    from .commands.reprocess import reprocess

    started = time.perf_counter()
    outcomes = reprocess(args.recordings, args.db, workers=args.workers, scheduler=args.scheduler, force=args.force,
                         options=_analysis_options(args), source=args.structure, progress=not args.json)
    wall = time.perf_counter() - started
    if args.json:
        _print_json({"files": [o.as_dict() for o in outcomes], "wall_s": round(wall, 3)})
    else:
        for o in outcomes:
            detail = f"{o.windows} windows" if o.status == "done" else (o.error or "")
            print(f"{o.status:8} {o.path}  {detail}")
        counts = {s: sum(o.status == s for o in outcomes) for s in ("done", "skipped", "failed")}
        print(f"{counts['done']} done, {counts['skipped']} skipped, {counts['failed']} failed in {wall:.1f} s -> {args.db}")
    return 1 if any(o.status == "failed" for o in outcomes) else 0


def _time_arg(text: str) -> float:
    """UNIX seconds or an ISO 8601 time (UTC unless it says otherwise)."""
    from datetime import datetime, timezone

    try:
        return float(text)
    except ValueError:
        pass
    try:
        moment = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither UNIX seconds nor an ISO 8601 time") from None
    return (moment if moment.tzinfo else moment.replace(tzinfo=timezone.utc)).timestamp()


def _cmd_baseline_learn(args: argparse.Namespace) -> int:
    import math

    from .commands.reprocess import learn_baseline

    period = (args.start if args.start is not None else -math.inf, args.end if args.end is not None else math.inf)
    if period[0] >= period[1]:
        raise CliError(f"--from {args.start} must be before --to {args.end}")
    try:
        summary = learn_baseline(args.recordings, args.db, args.structure, (max(period[0], -1e18), min(period[1], 1e18)),
                                 workers=args.workers, scheduler=args.scheduler, options=_analysis_options(args),
                                 progress=not args.json)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if args.json:
        _print_json(summary)
    else:
        print(f"baseline {summary['baseline_id']} of {summary['structure']} from {summary['trusted_windows']} trusted "
              f"windows in {summary['files_used']} file(s), stored in {args.db} (active)")
        for m in summary["modes"]:
            print(f"  mode {m['mode']} (unit {m['unit']}): {m['frequency_hz']:.4f} Hz ± {100 * m['sigma_rel']:.3f} % "
                  f"({m['windows']} windows)")
        for failure in summary["failed"]:
            print(f"  failed: {failure['path']}: {failure['error']}")
    return 0


def _add_analysis_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", default=None, help="a `shm serve` configuration (TOML): the same analytics, alarm hysteresis and warm-up")
    add_model_arguments(p, aided=False)


def _add_cluster_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=number(int, low=1, high=512), default=None, metavar="N",
                   help="worker processes of the local cluster (default: the cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="an existing dask.distributed scheduler (tcp://host:8786) instead of a local cluster; its "
                        "workers need this package and the files at the same paths")


# -- shm oma -----------------------------------------------------------------------------
def _cmd_oma(args: argparse.Namespace) -> int:
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

    from .formats.oma_input import clean_for_identification
    from .formats.tables import TableError, read_table, select_channels

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


# -- shm inspect -------------------------------------------------------------------------
def _cmd_inspect(args: argparse.Namespace) -> int:
    from .recording import format_inspection, inspect_recording

    if args.print_rig:  # the recording's rig description (rig.json), to edit or to reuse with shm import --rig
        from .recording import read_recording

        print(read_recording(args.recording, rig=args.rig).rig.to_json())
        return 0
    report = inspect_recording(args.recording, rig=args.rig)
    if args.json:
        _print_json(report)
    else:
        print(format_inspection(report))
    return 0


def _add_configuration_arguments(p: argparse.ArgumentParser, *, rig_file: bool) -> None:
    """--support, --orientation and --length of a layout's rig (the contract's keys)."""
    over = " (overrides the --rig file's key)" if rig_file else ""
    p.add_argument("--support", choices=("pinned", "clamped"), default=None,
                   help=f"pinned: the plain bearing (default); clamped: the fixed bearing, φ ≡ 0{over}")
    p.add_argument("--orientation", choices=("hanging", "standing"), default=None,
                   help=f"hanging below D (default) or standing above it, a mast (needs --support clamped){over}")
    p.add_argument("--length", type=number(low=0, low_open=True, high=1000, unit="m"), default=None, metavar="M",
                   help="beam length in m (default 4); the layout's sensors and truth stations scale with it")


def _cmd_import(args: argparse.Namespace) -> int:
    from .commands.daq import cmd_import

    return cmd_import(args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="shm", description="Structural health monitoring by integrated motion measurement.")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_modes_parser(sub)
    _add_simulate_parser(sub)
    _add_estimate_parser(sub)
    _add_study_parser(sub)
    _add_analyze_parser(sub)
    _add_reprocess_parser(sub)
    _add_baseline_parser(sub)
    _add_oma_parser(sub)
    _add_inspect_parser(sub)
    from .commands.demo import add_demo_parser
    from .commands.loads import add_loads_parser  # shm loads
    from .service._cli import add_serve_parser  # shm serve
    add_serve_parser(sub)
    add_demo_parser(sub)
    add_loads_parser(sub)
    _add_import_parser(sub)
    return parser


def _add_modes_parser(sub: Any) -> None:
    p = sub.add_parser("modes", help="eigenfrequencies of the rig model (against the paper's Table 1 when pinned and hanging)")
    p.add_argument("--rig", help="rig description (.json or .toml); default: the calibrated rig of --layout")
    p.add_argument("--layout", choices=("benchmark", "dense"), default="benchmark")
    _add_configuration_arguments(p, rig_file=True)
    p.add_argument("--temperature", type=number(low=-60, high=150, unit="°C"), default=None,
                   help="°C, -60 to 150 (default: the beam's reference temperature)")
    p.add_argument("--count", type=number(int, low=1, high=20), default=6, metavar="N", help="modes to list (1-20)")
    p.add_argument("--calibration", action="store_true",
                   help="the shipped model update against Table 1: each parameter's value, 1σ and resolution "
                        "(what the six frequencies determine), and the identifiable combinations")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_modes)


def _add_simulate_parser(sub: Any) -> None:
    p = sub.add_parser("simulate", help="simulate the virtual rig and write a recording")
    p.add_argument("--duration", type=number(low=0, low_open=True, high=7 * 24 * 3600, unit="s"), default=300.0,
                   help="s, up to a week (default 300)")
    p.add_argument("--seed", type=number(int, low=0), default=1)
    p.add_argument("--plant-seed", type=number(int, low=0), default=None, metavar="SEED",
                   help="seed of the structure as built (E and masses a few per cent off the rig file; default --seed): "
                        "a baseline and later recordings of the same structure share it")
    p.add_argument("--out", required=True, type=output_path, help="output .mcap (its directory must exist)")
    p.add_argument("--excitation", choices=("paper", "ambient", "decay", "operational"), default="paper",
                   help="paper: the paper's bearing moves and sine bursts; ambient: random loads, the bearing still; decay: "
                        "plucks and free decays; operational: the support moving randomly (3 mm RMS, broadband) and a "
                        "spatially correlated random load along the beam")
    p.add_argument("--layout", choices=("benchmark", "dense"), default="benchmark")
    p.add_argument("--rig", help="simulate this rig description (.json or .toml) instead of a --layout: any beam, with the "
                                 "sensors it has (no bearing sensor: the support is fixed to the ground); its 'simulator' "
                                 "key may hold settings, which the options given here override")
    _add_configuration_arguments(p, rig_file=True)
    p.add_argument("--wind-load", type=number(low=0, high=1e6, unit="N/m"), default=None, metavar="N/m",
                   help="RMS of the ambient (wind) load along the beam for the ambient and operational excitations, "
                        "N/m (default: 0.05 for the built-in sheet; for a --rig the load whose quasi-static RMS strain "
                        "at the support is 50 µε, about 10 MPa on steel)")
    p.add_argument("--wind-correlation", type=number(low=0, low_open=True, high=1e4, unit="m"), default=None, metavar="M",
                   help="correlation length of the wind load along the beam, m (default 1; a quarter of a --rig beam)")
    p.add_argument("--ideal", action="store_true", help="plant = nominal rig (no mismatch, friction, scale/misalignment)")
    p.add_argument("--damage", action="append", metavar="SPEC", help="mass:KG@POS or stiffness:FACTOR@A-B (repeatable)")
    p.add_argument("--damage-at", type=number(low=0, unit="s"), default=None, metavar="SECONDS",
                   help="damage appears at this time (within --duration)")
    p.add_argument("--temperature-swing", type=number(low=0, high=100, unit="K"), default=0.0, metavar="K",
                   help="peak-to-peak swing, 0-100 K")
    p.add_argument("--temperature-mean", type=number(low=-60, high=150, unit="°C"), default=20.0, metavar="C",
                   help="°C, -60 to 150 (default 20)")
    p.add_argument("--friction", type=number(low=0, high=10, unit="N·m"), default=0.0, metavar="N·m",
                   help="Coulomb friction torque of the bearing (default 0; the study uses 0.03): makes the modal "
                        "figures amplitude dependent, so the recording's exact linear modal figures no longer hold")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_simulate)


def _add_estimate_parser(sub: Any) -> None:
    p = sub.add_parser("estimate", help="run the IMMS estimator over a recording")
    p.add_argument("recording")
    add_model_arguments(p)
    p.add_argument("--out", type=output_path, help="write the estimates to this .mcap (its directory must exist)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_estimate)


def _add_study_parser(sub: Any) -> None:
    p = sub.add_parser("study", help="the paper's sensor-configuration study; design mode with --target-*")
    p.add_argument("--out", default="study", help="output folder (default study/)")
    p.add_argument("--seeds", default=None, help="seeds, one simulated recording each (default 1,2,3)")
    p.add_argument("--duration", type=number(low=0, low_open=True, high=3600, unit="s"), default=None,
                   help="recording length, s, up to 3600 (default 300)")
    p.add_argument("--rest", type=number(low=5, unit="s"), default=None, help="initial rest phase, s, at least 5 (default 60)")
    p.add_argument("--tofs", default=None, help="ν_ρ swept, e.g. 4-13 (default)")
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="study this rig description (.json/.toml) instead of the paper's dense layout, under its "
                        "ambient wind: the sweeps keep the sensor counts it has (no ToFs: ν_ρ = 0)")
    p.add_argument("--modes", type=number(int, low=1, high=5), default=None, metavar="Γ",
                   help="unit deformations Γ (default 4, the paper's; another Γ needs --rig)")
    p.add_argument("--ideal", action="store_true", help="idealised plant (the drift without gauges disappears)")
    p.add_argument("--quick", action="store_true", help="small study: 2 seeds of 240 s, ν_ρ = 4, 5, ν_ε = 0, 2, 4")
    p.add_argument("--workers", type=number(int, low=1, high=64), default=None, help="worker processes, 1-64 (default: the cores)")
    p.add_argument("--keep-recordings", action="store_true", help="keep the simulated recordings in OUT/recordings/")
    p.add_argument("--target-phi-deg", type=number(low=0, low_open=True, high=90, unit="°"), default=None, metavar="X",
                   help="design mode: RMSE target of φ, degrees (0-90]")
    p.add_argument("--target-e-m", type=number(low=0, low_open=True, high=4, unit="m"), default=None, metavar="Y",
                   help="design mode: RMSE target of e, m (0-4]")
    p.set_defaults(func=_cmd_study)


def _add_analyze_parser(sub: Any) -> None:
    p = sub.add_parser("analyze", help="modal analytics of the deformation variables (runs the estimator on raw recordings)")
    p.add_argument("recording", help="an estimates recording (shm estimate --out, shm serve's archive) or a raw recording")
    p.add_argument("--baseline", help="a healthy recording to learn the baseline from (all of it; with or without a temperature swing)")
    p.add_argument("--not-before", type=number(low=0, unit="s"), default=None, metavar="S",
                   help="analyse windows starting at or after S seconds into the recording (default: the rest phase's end plus "
                        "the warm-up, when the recording tells the rest phase)")
    _add_analysis_arguments(p)  # the same as reprocess and baseline learn take
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_analyze)


def _add_reprocess_parser(sub: Any) -> None:
    p = sub.add_parser("reprocess", help="estimator and analysis over many recordings (dask.distributed) into a service database")
    p.add_argument("recordings", nargs="+", metavar="FILE", help="recordings (.mcap) of the contract")
    p.add_argument("--db", required=True, type=database_target,
                   help="the service's database: a SQLite file (created if missing) or postgresql://USER@HOST:PORT/DB")
    _add_cluster_arguments(p)
    p.add_argument("--force", action="store_true", help="reprocess files already done with this configuration")
    p.add_argument("--structure", default=None, metavar="ID",
                   help="source id of the rows (default: an archive file's source, else the file's stem)")
    _add_analysis_arguments(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_reprocess)


def _add_baseline_parser(sub: Any) -> None:
    p = sub.add_parser("baseline", help="baselines of the live service")
    baseline_sub = p.add_subparsers(dest="baseline_command", required=True)
    p = baseline_sub.add_parser("learn", help="learn a baseline from a healthy period spread over recordings and store "
                                              "it as the structure's active baseline (the service loads it at start)")
    p.add_argument("recordings", nargs="+", metavar="FILE", help="recordings (.mcap) of the healthy period")
    p.add_argument("--structure", required=True, metavar="ID", help="the source id the service monitors it as")
    p.add_argument("--db", required=True, type=database_target,
                   help="the service's database: a SQLite file or postgresql://USER@HOST:PORT/DB")
    p.add_argument("--from", dest="start", type=_time_arg, default=None, metavar="TIME",
                   help="start of the healthy period: UNIX s or ISO 8601 (default: the files' start)")
    p.add_argument("--to", dest="end", type=_time_arg, default=None, metavar="TIME",
                   help="end of the healthy period (default: the files' end)")
    _add_cluster_arguments(p)
    _add_analysis_arguments(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_baseline_learn)


def _add_oma_parser(sub: Any) -> None:
    p = sub.add_parser("oma", help="operational modal analysis (SSI-cov) of measured channels: .npy/.npz, CSV/TSV/text, .mat, HDF5, .mcap")
    p.add_argument("data", help="measured channels (see shm_service/formats/tables.py for the formats)")
    p.add_argument("--fs", type=number(low=0, low_open=True, unit="Hz"), default=None,
                   help="sample rate, Hz (required without a time column)")
    p.add_argument("--channels", default=None, help="channels to use, names or column indices: A,B,...")
    p.add_argument("--fmin", type=number(low=0, unit="Hz"), default=None, help="lower edge of the analysed band, Hz")
    p.add_argument("--fmax", type=number(low=0, low_open=True, unit="Hz"), default=None,
                   help="upper edge of the analysed band, Hz (default 0.4·fs)")
    p.add_argument("--inputs", default=None, help="measured input channels (support acceleration): FRF cross-check and excitation class")
    p.add_argument("--window", type=number(low=0, low_open=True, unit="s"), default=None, metavar="S",
                   help="also identify windows of S seconds")
    p.add_argument("--step", type=number(low=0, low_open=True, unit="s"), default=None, metavar="S",
                   help="window step, s (default: --window)")
    p.add_argument("--max-abs", type=number(low=0, low_open=True), default=None, metavar="X",
                   help="reject |value| > X (the file's units) as implausible")
    p.add_argument("--outlier-factor", type=number(low=0), default=1000.0, metavar="F",
                   help="reject |x - median| > F x the channel's 90th percentile of |x - median| as implausible (0: off) [1000]")
    p.add_argument("--max-fill", type=int, default=4, metavar="N",
                   help="fill runs of at most N rejected samples by linear interpolation; longer gaps: the longest valid span [4]")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_oma)


def _add_inspect_parser(sub: Any) -> None:
    p = sub.add_parser("inspect", help="topics, counts, rates, gaps and problems of a recording")
    p.add_argument("recording")
    p.add_argument("--rig", help="rig description to use instead of the attached rig.json")
    p.add_argument("--json", action="store_true")
    p.add_argument("--print-rig", action="store_true", help="print the recording's rig description (rig.json) and exit")
    p.set_defaults(func=_cmd_inspect)


def _add_import_parser(sub: Any) -> None:
    p = sub.add_parser(
        "import",
        help="measured channels of DAQ files (CSV/TSV/text, LabVIEW, .npy/.npz, .mat, HDF5) into a contract recording",
    )
    p.add_argument("data", nargs="+", help="the DAQ file(s); several when the map's clocks read different files")
    p.add_argument("--rig", required=True, help="rig description (.json or .toml) declaring every topic of the map")
    p.add_argument("--map", required=True, help="channel map (.toml): per column topic, field, index, scale, offset, clock")
    p.add_argument("--out", required=True, type=output_path, help="the recording to write (.mcap; its directory must exist)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_import)


def _user_errors() -> tuple[type[BaseException], ...]:
    """Errors that are the user's (bad file, bad rig): the modules defining them are imported only
    when a command has already loaded them."""
    errors: list[type[BaseException]] = [CliError, FileNotFoundError]
    if "contract._rig" in sys.modules:
        errors.append(sys.modules["contract._rig"].RigError)
    if "shm_service.recording._reader" in sys.modules:
        errors.append(sys.modules["shm_service.recording._reader"].RecordingError)
    return tuple(errors)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or an argument error (2, already printed)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        code = args.func(args)
        sys.stdout.flush()  # a reader that went away (``| head``) answers here, not in the flush at exit
        return code
    except BrokenPipeError:
        if not _stdout_closed():
            raise  # another pipe of the command's: its own error
        return _stdout_gone()
    except Exception as exc:
        if not isinstance(exc, _user_errors()):
            raise
        print(f"shm {args.command}: error: {exc}", file=sys.stderr)
        return 2


#: The exit status of a writer whose reader closed the pipe (the shell's 128 + SIGPIPE).
EXIT_BROKEN_PIPE = 141


def _stdout_closed() -> bool:
    """Whether stdout is a pipe whose reader has gone (poll reports an error on its write end)."""
    import select

    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poller.poll(0))
    except (AttributeError, OSError, ValueError):
        return True  # no file descriptor to ask: the error was raised writing to it


def _stdout_gone() -> int:
    """What Python's documentation advises for SIGPIPE: stdout pointed at devnull, so the flush at
    exit does not raise again, and a quiet exit with the shell's status of a closed pipe."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):
        pass
    return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
