"""Write the discrepancy report: report.json, report.md and the plots (`report_plots`), each atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.discrepancy.gyro_lines import LINE_RATIO, NEIGHBOURS_HZ
from gyrodenoise.discrepancy.rank import MIN_DRIFT_DEG
from gyrodenoise.discrepancy.report_plots import PLOT_NAMES, plots
from gyrodenoise.discrepancy.truth_check import BANDS_HZ, FOLLOWS_RATIO, TRUTH_FREE
from gyrodenoise.discrepancy.workflow import NO_EFFECT


def _fmt(v) -> str:
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        return f"{float(a):.4g}"
    return "[" + ", ".join(_fmt(x) for x in a) + "]"


def _fmt_fixed(v, decimals: int) -> str:
    """Values rounded to `decimals` places, printed in full (no exponent)."""
    a = np.round(np.asarray(v, dtype=float), decimals)
    if a.ndim == 0:
        return f"{float(a):.{decimals}f}" if decimals > 0 else f"{float(a):.0f}"
    return "[" + ", ".join(_fmt_fixed(x, decimals) for x in a) + "]"


def _label(c: dict) -> str:
    """Effect name with its variant where it has two (vibration: sinusoid / band-limited)."""
    return f"{c['name' if 'name' in c else 'effect']}" + (f" ({c['variant']})" if c.get("variant") else "")


def _corner_se_words(report: dict) -> list[str]:
    """Where a named low-pass's corner was read from the motion, what its standard error is made of."""
    d = report.get("delay_or_lowpass") or {}
    if d.get("kept") == "both" and d.get("removed_by_backward_check"):
        return [
            f"sensor_bandwidth corner_hz: read from the motion's droop beside a time offset, which the final "
            f"backward check then removed (given the other named effects it no longer cleared its threshold); its "
            f"standard error is that pair's profile, {_fmt(d['both_corner_se_white_hz'])} Hz with the rows taken as "
            f"white, times {d['both_corner_se_colour_factor']:.2f} for the residual's colour."
        ]
    if d.get("kept") == "both":
        return [
            f"sensor_bandwidth corner_hz: read from the motion's droop beside a time offset (the two share the delay "
            f"the motion shows, {_fmt(1e3 * d['delay_s'])} ms); its standard error is the pair's profile, "
            f"{_fmt(d['both_corner_se_white_hz'])} Hz with the rows taken as white, times "
            f"{d['both_corner_se_colour_factor']:.2f} for the residual's colour; the time offset's standard error "
            f"includes the corner's part, {_fmt(1e3 * d['both_delay_se_from_corner_s'])} ms."
        ]
    if d.get("kept") != "sensor_bandwidth" or "lowpass_corner_se_colour_factor" not in d:
        return []
    return [
        f"sensor_bandwidth corner_hz: read from the motion (it replaced a time offset); its standard error is the "
        f"fit's profile, {_fmt(d['lowpass_corner_se_white_hz'])} Hz with the rows taken as white, times "
        f"{d['lowpass_corner_se_colour_factor']:.2f} for the residual's colour (`spectral.colour_factor`: the "
        "low-passed noise has its power where the motion the corner is read from has)."
    ]


def _raw_sample_evidence_md(report: dict) -> list[str]:
    """Effects named from the raw gyro samples, not by the regression (no delta BIC): what they rest on."""
    lines = []
    for e in report["named_effects"]:
        if e["name"] == "quantization" and e.get("lattice"):
            lat = e["lattice"]
            lines.append(
                "- quantization is read from the raw gyro samples, not fitted (so no delta BIC): "
                f"{100 * lat['fraction']:.1f}% of the fit sequences' samples lie on a lattice of step "
                f"{_fmt(np.degrees(lat['step']))} deg/s (named at >= {100 * lat['required_fraction']:.0f}%, "
                "with a step not far below the noise). It is the sensor's output resolution: it enters the "
                "re-simulation, not the prediction."
            )
        if e["name"] == "saturation" and e.get("saturation_check"):
            sat = e["saturation_check"]
            lines.append(
                "- saturation is read from the raw gyro samples, not fitted (so no delta BIC): "
                f"{sat['plateau_samples']} samples sit at the largest reported rate and {sat['beyond_samples']} "
                "samples of the true rate lie beyond it."
            )
    return [*lines, ""] if lines else []


