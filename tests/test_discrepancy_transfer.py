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
