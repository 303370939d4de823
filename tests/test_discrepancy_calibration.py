"""Issue 11, points 3-5: the sensor bandwidth as a library effect, calibrated decisions (null
bootstrap) and identifiability as a number. Own-simulator data (exact ground truth): fast."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.hidden import make_measured
from gyrodenoise.discrepancy.null import null_distribution
from gyrodenoise.discrepancy.rank import practical, select_effects
from gyrodenoise.discrepancy.report import _below_practical_md
from gyrodenoise.discrepancy.workflow import decide
from gyrodenoise.sim.context import SignalContext
from gyrodenoise.sim.effects import GSensitivity, SensorBandwidth, WhiteNoise

DURATION = 25.0


def _contexts(root, hidden, n, seed, trajectory="handheld"):
    names = make_measured(root, hidden, n, DURATION, seed=seed, trajectory=trajectory)
    return [load_fit_context(root, name) for name in names]


# ----------------------------------------------------------------------------- 3: sensor bandwidth


def test_floor_shape_is_the_simulated_low_passed_noise():
    rate, m, n = 200.0, 10, 200 * 10 * 120
    sig = SignalContext(t=np.arange(n) / (rate * m), omega=np.zeros((n, 3)), alpha=None, f=None, rate_hz=rate * m)
    rng = np.random.default_rng(0)
    y = WhiteNoise(density=np.full(3, 1e-4)).apply(sig, np.zeros((n, 3)), rng)
    y = SensorBandwidth(corner_hz=40.0).apply(sig, y, rng).reshape(-1, m, 3).mean(1)
    f, p = signal.welch(y, fs=rate, nperseg=256, axis=0)
    model = 2e-8 * SensorBandwidth.floor_shape(f, 40.0, rate)
    ok = (f > 2) & (f < 98)
    assert np.allclose(p[ok].mean(1), model[ok], rtol=0.15)
    assert SensorBandwidth.floor_shape(np.array([100.0]), 40.0, rate)[0] < 0.3  # a real droop
    # the motion part: a delay of 1 / (2 pi corner) at low frequencies
    t = np.arange(4000) / rate
    x = np.sin(2 * np.pi * 1.0 * t)[:, None]
    lag = np.argmax(np.correlate(SensorBandwidth.filter_rate(x, 40.0, rate)[:, 0], x[:, 0], "full")) - 3999
    assert abs(lag / rate - 1 / (2 * np.pi * 40.0)) < 1 / rate


def test_low_passed_sensor_is_named_bandwidth_not_vibration_nor_time_offset(tmp_path):
    fcs = _contexts(tmp_path, [SensorBandwidth(corner_hz=40.0)], 3, seed=4)
    _, sel, _ = decide(fcs[:2], fcs[2:], null_draws=0)
    assert sel.named == ["sensor_bandwidth"], sel.steps[0]["candidates"][:3]
    assert float(sel.params["sensor_bandwidth"]["corner_hz"]) == pytest.approx(40.0, rel=0.05)
    assert float(sel.se["sensor_bandwidth"]["corner_hz"]) > 0
    # the floor under the low-pass is the white noise's level at 0 Hz
    assert np.allclose(sel.params["white_noise"]["density"], 1.7e-4, rtol=0.05)


# ----------------------------------------------------------------------------- 4: null bootstrap


def test_null_distribution_calibrates_thresholds_with_common_random_numbers(tmp_path):
    fcs = _contexts(tmp_path, [], 2, seed=6)
    base = select_effects(fcs, candidates=[])
    cands = ["scale_factor", "time_offset", "vibration"]
    null = null_distribution(base, fcs, cands, draws=4, seed=3)
    again = null_distribution(base, fcs, cands, draws=4, seed=3)
    for c in cands:
        v = null.delta_bic[c]
        assert v.shape == (4,) and np.isfinite(v).all()
        assert np.array_equal(v, again.delta_bic[c])  # same seed, same worlds
        assert null.threshold(c, 10.0) >= max(10.0, float(np.quantile(v, 0.95, method="higher")))
        assert null.p_value(c, 1e9) == pytest.approx(1 / 5)
        assert null.p_value(c, -1e9) == pytest.approx(1.0)
    # nothing is hidden: the null's delta BIC of a linear effect sits near chi2 - k log n
    assert np.median(null.delta_bic["scale_factor"]) < 0


def test_decision_reports_thresholds_and_rank(tmp_path):
    fcs = _contexts(tmp_path, [GSensitivity(matrix=np.diag([4e-4, -3e-4, 5e-4]))], 3, seed=7)
    _, sel, null = decide(fcs[:2], fcs[2:], candidates=["g_sensitivity", "scale_factor"], null_draws=5)
    assert sel.named == ["g_sensitivity"]
    step = sel.steps[0]["candidates"][0]
    assert step["effect"] == "g_sensitivity" and step["delta_bic"] > step["threshold"] >= 10.0
    assert step["holdout_gain"] >= 0.01  # closes more than the practical minimum on the held-out flight
    assert null.p_value("g_sensitivity", step["delta_bic"]) == pytest.approx(1 / 6)


def test_practical_minimum_is_power_share_or_ten_second_drift(tmp_path):
    assert practical(0.02, None) and practical(0.005, 0.15) and practical(0.02, -0.3)
    assert not practical(0.005, 0.05) and not practical(0.005, None)
    # a sensor-constant effect: with the power share set between what it closes on the fit sequences
    # (22%) and on the held-out one (20%), the drift alternative alone names it
    fcs = _contexts(tmp_path, [GSensitivity(matrix=np.diag([4e-4, -3e-4, 5e-4]))], 3, seed=7)
    kw = {"candidates": ["g_sensitivity"], "min_gain": 0.21, "holdout": fcs[2:]}
    sel = select_effects(fcs[:2], min_drift_deg=0.1, **kw)
    assert sel.named == ["g_sensitivity"], sel.steps[0]["candidates"]
    step = sel.steps[0]["candidates"][0]
    assert step["gain"] >= 0.21 > step["holdout_gain"] and step["holdout_drift_reduction_deg"] >= 0.1
    assert select_effects(fcs[:2], min_drift_deg=np.inf, **kw).named == []
    # the held-out sequences decide: a share above what it closes even on the fit sequences (22%) does
    # not veto the drift alternative
    kw["min_gain"] = 0.5
    assert select_effects(fcs[:2], min_drift_deg=0.1, **kw).named == ["g_sensitivity"]
    # without it, the effect is reported as detected but below the practical minimum
    sel = select_effects(fcs[:2], min_drift_deg=np.inf, **kw)
    assert sel.named == [] and [c["effect"] for c in sel.below_practical] == ["g_sensitivity"]
    c = sel.below_practical[0]
    assert c["delta_bic"] >= c["threshold"] and c["holdout_gain"] < 0.5
    md = _below_practical_md({"below_practical": sel.below_practical})
    assert "below the practical minimum" in md[0] and md[-2].startswith("| g_sensitivity |")


# ----------------------------------------------------------------------------- 5: identifiability


def test_identifiability_is_a_number_that_predicts_detection(tmp_path):
    null = _contexts(tmp_path / "null", [], 2, seed=8)
    idf = select_effects(null, candidates=["g_sensitivity"]).identifiability["g_sensitivity"]
    assert idf["reference_datasheet"] == pytest.approx(0.5) and idf["unit"] == "deg/s/g"
    assert idf["identifiable"] and 0 < idf["min_magnitude_datasheet"] < 0.5  # hand-held motion: rich
    assert idf["expected_delta_bic"] > idf["threshold"]
    m = idf["min_magnitude"]  # SI: where the expected delta BIC reaches the threshold
    signs = np.random.default_rng(1).choice([-1.0, 1.0], (3, 3))
    for factor, named in ((4.0, True), (0.25, False)):
        fcs = _contexts(tmp_path / str(factor), [GSensitivity(matrix=factor * m * signs)], 2, seed=8)
        sel = select_effects(fcs, candidates=["g_sensitivity"], min_gain=0.0)
        assert ("g_sensitivity" in sel.named) is named, (factor, sel.steps[0]["candidates"])


def test_a_named_effect_is_reported_identifiable_beside_a_large_one(tmp_path):
    """The identifiability table is stated against the final model: a large hidden g-sensitivity swells the base
    model's residual, against which a time offset the selection names looked 'not identifiable' at 1 ms."""
    from gyrodenoise.sim.effects import TimeOffset

    g = GSensitivity(matrix=np.radians(10.0) / 9.80665 * np.random.default_rng(2).choice([-1.0, 1.0], (3, 3)))
    fcs = _contexts(tmp_path, [g, TimeOffset(delta=0.003)], 2, seed=8)
    sel = select_effects(fcs, candidates=["g_sensitivity", "time_offset"], min_gain=0.0)
    assert set(sel.named) == {"g_sensitivity", "time_offset"}, sel.steps[0]["candidates"]
    idf = sel.identifiability["time_offset"]
    assert idf["identifiable"] and idf["min_magnitude_datasheet"] < 1.0  # ms: the old table said 1.5, not identifiable


