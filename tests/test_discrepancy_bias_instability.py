"""The bias instability (flicker floor): the test world's independent generator, the workflow's check after the
selection, and what the report and the simulator model make of it."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from gyrodenoise.allan import pooled_allan
from gyrodenoise.discrepancy import bias_instability
from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.hidden import make_measured
from gyrodenoise.discrepancy.sim_model import simulator_model
from gyrodenoise.discrepancy.workflow import decide
from gyrodenoise.sim.effects import build_effect, effect_from_config
from gyrodenoise.testworld.sensor import flicker_bias
from gyrodenoise.testworld.spec import EffectSpecError, parse_effects, realise

DEG_H = np.pi / 180 / 3600


def test_the_test_worlds_flicker_has_a_flat_allan_floor_at_the_given_level():
    fs, floor = 50.0, np.array([1e-4, 3e-4, 5e-5])
    xs = [flicker_bias(int(300 * fs), fs, floor, 1000.0, np.random.default_rng(i)) for i in range(12)]
    adev = pooled_allan(xs, fs, np.array([0.5, 2.0, 8.0, 30.0]))
    assert np.allclose(adev / floor, 1.0, atol=0.12), adev / floor
    # a short tau_max: the floor falls off beyond it (a stationary bias, not a flicker out to hours)
    short = [flicker_bias(int(300 * fs), fs, floor, 2.0, np.random.default_rng(i)) for i in range(12)]
    assert (pooled_allan(short, fs, np.array([60.0])) / floor < 0.6).all()
    with pytest.raises(ValueError, match="tau_max"):
        flicker_bias(100, fs, floor, 0.0, np.random.default_rng(0))


def test_the_test_world_reads_a_floor_in_datasheet_units():
    eff = realise(parse_effects("bias_instability=14.5deg/h"), np.random.default_rng(0))
    assert np.allclose(eff.get("bias_instability"), 14.5 * DEG_H)
    assert float(eff.get("bias_instability", "tau_max")) == 1000.0
    with pytest.raises(EffectSpecError, match="negative"):
        realise(parse_effects("bias_instability=-3deg/h"), np.random.default_rng(0))


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """Five 60-s hand-held flights (own simulator: bias and white noise), exact truth."""
    root = tmp_path_factory.mktemp("flights")
    names = make_measured(root, [], 5, 60.0, seed=3)
    return [load_fit_context(root, n) for n in names]


def _with(fcs, bias):
    """The flights with a bias process added to the gyro, each its own draw."""
    return [dataclasses.replace(fc, gyro=fc.gyro + bias(len(fc.t), fc.rate_hz, k)) for k, fc in enumerate(fcs)]


def test_a_hidden_flicker_floor_is_named_with_its_level_and_replaces_the_walk_that_stood_in(flights):
    floor = np.full(3, 150 * DEG_H)  # the test world's generator, not the simulator's Gauss-Markov bank
    fcs = _with(flights, lambda n, fs, k: flicker_bias(n, fs, floor, 1000.0, np.random.default_rng(k)))
    _, sel, _ = decide(fcs[:3], fcs[3:], null_draws=0)
    check = sel.instability
    assert check["named"], check
    assert "bias_instability" in sel.named and "bias_random_walk" not in sel.named, sel.named
    assert min(check["floor_z"]) >= bias_instability.MIN_Z
    assert min(check["holdout_floor_z"]) >= bias_instability.MIN_Z_HOLDOUT
    assert np.allclose(sel.params["bias_instability"]["instability"], floor, rtol=0.3)
    assert (sel.se["bias_instability"]["instability"] > 0).all()
    greedy = [s["added"] for s in sel.steps if s.get("added")]
    assert "bias_random_walk" in greedy  # the selection named a walk for it; judged beside the floor, it left
    assert check["random_walk"]["kept"] is False and "bias_random_walk" not in sel.selected


def test_a_random_walk_in_the_base_model_stays_beside_a_named_floor(flights):
    floor = np.full(3, 150 * DEG_H)
    fcs = _with(flights, lambda n, fs, k: flicker_bias(n, fs, floor, 1000.0, np.random.default_rng(k)))
    base = ["bias", "white_noise", "bias_random_walk"]
    _, sel, _ = decide(fcs[:3], fcs[3:], base, candidates=["bias_instability"], null_draws=0)
    assert sel.named == ["bias_instability"] and "bias_random_walk" in sel.selected
    assert "random_walk" not in sel.instability  # a base effect is not judged as a stand-in


def test_no_floor_is_named_on_white_noise_nor_on_a_random_walk(flights):
    _, sel, _ = decide(flights[:3], flights[3:], null_draws=0)
    assert not sel.instability["named"] and "bias_instability" not in sel.named
    assert max(sel.instability["floor_z"]) < bias_instability.MIN_Z

    def walk(n, fs, k):  # 2e-5 rad/s^2/sqrt(Hz): EuRoC's Kalibr figure for the ADIS16448
        rng = np.random.default_rng(100 + k)
        return np.cumsum(rng.standard_normal((n, 3)) * 2e-5 * np.sqrt(1 / fs), 0)

    fcs = _with(flights, walk)
    _, sel, _ = decide(fcs[:3], fcs[3:], null_draws=0)
    assert "bias_instability" not in sel.named, sel.instability


def test_candidates_without_the_floor_leave_it_unjudged(flights):
    _, sel, _ = decide(flights[:3], flights[3:], candidates=["scale_factor"], null_draws=0)
    assert sel.instability is None
    _, sel, _ = decide(flights[:3], flights[3:], candidates=["bias_instability"], null_draws=0)
    assert sel.instability is not None and sel.named == []


def test_the_simulator_model_carries_a_named_floor():
    report = {
        "base_params": {"white_noise": {"density": [1.7e-4] * 3}},
        "named_effects": [
            {"name": "bias_instability", "params": {"instability": [7e-5] * 3, "tau_min": 1.0, "tau_max": 1000.0}}
        ],
    }
    model = simulator_model(report)
    entry = model["error_model"][-1]
    assert entry["name"] == "bias_instability"
    effect = effect_from_config(entry)
    assert np.allclose(effect.params["instability"], 7e-5)
    assert build_effect("bias_instability", instability=np.full(3, 7e-5)).magnitude() == pytest.approx(7e-5)


def test_the_cli_takes_the_floor_as_a_candidate_but_not_as_a_base_effect(tmp_path):
    def cli(*extra):
        cmd = [sys.executable, "-m", "gyrodenoise.discrepancy", "--root", str(tmp_path), "--fit", "a"]
        cmd += ["--holdout", "b", "--out", str(tmp_path / "out"), *extra]
        return subprocess.run(cmd, capture_output=True, text=True)

    bad = cli("--base", "bias,bias_instability")
    assert bad.returncode == 2 and "unknown effect(s) ['bias_instability']" in bad.stderr
    ok = cli("--candidates", "bias_instability,scale_factor")
    assert "unknown effect" not in ok.stderr  # past the arguments: it fails on the missing sequences instead
    assert ok.returncode == 2 and "error:" in ok.stderr


def test_a_model_whose_re_simulations_wander_far_more_than_the_flights_leaves_the_floor_unjudged(flights, monkeypatch):
    """EuRoC's default split: the selected model's re-simulations made floors 19-50 of their own standard deviations
    above the flights' (its truth follows the gyro): no null to judge a floor by, so it is not identifiable."""
    _, sel, _ = decide(flights[:3], flights[3:], candidates=["scale_factor"], null_draws=0)  # the floor unjudged
    rng = np.random.default_rng(0)
    fake = {"floor2": rng.normal(1e-6, 1e-8, (40, 3)), "walk2": rng.normal(0.0, 1e-9, (40, 3))}
    monkeypatch.setattr(bias_instability, "_null", lambda *a, **k: fake)
    out = bias_instability.check(sel, flights[:3], flights[3:], 0.05)
    assert out["null_mismatch"] and not out["named"] and max(out["floor_z"]) < -bias_instability.MISMATCH_Z
    assert "bias_instability" in sel.not_identifiable and "bias_instability" not in sel.named


