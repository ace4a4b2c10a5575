"""``shm analyze``: the modal analytics of a recording's deformation variables (the estimator first on a raw
recording), against a baseline learnt from a healthy one, with the loads at the hot spots."""

from __future__ import annotations

import argparse
import json

from ._common import CliError, _analysis_settings, _cut_note, _deformations_of, _print_json, _recording_problems

__all__ = ['cmd_analyze']


def cmd_analyze(args: argparse.Namespace) -> int:
    from analytics import BaselineError

    from ..processing.analysis import analyze_deformations, baseline_from_deformations, baseline_xi_from_deformations, recording_gauges

    config, warmup = _analysis_settings(args)
    baseline = baseline_xi = None
    if args.baseline:
        rec_b, healthy = _deformations_of(args.baseline, args)
        try:
            baseline = baseline_from_deformations(rec_b.rig, healthy, config=config, warmup_s=warmup)
            baseline_xi = baseline_xi_from_deformations(rec_b.rig, healthy, config=config, warmup_s=warmup)
        except BaselineError as exc:
            raise CliError(f"{args.baseline}: {exc}") from None
    rec, data = _deformations_of(args.recording, args)
    try:
        result = analyze_deformations(rec.rig, data, config=config, baseline=baseline, warmup_s=warmup, not_before_s=args.not_before,
                                      gauges=recording_gauges(rec), baseline_xi=baseline_xi)
    except ValueError as exc:
        raise CliError(f"{args.recording}: {exc}{_cut_note(rec)}") from None
    output = {**result.as_dict(), **_recording_problems(rec)}
    if "loads" in output:
        output["loads_band"] = _loads_band_note(output["loads"])
    if data.truth_metadata and "eigenfrequencies_hz" in data.truth_metadata:
        output["truth"] = _truth_errors(data.truth_metadata, output["modes"], "zeta")
        if "degenerate_pairs" in output:  # a biaxial record: the ξ plane against its own truth
            output["truth"].update(_truth_errors(data.truth_metadata, output["modes"], "xi"))
    if args.json:
        _print_json(output)
    else:
        skipped = ", ".join(f"{v} {k}" for k, v in output["skipped_windows"].items() if v)
        print(f"{rec.path}: {data.times[-1] - data.times[0]:.0f} s of b1..b{data.b.shape[1]}"
              f"{'' if data.b_xi is None else f' and bxi1..bxi{data.b_xi.shape[1]}'}"
              f"{' (estimated here)' if data.estimated_here else ''}, {len(output['windows'])} windows"
              f"{f' ({skipped} skipped)' if skipped else ''}")
        print(f"{'unit':>4} {'mode':>4} {'f [Hz]':>9} {'± [Hz]':>8} {'zeta [%]':>9} {'± [%]':>7}  damping by")
        planes = "degenerate_pairs" in output
        for k, m in enumerate(output["modes"]):
            if planes and (k == 0 or output["modes"][k - 1]["plane"] != m["plane"]):
                print(f"{m['plane']} plane:")
            f = m.get("frequency_hz")
            z = m.get("damping_ratio")
            sf = m.get("frequency_std_hz")
            sz = m.get("damping_std")
            print(f"{m['unit']:4d} {m.get('mode') or '-':>4} {'-' if f is None else round(f, 4)!s:>9} "
                  f"{'-' if sf is None else round(sf, 4)!s:>8} {'-' if z is None else round(100 * z, 3)!s:>9} "
                  f"{'-' if sz is None else round(100 * sz, 3)!s:>7}  {m.get('damping_method') or '-'}")
        for pair in output.get("degenerate_pairs", []):
            print(_degenerate_sentence(pair))
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


def _truth_errors(meta: dict, modes: list[dict], plane: str) -> dict:
    """The simulator's eigenfrequencies and damping ratios of one plane ("zeta": the planar keys; "xi": the
    ``_xi`` keys) and the relative errors of that plane's listed modes against them."""
    suffix = "" if plane == "zeta" else "_xi"
    key = f"eigenfrequencies{suffix}_hz"
    if key not in meta:
        return {}
    exact = json.loads(meta[key])
    mine = [m for m in modes if m.get("plane", "zeta") == plane and m.get("mode")]
    zeta_key = next((k for k in (f"modal_damping_ratios{suffix}", f"damping_ratios{suffix}") if k in meta), None)
    zeta = json.loads(meta[zeta_key]) if zeta_key else None
    return {
        key: exact,
        f"relative_error{suffix}": {str(m["mode"]): (m["frequency_hz"] / exact[m["mode"] - 1] - 1 if m.get("frequency_hz") else None)
                                    for m in mine if m["mode"] <= len(exact)},
        **({f"damping_ratios{suffix}": zeta,
            f"damping_relative_error{suffix}": {
                str(m["mode"]): (m["damping_ratio"] / zeta[m["mode"] - 1] - 1 if m.get("damping_ratio") else None)
                for m in mine if m["mode"] <= len(zeta)}} if zeta else {}),
    }


def _degenerate_sentence(pair: dict) -> str:
    """A degenerate pair of ``shm analyze``'s text output."""
    return (f"mode {pair['mode']} is a degenerate pair: zeta {pair['frequency_zeta_hz']:.5g} Hz and xi "
            f"{pair['frequency_xi_hz']:.5g} Hz ({100 * pair['relative_difference']:+.3f} %, within "
            f"{'their combined 1 sigma' if pair['within'] == 'sigma' else '0.5 %'}): a symmetric section bends alike in both "
            f"planes; each plane is tracked on its own")


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
