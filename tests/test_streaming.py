"""Streaming corrector == batch model (predict_gyro), from the first sample on."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from _models import random_imu, random_model

from gyrodenoise.data.readers import read_imu
from gyrodenoise.models.build import build_model
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.pretrained import available_models, load_model
from gyrodenoise.streaming import StreamingCorrector

ATOL = 2e-5  # rad/s; float32 network, different summation order


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_push_matches_batch(backend):
    model, imu = random_model(), random_imu(800)
    ref = predict_gyro(model, imu).numpy()
    sc = StreamingCorrector(model, backend=backend)
    out = np.stack([sc.push(s) for s in imu])
    assert np.abs(out - ref).max() < ATOL
    assert np.abs(ref - imu[:, :3]).max() > 1e-2  # the correction is not trivially zero


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_chunks_and_samples_mixed(backend):
    model, imu = random_model(), random_imu(900)
    ref = predict_gyro(model, imu).numpy()
    sc = StreamingCorrector(model, backend=backend)
    parts = [sc.push_chunk(imu[:5]), sc.push_chunk(imu[5:400])]
    parts += [sc.push(s)[None] for s in imu[400:420]]
    parts += [sc.push_chunk(imu[420:421]), sc.push_chunk(imu[421:])]
    assert np.abs(np.concatenate(parts) - ref).max() < ATOL


@pytest.mark.parametrize("act", ["elu", "silu", "tanh", "softplus", "mish", "relu"])
def test_other_activations_and_no_batchnorm(act):
    model = random_model(seed=3, act=act, batch_norm=act != "elu", channels=(8, 8), dilations=(1, 3))
    imu = random_imu(200)
    ref = predict_gyro(model, imu).numpy()
    sc = StreamingCorrector(model, dtype="float64")
    assert np.abs(np.stack([sc.push(s) for s in imu]) - ref).max() < ATOL


def test_reset_starts_a_new_sequence():
    model, imu = random_model(), random_imu(300)
    sc = StreamingCorrector(model)
    sc.push_chunk(random_imu(100, seed=9))
    sc.reset()
    assert np.abs(sc.push_chunk(imu) - predict_gyro(model, imu).numpy()).max() < ATOL


@pytest.mark.parametrize("g_sensitivity", [False, True])
def test_calibrated_model(g_sensitivity):
    model = build_model("calibrated", g_sensitivity=g_sensitivity)
    model.bias.data[:] = torch.tensor([0.01, -0.02, 0.03])
    model.C_delta.data.normal_(std=0.01)
    if g_sensitivity:
        model.G.data.normal_(std=1e-3)
        model.set_normalization(np.r_[0.0, 0.1, 0.0, 0.2, -0.3, 9.8], np.r_[0.5, 0.5, 0.5, 2.0, 1.5, 3.0])
    imu = random_imu(50)
    sc = StreamingCorrector(model)
    assert np.abs(np.stack([sc.push(s) for s in imu]) - predict_gyro(model, imu).numpy()).max() < 1e-6


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_non_finite_sample_is_refused_and_leaves_the_state(backend):
    model, imu = random_model(), random_imu(300)
    ref = StreamingCorrector(model, backend=backend).push_chunk(imu)
    sc = StreamingCorrector(model, backend=backend)
    first = sc.push_chunk(imu[:100])
    bad = imu[100].copy()
    bad[4] = np.nan
    with pytest.raises(ValueError, match="NaN/inf"):
        sc.push(bad)
    with pytest.raises(ValueError, match=r"NaN/inf IMU value in sample 2 of this call \(counting from 1\)"):
        sc.push_chunk(np.stack([imu[100], bad]))
    rest = np.stack([sc.push(s) for s in imu[100:]])  # as if the bad sample had never come
    assert np.abs(np.concatenate([first, rest]) - ref).max() < ATOL


@pytest.mark.parametrize("value", [1e30, 1e39])  # finite in float64, beyond any IMU; 1e39 is inf in float32
def test_a_sample_beyond_any_sensor_is_refused_and_leaves_the_state(value):
    model, imu = random_model(), random_imu(200)
    ref = StreamingCorrector(model).push_chunk(imu)
    sc = StreamingCorrector(model)
    first = sc.push_chunk(imu[:50])
    bad = imu[50].copy()
    bad[2] = value
    with pytest.raises(ValueError, match="NaN/inf|beyond any sensor"):
        sc.push(bad)
    with pytest.raises(ValueError, match="NaN/inf|beyond any sensor"):
        sc.push_chunk(bad[None])
    rest = sc.push_chunk(imu[50:])
    assert np.abs(np.concatenate([first, rest]) - ref).max() < ATOL


def test_bad_sample_shape():
    sc = StreamingCorrector(random_model())
    with pytest.raises(ValueError, match=r"\(6,\)"):
        sc.push([1.0, 2.0, 3.0])


def test_real_euroc_slice(euroc_root):
    """Parity on real data: the shipped EuRoC model when present, else a random one normalised on the data."""
    imu_data = read_imu(euroc_root / "V1_01_easy" / "mav0" / "imu0" / "data.csv")
    imu = np.concatenate([imu_data.gyro, imu_data.acc], axis=1)[2000:4000]
    if "euroc" in available_models():
        model, _ = load_model("euroc")
    else:
        model = random_model()
        model.set_normalization(imu.mean(0), imu.std(0))
    ref = predict_gyro(model, imu).numpy()
    sc = StreamingCorrector(model)
    out = np.concatenate([np.stack([sc.push(s) for s in imu[:700]]), sc.push_chunk(imu[700:])])
    assert np.abs(out - ref).max() < ATOL


def test_ensemble_refuses_a_non_finite_sample_without_changing_its_state():
    from gyrodenoise.models.ensemble import EnsembleCorrection

    ens, imu = EnsembleCorrection([random_model(seed=1), random_model(seed=2)]).eval(), random_imu(200)
    ref = StreamingCorrector(ens).push_chunk(imu)
    sc = StreamingCorrector(ens)
    first = sc.push_chunk(imu[:50])
    with pytest.raises(ValueError, match="NaN/inf"):
        sc.push(np.full(6, np.nan))
    assert sc.n_pushed == 50
    rest = np.stack([sc.push(s) for s in imu[50:]])
    assert np.abs(np.concatenate([first, rest]) - ref).max() < ATOL