def test_the_report_says_what_the_check_found():
    from gyrodenoise.discrepancy.report import _instability_md

    base = {"draws": 40, "min_z": 3.5, "min_z_holdout": 3.5, "longest_tau_s": 13.2, "floor_z": [10.0, 12.0, 9.0]}
    named = {
        **base,
        "holdout_floor_z": [8.0, 7.0, 6.0],
        "named": True,
        "floor_rad_s": [50 * DEG_H] * 3,
        "random_walk": {"walk_z": [0.1, -0.5, 0.3], "ratio": [0.9, 1.1, 1.0], "kept": False},
        "vibration": {"band_hz": [1.4, 1.8], "z": 6.7, "ratio": 1.26, "kept": False},
    }
    text = " ".join(_instability_md({"bias_instability_check": named}))
    assert "Named: floor [50, 50, 50] deg/h" in text
    assert "random walk the selection named is replaced by it" in text and "1.4 Hz is replaced" in text
    text = " ".join(_instability_md({"bias_instability_check": {**base, "named": False}}))
    assert text.strip().endswith("Not named.")
    mismatch = {**base, "floor_z": [-67.0, -99.0, -90.0], "named": False, "null_mismatch": True}
    assert "Not judged (not identifiable)" in " ".join(_instability_md({"bias_instability_check": mismatch}))
    assert _instability_md({"bias_instability_check": None}) == []


