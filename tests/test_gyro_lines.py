"""Lines in the raw gyro above the band the truth can judge (gyrodenoise.discrepancy.gyro_lines): found from the
gyro's own spectrum, nothing on white noise and smooth motion, nothing where the whole spectrum is compared."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gyrodenoise.discrepancy.gyro_lines import gyro_lines, sentence, stretch_lines

RATE = 200.0


def _gyro(seconds: float, seed: int, line_hz: float | None = None, amp: float = 0.01) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE)) / RATE
    motion = np.stack(
        [np.sin(2 * np.pi * f * t + p) for f, p in zip(rng.uniform(0.1, 2, 3), rng.uniform(0, 6, 3), strict=True)], 1
    )
    g = 0.8 * motion + 2e-4 * np.sqrt(RATE / 2) * rng.standard_normal((len(t), 3))  # 2e-4 rad/s/sqrt(Hz)
    if line_hz is not None:  # a line that wanders by +-0.5 Hz, as a rotor's does
        phase = 2 * np.pi * np.cumsum(line_hz + 0.5 * np.sin(2 * np.pi * 0.05 * t)) / RATE
        g += amp * np.sin(phase)[:, None] * np.array([1.0, 0.5, 0.8])
    return g


def _stretch(gyro: np.ndarray, band_hz: float | None, recording: str) -> SimpleNamespace:
    return SimpleNamespace(gyro=gyro, rate_hz=RATE, name=recording, extra={"band_hz": band_hz, "sequence": recording})


def test_a_line_above_the_band_is_found_with_its_frequency_and_size():
    (line,) = stretch_lines(_gyro(60, 1, line_hz=41.0), RATE, above_hz=8.0)
    assert abs(line["frequency_hz"] - 41.0) < 1.0 and min(line["ratio"]) > 20
    # RMS of the line: amp / sqrt(2) per unit of the axis weights
    assert np.allclose(line["rms_rad_s"], 0.01 / np.sqrt(2) * np.array([1.0, 0.5, 0.8]), rtol=0.2)
    assert stretch_lines(_gyro(60, 1, line_hz=41.0), RATE, above_hz=45.0) == []  # inside the band: the truth's


def test_white_noise_and_smooth_motion_give_no_line():
    assert all(stretch_lines(_gyro(60, seed), RATE, above_hz=3.0) == [] for seed in range(10))


def test_lines_are_merged_over_recordings_and_a_wholly_compared_stretch_reports_none():
    fcs = [
        _stretch(_gyro(60, 2, line_hz=40.5), 8.0, "seq00"),
        _stretch(_gyro(60, 3, line_hz=41.5), 9.0, "seq01"),
        _stretch(_gyro(60, 4, line_hz=70.0), None, "seq02"),  # compared over the whole spectrum: not reported
        _stretch(_gyro(10, 5, line_hz=70.0), 8.0, "short"),  # too short for a spectrum worth reading
    ]
    (line,) = gyro_lines(fcs)
    assert line["recordings"] == ["seq00", "seq01"]
    said = sentence([line], 9.0)
    assert said is not None and "(compared up to 9.0 Hz)" in said and "in 2 recordings" in said
    assert sentence([], 9.0) is None


@pytest.mark.parametrize("amp", [0.0005, 0.002])
def test_a_weak_line_is_found_only_when_it_stands_out(amp):
    """The threshold is a ratio to the floor: a 0.002 rad/s line stands out of this noise, one of 0.0005 (16 times
    less power) does not."""
    found = stretch_lines(_gyro(60, 6, line_hz=55.0, amp=amp), RATE, above_hz=8.0)
    assert bool(found) == (amp > 0.001)