def _instability_md(report: dict) -> list[str]:
    """The flicker floor's check after the selection (`bias_instability`), named or not."""
    c = report.get("bias_instability_check")
    if not c:
        return []
    if "floor_z" not in c:  # flights too short for the fit
        return [f"Bias instability was not judged: {c.get('not_judged', 'no record')}.", ""]
    deg_h = 3600 * 180 / np.pi
    z = ", ".join(f"{v:.1f}" for v in c["floor_z"])
    words = (
        f"Bias instability (a flicker floor, the flat part of the Allan deviation) was judged after the selection: "
        f"the floor of a weighted fit of the Allan variance (white noise, floor, random walk) to what the model "
        f"leaves with the bias's wander kept, against {c['draws']} re-simulations of the selected model. Its z per "
        f"axis on the fit sequences: {z} (named at >= {c['min_z']:g}, with a share of at least the practical minimum "
        f"of the Allan variance at {c['longest_tau_s']:.3g} s"
    )
    if "holdout_floor_z" in c:
        words += (
            ", and z >= "
            + f"{c['min_z_holdout']:g} on the held-out sequences: "
            + ", ".join(f"{v:.1f}" for v in c["holdout_floor_z"])
        )
    words += "). "
    if c.get("not_judged"):
        words += f"Not judged on the {c['not_judged']}. "
    if c.get("null_mismatch"):
        return [
            words + "Not judged (not identifiable): on some flights the measured floor lies far below anything the "
            "selected model's re-simulations make, whose slow wander (the truth's reconstruction error drawn at its "
            "fitted level, the noise) is not these flights'.",
            "",
        ]
    if not c["named"]:
        return [words + "Not named.", ""]
    words += f"Named: floor {_fmt(np.asarray(c['floor_rad_s']) * deg_h)} deg/h beyond what the other terms make."
    rw, vib = c.get("random_walk"), c.get("vibration")
    if rw is not None:
        zk = ", ".join(f"{v:.1f}" for v in rw["walk_z"])
        words += (
            f" The random walk the selection named {'stays' if rw['kept'] else 'is replaced by it'}: its K^2 against "
            f"re-simulations with the floor and no walk, z [{zk}]; K^2 ["
            + ", ".join(f"{v:.2g}" for v in rw["ratio"])
            + "] times their mean."
        )
    if vib is not None:
        words += (
            f" The band-limited vibration at {vib['band_hz'][0]:.3g} Hz {'stays' if vib['kept'] else 'is replaced'}"
            f": its band's power against re-simulations with the floor and no band, z {vib['z']:.1f}, "
            f"{vib['ratio']:.2g} times their mean."
        )
    return [
        words + " The floor's band (1 to 1000 s) is the simulator's default: flights of minutes cannot say "
        "where it ends.",
        "",
    ]


def _gap_words(gb: dict, ga: dict) -> list[str]:
    """The held-out gap table in words: which way each measure moved, and how to read a small RMS change."""

    def pct(k: str) -> float:
        return 100 * (ga[k] - gb[k]) / gb[k] if gb.get(k) else float("nan")

    drift = pct("drift_10s_median_deg")
    words = [
        f"With the named effects, on the held-out sequences: residual RMS {pct('residual_rms_rad_s'):+.1f}%, median "
        f"10-s drift {drift:+.1f}%"
        + (" (it grows: the named effects do not reduce the held-out drift)" if drift > 0 else "")
        + f", Allan-deviation gap {pct('allan_gap_log10'):+.1f}%"
        + (f", spectral gap {pct('psd_gap_log10'):+.1f}%" if "psd_gap_log10" in gb and "psd_gap_log10" in ga else "")
        + ". The RMS is mostly white noise, which no model predicts sample by sample: it moves little even when "
        "a named effect is right; the share of the in-band power an effect closes (tables above) and the spectral "
        "and Allan gaps are the measures of fit.",
        "",
    ]
    return words


def _band_vibration(report: dict) -> dict | None:
    for e in report["named_effects"]:
        if e["name"] == "vibration" and float(np.max(e["params"].get("bandwidth_hz", 0.0))) > 0:
            return e
    return None


def _band_words(report: dict) -> list[str]:
    """What a band-limited vibration does to the gap, in words (it is noise: no prediction)."""
    e = _band_vibration(report)
    if e is None:
        return []
    gb, ga = report["gap_before"], report["gap_after"]
    p = e["params"]

    def change(k, fmt):
        b, a = gb.get(k), ga.get(k)
        if b is None or a is None:
            return "n/a"
        word = "shrinks" if a < b else "does not shrink"
        return f"{word} ({fmt.format(b)} -> {fmt.format(a)})"

    return [
        f"The named vibration is band-limited: noise in a {float(p['bandwidth_hz']):.3g} Hz wide band around "
        f"{float(p['frequency_hz']):.4g} Hz, not a line. No regressor can predict noise, so it cannot lower the "
        "held-out residual RMS or the 10-s drift of the model gyro (those change only through the other named "
        "effects); it enters the re-simulation instead, together with the white-noise floor fitted beside it. "
        f"With it the spectral gap {change('psd_gap_log10', '{:.3f}')} and the Allan-deviation gap "
        f"{change('allan_gap_log10', '{:.3f}')}: this is the test of whether the re-simulated data now "
        "reproduce the measured spectrum and Allan deviation (plots `spectrum.png`, `allan.png`).",
        "",
    ]


