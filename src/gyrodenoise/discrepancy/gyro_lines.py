"""Narrow lines in the raw gyro's spectrum above the band the ground truth can judge.

The comparison with the truth stops at the trusted band (`reconstruction`: behind a noisy motion capture, a few Hz),
so a vibration line above it (a rotor's, a mount's) is never compared with the simulator's model: a blind trial's
41 Hz line, 290-1190 times the gyro's noise floor, went unseen (benchmarks/results/blind_discrepancy.md). The gyro's
own spectrum shows such a line without any truth: power in a few bins far above the running median of the bins around
it. That says the measured gyro has a line, not whether it is motion or sensor error (above the band the truth cannot
tell); a simulator meant to reproduce this gyro misses it either way. Reported, not named: no effect is fitted.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import welch

LINE_RATIO = 20.0  # a line: PSD at least this x the running median around it (white noise: ~1 +- 0.2 per bin)
NEIGHBOURS_HZ = 5.0  # the running median spans this either side of a bin (a line of a few bins does not move it)
SEGMENT_S = 4.0  # Welch segment: 0.25 Hz bins
MIN_SEGMENTS = 8  # a stretch shorter than this many segments (half overlap) gives no spectrum worth reading
MERGE_HZ = 2.0  # lines of different stretches this close are one line (a band-limited line wanders ~1 Hz)


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
                }
            )
            continue
        if line["recording"] not in same["recordings"]:
            same["recordings"].append(line["recording"])
        same["ratio"] = np.maximum(same["ratio"], line["ratio"]).tolist()
        same["rms_rad_s"] = np.maximum(same["rms_rad_s"], line["rms_rad_s"]).tolist()
    return sorted(({**m, "recordings": sorted(m["recordings"])} for m in merged), key=lambda m: m["frequency_hz"])


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
    return (
        f"lines in the raw gyro above the band the truth can judge{band}: {listed}{more}; not compared with the "
        "model: a simulator without them will not reproduce this gyro there"
    )
