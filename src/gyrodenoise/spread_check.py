"""Is a recording like the data an ensemble learned? Its members' disagreement as a check on the input.

The members of an ensemble agree where they were trained and disagree on many inputs unlike their training data
(another IMU, a gyro in other units, a turned mounting), though not on all. An ensemble file carries a reference, the
median over samples of the norm of its members' per-sample std on each of its training recordings (whole), and
the largest of those is the figure a new recording is compared with. `correct` and `evaluate` warn when a
recording's median spread is more than SPREAD_RATIO_LIMIT times that reference.

The limit comes from `python benchmarks/spread_ood.py` (benchmarks/results/spread_ood.md): the shipped `euroc`
ensemble's unseen EuRoC test flights sit at 0.6-1.1 times its reference, TUM-VI's BMI160 (another IMU, real
data this project did not make) at ~39 times, a gyro in deg/s at 45-115 and a mounting turned 90 deg at 14-15. It
does not see an accelerometer in g (2.2-2.5; its worst 10-s stretch 2.3-3.1 fires on 1 of 5 flights; the data
checks of `correct` refuse that), a halved rate (0.9-1.6) or another gyro bias (unchanged): a quiet spread is no
proof that a recording suits the model.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from gyrodenoise.models.ensemble import CorrectionModel, EnsembleCorrection, predict_with_spread

SPREAD_RATIO_LIMIT = 3.0
WINDOW_S = 10.0  # the stretch `worst_window` judges too
STATISTIC = "median over samples of ||members' std|| (rad/s), members' raw std (no spread_scale), whole recordings"


def median_spread(std: np.ndarray) -> float:
    """Median over samples of the norm (rad/s) of a per-sample std (N, 3)."""
    return float(np.median(np.linalg.norm(std, axis=1)))


def spread_reference(model: CorrectionModel, recordings: Iterable[tuple[str, np.ndarray]]) -> dict:
    """The reference an ensemble file records (metadata key `spread_reference`) from its training recordings,
    (name, (N, 6) raw IMU) pairs."""
    if not isinstance(model, EnsembleCorrection) or len(model) < 2:
        raise TypeError("only an ensemble of two or more members has a spread to take a reference of")
    per = {name: median_spread(predict_with_spread(model, imu)[1]) / model.spread_scale for name, imu in recordings}
    if not per:
        raise ValueError("no recordings to take the spread reference on")
    return {"per_recording_rad_s": per, "reference_rad_s": max(per.values()), "statistic": STATISTIC}


def _reference(meta: dict) -> tuple[float, float] | None:
    """(the file's spread reference in rad/s, its spread_scale), or None when it records no reference."""
    ref = (meta.get("spread_reference") or {}).get("reference_rad_s")
    return (ref, float((meta.get("model") or {}).get("spread_scale", 1.0))) if ref else None


def spread_ratio(std: np.ndarray | None, meta: dict) -> float | None:
    """A recording's median spread over the ensemble's reference, or None (a single model, or a file without a
    reference: `python -m gyrodenoise.ensemble reference` adds one)."""
    if std is None or (found := _reference(meta)) is None:
        return None
    ref, scale = found
    return median_spread(std) / scale / ref


def worst_window(std: np.ndarray | None, meta: dict, rate_hz: float) -> tuple[float, float] | None:
    """(ratio, start in s since the first sample) of the WINDOW_S stretch whose median spread is the largest against
    the reference (windows overlapping by half), or None (no std or no reference). The whole recording's median
    misses a bad stretch shorter than about half of it (an audit's 20 s of deg/s in a 2-min flight: 0.69 whole,
    63.8 in its window); on EuRoC's 11 flights the largest window is 0.73-1.59 (benchmarks/results/spread_ood.md)."""
    if std is None or (found := _reference(meta)) is None or not np.isfinite(rate_hz) or rate_hz <= 0:
        return None
    ref, scale = found
    norm = np.linalg.norm(std, axis=1) / scale / ref
    n = max(int(round(WINDOW_S * rate_hz)), 1)
    if len(norm) <= n:
        return float(np.median(norm)), 0.0
    starts = [*range(0, len(norm) - n + 1, max(n // 2, 1)), len(norm) - n]  # the last window ends at the end
    ratio, start = max((float(np.median(norm[i : i + n])), i) for i in starts)
    return ratio, start / rate_hz


def spread_warning(ratio: float | None, what: str, meta: dict, window: tuple[float, float] | None = None) -> str | None:
    """The warning for a recording `what` whose spread ratio, or that of its worst stretch (`window`, from
    `worst_window`), is above the limit, else None."""
    whole = ratio is not None and ratio > SPREAD_RATIO_LIMIT
    part = window is not None and window[0] > SPREAD_RATIO_LIMIT
    if not (whole or part):
        return None
    ref_deg = np.degrees(meta["spread_reference"]["reference_rad_s"])
    r, where = (
        (ratio, "") if whole else (window[0], f" from {window[1]:.1f} s to {window[1] + WINDOW_S:.1f} s (its worst "
                                              f"{WINDOW_S:g}-s stretch; the whole recording: {ratio:.2f})")
    )  # fmt: skip
    return (
        f"{what}: the members of {meta.get('name', 'this ensemble')} disagree {r:.1f} times more than on their "
        f"own training recordings{where} (median spread {r * ref_deg:.3f} vs {ref_deg:.3f} deg/s; the check warns "
        f"above {SPREAD_RATIO_LIMIT:g}): the recording is unlike the data the model learned (another IMU, a gyro in "
        "other units, another mounting), so its correction is not to be trusted. Check the units; for "
        "another IMU, fit a calibrated model (python -m gyrodenoise.fit_calibrated) or train on its own data."
    )


def no_reference_note(meta: dict) -> str:
    """What a user of an ensemble without a spread reference is told: the check above is off."""
    return (
        f"{meta.get('name', 'this ensemble')} records no spread reference, so whether the recording is like its "
        "training data is not checked by the spread: add one with python -m gyrodenoise.ensemble reference FILE"
    )
