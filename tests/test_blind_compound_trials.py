"""The blind runner's compound trials (several hidden effects at once): how the standalone generator composes them
and how the runner scores a report against them (benchmarks/blind_discrepancy/generate.py and run.py)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "blind_discrepancy"))
import generate  # noqa: E402
import run  # noqa: E402


def _report(values: dict[str, dict[str, tuple]]) -> dict:
    """A report.json's named_effects: name -> {parameter: (value, standard error)}."""
    return {
        "named_effects": [
            {
                "name": name,
                "datasheet": {k: {"value": v, "standard_error": se, "unit": "u"} for k, (v, se) in params.items()},
            }
            for name, params in values.items()
        ]
    }


SCALE = [3000.0, -2000.0, 4000.0]
DELAY = 4.0
COMPOUND_KEY = {
    "hidden": [
        {"kind": "time_offset", "params": {"imu_stamp_late_ms": DELAY}},
        {"kind": "scale_factor", "params": {"scale_ppm": SCALE}},
    ]
}


def test_compound_named_exactly_and_agreeing_passes():
    rep = _report({"time_offset": {"delta": (4.01, 0.01)}, "scale_factor": {"scale": ([2990, -2010, 4020], [20] * 3)}})
    s = run.score("t", COMPOUND_KEY, rep)
    assert s["verdict"] == "PASS"
    assert len(s["z"]) == 4  # the delay's and the three scales' z pooled


def test_compound_one_value_off_fails_the_pooled_test():
    rep = _report({"time_offset": {"delta": (4.2, 0.01)}, "scale_factor": {"scale": ([2990, -2010, 4020], [20] * 3)}})
    assert run.score("t", COMPOUND_KEY, rep)["verdict"] == "MAGNITUDE OFF"


def test_compound_partly_named_is_partial_and_says_what_is_missing():
    s = run.score("t", COMPOUND_KEY, _report({"time_offset": {"delta": (4.0, 0.01)}}))
    assert s["verdict"] == "PARTIAL"
    assert s["missed"] == ["scale_factor"]
    s = run.score("t", COMPOUND_KEY, _report({"time_offset": {"delta": (4.0, 0.01)}, "misalignment": {}}))
    assert s["verdict"] == "PARTIAL + EXTRA"


def test_compound_none_of_the_hidden_named_is_wrong_and_nothing_is_a_miss():
    assert run.score("t", COMPOUND_KEY, _report({"misalignment": {}}))["verdict"] == "WRONG"
    assert run.score("t", COMPOUND_KEY, _report({}))["verdict"] == "MISS"


def test_single_effect_keys_score_as_before():
    key = {"hidden": {"kind": "scale_factor", "params": {"scale_ppm": SCALE}}}
    good = _report({"scale_factor": {"scale": ([2990, -2010, 4020], [20] * 3)}})
    assert run.score("t", key, good)["verdict"] == "PASS"
    extra = _report({"scale_factor": {"scale": ([2990, -2010, 4020], [20] * 3)}, "time_offset": {}})
    assert run.score("t", key, extra)["verdict"] == "PASS + EXTRA"
    assert run.score("t", {"hidden": None}, _report({}))["verdict"] == "PASS"
    assert run.expected("t", key)[0] == "scale_factor"


def test_generator_refuses_effects_it_cannot_compose():
    lp, asym = generate.TRIALS["sensor_lowpass_40hz"], generate.TRIALS["scale_asymmetry"]
    with pytest.raises(ValueError, match="more than one"):
        generate.hidden_effects((lp, asym))
    with pytest.raises(ValueError, match="a kind twice"):
        generate.hidden_effects((lp, lp))
    assert set(generate.hidden_effects(generate.TRIALS["consumer_imu"])) == {
        "sensor_lowpass",
        "misalignment",
        "scale_factor",
        "g_sensitivity",
        "quantization",
    }


def test_generator_composes_a_scale_factor_on_the_misaligned_rate(tmp_path):
    """Same seed, misalignment alone and with a scale factor: the gyros differ by the scale factor times the
    misaligned rate (neither effect draws from the generator, so the bias and noise draws are the same)."""
    mis, scale = generate.TRIALS["misalignment"], generate.TRIALS["scale_factor"]
    generate.make_sequence(tmp_path / "m", 7, 8.0, mis)
    generate.make_sequence(tmp_path / "ms", 7, 8.0, (mis, scale))
    g_m, g_ms = (np.loadtxt(tmp_path / d / "mav0/imu0/data.csv", delimiter=",")[:, 1:4] for d in ("m", "ms"))
    s = np.asarray(scale.params["scale_ppm"]) * 1e-6
    assert np.abs(g_ms - g_m).max() > 1e-3  # the scale factor is there: ~1 rad/s x 4000 ppm
    # what is left is the scale factor times bias and noise (~0.02 rad/s x 4000 ppm)
    assert np.abs(g_ms - g_m - s * g_m).max() < 2e-4