def test_g_sensitivity_on_a_turntable_is_not_identifiable_with_the_numbers(tmp_path):
    fcs = _contexts(tmp_path, [], 2, seed=9, trajectory="yaw_only")
    sel = select_effects(fcs, candidates=["g_sensitivity"])
    assert "g_sensitivity" in sel.not_identifiable and sel.named == []
    idf = sel.identifiability["g_sensitivity"]
    assert not idf["testable"] and idf["expected_delta_bic_at_prior"] < 10.0


# ------------------------------------------------------------------ time offset or sensor bandwidth


def test_delay_or_lowpass_separability_grows_with_the_delay(tmp_path):
    """A low-pass of corner 1 / (2 pi delay) is that delay plus a droop ~ (f / corner)^2 / 2: the
    expected delta BIC between the two explanations grows with the delay (~ delay^4) and is a
    number, stated with the equivalent corner."""
    from gyrodenoise.discrepancy.design import Design, noise_weights
    from gyrodenoise.discrepancy.identifiability import delay_or_lowpass
    from gyrodenoise.sim.effects import Bias, TimeOffset

    fcs = _contexts(tmp_path, [], 1, seed=5)
    sigma = noise_weights([fc.residual for fc in fcs])
    design = Design(fcs, {"bias": Bias(), "time_offset": TimeOffset()}, sigma)
    small = delay_or_lowpass(design, ["bias", "time_offset"], 1.0, 0.002, 10.0)
    big = delay_or_lowpass(design, ["bias", "time_offset"], 1.0, 0.02, 10.0)
    assert small.corner_hz == pytest.approx(1 / (2 * np.pi * 0.002))
    assert big.expected_delta_bic > 1000 * small.expected_delta_bic  # ~ 10^4 for a 10x delay
    assert big.separable
    assert "equivalent delay" in small.sentence() or small.separable