def test_a_mismatch_on_the_held_out_flights_leaves_the_floor_unjudged_too(flights, monkeypatch):
    """EuRoC fitted on V1_02 alone: fit z up to 54, the held-out V2_03 -127 to -529 (a floor on the fit flight that
    the model's re-simulations of the held-out one make far more of): not a floor to name, not identifiable."""
    _, sel, _ = decide(flights[:3], flights[3:], candidates=["scale_factor"], null_draws=0)
    fit, hold = flights[:3], flights[3:]
    measured = {
        tag: bias_instability.allan_terms(bias_instability.wander_residuals(sel, f), f, False)
        for tag, f in ((11, fit), (14, hold))
    }
    rng = np.random.default_rng(1)

    def fake(sel_, fcs, angle_noise, seed, tag):
        m = measured[tag]
        sd = 0.01 * m["longest"]
        centre = m["floor2"] - 0.5 * m["longest"] if tag == 11 else m["floor2"] + 100 * sd
        return {"floor2": centre + sd * rng.standard_normal((40, 3)), "walk2": np.zeros((40, 3))}

    monkeypatch.setattr(bias_instability, "_null", fake)
    out = bias_instability.check(sel, fit, hold, 0.05)
    assert min(out["floor_z"]) > 10 and max(out["holdout_floor_z"]) < -bias_instability.MISMATCH_Z
    assert out["null_mismatch"] and not out["named"] and "bias_instability" in sel.not_identifiable


def test_flights_too_short_for_the_fit_leave_the_floor_unjudged_and_no_white_noise_none_at_all(flights):
    from types import SimpleNamespace

    short = [np.random.default_rng(0).standard_normal((200, 3))]
    assert bias_instability.allan_terms(short, [SimpleNamespace(rate_hz=200.0, extra={"band_hz": 5.0})], False) is None
    with_nan = np.random.default_rng(0).standard_normal((20000, 3))
    with_nan[5] = np.nan
    assert bias_instability.allan_terms([with_nan], [SimpleNamespace(rate_hz=200.0, extra={})], False) is None
    # a base without white noise: no noise model to re-simulate a floor against
    _, sel, _ = decide(flights[:3], flights[3:], ["bias"], candidates=["bias_instability"], null_draws=0)
    assert sel.instability is None


def test_the_report_says_when_the_flights_were_too_short_to_judge_a_floor():
    from gyrodenoise.discrepancy.report import _instability_md

    short = {"named": False, "not_judged": "fewer than 6 cluster times in the compared band"}
    assert _instability_md({"bias_instability_check": short}) == [
        "Bias instability was not judged: fewer than 6 cluster times in the compared band.",
        "",
    ]
