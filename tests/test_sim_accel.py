"""The accelerometer's error effects (`gyrodenoise.sim.accel`): what the simulator's output carries, checked with
statistics of our own (overlapping Allan variance, least squares), and one line for what no sensor has."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.allan import allan_variance
from gyrodenoise.sim import build_effect, drone_trajectory, noise_model, simulate_imu
from gyrodenoise.sim.accel import MG, acc_effects_from_config, build_acc_effect
from gyrodenoise.sim.context import SignalContext
from gyrodenoise.sim.dataset import generate_sequence, generation_key

SCALE_PPM = [2000.0, -1500.0, 1000.0]
ANGLES_MRAD = [2.0, -1.0, 1.0, 3.0, -2.0, 1.5]


@pytest.fixture(scope="module")
def traj():
    return drone_trajectory(14.0, 3)  # varied specific force on every axis


def test_scale_and_misalignment_are_recovered_exactly_from_a_noise_free_simulation(traj):
    """a = (I + diag(s) + M) f: a least-squares fit of the output against the same simulation without them returns
    the datasheet's ppm and mrad to rounding; the gyro, white noise and random walk included, is untouched."""
    entries = [
        {"name": "scale_factor", "units": "datasheet", "params": {"scale": SCALE_PPM}},
        {"name": "misalignment", "units": "datasheet", "params": {"angles": ANGLES_MRAD}},
    ]
    gyro_model = noise_model("ADIS16448")
    kw = {"duration_s": 10, "acc_noise_density": 0.0, "oversample": 4, "seed": 5}
    plain = simulate_imu(traj, gyro_model, **kw)
    sim = simulate_imu(traj, gyro_model, acc_effects=acc_effects_from_config(entries, "acc"), **kw)
    assert np.array_equal(sim.gyro, plain.gyro)
    c, *_ = np.linalg.lstsq(plain.acc, sim.acc, rcond=None)
    c = c.T - np.eye(3)  # sim.acc = plain.acc @ (I + S + M)^T
    assert np.allclose(np.diag(c) * 1e6, SCALE_PPM, atol=1e-6)
    pairs = [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]
    assert np.allclose([c[i, j] * 1e3 for i, j in pairs], ANGLES_MRAD, atol=1e-9)
    assert sim.meta["acc_effects"][0]["name"] in ("scale_factor", "misalignment")


def test_bias_random_walk_has_the_allan_deviation_of_its_density(traj):
    """A random walk of density K has the Allan deviation K sqrt(tau / 3): slope 1/2 on a log-log plot. Given in
    the datasheet's mg/sqrt(h) (the bias's spread after one hour)."""
    k_mg = 20.0  # mg/sqrt(h)
    k = k_mg * MG / 60.0  # m/s^2/sqrt(s)
    entry = {"name": "bias_random_walk", "units": "datasheet", "params": {"density": [k_mg] * 3}}
    (rw,) = acc_effects_from_config([entry], "acc")
    assert np.allclose(rw.params["density"], k)
    long = drone_trajectory(202.0, 4)
    kw = {"rate_hz": 100.0, "oversample": 2, "acc_noise_density": 0.0, "seed": 11}
    d = simulate_imu(long, [], acc_effects=[rw], **kw).acc - simulate_imu(long, [], **kw).acc
    taus = np.geomspace(0.2, 10.0, 12)
    av = allan_variance(d, 100.0, taus).mean(1)  # pooled over the axes
    slope = np.polyfit(np.log(taus), 0.5 * np.log(av), 1)[0]
    level = np.sqrt(np.mean(av / (taus / 3)))
    # over 200 fresh draws: slope 0.497 +- 0.024, level 1.007 +- 0.035 K
    assert slope == pytest.approx(0.5, abs=0.08)
    assert level == pytest.approx(k, rel=0.12)


def test_bias_instability_has_its_allan_floor_in_mg():
    """The datasheet's in-run bias stability (mg) is the Allan floor from tau_min to tau_max (the gyro's flicker
    bank: tests/test_sim_flicker.py)."""
    entry = {"name": "bias_instability", "units": "datasheet",
             "params": {"instability": [0.25, 0.1, 0.5], "tau_min": 1.0, "tau_max": 100.0}}  # fmt: skip
    (e,) = acc_effects_from_config([entry], "acc")
    assert np.allclose(e.params["instability"], np.array([0.25, 0.1, 0.5]) * MG)
    rate, n = 10.0, 200_000
    z = np.zeros((n, 3))
    x = e.apply(SignalContext(np.arange(n) / rate, z, z, z, rate), z, np.random.default_rng(1))
    taus = np.geomspace(1.0, 100.0, 9)
    adev = np.sqrt(allan_variance(x / e.params["instability"], rate, taus).mean(1))
    assert np.allclose(adev, 1.0, rtol=0.10), adev


def test_effects_given_to_the_other_sensor_are_refused(traj):
    with pytest.raises(ValueError, match="acc_effects\\[0\\] is the gyro effect 'scale_factor'"):
        simulate_imu(traj, [], duration_s=2, acc_effects=[build_effect("scale_factor", scale=[1e-3] * 3)])
    with pytest.raises(ValueError, match="effects\\[0\\] is the accelerometer effect 'scale_factor'"):
        simulate_imu(traj, [build_acc_effect("scale_factor", scale=[1e-3] * 3)], duration_s=2)


@pytest.mark.parametrize(
    ("entry", "said"),
    [
        (
            {"name": "g_sensitivity", "units": "si", "params": {"matrix": [0.0] * 9}},
            r"acc\[0\]: 'name' 'g_sensitivity' must be",
        ),
        ({"name": "bias_random_walk", "units": "datasheet", "params": {"density": -1}}, r"density = -1 \(mg/sqrt"),
        (
            {"name": "misalignment", "units": "si", "params": {"angles": [1e-3] * 3}},
            "angles .* has 3 values; give one number or 6",
        ),
        (
            {"name": "bias_instability", "units": "si", "params": {"instability": 0, "tau_min": 10, "tau_max": 1}},
            "tau_max = 1 must",
        ),
    ],
)
def test_accelerometer_entries_no_sensor_has_are_named(entry, said):
    with pytest.raises(ValueError, match=said):
        acc_effects_from_config([entry], "acc")


def test_the_sim_dataset_takes_an_accelerometer_model_and_keeps_its_old_cache_key(tmp_path):
    """An empty acc_error_model is the data set generated before it existed: same folder; a model is another."""
    gen = {"seed": 0, "duration_s": 3, "error_model": []}
    names = ["drone_00"]
    assert generation_key({**gen, "acc_error_model": []}, names) == generation_key(gen, names)
    model = [{"name": "scale_factor", "units": "datasheet", "params": {"scale": SCALE_PPM}}]
    assert generation_key({**gen, "acc_error_model": model}, names) != generation_key(gen, names)
    plain = np.loadtxt(generate_sequence(tmp_path / "a", "drone_00", gen) / "mav0/imu0/data.csv", delimiter=",")
    scaled = generate_sequence(tmp_path / "b", "drone_00", {**gen, "acc_error_model": model, "acc_noise_density": 0})
    scaled = np.loadtxt(scaled / "mav0/imu0/data.csv", delimiter=",")
    assert np.array_equal(plain[:, :4], scaled[:, :4])  # stamps and gyro
    with pytest.raises(ValueError, match="dataset.generation.acc_error_model\\[0\\]: 'name' 'scale' must be one of"):
        generate_sequence(
            tmp_path / "c", "drone_00", {**gen, "acc_error_model": [{"name": "scale", "units": "si", "params": {}}]}
        )
