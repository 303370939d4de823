"""The rest-bias estimate of round 6 (benchmarks/cv_rest_bias.py): it must find rest, recover a known bias there,
leave motion alone and use no future sample, or its "resolved worse" would say nothing about the idea."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from cv_rest_bias import RestDetector, remove_rest_bias, rest_bias, rest_periods  # noqa: E402

RATE = 200.0


def _flight(seed: int = 0, ramp: float = 0.05):
    """10 s at rest, then 20 s of rotation (periodic motion alone can fool the detector: its 1-s means
    can repeat a second apart, as a steady hover does); constant gyro bias b, white noise, gravity on z."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(30 * RATE)) / RATE
    rate = np.zeros((len(t), 3))
    moving = t >= 10
    rate[moving, 0] = 0.5 * np.sin(2 * np.pi * 0.3 * (t[moving] - 10))
    rate[moving, 1] = ramp * (t[moving] - 10)  # a ramp: 1-s means 1 s apart never coincide
    rate[moving, 2] = 0.3 * np.sin(2 * np.pi * 0.7 * (t[moving] - 10))
    bias = np.array([0.002, -0.001, 0.003])
    gyro = rate + bias + 0.002 * rng.standard_normal(rate.shape)
    acc = np.array([0.0, 0.0, 9.81]) + 0.02 * rng.standard_normal(rate.shape)
    acc[moving] += 2.0 * np.sin(2 * np.pi * 0.5 * t[moving])[:, None]
    return t, rate, bias, gyro, acc


def test_rest_is_found_and_its_bias_removed_without_touching_motion():
    t, rate, bias, gyro, acc = _flight()
    det = RestDetector()
    flags = det.flags(gyro, acc, RATE)
    assert not flags[: 2 * int(RATE) - 1].any()  # two windows of history first
    assert flags[(t > 2.5) & (t < 9.9)].all() and not flags[t > 11].any()
    (first, last), *_ = rest_periods(flags)
    assert t[first] < 2.1 and 9.9 < t[last] < 11
    out = remove_rest_bias(gyro, np.concatenate([gyro, acc], axis=1), RATE)
    held = gyro - out
    at_rest = np.searchsorted(t, 9.9)
    np.testing.assert_allclose(held[at_rest], bias, atol=2e-4)  # noise of a ~8 s mean: 0.002 / sqrt(1600)
    # The flags outlive rest by the time the motion takes to move a 1-s mean by the tolerance (0.1 s here),
    # and that motion enters the held estimate: the weakness round 6 met on real flights (settling, hover).
    assert 1e-4 < np.abs(held[-1] - bias).max() < 1e-3
    np.testing.assert_allclose(held[t > 12], np.broadcast_to(held[-1], held[t > 12].shape))  # held after rest
    assert np.all(held[: 2 * int(RATE) - 1] == 0)  # nothing known before the first rest


def test_periodic_motion_fools_the_detector():
    """The weakness reports/accuracy.md (round 6) names: 1-s means of a periodic motion repeat a second apart."""
    t, _, _, gyro, acc = _flight(ramp=0.0)
    flags = RestDetector().flags(gyro, acc, RATE)
    assert flags[t > 11].any()


def test_rest_bias_is_causal_and_equals_a_plain_loop():
    _, _, _, gyro, acc = _flight(1)
    det, w = RestDetector(), int(RATE)
    flags = det.flags(gyro, acc, RATE)
    flags[3000:3600] = True  # a second rest period replaces the first
    bias = rest_bias(gyro, flags, w)
    ref, start = np.zeros(3), None
    for n in range(len(gyro)):
        if flags[n]:
            if start is None:
                start = max(0, n - 2 * w + 1)
            ref = gyro[start : n + 1].mean(axis=0)
        else:
            start = None
        np.testing.assert_allclose(bias[n], ref, atol=1e-12)
    later = gyro.copy()
    later[4000:] += 1.0  # the future changes; the past estimate must not
    np.testing.assert_array_equal(rest_bias(later, flags, w)[:4000], bias[:4000])


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="imu must be"):
        remove_rest_bias(np.zeros((10, 3)), np.zeros((10, 3)), RATE)
    with pytest.raises(ValueError, match="non-finite values .first at row 4"):
        RestDetector().flags(
            np.where(np.arange(10)[:, None] == 4, np.nan, 0.0) * np.ones((10, 3)), np.zeros((10, 3)), RATE
        )
    with pytest.raises(ValueError, match="positive IMU rate"):
        RestDetector().window(0.0)
