"""Simulator: trajectory derivatives, effect units, ASL round trip, noise levels, seeding."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrodenoise.data.cache import load_sequence
from gyrodenoise.sim import EFFECTS, build_effect, handheld_trajectory, simulate_imu, write_asl
from gyrodenoise.sim.effects import DEG, G0, GSensitivity, TimeOffset, WhiteNoise, effect_from_config


@pytest.fixture(scope="module")
def traj():
    return handheld_trajectory(20.0, seed=3)


def test_rate_and_acceleration_match_finite_differences(traj):
    t = np.linspace(2, 18, 400)
    h = 1e-6
    k0, k1 = traj.evaluate(t), traj.evaluate(t + h)
    fd = Rotation.from_matrix(np.swapaxes(k0.rot, 1, 2) @ k1.rot).as_rotvec() / h
    assert np.abs(fd - k0.omega).max() < 1e-4
    assert np.abs((k1.omega - k0.omega) / h - k0.alpha).max() < 1e-3
    # at rest with a level body the specific force is +g up
    assert np.allclose(np.linalg.norm(k0.specific_force, axis=1).mean(), G0, rtol=0.2)


def test_sample_mean_is_the_simulators_centred_mean(traj):
    """The detector's truth (`sample_mean`) is what the simulator's ideal gyro outputs: the rate's mean over the
    period centred on the stamp, not the instantaneous rate (which differs by the mean's droop)."""
    t, period = np.linspace(2, 18, 400), 1 / 200
    fine = ((np.arange(1000) + 0.5) / 1000 - 0.5) * period  # midpoint rule on a fine grid
    kins = [traj.evaluate(t + s) for s in fine]
    mean = traj.sample_mean(t, period)
    for field in ("omega", "alpha", "specific_force"):
        want = np.mean([getattr(k, field) for k in kins], axis=0)
        scale = np.abs(want).max()
        assert np.abs(getattr(mean, field) - want).max() < 1e-6 * scale, field
    inst = traj.evaluate(t)
    # the mean differs from the instantaneous rate by its droop, T^2/24 w'' to leading order
    h = 1e-4
    w2 = (traj.evaluate(t + h).alpha - traj.evaluate(t - h).alpha) / (2 * h)
    droop = mean.omega - inst.omega
    assert np.abs(droop - period**2 / 24 * w2).max() < 1e-3 * np.abs(period**2 / 24 * w2).max()
    assert np.allclose(mean.rot, inst.rot) and np.allclose(mean.pos, inst.pos)


def test_sampled_view_gives_sample_means_numbers_and_computes_the_rate_once(traj, monkeypatch):
    """`sampled_at` is `sample_mean` field by field, in either reading order, and a rate read after another field is
    taken from the fields already computed (`rate_mean` is not called again)."""
    t, period = np.linspace(2, 18, 400), 1 / 200
    want = traj.sample_mean(t, period)
    calls = []
    rate_mean = type(traj).rate_mean
    monkeypatch.setattr(type(traj), "rate_mean", lambda self, *a, **k: calls.append(1) or rate_mean(self, *a, **k))

    rate_first = traj.sampled_at(t, period)
    assert np.array_equal(rate_first.omega, want.omega) and calls == [1]
    assert np.array_equal(rate_first.specific_force, want.specific_force)

    calls.clear()
    rate_last = traj.sampled_at(t, period)
    assert np.array_equal(rate_last.alpha, want.alpha) and np.array_equal(rate_last.rot, want.rot)
    assert np.array_equal(rate_last.omega, want.omega) and calls == []


def test_vocabulary_and_datasheet_units():
    expected = {
        "bias", "bias_random_walk", "white_noise", "scale_factor", "misalignment", "g_sensitivity",
        "time_offset", "quantization", "vibration", "warmup_bias", "nonlinearity", "saturation",
    }  # fmt: skip
    assert expected <= set(EFFECTS)
    g = GSensitivity.from_datasheet(matrix=np.eye(3) * 0.1)  # deg/s/g
    assert np.allclose(g.params["matrix"], np.eye(3) * 0.1 * DEG / G0)
    assert np.allclose(g.datasheet()["matrix"]["value"], np.eye(3) * 0.1)
    assert TimeOffset.from_datasheet(delta=5.0).params["delta"] == pytest.approx(0.005)
    e = effect_from_config({"name": "white_noise", "units": "datasheet", "params": {"density": [0.5] * 3}})
    assert np.allclose(e.params["density"], 0.5 * DEG / 60)
    with pytest.raises(ValueError, match="unknown effect"):
        build_effect("gyro_gremlins")
    with pytest.raises(ValueError, match="unknown parameter"):
        build_effect("bias", offset=1.0)


def test_asl_round_trip_and_noise_density(traj, tmp_path):
    n = 1.7e-4
    sim = simulate_imu(traj, [WhiteNoise(density=np.full(3, n))], seed=7)
    write_asl(tmp_path / "seq", sim)
    seq = load_sequence(tmp_path, "seq", cache_dir="")
    assert np.array_equal(seq.gyro, sim.gyro)
    assert (np.diff(seq.t) > 0).all()
    # white noise keeps its density through the 10x oversampling and the averaging
    std = (sim.gyro - sim.true_gyro).std(0)
    assert np.allclose(std, n * np.sqrt(200.0), rtol=0.05)
    # ground truth read back (w,x,y,z on disk) equals the truth
    R = Rotation.from_quat(sim.gt_quat_xyzw).as_matrix()
    assert np.abs(Rotation.from_matrix(np.swapaxes(seq.rot, 1, 2) @ R).magnitude()).max() < 1e-8


def test_seeded(traj):
    eff = [WhiteNoise(density=np.full(3, 1e-4)), build_effect("bias_random_walk", density=np.full(3, 1e-4))]
    a = simulate_imu(traj, eff, seed=1, duration_s=5)
    b = simulate_imu(traj, eff, seed=1, duration_s=5)
    c = simulate_imu(traj, eff, seed=2, duration_s=5)
    assert np.array_equal(a.gyro, b.gyro) and not np.array_equal(a.gyro, c.gyro)
