"""Narrow lines in the raw gyro's spectrum above the band the ground truth can judge.

The comparison with the truth stops at the trusted band (`reconstruction`: behind a noisy motion capture, a few Hz),
so a vibration line above it (a rotor's, a mount's) is never compared with the simulator's model: a blind trial's
41 Hz line, 290-1190 times the gyro's noise floor, went unseen (benchmarks/results/blind_discrepancy.md). The gyro's
own spectrum shows such a line without any truth: power in a few bins far above the running median of the bins around
it. That says the measured gyro has a line, not whether it is motion or sensor error (above the band the truth cannot
tell); a simulator meant to reproduce this gyro misses it either way. Reported, not named against the truth.

A line in every fitted recording is a property of this sensor on this platform, motion or not: it goes into the
simulator's model as a band-limited vibration (`simulator_vibration`: its frequency, width and the fitted recordings'
mean RMS), and the held-out recordings say whether it transfers (`held_out_check`: the line's RMS measured there
against the same line read from a simulation with that effect, the gap before and after).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import welch

from gyrodenoise.sim.context import SignalContext
from gyrodenoise.sim.effects import Vibration, WhiteNoise

LINE_RATIO = 20.0  # a line: PSD at least this x the running median around it (white noise: ~1 +- 0.2 per bin)
NEIGHBOURS_HZ = 5.0  # the running median spans this either side of a bin (a line of a few bins does not move it)
SEGMENT_S = 4.0  # Welch segment: 0.25 Hz bins
MAIN_LOBE_BINS = 2  # a sinusoid flags ~3 bins of the Hann window over LINE_RATIO, a band ~2 bins more than its width
MIN_SEGMENTS = 8  # a stretch shorter than this many segments (half overlap) gives no spectrum worth reading
MERGE_HZ = 2.0  # lines of different stretches this close are one line (a band-limited line wanders ~1 Hz)
BAND_TOP = 0.495  # x the fitted rate: where a modelled band stops, 0.5 % of the rate under the Nyquist frequency


def stretch_lines(gyro: np.ndarray, rate_hz: float, above_hz: float, ratio: float = LINE_RATIO) -> list[dict]:
    """Lines above `above_hz` in one stretch of gyro (N, 3): each run of adjacent bins over `ratio` x the running
    median on any axis, with its peak frequency, its peak ratio per axis and its RMS per axis (rad/s, the power above
    the median summed over the run)."""
    nper = int(round(SEGMENT_S * rate_hz))
    if len(gyro) < nper * (MIN_SEGMENTS + 1) // 2:
        return []
    f, p = welch(gyro - gyro.mean(0), fs=rate_hz, nperseg=nper, axis=0)
    df = f[1] - f[0]
    floor = median_filter(p, size=(2 * int(NEIGHBOURS_HZ / df) + 1, 1), mode="nearest")
    r = p / np.maximum(floor, 1e-300)
    # above the band, below the last neighbourhood (its median would lean on the bins beyond Nyquist's edge)
    usable = (f > above_hz) & (f < f[-1] - NEIGHBOURS_HZ)
    flagged = usable & (r > ratio).any(axis=1)
    lines = []
    k = 0
    while k < len(f):
        if not flagged[k]:
            k += 1
            continue
        end = k
        while end + 1 < len(f) and flagged[end + 1]:
            end += 1
        run = slice(k, end + 1)
        peak = k + int(np.argmax(r[run].max(axis=1)))
        lines.append(
            {
                "frequency_hz": float(f[peak]),
                "width_hz": float((end - k + 1) * df),
                "ratio": r[run].max(axis=0).tolist(),
                "rms_rad_s": np.sqrt(np.clip(p[run] - floor[run], 0.0, None).sum(axis=0) * df).tolist(),
            }
        )
        k = end + 1
    return lines


def gyro_lines(fcs: list, ratio: float = LINE_RATIO) -> list[dict]:
    """Lines of the raw gyro above each stretch's compared band (`fc.extra['band_hz']`; a stretch compared over the
    whole spectrum has none to report), merged over stretches: frequency (the strongest stretch's), the recordings it
    is in, the largest ratio and RMS per axis. Sorted by frequency."""
    found: list[dict] = []
    for fc in fcs:
        band = fc.extra.get("band_hz")
        if band is None or band >= fc.rate_hz / 2:
            continue
        for line in stretch_lines(np.asarray(fc.gyro), fc.rate_hz, float(band), ratio):
            line["recording"] = fc.extra.get("sequence", fc.name)
            line["stretch"] = fc.name
            found.append(line)
    merged: list[dict] = []
    for line in sorted(found, key=lambda x: -max(x["ratio"])):
        same = next((m for m in merged if abs(m["frequency_hz"] - line["frequency_hz"]) <= MERGE_HZ), None)
        if same is None:
            merged.append(
                {
                    "frequency_hz": line["frequency_hz"],
                    "recordings": [line["recording"]],
                    "ratio": line["ratio"],
                    "rms_rad_s": line["rms_rad_s"],
                    "width_hz": line["width_hz"],
                    "per_stretch": {line["stretch"]: line["rms_rad_s"]},
                }
            )
            continue
        if line["recording"] not in same["recordings"]:
            same["recordings"].append(line["recording"])
        same["ratio"] = np.maximum(same["ratio"], line["ratio"]).tolist()
        same["rms_rad_s"] = np.maximum(same["rms_rad_s"], line["rms_rad_s"]).tolist()
        same["width_hz"] = max(same["width_hz"], line["width_hz"])
        same["per_stretch"].setdefault(line["stretch"], line["rms_rad_s"])  # a stretch's strongest line (sorted)
    return sorted(({**m, "recordings": sorted(m["recordings"])} for m in merged), key=lambda m: m["frequency_hz"])


def simulator_vibration(line: dict, fit: list) -> dict | None:
    """The band-limited vibration (`sim.effects.Vibration`, SI) a simulator needs to reproduce `line` (from
    `gyro_lines`): None unless the line is in every fitted stretch. Amplitude A = sqrt(2) x the fitted stretches'
    mean RMS per axis (the effect's band RMS is A / sqrt(2)); width: the line's flagged bins less the Hann window's
    own spread (MAIN_LOBE_BINS), so that simulating the model and reading it again gives the same width (it grew by
    0.5 Hz a round); a line no wider than one bin after that is a sinusoid (width 0). The band stops at BAND_TOP x
    the fitted recordings' rate, under the Nyquist frequency (the simulator refuses a band past it:
    `Vibration.rate_problem`) by a margin for recordings and simulations a little slower (measured rates differ in
    the 5th digit, and the model is simulated at the nominal one); a line above that is a sinusoid, and one at the
    Nyquist frequency gets no model."""
    names = [fc.name for fc in fit]
    if not names or any(n not in line["per_stretch"] for n in names):
        return None
    rms = np.mean([line["per_stretch"][n] for n in names], axis=0)
    df = 1.0 / SEGMENT_S
    f, rate = float(line["frequency_hz"]), min(float(fc.rate_hz) for fc in fit)
    if f >= rate / 2:
        return None
    width = line["width_hz"] - MAIN_LOBE_BINS * df
    if f < BAND_TOP * rate:  # the band kept centred on the line: both its edges move in
        width = min(width, 2 * (BAND_TOP * rate - f))
    else:  # a line this close to the Nyquist frequency: a sinusoid
        width = 0.0
    return {"frequency_hz": f, "amplitude": (np.sqrt(2.0) * rms).tolist(), "bandwidth_hz": width if width > df else 0.0}


def held_out_check(line: dict, params: dict, holdout: list, noise_density: np.ndarray, seed: int = 0) -> dict:
    """The line on the held-out stretches: its RMS there (measured), and the same line read the same way from a
    simulated gyro of each stretch's length (white noise of the fitted density, plus the vibration `params`):
    the spectral gap at the line, |log10(measured power / simulated power)| summed over the line's bins, before
    (the model without the line) and after. A stretch without the line counts as measured RMS 0."""
    rows = []
    for s, fc in enumerate(holdout):
        n, rate = len(fc.t), fc.rate_hz
        sig = SignalContext(t=np.arange(n) / rate, omega=np.zeros((n, 3)), alpha=None, f=None, rate_hz=rate)
        rng = np.random.default_rng([seed, s])
        noise = WhiteNoise(density=np.asarray(noise_density)).apply(sig, np.zeros((n, 3)), rng)
        with_line = Vibration(**{k: np.asarray(v) for k, v in params.items()}).apply(sig, noise, rng)
        band = fc.extra.get("band_hz") or rate / 2
        measured = _line_power(np.asarray(fc.gyro), rate, line)
        before = _log_gap(measured, _line_power(noise, rate, line))
        after = _log_gap(measured, _line_power(with_line, rate, line))
        rows.append(
            {
                "stretch": fc.name,
                "measured_rms_rad_s": line["per_stretch"].get(fc.name, [0.0, 0.0, 0.0]),  # read by `gyro_lines`
                "simulated_rms_rad_s": _line_rms(with_line, rate, band, line["frequency_hz"]),
                "gap_before_log10": before,
                "gap_after_log10": after,
            }
        )
    return {"stretches": rows}


def _line_rms(gyro: np.ndarray, rate_hz: float, above_hz: float, frequency_hz: float) -> list[float]:
    """RMS per axis of the line of `gyro` nearest `frequency_hz` (within MERGE_HZ), zeros if none is flagged."""
    found = [m for m in stretch_lines(gyro, rate_hz, above_hz) if abs(m["frequency_hz"] - frequency_hz) <= MERGE_HZ]
    if not found:
        return [0.0, 0.0, 0.0]
    return min(found, key=lambda m: abs(m["frequency_hz"] - frequency_hz))["rms_rad_s"]


def _line_power(x: np.ndarray, rate_hz: float, line: dict) -> np.ndarray:
    """(3,) power of x (N, 3) in the line's bins (its width about its frequency), Welch as `stretch_lines`."""
    f, p = welch(x - x.mean(0), fs=rate_hz, nperseg=int(round(SEGMENT_S * rate_hz)), axis=0)
    half = max(line["width_hz"], 2.0 / SEGMENT_S) / 2
    return p[np.abs(f - line["frequency_hz"]) <= half].sum(0)


def _log_gap(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Mean over axes of |log10| of the measured over the simulated power at a line: the spectral gap there, 0 when
    the simulation holds the line's power."""
    return float(np.mean(np.abs(np.log10(measured / np.maximum(simulated, 1e-300)))))


def add_lines_to_model(report: dict, fit: list, holdout: list, seed: int = 0) -> None:
    """Each line of `report['gyro_lines_above_band']` that is in every fitted stretch gets the vibration a simulator
    needs (`simulator_vibration`, written into error_model.yaml by `sim_model`) and its held-out check."""
    density = (report.get("base_params") or {}).get("white_noise", {}).get("density")
    for line in report.get("gyro_lines_above_band") or []:
        params = simulator_vibration(line, fit)
        if params is None:
            continue
        line["simulator_vibration"] = params
        if holdout and density is not None:
            line["held_out"] = held_out_check(line, params, holdout, np.asarray(density, dtype=float), seed)


def compared_band_hz(fcs: list) -> float | None:
    """The widest band compared with the truth over the stretches (None: the whole spectrum in every stretch)."""
    bands = [fc.extra.get("band_hz") for fc in fcs]
    return None if any(b is None for b in bands) or not bands else float(max(bands))


def sentence(lines: list[dict], compared_hz: float | None) -> str | None:
    """One sentence for the verdict's neighbourhood (None: no line)."""
    if not lines:
        return None
    listed = ", ".join(
        f"{m['frequency_hz']:.1f} Hz ({max(m['ratio']):.0f}x the floor, in {len(m['recordings'])} recording"
        f"{'s' if len(m['recordings']) > 1 else ''})"
        for m in lines[:5]
    )
    more = f" and {len(lines) - 5} more" if len(lines) > 5 else ""
    band = f" (compared up to {compared_hz:.1f} Hz)" if compared_hz is not None else ""
    added = [m for m in lines if m.get("simulator_vibration")]
    if added:
        what = "in every fitted recording, added to the simulator's model as band-limited vibration: " + ", ".join(
            f"{m['frequency_hz']:.1f} Hz" for m in added
        )
    else:
        what = "none in every fitted recording: a simulator of this model will not reproduce this gyro there"
    head = f"lines in the raw gyro above the band the truth can judge{band}: {listed}{more}"
    return f"{head}; not judged by the truth, {what}"
