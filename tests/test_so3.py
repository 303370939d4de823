import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from gyrodenoise import so3


def _rotvecs(rng, n, max_angle):
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return axis * rng.uniform(0, max_angle, size=(n, 1))


@pytest.mark.parametrize("max_angle", [1e-9, 1e-5, 1e-2, 1.0, np.pi - 1e-7])
def test_exp_matches_scipy(max_angle):
    phi = _rotvecs(np.random.default_rng(0), 200, max_angle)
    R = so3.exp(torch.from_numpy(phi)).numpy()
    np.testing.assert_allclose(R, Rotation.from_rotvec(phi).as_matrix(), atol=1e-14)


@pytest.mark.parametrize("max_angle", [1e-10, 1e-6, 1e-3, 1.0, 3.0])
def test_log_matches_scipy(max_angle):
    phi = _rotvecs(np.random.default_rng(1), 200, max_angle)
    R = Rotation.from_rotvec(phi).as_matrix()
    np.testing.assert_allclose(so3.log(torch.from_numpy(R)).numpy(), phi, atol=1e-12, rtol=1e-9)


def test_log_near_pi_is_accurate():
    rng = np.random.default_rng(2)
    phi = _rotvecs(rng, 100, 1.0)
    phi = phi / np.linalg.norm(phi, axis=1, keepdims=True) * (np.pi - 10.0 ** -rng.uniform(4, 9, size=(100, 1)))
    R = Rotation.from_rotvec(phi).as_matrix()
    out = so3.log(torch.from_numpy(R)).numpy()
    # compare as rotations (the sign of the axis flips at exactly pi)
    np.testing.assert_allclose(Rotation.from_rotvec(out).as_matrix(), R, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), np.linalg.norm(phi, axis=1), atol=1e-10)


def test_log_exp_gradients_are_finite_at_identity():
    phi = torch.zeros(4, 3, dtype=torch.float64, requires_grad=True)
    so3.log(so3.exp(phi)).sum().backward()
    assert torch.isfinite(phi.grad).all()
    np.testing.assert_allclose(phi.grad.numpy(), np.ones((4, 3)), atol=1e-12)


def test_tree_product_equals_sequential_product():
    R = so3.exp(torch.from_numpy(_rotvecs(np.random.default_rng(3), 64, 0.5)))
    out = so3.tree_product(R[None], 5)[0]  # blocks of 32
    for k in range(2):
        ref = torch.eye(3, dtype=R.dtype)
        for i in range(32 * k, 32 * k + 32):
            ref = ref @ R[i]
        np.testing.assert_allclose(out[k].numpy(), ref.numpy(), atol=1e-13)


def test_integrate_gyro_matches_sequential_and_constant_rate():
    rng = np.random.default_rng(4)
    w = rng.normal(size=(1000, 3))
    dt = np.full(1000, 0.005)
    R0 = Rotation.random(random_state=5).as_matrix()
    out = so3.integrate_gyro(R0, w, dt)
    R = R0.copy()
    for n in range(1, 1000):
        R = R @ Rotation.from_rotvec(w[n] * dt[n]).as_matrix()
    np.testing.assert_allclose(out[-1], R, atol=1e-10)
    # constant rate about z for 1 s: 1 rad
    const = so3.integrate_gyro(np.eye(3), np.tile([0, 0, 1.0], (201, 1)), np.full(201, 0.005))
    np.testing.assert_allclose(Rotation.from_matrix(const[-1]).as_rotvec(), [0, 0, 1.0], atol=1e-12)


def test_matrix_to_quat_matches_scipy_all_branches():
    R = Rotation.random(500, random_state=6)
    q = so3.matrix_to_quat(torch.from_numpy(R.as_matrix())).numpy()
    ref = R.as_quat()
    ref = np.where(ref[:, 3:] < 0, -ref, ref)
    np.testing.assert_allclose(q, ref, atol=1e-12)
