import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from gyrodenoise import so3
from gyrodenoise.losses import IncrementLoss
from gyrodenoise.models.build import build_model
from gyrodenoise.models.cpu_layers import DilatedConv1d, FastDropout
from gyrodenoise.models.denoiser import count_parameters, predict_gyro


def test_default_network_has_paper_parameter_count():
    assert count_parameters(build_model("denoiser")) == 77_052
    assert count_parameters(build_model("calibrated")) == 12


def test_untrained_model_reproduces_raw_imu():
    model = build_model("denoiser").eval()
    imu = torch.randn(2, 700, 6)
    np.testing.assert_allclose(model(imu).detach().numpy(), imu[..., :3].numpy(), atol=1e-6)


@pytest.mark.parametrize("act", ["gelu", "relu", "elu", "silu"])
def test_outputs_do_not_depend_on_future_samples(act):
    torch.manual_seed(0)
    model = build_model("denoiser", act=act)
    for p in model.parameters():  # break the zero-initialised head so the network matters
        p.data.add_(0.1 * torch.randn_like(p))
    model.eval()
    imu = torch.randn(1, 1200, 6)
    changed = imu.clone()
    changed[:, 800:] = torch.randn(1, 400, 6) * 5
    a, b = model(imu), model(changed)
    torch.testing.assert_close(a[:, :800], b[:, :800])
    assert not torch.allclose(a[:, 800:], b[:, 800:])


@pytest.mark.parametrize("dilation", [1, 4, 64])
def test_dilated_conv_gradients_equal_torch_conv(dilation):
    """The CPU layer's hand-written input gradient: exact in float64 (gradcheck), torch's in float32."""
    torch.manual_seed(0)
    conv = DilatedConv1d(5, 4, 7, dilation=dilation).double()
    x = torch.randn(2, 5, 6 * dilation + 40, dtype=torch.float64, requires_grad=True)
    w, b = (p.detach().clone().requires_grad_() for p in (conv.weight, conv.bias))
    assert torch.autograd.gradcheck(
        lambda x, w, b: torch.func.functional_call(conv, {"weight": w, "bias": b}, (x,)), (x, w, b)
    )
    conv32 = DilatedConv1d(16, 32, 7, dilation=dilation)
    plain = torch.nn.Conv1d(16, 32, 7, dilation=dilation)
    plain.load_state_dict(conv32.state_dict())
    x32 = torch.randn(3, 16, 6 * dilation + 500)
    g = torch.randn(3, 32, 500)
    grads = []
    for layer in (conv32, plain):
        xi = x32.clone().requires_grad_()
        layer(xi).backward(g)
        grads.append([xi.grad, layer.weight.grad, layer.bias.grad])
    for a, b in zip(*grads, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4 * float(b.abs().max()))


def test_fast_dropout_rate_scale_and_seeding():
    x = torch.ones(4, 64, 4096)
    drop = FastDropout(0.1).train()
    torch.manual_seed(0)
    y = drop(x)
    assert abs(float((y == 0).float().mean()) - 0.1) < 0.003  # 1M draws: std 3e-4
    assert abs(float(y.mean()) - 1.0) < 0.005  # kept values scaled by 1 / (1 - p)
    torch.manual_seed(0)
    assert torch.equal(drop(x), y)  # the mask follows torch's seed
    assert not torch.equal(drop(x), y)
    assert torch.equal(drop.eval()(x), x)


def test_fast_dropout_is_torchs_own_inside_torch_compile(monkeypatch):
    """numpy's generator cannot be traced: while torch.compile traces, the layer is nn.Dropout (same torch draws)."""
    x = torch.ones(2, 8, 256)
    drop = FastDropout(0.25).train()
    monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    torch.manual_seed(0)
    y = drop(x)
    torch.manual_seed(0)
    assert torch.equal(y, torch.nn.functional.dropout(x, 0.25, training=True))


def test_dilated_conv_trains_under_cpu_autocast():
    """Under bfloat16 autocast (e.g. Lightning's precision=bf16-mixed) the layer is nn.Conv1d: a backward that
    mixed the bf16 gradient with the float32 kernel would fail."""
    conv = DilatedConv1d(4, 8, 7, dilation=4)
    x = torch.randn(2, 4, 200, requires_grad=True)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        y = conv(x)
    y.float().sum().backward()
    assert y.dtype == torch.bfloat16 and x.grad is not None and conv.weight.grad.dtype == torch.float32


def test_unknown_activation_is_a_clear_error():
    with pytest.raises(ValueError, match="model.act='swish2'"):
        build_model("denoiser", act="swish2")


def _loss_reference(w, dt, R_gt, j, delta, weight):
    """Per-increment loss with scipy, sequential products (independent of the tree code)."""
    terms = []
    for i in range(0, len(w) - 1 - j + 1, j):
        dR_hat = Rotation.identity()
        for k in range(i + 1, i + j + 1):
            dR_hat = dR_hat * Rotation.from_rotvec(w[k] * dt[k])
        dR = Rotation.from_matrix(R_gt[i].T @ R_gt[i + j])
        r = (dR * dR_hat.inv()).as_rotvec()
        a = np.abs(r)
        terms.append(np.where(a < delta, 0.5 * a**2, delta * (a - 0.5 * delta)))
    return weight * np.mean(terms)


