"""Issue 11, point 2: the reconstructed true rate's error in the model (trusted band, nuisance term),
on data with a measured ground truth (the independent test world's mocap) and with an exact one."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.hidden import make_measured
from gyrodenoise.discrepancy.reconstruction import band_limit, band_rows, estimate_band, row_frequencies
from gyrodenoise.discrepancy.worldcases import FIT_FLIGHT, make_world
from gyrodenoise.testworld.replay import default_euroc_root

EUROC = default_euroc_root()
needs_euroc = pytest.mark.skipif(
    not (EUROC / FIT_FLIGHT).is_dir(), reason="EuRoC V-room ground truth not available (../shared/data/euroc)"
)


def _band(root, name):
    fc = load_fit_context(root, name)
    r = fc.residual
    return fc, estimate_band(fc, r - r.mean(0))


def test_exact_ground_truth_compares_the_whole_spectrum(tmp_path):
    (name,) = make_measured(tmp_path, [], 1, 20.0, seed=3)
    _, b = _band(tmp_path, name)
    assert b.exact and b.whole_spectrum and b.f_max_hz == pytest.approx(100.0, rel=1e-3)
    assert np.all(b.orientation_noise_rad < 1e-8)


@needs_euroc
def test_measured_ground_truth_noise_and_band_are_estimated(tmp_path):
    truth = make_world(tmp_path, "", seed=2, duration_s=25.0, euroc_root=EUROC, flights=(FIT_FLIGHT,))
    fc, b = _band(tmp_path, FIT_FLIGHT)
    sigma = np.deg2rad(truth["mocap"]["realised_orientation_noise_deg"])
    assert np.allclose(b.orientation_noise_rad, sigma, rtol=0.15)  # from the ground truth alone
    assert not b.whole_spectrum and 3.0 < b.f_max_hz < 10.0  # the spline's corner is 10 Hz
    # inside the band the residual is the reconstruction error (the sensor floor is ~6e-8 there):
    # the model of that error explains the measured spectrum
    f = (b.f_hz >= 2.0) & (b.f_hz <= b.f_max_hz)
    ratio = b.residual_psd[f] / b.error_psd(b.f_hz[f])
    assert 0.7 < np.median(ratio) < 1.4
    assert b.f_equal_hz < 1.0  # where the reconstruction error overtakes a 1.7e-4 rad/s/sqrt(Hz) gyro


def test_band_rows_are_the_band_limited_signal():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((4000, 3))
    full = band_rows(x, 200.0, None, force=True)
    assert full.shape == x.shape and np.allclose((full**2).sum(0), (x**2).sum(0))  # Parseval
    rows = band_rows(x, 200.0, 10.0)
    assert len(rows) == len(row_frequencies(4000, 200.0, 10.0)) == 2 * 201 - 1
    lp = band_limit(x, 200.0, 10.0)
    assert np.allclose((rows**2).sum(0), (lp**2).sum(0))
    # a regression on the rows is the regression of the band-limited signals
    beta = np.array([0.3, -1.2, 2.0])
    y = (x * beta).sum(1, keepdims=True) + 0.1 * rng.standard_normal((4000, 1))
    b_rows = np.linalg.lstsq(rows, band_rows(y, 200.0, 10.0)[:, 0], rcond=None)[0]
    b_lp = np.linalg.lstsq(lp, band_limit(y, 200.0, 10.0)[:, 0], rcond=None)[0]
    assert np.allclose(b_rows, b_lp)


def _blue_context(n=4000, rate=200.0, f_max=6.0, mask=None, corner_hz=None):
    from gyrodenoise.discrepancy.reconstruction import row_frequencies
    from gyrodenoise.sim.context import FitContext

    t = np.arange(n) / rate
    z = np.zeros((n, 3))
    f = row_frequencies(n, rate, f_max)
    # GLS weights sqrt(c / (c + E(f))): a flat sensor floor, a reconstruction error ~ f^2 above corner_hz
    w = np.ones((len(f), 3)) if corner_hz is None else np.repeat(np.sqrt(1 / (1 + (f / corner_hz) ** 2))[:, None], 3, 1)
    extra = {"band_hz": f_max, "row_weights": w}
    if mask is not None:
        extra["row_mask"] = mask
    return FitContext("blue", t, z, z, z, z, rate, extra)


def test_edge_impulses_of_the_reconstruction_error_are_projected_out():
    """The reconstructed rate's error is the derivative of an angle error: over a record its Fourier
    sum holds the angle error's jump between the ends, the same in every bin. At low frequencies,
    where its own spectrum ~ f^2 is small and the GLS rows weigh most, uncorrected that jump is
    fitted by slow regressors (a warm-up exponential here); projected out, they see noise only."""
    from gyrodenoise.discrepancy.design import band_power, fit_rows

    rng = np.random.default_rng(0)
    n, rate, s_w, s_th = 4000, 200.0, 2.4e-3, 1e-3
    fc = _blue_context(n, rate, corner_hz=s_w / s_th / (2 * np.pi))  # where the two spectra cross
    w = fc.extra["row_weights"][:, 0]
    col = np.zeros((n, 3, 1))
    col[:, 0, 0] = np.exp(-fc.t / 2.0)
    X = col.reshape(-1, 1)
    Xb = band_rows(col[:, :, 0], rate, 6.0, force=True)[:, 0] * w
    coefs, raw = [], []
    for _ in range(60):
        theta = s_th * rng.standard_normal((n + 1, 3))
        r = np.diff(theta, axis=0) * rate + s_w * rng.standard_normal((n, 3))  # blue + the sensor's white
        Xr, rr = fit_rows(fc, X, r.reshape(-1))
        coefs.append(np.linalg.lstsq(Xr, rr, rcond=None)[0][0])
        rb = band_rows(r, rate, 6.0, force=True)[:, 0] * w
        raw.append(Xb @ rb / (Xb @ Xb))
    # the edge jump would be fitted as a warm-up; without it the spread is several times smaller
    assert np.std(raw) > 3 * np.std(coefs)
    assert abs(np.mean(coefs)) < 3 * np.std(coefs) / np.sqrt(len(coefs))
    # an impulse at the record's start, or at the edges of a gap of left-out samples, is no signal
    mask = np.ones((n, 3), dtype=bool)
    mask[1000:1040] = False
    fcm = _blue_context(n, rate, mask=mask)
    for pos in (0, 1000, 1040):
        r = np.zeros((n, 3))
        r[pos] = 1.0
        assert band_power(fcm, r, np.ones(3)) < 1e-20
    r = np.zeros((n, 3))
    r[2000] = 1.0  # inside the record: kept
    assert band_power(fcm, r, np.ones(3)) > 1e-6
