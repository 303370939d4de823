"""The rate random walk read from the fitted knots (`fitted_model._walk_from_knots`, the K of a sequence behind a
reconstructed truth, whose noisy angle derivative swamps the walk's Allan variance)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gyrodenoise.discrepancy.design import Design
from gyrodenoise.discrepancy.fitted_model import _walk_from_knots, knot_increment_variance
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import EFFECTS

FS = 200.0
K = 1e-3  # rad/s^2/sqrt(Hz): a walk far above the knots' estimation noise


def _flight(duration: float, seed: int, noise: float = 1e-4) -> FitContext:
    rng = np.random.default_rng(seed)
    n = int(duration * FS)
    walk = np.cumsum(rng.standard_normal((n, 3)) * K / np.sqrt(FS), 0)
    zero = np.zeros((n, 3))
    gyro = 0.01 + walk + noise * np.sqrt(FS) * rng.standard_normal((n, 3))
    return FitContext(name=f"f{seed}", t=np.arange(n) / FS, gyro=gyro, omega=zero, alpha=zero, f=zero, rate_hz=FS)


def _walk(spacing: float):
    e = EFFECTS["bias_random_walk"]()
    e.knot_spacing_s = spacing
    return e


@pytest.mark.parametrize(("duration", "spacing"), [(45.0, 20.0), (60.0, 2.0)])
def test_the_knot_increments_variance_is_the_least_squares_fits(duration, spacing):
    """Against walks fitted by least squares (bias and hats): 45 s at 20 s is 3 knots 15 s apart, not 20 (the nominal
    spacing K was read with is 1.1 times too large there); 60 s at 2 s is 30 knots, more than the layout the variances
    are computed on (inside it the spacing alone is 1.17 times too small)."""
    e, fc = _walk(spacing), _flight(duration, 0)
    hats = e.columns(fc)[:, 0, :]
    hats = hats[:, : hats.shape[1] // 3]
    A = np.concatenate([np.ones((len(fc.t), 1)), hats], 1)
    n_walks = 1500
    walks = np.cumsum(np.random.default_rng(1).standard_normal((len(fc.t), n_walks)) / np.sqrt(FS), 0)  # unit K
    knots = np.linalg.lstsq(A, walks, rcond=None)[0][1:]
    incs = np.diff(np.concatenate([np.zeros((1, knots.shape[1])), knots]), axis=0)
    expected = knot_increment_variance(e, fc)
    assert expected.shape == (hats.shape[1],)
    ratio = np.mean(incs**2, 1) / expected
    # 4 standard errors of the mean square of n_walks x knots increments (chi-square), 0.084 on 3 knots
    assert abs(ratio.mean() - 1) < 4 * np.sqrt(2 / (n_walks * len(ratio))) and (np.abs(ratio - 1) < 0.2).all(), ratio
    assert 1.14 < expected.mean() / (fc.t[-1] / hats.shape[1]) < 1.24  # 1.17 inside a layout, up to 1.24 at its ends


def test_the_walk_is_read_at_its_density_from_flights_of_different_lengths():
    """Six flights of 45 and 60 s (9 and 12 knots 5 s apart): the design pads the shorter flights' columns after their
    own three axes, which the reading split as if every flight had 12 knots per axis (other axes' knots and padding read
    as increments); and the spacing alone read K^2 17 % high."""
    k2 = []
    for rep in range(12):
        fcs = [_flight(60.0 if k % 2 else 45.0, 100 * rep + k) for k in range(6)]
        effects = {"bias": EFFECTS["bias"](), "bias_random_walk": _walk(5.0)}
        design = Design(fcs, effects, np.full(3, 1e-4 * np.sqrt(FS)))
        sel = SimpleNamespace(effects=effects, design=design, result=design.fit(["bias", "bias_random_walk"]))
        params, se = _walk_from_knots(sel)
        assert (se["density"] > 0).all()
        k2.append((params["density"] / K) ** 2)
    assert 0.9 < np.mean(k2) < 1.1, np.mean(k2, 0)  # standard error of the mean about 0.03
