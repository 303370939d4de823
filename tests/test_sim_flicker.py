"""Bias instability (`gyrodenoise.sim.flicker`, the gyro's `bias_instability`): the Allan deviation's flat floor at
the datasheet's value, checked in closed form and on simulations with our own overlapping Allan deviation."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.allan import allan_variance
from gyrodenoise.sim import build_effect, constant_rate_trajectory, effect_from_config, simulate_imu
from gyrodenoise.sim.context import SignalContext
from gyrodenoise.sim.effects import DEG, EFFECTS, SIM_EFFECTS
from gyrodenoise.sim.flicker import IEEE_FLOOR_PER_B, allan_deviation, psd

DEG_H = DEG / 3600.0  # rad/s


@pytest.mark.parametrize(("tau_min", "tau_max"), [(1.0, 1000.0), (0.1, 10.0), (5.0, 50.0), (0.01, 1e5)])
def test_the_closed_form_floor_is_flat_and_a_flicker_spectrum(tau_min, tau_max):
    """Flat within 1 % between tau_min and tau_max; in the band the PSD is IEEE Std 952's B^2 / (2 pi f), B the
    floor / 0.664, within 3 %."""
    taus = np.geomspace(tau_min, tau_max, 200)
    assert np.allclose(allan_deviation(taus, 2.0, tau_min, tau_max), 2.0, rtol=0.01)
    f = np.geomspace(1 / (2 * np.pi * tau_max), 1 / (2 * np.pi * tau_min), 50)
    b = 2.0 / IEEE_FLOOR_PER_B
    assert np.allclose(psd(f, 2.0, tau_min, tau_max) / (b**2 / (2 * np.pi * f)), 1.0, atol=0.03)
    # beyond the band it falls off, as a datasheet's plot does where white noise or the random walk takes over
    assert allan_deviation(np.array([tau_min / 1000, tau_max * 1000]), 2.0, tau_min, tau_max).max() < 0.5


def test_bias_instability_has_its_allan_floor():
    """20000 s at 10 Hz: the pooled Allan deviation within 10 % of each axis's floor from 1 to 100 s (over 100
    fresh draws the largest error over the band: median 3 %, 99th percentile 6 %)."""
    floor_deg_h = np.array([5.0, 14.5, 30.0])
    e = effect_from_config(
        {"name": "bias_instability", "units": "datasheet",
         "params": {"instability": floor_deg_h.tolist(), "tau_min": 1.0, "tau_max": 100.0}}
    )  # fmt: skip
    assert np.allclose(e.params["instability"], floor_deg_h * DEG_H)
    rate, n = 10.0, 200_000
    t = np.arange(n) / rate
    z = np.zeros((n, 3))
    x = e.apply(SignalContext(t, z, z, z, rate), z, np.random.default_rng(0))
    taus = np.geomspace(1.0, 100.0, 9)
    adev = np.sqrt(allan_variance(x / e.params["instability"], rate, taus).mean(1))
    assert np.allclose(adev, 1.0, rtol=0.10), adev


def test_the_simulator_carries_it():
    """Through simulate_imu (internal rate 200 Hz, output 100 Hz): the floor where the output resolves it."""
    traj = constant_rate_trajectory(302.0)
    kw = {"rate_hz": 100.0, "oversample": 2, "seed": 2}
    floor = 10.0 * DEG_H
    plain = simulate_imu(traj, [], **kw)
    sim = simulate_imu(traj, [build_effect("bias_instability", instability=floor, tau_min=0.1, tau_max=10.0)], **kw)
    taus = np.geomspace(0.2, 3.0, 6)
    adev = np.sqrt(allan_variance(sim.gyro - plain.gyro, 100.0, taus).mean(1))
    assert np.allclose(adev, floor, rtol=0.15), adev / floor


def test_it_is_simulated_only():
    """No detector: the discrepancy workflow refuses it as unknown instead of leaving it out without a word."""
    assert "bias_instability" in SIM_EFFECTS and "bias_instability" not in EFFECTS


@pytest.mark.parametrize(
    ("params", "said"),
    [
        ({"instability": -1.0, "tau_min": 1.0, "tau_max": 10.0}, r"instability = -1.0 \(deg/h\) must not be negative"),
        ({"instability": 1.0, "tau_min": 10.0, "tau_max": 10.0}, "tau_max = 10 must be above params.tau_min = 10"),
        ({"instability": 1.0, "tau_min": 0.0, "tau_max": 10.0}, "tau_min = 0.0 .* must be above 0"),
        ({"instability": 1.0, "tau_min": 1e-6, "tau_max": 1e6}, "spans more than"),
        ({"instability": 1.0, "tau_min": 1.0}, r"missing \['tau_max'\]"),
    ],
)
def test_bias_instability_settings_no_sensor_has_are_named(params, said):
    with pytest.raises(ValueError, match=said):
        effect_from_config({"name": "bias_instability", "units": "datasheet", "params": params})