def _network_md(net: dict) -> list[str]:
    """The network relation (`--network`): what the trained denoiser's correction regresses on."""
    lines = [f"## What the trained denoiser learned (`--network`, {net.get('model_dataset') or 'model'})", ""]
    lines += [
        f"Model: `{net['model']}`, run on the fit and held-out sequences. Its correction w_tilde = w_hat - C_hat "
        f"w_imu (RMS {net['w_tilde_rms_rad_s']:.3g} rad/s) is regressed on the effect library (greedy BIC selection, "
        "base model: per-sequence bias, deterministic effects only). Parameters are those of the *correction*, "
        "i.e. the opposite sign of the sensor's error.",
        "",
        "| effect (order of selection) | share of w_tilde variance explained | delta BIC | parameters of the "
        "correction |",
        "|---|---|---|---|",
    ]
    learned = {e["name"]: e for e in net["learned_effects"]}
    left = 1.0
    for step in net["selection"]:
        share = left * step["explained_fraction"]
        left -= share
        e = learned.get(step["effect"], {"datasheet": {}})
        par = "; ".join(
            f"{k} {_fmt_fixed(d['value'], 3)} {d['unit']}"
            for k, d in e["datasheet"].items()
            if not k.endswith("per_sequence")
        )
        lines.append(f"| {step['effect']} | {100 * share:.1f}% | {step['delta_bic']:.0f} | {par} |")
    lines += [
        "",
        f"Together the named effects explain {100 * (1 - left):.0f}% of w_tilde's variance (after the per-sequence "
        "bias; shares of that variance, in the order of selection); the rest is not a library effect.",
        "",
    ]
    c = net.get("C_hat_as_effects")
    if c:
        lines += [
            "C_hat itself (the linear part outside w_tilde) reads as scale factor "
            f"{_fmt_fixed(c['scale_factor_ppm'], 0)} ppm and misalignment "
            f"{_fmt_fixed(c['misalignment_mrad'], 2)} mrad (xy, xz, yx, yz, zx, zy).",
            "",
        ]
    return lines


def _gyro_lines_md(report: dict) -> list[str]:
    """Lines of the raw gyro above the compared band (`gyro_lines`): seen, not compared with the truth; those in
    every fitted recording are in the simulator's model, with their held-out check."""
    found = report.get("gyro_lines_above_band") or []
    if not found:
        return []
    out = [
        "## Lines in the raw gyro above the band the truth can judge (not compared with the truth)",
        "",
        "Narrow lines in the measured gyro's own spectrum (Welch, 0.25 Hz bins) at least "
        f"{LINE_RATIO:g} times the running median of the bins within {NEIGHBOURS_HZ:g} Hz, above each stretch's "
        "trusted band: the truth cannot say there whether a line is motion or sensor error, so none is named. A line "
        "in every fitted recording is a property of this sensor on this platform either way, and a simulator meant to "
        "reproduce this gyro needs it: it is in error_model.yaml as a band-limited vibration (its frequency and "
        "width, amplitude sqrt(2) x the fitted recordings' mean RMS). Held-out gap: |log10| of the measured over the "
        "simulated power in the line's bins, mean over axes, without the line and with it.",
        "",
        "| frequency (Hz) | recordings | peak / running median (x, y, z) | RMS in the line (deg/s; x, y, z) | "
        "in the simulator's model | held-out gap at the line, without -> with |",
        "|---|---|---|---|---|---|",
    ]
    for m in found:
        ratio = ", ".join(f"{r:.0f}" for r in m["ratio"])
        rms = ", ".join(f"{np.degrees(v):.3g}" for v in m["rms_rad_s"])
        sim = m.get("simulator_vibration")
        model = "no (not in every fitted recording)"
        if sim:
            model = f"vibration {sim['frequency_hz']:.2f} Hz, width {sim['bandwidth_hz']:.2f} Hz"
        held = (m.get("held_out") or {}).get("stretches") or []
        gaps = "; ".join(f"{h['stretch']} {h['gap_before_log10']:.2f} -> {h['gap_after_log10']:.2f}" for h in held)
        out.append(
            f"| {m['frequency_hz']:.2f} | {', '.join(m['recordings'])} | {ratio} | {rms} | {model} | {gaps or '-'} |"
        )
    return [*out, ""]


