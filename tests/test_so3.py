import math

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


def test_log_has_finite_gradients_at_a_half_turn():
    """A rotation by exactly pi (w = 0): the Taylor branch not taken divided by w and its gradient was NaN (an
    audit of the SO(3) path against mpmath)."""
    R = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=torch.float64)).requires_grad_()
    v = so3.log(R)
    v.norm().backward()
    assert torch.isfinite(R.grad).all() and torch.allclose(v.norm(), torch.tensor(math.pi, dtype=torch.float64))


@pytest.mark.parametrize("angle", [1.01e-6, 3e-6, 1e-5])
def test_exp_jacobian_just_above_the_taylor_switch(angle):
    """(1 - cos t) / t^2 lost ~5 digits of its Jacobian just above 1e-6 rad (1.2e-11 against mpmath); against
    Rodrigues with its series to t^4 (exact to float64 at these angles) it now agrees to ~1e-16."""

    def series_exp(phi):
        t2 = (phi * phi).sum()
        a, b = 1 - t2 / 6 + t2**2 / 120, 0.5 - t2 / 24 + t2**2 / 720
        return torch.eye(3, dtype=phi.dtype) + a * so3.hat(phi) + b * so3.hat(phi) @ so3.hat(phi)

    phi = torch.tensor([angle, 0.3 * angle, -0.2 * angle], dtype=torch.float64)
    got = torch.autograd.functional.jacobian(so3.exp, phi)
    want = torch.autograd.functional.jacobian(series_exp, phi)
    assert (got - want).abs().max() < 1e-14


def test_integration_edges_are_named():
    """Empty input gave one rotation; a NaN gyro made every later orientation NaN; steps out of order integrated
    backwards; float32 steps drifted; none said so."""
    R0 = np.eye(3)
    assert so3.integrate_gyro(R0, np.zeros((0, 3)), np.zeros(0)).shape == (0, 3, 3)
    gyro = np.zeros((5, 3))
    gyro[2, 1] = np.nan
    with pytest.raises(ValueError, match="gyro row 2 is not finite"):
        so3.integrate_gyro(R0, gyro, 0.005)
    with pytest.raises(ValueError, match=r"dt\[3\]"):
        so3.integrate_gyro(R0, np.zeros((5, 3)), np.array([0, 0.005, 0.005, -0.005, 0.005]))
    with pytest.raises(ValueError, match="not a rotation"):
        so3.integrate_gyro(2 * R0, np.zeros((5, 3)), 0.005)
    g = torch.zeros((5, 3), dtype=torch.float64)
    with pytest.raises(ValueError, match="float64"):
        so3.integrate_gyro_torch(torch.eye(3, dtype=torch.float64), g, torch.full((5,), 0.005, dtype=torch.float32))
    with pytest.raises(ValueError, match="median step"):
        so3.integrate_gyro_torch(torch.eye(3, dtype=torch.float64), g, torch.full((5,), 5e6, dtype=torch.float64))
    with pytest.raises(ValueError, match="blocks of 2"):
        so3.tree_product(torch.eye(3).expand(6, 3, 3), 2)


def test_an_integer_mask_is_refused_by_the_aoe():
    """np.array([1, 0, 1, 1]) indexed samples 1, 0, 1, 1 instead of selecting three of them."""
    from gyrodenoise.metrics import aoe

    R = Rotation.from_rotvec(np.random.default_rng(0).normal(0, 0.01, (4, 3))).as_matrix()
    with pytest.raises(ValueError, match="boolean"):
        aoe(np.repeat(np.eye(3)[None], 4, 0), R, np.array([1, 0, 1, 1]))


def test_log_refuses_a_matrix_that_is_not_a_rotation():
    R = so3.exp(torch.tensor([[0.1, -0.2, 0.3], [1.0, 0.5, -2.0]], dtype=torch.float64))
    assert torch.allclose(so3.log(R), so3.log(R, check=False))
    for bad, why in ((R * 1.01, "not a rotation"), (-R, "det"), (R[..., :2], "shape")):
        with pytest.raises(ValueError, match=why):
            so3.log(bad)
    nan = R.clone()
    nan[1, 0, 0] = float("nan")
    with pytest.raises(ValueError, match=r"index \(1,\)"):
        so3.log(nan)
    # float32 rotations from a long product still pass at their own tolerance
    steps = so3.exp(torch.full((2000, 3), 0.01, dtype=torch.float32))
    prod = steps[0]
    for s in steps[1:]:
        prod = prod @ s
    so3.log(prod)


def test_validations_aoe_of_nan_weights_is_nan_not_a_rotation_error():
    """Diverged weights give NaN orientations: the validation AOE must be NaN (TrainingDiverged then names the cure),
    not log's 'not a rotation' error (a review of the rotation check)."""
    from gyrodenoise.metrics import aoe_torch

    gyro = torch.full((100, 3), 0.1, dtype=torch.float64)
    gyro[50] = float("nan")
    dt = torch.full((100,), 0.005, dtype=torch.float64)
    R_est = so3.integrate_gyro_torch(torch.eye(3, dtype=torch.float64), gyro, dt)
    R_gt = so3.integrate_gyro_torch(torch.eye(3, dtype=torch.float64), gyro.nan_to_num(), dt)
    assert math.isnan(aoe_torch(R_gt, R_est)[0])
