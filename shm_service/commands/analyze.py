"""``shm analyze``: the modal analytics of a recording's deformation variables (the estimator first on a raw
recording), against a baseline learnt from a healthy one, with the loads at the hot spots."""

from __future__ import annotations

import argparse
import json

from ._common import CliError, _analysis_settings, _cut_note, _deformations_of, _print_json, _recording_problems

__all__ = ['cmd_analyze']


def cmd_analyze(args: argparse.Namespace) -> int:
    from analytics import BaselineError

    from ..processing.analysis import analyze_deformations, baseline_from_deformations, recording_gauges

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

    from .loads import WITHHOLD_REMEDY

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