def test_increment_loss_matches_scipy_reference():
    rng = np.random.default_rng(0)
    n = 1 + 64
    dt = np.full(n, 0.005)
    w_true = rng.normal(scale=1.0, size=(n, 3))
    R = np.stack([np.eye(3)] * n)
    for k in range(1, n):
        R[k] = R[k - 1] @ Rotation.from_rotvec(w_true[k] * dt[k]).as_matrix()
    w_hat = w_true + rng.normal(scale=0.3, size=(n, 3))  # errors on both sides of the Huber threshold
    dR16 = np.stack([R[16 * k].T @ R[16 * k + 16] for k in range(4)])
    loss = IncrementLoss((16, 32), huber_delta=0.005, weight=1.0)
    got = loss(
        torch.from_numpy(w_hat)[None],
        torch.from_numpy(dt)[None],
        torch.from_numpy(dR16)[None],
        torch.ones(1, 4, dtype=torch.bool),
    )
    ref = sum(_loss_reference(w_hat, dt, R, j, 0.005, 1.0) for j in (16, 32))
    np.testing.assert_allclose(got.item(), ref, rtol=1e-9)


def test_loss_ignores_increments_without_ground_truth():
    loss = IncrementLoss((16, 32), weight=1.0)
    w = torch.zeros(1, 65, 3, dtype=torch.float64)
    dt = torch.full((1, 65), 0.005, dtype=torch.float64)
    dR = torch.eye(3, dtype=torch.float64).repeat(1, 4, 1, 1)
    dR[0, 3] = torch.from_numpy(Rotation.from_rotvec([0, 0, 1.0]).as_matrix())
    mask = torch.tensor([[True, True, True, False]])
    assert loss(w, dt, dR, mask).item() == 0.0  # the bad increment is masked, and its 32-sample parent too
    assert loss(w, dt, dR, torch.ones(1, 4, dtype=torch.bool)).item() > 0


def test_masked_loss_equals_the_mean_over_available_increments_with_its_gradient():
    """The sync-free masked mean equals the Huber mean over the available components (boolean indexing),
    value and gradient, for a batch with increments missing at random; nothing available gives 0."""
    gen = torch.Generator().manual_seed(0)
    B, n = 3, 1 + 128
    w = (0.5 * torch.randn(B, n, 3, generator=gen, dtype=torch.float64)).requires_grad_()
    dt = torch.full((B, n), 0.005, dtype=torch.float64)
    dR = so3.exp(0.02 * torch.randn(B, 8, 3, generator=gen, dtype=torch.float64))
    mask = torch.rand(B, 8, generator=gen) > 0.3
    loss = IncrementLoss((16, 32), huber_delta=0.005, weight=1e6)
    got = loss(w, dt, dR, mask)
    (g_got,) = torch.autograd.grad(got, w)
    ref = 0.0
    for _, r, m in loss.residuals(w, dt, dR, mask):
        ref = ref + 1e6 * torch.nn.functional.huber_loss(r[m], torch.zeros_like(r[m]), delta=0.005)
    (g_ref,) = torch.autograd.grad(ref, w)
    torch.testing.assert_close(got, ref, rtol=1e-12, atol=0)
    torch.testing.assert_close(g_got, g_ref, rtol=1e-10, atol=1e-12)
    none = loss(w, dt, dR, torch.zeros_like(mask))
    (g_none,) = torch.autograd.grad(none, w)
    assert none.item() == 0.0 and torch.count_nonzero(g_none) == 0


def test_predict_gyro_is_float64_and_restores_mode():
    model = build_model("denoiser")
    out = predict_gyro(model, np.zeros((600, 6)))
    assert out.dtype == torch.float64 and out.shape == (600, 3) and model.training


@pytest.mark.parametrize(
    "loss, message",
    [
        ({"increments": [0]}, "distinct increment lengths"),  # a ZeroDivisionError before
        ({"increments": [16, 16]}, "distinct increment lengths"),  # the 16-sample term counted twice before
        ({"huber_delta": 0.0}, "huber_delta=0.0"),  # torch's RuntimeError at the first step before
        ({"weight": -1.0}, "weight=-1.0"),
        ({"huber": 0.01}, "unexpected keyword argument 'huber'"),
    ],
)
def test_bad_loss_settings_are_refused_when_the_loss_is_built(loss, message):
    from gyrodenoise.baseline import fit_calibrated
    from gyrodenoise.cli_errors import ConfigError

    if "huber" not in loss:
        with pytest.raises(ValueError, match=message):
            IncrementLoss(**loss)
    with pytest.raises(ConfigError, match=message):  # fit_calibrated's command: one line, not a traceback
        fit_calibrated([], loss=loss)
