"""The held-out transfer check: a named sensor constant refitted on the held-out sequences (`discrepancy.transfer`)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.workflow import decide

SENSOR = "bias=0.5deg/s,white_noise=0.007deg/s/sqrt(Hz),scale_factor=3000ppm"


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """Test-world flights (procedural motion): 'fit' and 'same' from one sensor, 'other' from another draw."""
    from gyrodenoise.testworld import make_sequence

    root = tmp_path_factory.mktemp("transfer")
    for motion, seed, name in ((1, 7, "fit"), (2, 7, "same"), (2, 8, "other")):
        make_sequence(root, f"procedural:{motion}", SENSOR, preset="none", duration=40.0, seed=seed, name=name)
    return {name: load_fit_context(root, name) for name in ("fit", "same", "other")}


def test_a_constant_that_does_not_transfer_is_caught_and_its_errors_scaled(flights):
    _, same, _ = decide([flights["fit"]], [flights["same"]], candidates=["scale_factor"], null_draws=0)
    _, other, _ = decide([flights["fit"]], [flights["other"]], candidates=["scale_factor"], null_draws=0)
    assert "scale_factor" in same.named and "scale_factor" in other.named
    t_same, t_other = same.transfer["scale_factor"], other.transfer["scale_factor"]
    assert t_same["dof"] == t_other["dof"] == 3 and t_same["separable_on_held_out"]
    assert t_other["p_value"] < 1e-6 < t_same["p_value"]  # another sensor's scale factors: thousands of ppm apart
    assert t_other["se_factor"] == pytest.approx(t_other["birge_ratio"]) and t_other["birge_ratio"] > 5
    assert t_same["se_factor"] == max(1.0, t_same["birge_ratio"])
    # the same fit, so the raw errors are equal: the reported ones differ by the factors exactly
    ratio = np.ravel(other.se["scale_factor"]["scale"]) / np.ravel(same.se["scale_factor"]["scale"])
    np.testing.assert_allclose(ratio, t_other["se_factor"] / t_same["se_factor"], rtol=1e-9)


@pytest.fixture(scope="module")
def g_world(tmp_path_factory):
    """Test-world flights behind a Vicon-like mocap (60 s, procedural motion): s1-s5 from one sensor with a
    g-sensitivity of 0.1 deg/s/g; h4, h5 the same sensor but 15 % more g-sensitivity (held-out motion of s4, s5); o2,
    o3 other sensors (their own signs)."""
    from gyrodenoise.testworld import make_sequence

    root = tmp_path_factory.mktemp("g_world")
    made = [(k, 0, "0.1", f"s{k}") for k in range(1, 6)]
    made += [(4, 0, "0.115", "h4"), (5, 0, "0.115", "h5"), (2, 102, "0.1", "o2"), (3, 103, "0.1", "o3")]
    for motion, seed, g, name in made:
        make_sequence(root, f"procedural:{motion}", f"g_sensitivity={g}deg/s/g", seed=seed, duration=60.0, name=name)
    return {name: load_fit_context(root, name) for *_, name in made}


def _g_transfer(world, fit, held):
    _, sel, _ = decide([world[n] for n in fit], [world[n] for n in held], candidates=["g_sensitivity"], null_draws=0)
    assert sel.named == ["g_sensitivity"], sel.steps
    return sel.transfer["g_sensitivity"]


def test_a_constant_shared_by_every_flight_is_not_called_different(g_world):
    """The regression's covariances fall short by the same factor on every flight behind this mocap (its angle error
    times the body rate), so against them the same g-sensitivity was called different on the held-out flights (R 2.1,
    p 5e-6; p < 0.01 on 5 of 12 seeds). Against the fit sequences' own spread it is not."""
    t = _g_transfer(g_world, ["s1", "s2", "s3"], ["s4", "s5"])
    assert t["p_value"] > 0.05
    assert t["p_value_regression_se"] < 1e-4 and t["birge_ratio"] > 2  # what the check said before
    assert t["reference"] == "fit sequences" and t["fit_sequences"]["sequences"] == 3
    assert t["fit_sequences"]["p_value"] > 0.05 and t["fit_sequences"]["halves"]["sequences"] == 5
    assert t["se_factor"] == pytest.approx(t["birge_ratio"])  # the standard errors are scaled as before


def test_a_constant_that_differs_is_still_called_so(g_world):
    """15 % more g-sensitivity on the held-out flights is called; so are fit flights from three sensors, through the
    fit sequences' spread against their halves (the held-out test, set against that spread, cannot see it). (With
    the whole vocabulary a random walk takes the three sensors' disagreement and no g-sensitivity is named.)"""
    assert _g_transfer(g_world, ["s1", "s2", "s3"], ["h4", "h5"])["p_value"] < 1e-3
    mixed = _g_transfer(g_world, ["s1", "o2", "o3"], ["s4", "s5"])
    assert mixed["fit_sequences"]["p_value"] < 1e-6 and mixed["fit_sequences"]["birge_ratio"] > 5