def test_low_pass_that_replaces_a_named_delay_is_reported(tmp_path, monkeypatch):
    """When the noise floor is not visible in the trusted band (behind a noisy motion capture) the
    selection names the delay, and `lowpass_choice.choose` may then keep a low-pass instead. That design
    lacked the low-pass, and `fill_params` stopped with KeyError 'sensor_bandwidth' (a blind trial with a
    0.05 deg mocap, benchmarks/blind_discrepancy). A 5 Hz low-pass (32 ms of delay, a large droop)."""
    from gyrodenoise.discrepancy import rank

    monkeypatch.setattr(rank, "fit_floor_shape", lambda *a, **k: None)  # the floor not visible
    fcs = _contexts(tmp_path, [SensorBandwidth(corner_hz=5.0)], 2, seed=4)
    sel = select_effects(fcs, candidates=["time_offset", "sensor_bandwidth"])
    assert sel.delay_or_lowpass["kept"] == "sensor_bandwidth" and sel.named == ["sensor_bandwidth"]
    assert float(sel.params["sensor_bandwidth"]["corner_hz"]) == pytest.approx(5.0, rel=0.05)
    # an exact ground truth: no error of its own to smooth, a clear choice, no caution
    assert sel.delay_or_lowpass["truth_error_smoothing_bic"] == 0.0 and sel.cautions == []
    assert 25 < 1e3 * sel.delay_or_lowpass["delay_s"] < 40  # the delay it replaced stays in the record
