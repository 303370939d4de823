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


WHITE = {"white_noise": {"density": [2e-4] * 3}}


def _fit_and_holdout(line_in_second_fit: bool = True):
    fit = [
        _stretch(_gyro(60, 7, line_hz=41.0), 8.0, "seq00"),
        _stretch(_gyro(60, 8, line_hz=41.0 if line_in_second_fit else None), 8.0, "seq01"),
    ]
    holdout = [_stretch(_gyro(60, 9, line_hz=41.0), 8.0, "seq02")]
    for fc in fit + holdout:
        fc.t = np.arange(len(fc.gyro)) / RATE
    return fit, holdout


def test_a_line_in_every_fitted_recording_goes_into_the_simulator_model_and_transfers():
    """Its vibration reproduces the held-out line: the same RMS read back from a simulation, and the spectral gap at
    the line closes (from ~2 decades without it)."""
    from gyrodenoise.discrepancy.gyro_lines import add_lines_to_model
    from gyrodenoise.discrepancy.sim_model import simulator_model
    from gyrodenoise.sim.effects import effect_from_config

    fit, holdout = _fit_and_holdout()
    report = {"gyro_lines_above_band": gyro_lines(fit + holdout), "base_params": WHITE}
    add_lines_to_model(report, fit, holdout)
    (line,) = report["gyro_lines_above_band"]
    sim = line["simulator_vibration"]
    assert abs(sim["frequency_hz"] - 41.0) < 1.0 and sim["bandwidth_hz"] >= 0.5
    # amplitude: sqrt(2) x the band RMS, here the drawn line's peak amplitude per axis
    assert np.allclose(sim["amplitude"], 0.01 * np.array([1.0, 0.5, 0.8]), rtol=0.2)
    (held,) = line["held_out"]["stretches"]
    assert np.allclose(held["simulated_rms_rad_s"], held["measured_rms_rad_s"], rtol=0.15)
    assert held["gap_before_log10"] > 1.5 and held["gap_after_log10"] < 0.3
    (entry,) = [e for e in simulator_model(report)["error_model"] if e["name"] == "vibration"]
    assert float(effect_from_config(entry).params["frequency_hz"]) == pytest.approx(sim["frequency_hz"])
    assert "added to the simulator's model as band-limited vibration: 41" in sentence([line], 8.0)


def test_a_line_missing_from_a_fitted_recording_stays_out_of_the_model():
    from gyrodenoise.discrepancy.gyro_lines import add_lines_to_model

    fit, holdout = _fit_and_holdout(line_in_second_fit=False)
    report = {"gyro_lines_above_band": gyro_lines(fit + holdout), "base_params": WHITE}
    add_lines_to_model(report, fit, holdout)
    (line,) = report["gyro_lines_above_band"]
    assert "simulator_vibration" not in line and "held_out" not in line
    assert "none in every fitted recording" in sentence([line], 8.0)


@pytest.mark.parametrize("width", [0.0, 1.0, 2.0])
def test_the_written_width_is_a_fixed_point(width):
    """A line simulated with the width the model writes is read back with that width (it grew by 0.5 Hz each round
    of measure, write, simulate: the Hann window's own spread; a sinusoid came back as a 0.75 Hz band)."""
    from gyrodenoise.discrepancy.gyro_lines import simulator_vibration
    from gyrodenoise.sim.context import SignalContext
    from gyrodenoise.sim.effects import Vibration, WhiteNoise

    n = int(120 * RATE)
    sig = SignalContext(t=np.arange(n) / RATE, omega=np.zeros((n, 3)), alpha=None, f=None, rate_hz=RATE)
    rng = np.random.default_rng(5)
    g = WhiteNoise(density=np.full(3, 2e-4)).apply(sig, np.zeros((n, 3)), rng)
    g = Vibration(frequency_hz=60.0, amplitude=np.full(3, 0.005), bandwidth_hz=width).apply(sig, g, rng)
    fc = SimpleNamespace(gyro=g, rate_hz=RATE, name="s", extra={"band_hz": 8.0, "sequence": "s"})
    (line,) = gyro_lines([fc])
    written = simulator_vibration(line, [fc])["bandwidth_hz"]
    assert written == pytest.approx(width, abs=0.26)


def test_a_wide_line_near_nyquist_gets_a_band_the_simulator_accepts():
    """A line wider than its distance to the Nyquist frequency: the model's band stops there (the simulator refuses a
    band past it, at every oversampling), and the held-out check runs; a line at the Nyquist frequency gets none."""
    from gyrodenoise.discrepancy.gyro_lines import add_lines_to_model, simulator_vibration

    fit, holdout = _fit_and_holdout()
    report = {"gyro_lines_above_band": gyro_lines(fit + holdout), "base_params": WHITE}
    (line,) = report["gyro_lines_above_band"]
    near = {**line, "frequency_hz": 0.495 * RATE - 2.0, "width_hz": 12.0}
    report["gyro_lines_above_band"] = [near]
    add_lines_to_model(report, fit, holdout)  # raised ValueError from the simulator's Nyquist check
    sim = near["simulator_vibration"]
    assert sim["frequency_hz"] + sim["bandwidth_hz"] / 2 == pytest.approx(0.495 * RATE)
    assert simulator_vibration({**line, "frequency_hz": 0.5 * RATE}, fit) is None
    assert simulator_vibration({**line, "frequency_hz": 0.497 * RATE, "width_hz": 12.0}, fit)["bandwidth_hz"] == 0
    # under the cap a band keeps its own width (a 0.48 cap made a 3-Hz band at 0.4875 x the rate a sinusoid)
    kept = simulator_vibration({**line, "frequency_hz": 0.4875 * RATE, "width_hz": 2.0}, fit)["bandwidth_hz"]
    assert kept == pytest.approx(2.0 - 2 * 0.25)
    # the model is simulated at the nominal rate, a little under the measured one (review 63: refused at 200 Hz)
    from gyrodenoise.sim.effects import Vibration

    assert Vibration.rate_problem(sim["frequency_hz"], sim["bandwidth_hz"], RATE * (1 - 1e-3)) is None
