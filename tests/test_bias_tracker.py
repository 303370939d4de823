"""The gravity-aided bias tracker on motions whose truth comes from scipy, not from the tracker's equations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrodenoise.bias_tracker import GravityBiasTracker, accelerometer_offset, track_bias
from gyrodenoise.data.sequence import Sequence
from gyrodenoise.so3 import integrate_gyro, relative_rotvec

RATE = 200.0
G = 9.81


def flight(duration_s: float, tilt_deg: float, bias: np.ndarray, seed: int = 0):
    """Attitude from Euler angles (scipy), the body rate that integrate_gyro turns back into it, the specific
    force of a body that does not accelerate, gyro = rate + constant bias + white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / RATE)
    angles = np.stack(
        [
            0.3 * t + 0.5 * np.sin(0.05 * t),
            np.radians(tilt_deg) * np.sin(0.21 * t),
            np.radians(tilt_deg) * np.sin(0.13 * t + 1.0),
        ],
        axis=1,
    )
    R = Rotation.from_euler("ZYX", angles).as_matrix()
    dt = np.diff(t, prepend=t[0])
    rate = np.zeros((len(t), 3))
    rate[1:] = relative_rotvec(R[:-1], R[1:]) / dt[1:, None]
    acc = np.einsum("nji,j->ni", R, np.array([0.0, 0.0, G])) + 0.02 * rng.standard_normal((len(t), 3))
    gyro = rate + bias + 1e-3 * rng.standard_normal((len(t), 3))
    return R, gyro, acc, dt


def attitude_error_deg(R_true: np.ndarray, gyro: np.ndarray, dt: np.ndarray) -> float:
    est = integrate_gyro(R_true[0], gyro, dt)
    return float(np.degrees(np.linalg.norm(relative_rotvec(R_true, est), axis=1)).mean())


def test_recovers_a_constant_bias_when_the_body_tilts() -> None:
    bias = np.radians([0.15, -0.1, 0.2])
    R, gyro, acc, dt = flight(400.0, tilt_deg=40.0, bias=bias)
    est = GravityBiasTracker(k_p=0.3, k_i=0.01).bias(gyro, acc, dt)
    late = est[-20 * int(RATE) :].mean(axis=0)
    np.testing.assert_allclose(late, bias, atol=np.radians(0.02))
    tracked = GravityBiasTracker(k_p=0.3, k_i=0.01).correct(gyro, acc, dt)
    assert attitude_error_deg(R, tracked, dt) < 0.5 * attitude_error_deg(R, gyro, dt)


def test_level_yaw_motion_leaves_the_vertical_bias_alone() -> None:
    bias = np.radians([0.0, 0.0, 0.2])  # along gravity for a level body: not observable from the accelerometer
    R, gyro, acc, dt = flight(200.0, tilt_deg=0.0, bias=bias)
    est = GravityBiasTracker(k_p=0.3, k_i=0.01).bias(gyro, acc, dt)
    assert np.abs(np.degrees(est[:, 2])).max() < 0.01


def test_the_output_at_a_sample_uses_earlier_samples_only() -> None:
    R, gyro, acc, dt = flight(20.0, tilt_deg=30.0, bias=np.radians([0.1, 0.1, 0.1]))
    tracker = GravityBiasTracker(k_p=1.0, k_i=0.01)
    m = 1500
    gyro2, acc2 = gyro.copy(), acc.copy()
    gyro2[m:] += 0.5
    acc2[m:] *= -1.0
    np.testing.assert_array_equal(tracker.bias(gyro, acc, dt)[: m + 1], tracker.bias(gyro2, acc2, dt)[: m + 1])
    assert not np.allclose(tracker.bias(gyro, acc, dt)[m + 2 :], tracker.bias(gyro2, acc2, dt)[m + 2 :])


def test_a_grid_of_gains_equals_one_tracker_per_gain() -> None:
    _, gyro, acc, dt = flight(10.0, tilt_deg=30.0, bias=np.radians([0.1, -0.2, 0.1]))
    grid = track_bias(gyro, acc, dt, np.array([0.1, 1.0]), np.array([1e-3, 1e-2]))
    for g, (kp, ki) in enumerate(((0.1, 1e-3), (1.0, 1e-2))):
        np.testing.assert_allclose(grid[g], GravityBiasTracker(kp, ki).bias(gyro, acc, dt), rtol=0, atol=1e-15)


def test_no_integral_gain_changes_nothing() -> None:
    _, gyro, acc, dt = flight(5.0, tilt_deg=30.0, bias=np.zeros(3))
    np.testing.assert_array_equal(GravityBiasTracker(k_p=1.0, k_i=0.0).correct(gyro, acc, dt), gyro)


def test_bad_input_is_named() -> None:
    _, gyro, acc, dt = flight(1.0, tilt_deg=0.0, bias=np.zeros(3))
    acc[17] = 0.0
    with pytest.raises(ValueError, match="accelerometer is \\(near\\) zero at sample 17"):
        GravityBiasTracker().bias(gyro, acc, dt)
    with pytest.raises(ValueError, match="gyro must be \\(N, 3\\)"):
        GravityBiasTracker().bias(gyro[:, :2], acc, dt)
    gyro[5, 1] = np.nan
    with pytest.raises(ValueError, match="gyro has a non-finite value at sample 5"):
        GravityBiasTracker().bias(gyro, np.ones_like(gyro), dt)
    with pytest.raises(ValueError, match="k_i must be a finite number >= 0"):
        GravityBiasTracker(k_i=-1.0)


def moving_flight(offset: np.ndarray, gt_mask: np.ndarray | None = None) -> Sequence:
    """A body that moves and turns (positions and angles from closed-form sines, rotations from scipy), its
    accelerometer = R^T (p'' + g e_z) + offset + white noise, p'' from the closed form (not from a spline)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 60.0, 1.0 / RATE)
    w = np.array([0.4, 0.7, 0.3])
    pos = np.sin(np.outer(t, w)) * [2.0, 1.5, 0.5]
    acc_world = -np.sin(np.outer(t, w)) * [2.0, 1.5, 0.5] * w**2
    R = Rotation.from_euler("ZYX", np.stack([0.2 * t, 0.3 * np.sin(0.5 * t), 0.2 * np.sin(0.7 * t)], 1)).as_matrix()
    acc = np.einsum("nji,nj->ni", R, acc_world + [0.0, 0.0, G]) + offset + 0.05 * rng.standard_normal((len(t), 3))
    mask = np.ones(len(t), bool) if gt_mask is None else gt_mask
    return Sequence("synthetic", 0, t, np.zeros((len(t), 3)), acc, R, pos, mask)


def test_accelerometer_offset_is_recovered_from_the_ground_truth() -> None:
    offset = np.array([-0.02, 0.12, 0.07])
    np.testing.assert_allclose(accelerometer_offset(moving_flight(offset)), offset, atol=5e-3)
    mask = np.ones(len(moving_flight(offset).t), bool)
    mask[3000:3200] = False  # a 1-s ground-truth gap whose positions are garbage: not used, not a knot
    gappy = moving_flight(offset, mask)
    gappy.pos[3000:3200] = 0.0
    np.testing.assert_allclose(accelerometer_offset(gappy), offset, atol=5e-3)


def test_accelerometer_offset_needs_ground_truth() -> None:
    seq = moving_flight(np.zeros(3), gt_mask=np.zeros(12000, bool))
    with pytest.raises(ValueError, match="synthetic has too little ground truth \\(0 valid samples\\)"):
        accelerometer_offset(seq)