def _lack_of_fit_md(report: dict) -> list[str]:
    """Error the named effects leave unexplained (`lack_of_fit`): the table of the binned held-out residual."""
    lof = report.get("lack_of_fit")
    if not lof:
        return []
    lines = [
        "## Error the named effects leave unexplained",
        "",
        f"The held-out residual after the final model (compared band), split into {lof['bins']} quantile bins of "
        "each sensor reading (gyro rate, its time derivative, specific force) per axis; score = sum of n x bin "
        f"mean^2 / variance, set against {lof['draws']} re-simulations of the final model along the same motion "
        "(scaled chi-square fitted to their mean and variance; p corrected for the "
        f"{len(lof['rows'])} tests). Flagged: p < {lof['alpha']:g} and a share of the in-band residual power beyond "
        f"what chance puts in the bins of at least {100 * lof['min_share']:g}% (the size an effect needs to be "
        "named). A flag says the vocabulary lacks what the data hold, or a named effect does not hold on these "
        "sequences; it names nothing. `unexplained.png`: the bin means with the re-simulations' 95% band. Shape: "
        "the bin means fitted by an odd and an even part in the reading (odd: a scale factor, a misalignment, or for "
        "the angular acceleration a time offset; even: a scale asymmetry, a quadratic error).",
        "",
        "| reading | axis | score | re-simulated (mean +- sd) | p (corrected) | share of in-band power (beyond chance) "
        "| shape | flagged |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in lof["rows"]:
        lines.append(
            f"| {row['signal']} | {row['axis']} | {row['score']:.1f} | {row['null_mean']:.1f} +- {row['null_sd']:.1f} "
            f"| {row['p_corrected']:.2g} | {100 * row['share']:.2f}% ({100 * row['share_beyond_chance']:.2f}%) "
            f"| {row.get('shape', '')} | {'**yes**' if row['flagged'] else 'no'} |"
        )
    if lof.get("decided") is False:  # `truth_rule.withhold_unexplained`
        said = (
            "Not decided: every held-out ground truth used here follows the gyro in the compared band, so what the "
            "bins hold is the fusion's error as much as the sensor's"
            + (f" (flagged: {lof['caution']})." if lof["caution"] else ".")
        )
    elif lof["caution"]:
        said = f"**{lof['caution'][0].upper() + lof['caution'][1:]}.**"
    else:
        said = "Nothing flagged."
    lines += ["", said, ""]
    return lines


def _reconstruction_md(report: dict) -> list[str]:
    """Which band was compared, and why (`reconstruction`)."""
    rec = report.get("reconstruction")
    if not rec or not rec.get("fit"):
        return []
    rows = rec["fit"] + rec.get("holdout", [])
    lines = [
        "## Where the reconstructed true rate is trusted",
        "",
        "The true rate is the derivative of a spline fitted to the ground-truth poses, so it carries the ground "
        "truth's noise (differentiated) and loses the motion the spline smooths away. Both are estimated from the "
        "ground truth itself (its residual around the spline; the spline's transfer of white noise). The comparison "
        "stops where the lost motion exceeds half of what the sensor contributes (`f_max`); inside, the noise part "
        "is carried as a nuisance term of fitted level (its own spectrum) and the regressions are weighted by it "
        "(generalised least squares).",
        "",
        "| sequence | compared band | limited by | ground truth | orientation noise (mrad) | reconstruction error > "
        "sensor noise above | reconstruction error / residual just above the band |",
        "|---|---|---|---|---|---|---|",
    ]
    for b in rows:
        band = "whole spectrum" if b["whole_spectrum"] else f"0-{b['f_max_hz']:.1f} Hz"
        gt = f"{b['gt_rate_hz']:.0f} Hz, spline corner {b['spline_corner_hz']:.0f} Hz"
        fe = "never" if not np.isfinite(b["f_equal_hz"]) else f"{b['f_equal_hz']:.1f} Hz"
        share = b.get("error_share_above_band") or []
        sh = "-" if b["whole_spectrum"] or not share else _fmt_fixed(share, 2)
        lines.append(
            f"| {b['name']} | {band} | {b['limited_by']} | {gt} | {_fmt_fixed(b['orientation_noise_mrad'], 3)} | "
            f"{fe} | {sh} |"
        )
    if rec.get("nuisance_level") is not None:
        lines += [
            "",
            f"Sensor floor read where the reconstruction error does not reach: {_fmt(rec['sensor_floor_psd'])} "
            f"(rad/s)^2/Hz; fitted level of the reconstruction error relative to its estimate from the ground truth: "
            f"{_fmt_fixed(rec['nuisance_level'], 2)}.",
        ]
    if refit := rec.get("nuisance_refit"):
        lines += [
            "",
            f"That level was first fitted on the base model's residual as {_fmt_fixed(refit['first_fit'], 2)}: an "
            "effect the base model misses had swollen it (a time offset's residual is as blue as the reconstruction "
            f"error). Refitted on the residual of {' + '.join(refit['model'])}, the selection and its null "
            "re-simulations were run again with the refitted level.",
        ]
    return lines + [""] + _gt_gaps_md(report)


def _simulator_model_md(report: dict) -> list[str]:
    """Where the fitted model is written for the simulator (`sim_model`)."""
    name = report.get("simulator_model")
    if not name:
        return []
    lines = [
        f"The model with the named effects, as a simulator configuration: `{name}` (SI units; the turn-on bias "
        "as the fit sequences' mean and spread): `python -m gyrodenoise.train dataset=sim "
        f"dataset.generation.error_model_file=<this folder>/{name}` simulates with it.",
        "",
    ]
    b = report.get("bias_spread")
    if b and b.get("between_sequence_rad_s") is None:  # none estimated (`bias_spread`): one sentence on why
        why = b.get("reason") or "fewer than two sequences counted"
        return lines + [
            f"No turn-on bias spread between sequences was estimated, so `bias_jitter_rad_s` is null and a "
            f"simulation keeps its own setting: {why}.",
            "",
        ]
    if b:
        tau, own = np.degrees(b["between_sequence_rad_s"]), np.degrees(b["estimation_std_rad_s"])
        seen = b.get("observed_std_rad_s")
        left = b.get("held_out_left_out_for") or []
        which = (
            f"fit sequences alone: the held-out ones refit {', '.join(left)}, which did not transfer, and it trades "
            "with their bias"
            if left
            else "fit and held-out"
        )
        lines += [
            f"The turn-on bias's spread between the {b['sequences']} sequences ({which}): {tau:.2g} deg/s "
            f"(`bias_jitter_rad_s`): their estimates' spread less what the estimates' own errors account for, "
            f"{_fmt(own)} deg/s (x, y, z; the fit's standard errors x{b['se_inflation']:.2f}, the factor the "
            "sequences' halves show they fall short by), by the method of moments, at least 0"
            + (f" (the fit sequences' estimates alone spread by {np.degrees(seen):.2g} deg/s)." if seen else "."),
            "",
        ]
    return lines


def _gt_gaps_md(report: dict) -> list[str]:
    """How sequences were split at ground-truth gaps (`compare.load_fit_contexts`), and what was left out."""
    g = report.get("ground_truth_gaps")
    names = [*report.get("fit_sequences", []), *report.get("holdout_sequences", [])]
    if not g or not any("@" in n for n in names):
        return []
    left = g.get("left_out") or []
    lines = [
        f"Sequences whose ground truth has gaps longer than {g['max_gap_s']:g} s (a spline cannot bridge them) are "
        f"split there into the stretches named NAME@A-Bs above (seconds since the first IMU sample); stretches "
        f"shorter than {g['min_stretch_s']:g} s are left out: "
        + ("; ".join(f"{x['stretch']} ({x['seconds']:.1f} s)" for x in left) if left else "none")
        + ".",
        "",
    ]
    return lines


def _truth_caution(report: dict) -> list[str]:
    """Lines under the verdict: the IMU disagreed with its truth (`consistency`), or the ground truth of a
    sequence follows the gyro (`truth_check`)."""
    lines = [f"**Data check:** {w}" for w in report.get("data_warnings") or []]
    lines += [""] if lines else []
    return lines + _truth_follows_gyro(report)


def _truth_follows_gyro(report: dict) -> list[str]:
    followed = {n: c["follows_gyro_bands_hz"] for n, c in (report.get("truth_check") or {}).items()}
    followed = {n: b for n, b in followed.items() if b}
    if not followed:
        return []
    where = "; ".join(f"{n}: " + ", ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in b) for n, b in followed.items())
    lines = [
        f"**Caution: the ground truth follows the gyro** ({where}): the residual there lacks part of the gyro's own "
        'noise, so noise levels fitted on these sequences are too low (section "Is the ground truth independent of '
        'the gyro?"). Prefer sequences whose truth comes from a tracker that measures orientation.',
        "",
    ]
    tf = report.get("truth_followed")
    if tf:
        lines[-1:-1] = ["", _truth_rule_md(tf)]
    return lines


def _truth_rule_md(tf: dict) -> str:
    """What the ground-truth rule (`truth_rule.TruthRule`) did, in one paragraph."""
    fit_f, hold_f = tf.get("fit_sequences") or {}, tf.get("holdout_sequences") or {}
    aside = [n for n in hold_f if n not in tf.get("holdout_used", [])]
    text = []
    if aside:
        text.append(
            f"The held-out {', '.join(aside)} {'was' if len(aside) == 1 else 'were'} set aside: "
            "the practical minimum and the gaps below use the other held-out sequences only."
        )
    reasons = (
        [f"a fit sequence's truth follows the gyro inside its compared band ({', '.join(fit_f)})"] if fit_f else []
    )
    if hold_f and not aside:
        reasons.append(
            f"every held-out sequence's truth follows the gyro inside its compared band ({', '.join(hold_f)}; so the "
            "transfer of an effect cannot be judged, and the gaps below are measured against such truths)"
        )
    if reasons:
        what = (
            "the selection was redone with the effects named from the gyro's own values only "
            f"({', '.join(TRUTH_FREE)}); named against that truth and withheld: {', '.join(tf['withheld'])}"
            if tf["withheld"]
            else "none of the effects named here was judged against it, and an effect the truth follows cannot be "
            "seen in the residual"
        )
        text.append(
            f"Because {' and '.join(reasons)}, the effects judged against the truth are not decided: {what}. On the "
            "independent test world, a null sensor measured against such a truth gets effects named that it does "
            "not have (benchmarks/results/discrepancy_fused_truth.md)."
        )
    return " ".join(text)


def _truth_check_md(report: dict) -> list[str]:
    """The per-band table of `truth_check` (gyrodenoise.discrepancy.truth_check)."""
    checks = report.get("truth_check")
    if not checks:
        return []
    density = next(iter(checks.values())).get("noise_density")
    lines = [
        "## Is the ground truth independent of the gyro?",
        "",
        "Per band, on the ground truth's own samples: coherence of the truth's rate with the gyro (x/y/z), and "
        + (
            "the residual's PSD over that of the datasheet white noise (sigma = "
            f"{density:g} rad/s/sqrt(Hz)) averaged over the same ground-truth intervals (x/y/z). An independent "
            "truth leaves at least the gyro's noise in the residual (ratio >= ~1); a ratio below "
            f"{FOLLOWS_RATIO:g} on any axis (marked *) says the truth follows the gyro there: the gyro's noise, "
            "and any error of it in that band, is partly in the truth and cannot be measured against it."
            if density
            else "the share of the gyro's power the truth reproduces. Without the sensor's noise density "
            "(`--gyro-noise-density`) the check cannot tell a truth that follows the gyro from an exact one "
            "(both are coherent with it) and flags nothing."
        ),
        "",
    ]
    heads = [f"{lo:g}-{hi:g} Hz" for lo, hi in BANDS_HZ]
    lines += ["| sequence | truth rate | " + " | ".join(heads) + " |", "|---|---|" + "---|" * len(heads)]
    for name, c in checks.items():
        cells = {b["band_hz"][0]: b for b in c["bands"]}
        row = []
        for lo, nominal_hi in BANDS_HZ:
            b = cells.get(lo)
            if b is None:
                row.append("-")
                continue
            coh = "/".join(f"{x:.2f}" for x in b["coherence"])
            upto = f" (to {b['band_hz'][1]:g} Hz)" if b["band_hz"][1] < nominal_hi - 1e-9 else ""  # cut by its rate
            if b.get("residual_over_noise") is not None:
                ratio = "/".join(f"{x:.2g}" for x in b["residual_over_noise"])
                row.append(f"{coh}; {ratio}{' *' if b['follows_gyro'] else ''}{upto}")
            else:
                share = float(np.mean(b["reproduced_share"]))  # below -1: the residual outweighs the gyro's power
                row.append(f"{coh}; {f'{share:+.2f}' if share >= -1 else '< -1'}{upto}")
        lines.append(f"| {name} | {c['truth_rate_hz']:.0f} Hz | " + " | ".join(row) + " |")
    return lines + [""]


def _min_drift(settings: dict) -> float:
    return float(settings.get("min_drift_deg", MIN_DRIFT_DEG))


def _agreement(t: dict | None) -> str:
    """The held-out transfer check of a sensor constant (`transfer.transfer_check`)."""
    if not t:
        return ""
    if not t["separable_on_held_out"]:
        return "not separable there"
    out = f"R {t['birge_ratio']:.2f}, p {t['p_value']:.2g}"
    spread = t.get("fit_sequences")
    if spread:  # the p is against the fit sequences' own spread (`transfer`), which is checked against their halves
        out += f" against the fit sequences' spread (R {spread['birge_ratio']:.2f}"
        out += f", p {spread['p_value']:.2g} against their halves)" if "p_value" in spread else ")"
    return out + (f"; SE x{t['se_factor']:.2f}" if t["se_factor"] > 1 else "")


def _closed(e: dict) -> str:
    """What a named effect closes on the held-out sequences: in-band power share, and the reduction
    of the median 10-s drift where it is defined (sensor-constant effects)."""
    out = f"{100 * e['holdout_gain']:.2f}%" if e.get("holdout_gain") is not None else ""
    t = e.get("holdout_transfer_dloglik")
    if t is not None:  # a band-limited vibration: the share above is at a level refitted on the held-out flights
        out += f" (level refitted); at the fit level, held-out log-likelihood {t:+.1f}"
    d = e.get("holdout_drift_reduction_deg")
    if d is not None:
        out += f"{'; ' if out else ''}10-s drift {-d:+.3g} deg"
    return out


def _decisions_md(report: dict) -> list[str]:
    """The calibrated thresholds (`null.py`) and the practical minimum."""
    null = report.get("null")
    s = report["settings"]
    lines = ["## Decisions", ""]
    if null:
        lines += [
            f"An effect is named when its delta BIC exceeds its threshold: the 95th percentile of its delta BIC over "
            f"{null['draws']} re-simulations of the fitted base model along these sequences (fresh sensor noise and a "
            f"fresh draw of the reconstruction error; common random numbers), and at least {s['bic_threshold']:g}; and "
            f"when it closes at least {100 * s['min_gain']:g}% of the residual power in the compared band on the "
            "held-out sequences (a band-limited vibration: with its level refitted there; and with the level fitted on "
            "the fit sequences, a sensor constant, it must raise their Whittle log-likelihood), or, for an effect "
            "whose coefficients are sensor constants (fitted on the fit sequences, not refitted per sequence), "
            f"reduces the held-out median 10-s attitude drift of the model gyro against the measured gyro by at "
            f"least {_min_drift(s):g} deg. The null rank p is the "
            "share of null draws that reach the observed delta BIC (1/(draws+1): none did).",
            "",
            "| candidate | null median | null 95th percentile | threshold |",
            "|---|---|---|---|",
        ]
        for n, v in null["per_candidate"].items():
            med = "-" if v["median"] is None else f"{v['median']:.1f}"
            q = "-" if v["q95"] is None else f"{v['q95']:.1f}"
            lines.append(f"| {n} | {med} | {q} | {v['threshold']:.1f} |")
    else:
        lines += [
            f"Fixed BIC threshold {s['bic_threshold']:g} (no null re-simulations); practical minimum "
            f"{100 * s['min_gain']:g}% of the in-band residual power on the held-out sequences, or (sensor-constant "
            f"effects) {_min_drift(s):g} deg less held-out median 10-s drift of the model gyro."
        ]
    return lines + [""]


def _below_practical_md(report: dict) -> list[str]:
    """Effects the data show but that are too small to matter (clear the threshold, not the practical minimum)."""
    rows = report.get("below_practical") or []
    if not rows:
        return []
    lines = [
        "Detected on the fit sequences but below the practical minimum on the held-out ones (they clear their "
        "threshold, but fitted there they close less than the minimum of the held-out in-band power and of the "
        "10-s drift; a negative share: the held-out gap grows, a negative drift change: it shrinks; a band-limited "
        "vibration also fails when, at the level fitted on the fit sequences, it lowers the held-out "
        "log-likelihood: its level is not the sensor's; see Decisions):",
        "",
        "| effect | delta BIC | threshold | share of the fit residual | closed (held-out) |",
        "|---|---|---|---|---|",
    ]
    tf = report.get("truth_followed") or {}
    if tf and not tf.get("decided", True):
        lines[1:1] = [
            "",
            "Against a ground truth that follows the gyro (see the caution under the verdict) these are not decided "
            "either: a residual that lacks the gyro's own noise cannot say what an effect would close.",
        ]
    for c in rows:
        lines.append(
            f"| {_label(c)} | {c['delta_bic']:.1f} | {c['threshold']:.1f} | {100 * c.get('gain', 0.0):.2f}% | "
            f"{_closed(c) or '-'} |"
        )
    return lines + [""]


def _identifiability_md(report: dict) -> list[str]:
    """Expected delta BIC at stated magnitudes on this motion (`identifiability`)."""
    idf = report.get("identifiability") or {}
    if not idf:
        return []
    lines = [
        "## Identifiability on this motion",
        "",
        "Expected delta BIC of each effect at a stated magnitude (every coefficient at +-that value, random signs; "
        "and the least identifiable coefficient alone), from the Fisher information of its regressors on these fit "
        "sequences given the other effects of the final model (base and named) at its residual's variance, in the "
        "compared band; and the smallest magnitude expected to clear the threshold.",
        "",
        "| effect | stated magnitude | expected delta BIC | least identifiable coefficient alone | threshold | "
        "smallest detectable | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for n, v in idf.items():
        verdict = "identifiable" if v["identifiable"] else "not identifiable"
        lines.append(
            f"| {n} | {v['reference_datasheet']:.3g} {v['unit']} | {v['expected_delta_bic']:.1f} | "
            f"{v['expected_delta_bic_weakest']:.1f} | {v['threshold']:.1f} | {v['min_magnitude_datasheet']:.3g} "
            f"{v['unit']} | {verdict} |"
        )
    no_row = [e["name"] for e in report.get("named_effects", []) if e["name"] not in idf]
    if no_row:
        lines += [
            "",
            f"Named without a row here: {', '.join(no_row)} (no regression coefficients to state it for: a "
            "band-limited vibration is fitted to the spectrum, quantization read from the raw samples, a bias "
            "instability from the Allan variance).",
        ]
    return lines + [""]


PLOT_ALT = {"allan": "Allan deviation"}  # a figure's alt text in report.md, where it is not its name


def markdown(report: dict) -> str:
    lines = ["# Discrepancy report: simulation vs measurement", ""]
    lines += [
        f"Fit sequences: {', '.join(report['fit_sequences'])}  ",
        f"Held-out sequences: {', '.join(report['holdout_sequences'])}  ",
        f"Base model: {', '.join(report['base_model'])}",
        "",
        f"**Verdict: {report['verdict']}.**",
        "",
        "This is one split of the sequences into fitted and held out. Whether a named effect holds on other splits "
        "is what `python -m gyrodenoise.discrepancy.splits` measures (each sequence held out in turn); an effect "
        "named on one split only is a property of that split's data, not of the sensor.",
        "",
    ]
    lines += _truth_caution(report)
    if report["named_effects"]:
        lines += [
            "## Named effects (datasheet units, +- one standard error)",
            "",
            "A sensor constant's standard errors are the regression's, multiplied by its held-out agreement where "
            "that exceeds 1: the constant refitted on the held-out sequences, the Birge ratio sqrt(chi2 / dof) of the "
            "two estimates' difference (`gyrodenoise.discrepancy.transfer`). The regression's alone were up to ~2 "
            "times too small on independent test data; scaled, they were near calibrated "
            "(benchmarks/results/discrepancy_se_calibration_from10.md). A small p there means the constant did not "
            "transfer: the held-out motion gives another value. With two or more fit sequences that each separate "
            "the constant, p is an F-test against their own spread (the regression's errors fall short by about the "
            "same factor on every sequence: against them alone a constant shared by every flight was called "
            "different); that spread has its own p against the halves of each sequence, and a small one means the "
            "fit sequences do not share one value.",
            "",
        ]
        lines += [
            "| effect | parameter | value | unit | delta BIC | threshold | null rank p | explained (fit) | "
            "closed (held-out) | held-out agreement |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for e in report["named_effects"]:
            first = True
            for k, d in e["datasheet"].items():
                if k.endswith("per_sequence"):
                    continue
                val = _fmt(d["value"])
                if "standard_error" in d:
                    val += " +- " + _fmt(d["standard_error"])
                cells = ["", "", "", "", "", ""]
                if first:
                    cells = [
                        f"{e['delta_bic']:.1f}" if e.get("delta_bic") is not None else "",
                        f"{e['threshold']:.1f}" if e.get("threshold") is not None else "",
                        f"{e['null_p_value']:.3f}" if e.get("null_p_value") is not None else "",
                        f"{100 * e['explained_fraction']:.2f}%" if e.get("explained_fraction") else "",
                        _closed(e),
                        _agreement(e.get("held_out_agreement")),
                    ]
                lines.append(
                    f"| {_label(e) if first else ''} | {k} | {val} | {d['unit']} | " + " | ".join(cells) + " |"
                )
                first = False
        lines += [
            "",
            "explained (fit): the share of the fit residual left at the step the effect was added that it removes "
            "(weighted residual sum of squares), so the shares of successive effects need not add up to 100%.",
        ]
        if any(e["name"] == "time_offset" for e in report["named_effects"]):
            lines.append(
                "time_offset delta > 0: the IMU stamps are late (the sample stamped t holds the motion of t - delta); "
                "< 0: early."
            )
        lines += _corner_se_words(report)
        lines.append("")
        lines += _raw_sample_evidence_md(report)
    else:
        lines += [f"{NO_EFFECT[0].upper() + NO_EFFECT[1:]}: no candidate clears the threshold.", ""]
    lines += _below_practical_md(report)
    lines += _instability_md(report)
    if report["not_identifiable"]:
        lines += [
            f"Not identifiable from this motion: {', '.join(report['not_identifiable'])} "
            "(the data cannot separate these effects from the others; they were not tested).",
            "",
        ]
    lines += _gyro_lines_md(report)
    lines += _lack_of_fit_md(report)
    lines += _reconstruction_md(report) + _truth_check_md(report)
    lines += _decisions_md(report) + _identifiability_md(report)
    gb, ga = report["gap_before"], report["gap_after"]
    lines += [
        "## Gap on held-out sequences",
        "",
        "| | base model | with named effects |",
        "|---|---|---|",
        f"| residual RMS (rad/s) | {gb['residual_rms_rad_s']:.5g} | {ga['residual_rms_rad_s']:.5g} |",
        f"| median 10-s drift, measured vs model gyro (deg) | {gb['drift_10s_median_deg']:.4g} | "
        f"{ga['drift_10s_median_deg']:.4g} |",
        f"| Allan-deviation gap, mean abs log10 ratio | {gb['allan_gap_log10']:.3f} | {ga['allan_gap_log10']:.3f} |",
    ]
    if "psd_gap_log10" in gb and "psd_gap_log10" in ga:
        lines.append(
            f"| spectral gap (1/3-octave PSD, >= 1 Hz), mean abs log10 ratio | {gb['psd_gap_log10']:.3f} | "
            f"{ga['psd_gap_log10']:.3f} |"
        )
    lines += [
        "",
        "Sensor constants come from the fit sequences; per-sequence nuisances (bias, random-walk knots, "
        "vibration phase) are refitted on each held-out sequence. Residual RMS and drift compare the measured "
        "gyro with the model's prediction; the Allan and spectral gaps compare measured with re-simulated "
        "residuals (the spectral gap after removing the deterministic prediction from both).",
        "",
        *_gap_words(gb, ga),
        *_simulator_model_md(report),
        *_band_words(report),
        "## Selection steps (greedy forward selection, BIC)",
        "",
    ]
    for s in report["selection_steps"]:
        if "removed" in s:
            corner = s.get("floor_corner_hz")
            shaped = f", the floor shaped by the {corner:.1f} Hz low-pass" if corner is not None else ""
            lines.append(
                f"- backward check: {s['removed']} removed (delta BIC {s['delta_bic_on_final_residual']:+.0f} on the "
                f"final residual{shaped})"
            )
            continue
        parts = []
        for c in s["candidates"][:5]:
            txt = f"{_label(c)} {c['delta_bic']:+.0f}"
            if c.get("other_variant"):
                txt += f" ({c['other_variant']['variant']} {c['other_variant']['delta_bic']:+.0f})"
            parts.append(txt)
        added = s.get("added", "stop") + (f" ({s['added_variant']})" if s.get("added_variant") else "")
        lines.append(f"- model [{', '.join(s['model'])}] -> {added}; best delta BIC: {', '.join(parts)}")
    # only the figures drawn (`report["plots"]`): a figure with nothing to draw (no drift window as long as the
    # recordings, no gap measured) is not written, and a link to it would be a broken image
    drawn = report.get("plots") or []
    links = [f"![{PLOT_ALT.get(n, n)}]({n}.png)" for n in PLOT_NAMES if f"{n}.png" in drawn]
    lines += ["", "## Plots", "", *([" ".join(links)] if links else ["(none drawn)"]), ""]
    if report.get("network"):
        lines += _network_md(report["network"])
    if report.get("command"):
        lines += ["## Command", "", "    " + report["command"], ""]
        if report.get("wall_time_s") is not None:
            code = f"; {report['code']}" if report.get("code") else ""
            lines += [f"Wall time {report['wall_time_s']:.0f} s ({report.get('machine', 'this machine')}{code}).", ""]
    return "\n".join(lines)


def write_report(out_dir: str | Path, report: dict, arrays: dict, make_plots: bool = True) -> Path:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if make_plots:
        report["plots"] = plots(out, arrays, report)
    write_json(out / "report.json", report)
    write_text(out / "report.md", markdown(report))
    return out
