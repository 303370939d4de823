"""Does a ground truth follow the gyro it judges? (gyrodenoise.discrepancy.truth_check)"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrodenoise.data.readers import ImuData
from gyrodenoise.discrepancy.report import _truth_caution, _truth_check_md
from gyrodenoise.discrepancy.truth_check import (
    FOLLOWS_RATIO,
    check_sequence,
    check_truth,
    followed_bands,
    gyro_truth_pairs,
    white_reference,
)
from gyrodenoise.so3 import integrate_gyro

RATE = 200.0
DENSITY = 2e-3  # rad/s/sqrt(Hz)


def recording(kind: str, seconds: float = 120.0, seed: int = 0):
    """(IMU, truth stamps, truth quaternions): slow motion, a gyro with white noise of DENSITY, and a truth that
    is exact ('exact'), a tracker's noisy orientation ('mocap') or the gyro itself integrated ('follows');
    'lowpassed': an exact truth and a gyro (motion and noise) through a first-order 25 Hz low-pass."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t_ns = 1_000_000_000 + np.round(np.arange(n) * 1e9 / RATE).astype(np.int64)
    t = (t_ns - t_ns[0]) * 1e-9
    w = np.stack([0.4 * np.sin(2 * np.pi * 0.2 * t), 0.3 * np.cos(2 * np.pi * 0.3 * t), 0.2 * np.sin(0.5 * t)], 1)
    gyro = w + DENSITY * np.sqrt(RATE) * rng.standard_normal((n, 3))
    if kind == "lowpassed":
        from scipy import signal

        gyro = signal.lfilter(*signal.butter(1, 25.0, fs=RATE), gyro, axis=0)
    # the truth's rate over [t_k, t_k+1]: the true motion's, or the gyro's own (a fused estimate dominated by it)
    step = 0.5 * (w[1:] + w[:-1]) if kind != "follows" else 0.5 * (gyro[1:] + gyro[:-1])
    if kind == "follows":  # a little of the estimate's own error
        step = step + 0.1 * DENSITY * np.sqrt(RATE) * rng.standard_normal(step.shape)
    rates = np.concatenate([np.zeros((1, 3)), step])  # rates[k]: over [t_k-1, t_k]
    truth = Rotation.from_matrix(integrate_gyro(np.eye(3), rates, np.full(n, 1 / RATE)))
    if kind == "mocap":
        truth = truth * Rotation.from_rotvec(1e-3 * rng.standard_normal((n, 3)))
    imu = ImuData(t_ns, gyro, np.zeros((n, 3)), Path("imu.csv"))
    return imu, t_ns, truth.as_quat()


def run(kind: str, density: float | None = DENSITY) -> dict:
    imu, gt_t, q = recording(kind)
    gyro, truth, idx = gyro_truth_pairs(gt_t, q, imu)
    white = white_reference(density, imu.t_ns, gt_t, idx) if density else None
    return check_truth(gyro, truth, RATE, white, density)


def test_an_exact_truth_leaves_the_gyro_noise_and_is_not_flagged():
    c = run("exact")
    ratios = np.array([b["residual_over_noise"] for b in c["bands"]])
    # the reference is put through the same averaging as the gyro: ~1 in every band, 40-80 Hz included
    assert len(c["bands"]) == 5 and np.all((ratios > 0.7) & (ratios < 1.4)), ratios
    assert followed_bands(c) == []


def test_a_low_passed_gyro_behind_an_exact_truth_is_not_taken_for_a_truth_that_follows_it():
    """Above its corner the low-pass takes the gyro's noise below the datasheet's: against that figure the residual
    looks too small; against the gyro's own floor it does not."""
    c = run("lowpassed")
    top = c["bands"][-1]
    floor_share = np.array(top["own_floor_over_noise"])
    assert top["band_hz"] == [40.0, 80.0] and np.all(floor_share < 0.5), floor_share
    against_datasheet = np.array(top["residual_over_noise"]) * floor_share  # what the datasheet alone gave
    assert np.all(against_datasheet < FOLLOWS_RATIO), against_datasheet
    assert followed_bands(c) == []
    ratios = np.array([b["residual_over_noise"] for b in c["bands"]])
    assert np.all((ratios > 0.7) & (ratios < 1.4)), ratios


def test_a_truth_made_from_the_gyro_is_flagged_in_every_band():
    c = run("follows")
    ratios = np.array([b["residual_over_noise"] for b in c["bands"]])
    assert np.all(ratios < 0.1 * FOLLOWS_RATIO), ratios
    # its gyro holds the datasheet's noise: its floor is that noise, so the reference stays about the datasheet's
    floors = np.array([b["own_floor_over_noise"] for b in c["bands"]])
    assert np.all((floors > 0.8) & (floors < 1.25)), floors
    assert followed_bands(c) == [b["band_hz"] for b in c["bands"]]
    assert min(c["bands"][0]["coherence"]) > 0.95  # the truth carries the gyro's noise


def test_a_noisy_tracker_is_independent_and_without_the_density_nothing_is_flagged():
    c = run("mocap")
    assert followed_bands(c) == [] and min(c["bands"][-1]["residual_over_noise"]) > 10
    c = run("follows", density=None)
    assert followed_bands(c) == [] and all(b["follows_gyro"] is None for b in c["bands"])


def test_gyro_truth_pairs_refuses_records_that_do_not_overlap():
    imu, gt_t, q = recording("exact", seconds=5.0)
    with pytest.raises(ValueError, match="cover the same time"):
        gyro_truth_pairs(gt_t + 10**12, q, imu)


def test_report_cautions_when_a_truth_follows_the_gyro():
    flagged = {"truth_rate_hz": 200.0, "noise_density": DENSITY, "bands": run("follows")["bands"]}
    clean = {"truth_rate_hz": 200.0, "noise_density": DENSITY, "bands": run("exact")["bands"]}
    report = {
        "fit_sequences": ["a"],
        "holdout_sequences": ["b"],
        "base_model": ["bias", "white_noise"],
        "verdict": "no effect named",
        "named_effects": [],
        "not_identifiable": [],
        "gap_before": {},
        "gap_after": {},
        "truth_check": {
            "a": {**clean, "follows_gyro_bands_hz": followed_bands(clean)},
            "b": {**flagged, "follows_gyro_bands_hz": followed_bands(flagged)},
        },
    }
    caution = "\n".join(_truth_caution(report))
    assert "Caution: the ground truth follows the gyro" in caution and "b: 2-5 Hz" in caution and "a:" not in caution
    table = "\n".join(_truth_check_md(report))
    rows = {line.split(" | ")[0]: line for line in table.splitlines() if line.startswith(("| a |", "| b |"))}
    assert rows["| a"].count(" *") == 0 and rows["| b"].count(" *") == 5


@pytest.mark.parametrize(
    "mocap, effects",
    [
        ("ideal", None),
        ("euroc-gt", None),
        ("euroc-fused", None),
        ("ideal", "time_offset=5ms"),
        ("euroc-fused", "time_offset=5ms"),
    ],
)
def test_the_independent_test_world_truths(mocap, effects, tmp_path):
    """Data this module did not make: gyrodenoise.testworld's integrating sensor (null preset: white noise of
    1.6968e-4 rad/s/sqrt(Hz)) with an exact truth, its EuRoC-like measured one (200 Hz, 0.01 deg), and a
    tracker fused with the gyro by a 5-s complementary filter (as EuRoC's Machine Hall truth is made); with a
    5-ms time offset too, which the check must align before it compares (motion x delay would hide the fusion)."""
    from gyrodenoise.testworld import MOCAP_PRESETS, make_sequence

    seq = make_sequence(tmp_path, "procedural", effects, duration=60.0, seed=1, name="s", mocap=MOCAP_PRESETS[mocap])
    c = check_sequence(seq.imu_file.parent.parent, noise_density=1.6968e-4)
    assert c["lag_s"] == pytest.approx(0.005 if effects else 0.0, abs=2e-4)
    ratios = np.array([b["residual_over_noise"] for b in c["bands"]])
    assert len(ratios) == 5
    if mocap == "euroc-fused":  # the truth carries the gyro: every band flagged
        assert followed_bands(c) == [b["band_hz"] for b in c["bands"]] and ratios.max() < 0.3, ratios
        return
    assert followed_bands(c) == []
    if mocap == "ideal":  # nothing but the sensor's noise in the residual: the reference matches it
        assert np.all((ratios > 0.7) & (ratios < 1.5)), ratios


def _contexts(names: str, f_max_hz: float = 7.0) -> list:
    from types import SimpleNamespace

    return [SimpleNamespace(name=n, extra={"band": SimpleNamespace(f_max_hz=f_max_hz)}) for n in names]


def test_effects_judged_against_a_truth_that_follows_the_gyro_are_withheld():
    from gyrodenoise.discrepancy.truth_rule import truth_free_vocabulary, truth_rule

    follows, clean = run("follows"), run("exact")
    named = ["scale_factor", "quantization", "vibration"]
    rule = truth_rule(_contexts("ab"), _contexts("h"), {"a": clean, "b": follows, "h": clean})
    assert rule.fit_followed == {"b": [[2.0, 5.0], [5.0, 10.0]]}  # the bands that start inside b's compared band
    assert not rule.decided and rule.withheld(named) == ["scale_factor", "vibration"]  # quantization: gyro's values
    assert "not decided (it follows the gyro on b)" in rule.note()
    # a truth that follows the gyro only above the compared band, or no check at all: nothing withheld
    assert truth_rule(_contexts("b", 1.5), _contexts("h"), {"b": follows}).withheld(named) == []
    assert truth_rule(_contexts("ab"), _contexts("h"), None).withheld(named) == []
    assert truth_rule(_contexts("ab"), _contexts("h"), None).note() == ""
    assert sorted(truth_free_vocabulary(["bias", "white_noise"], None)) == ["quantization", "saturation"]
    assert truth_free_vocabulary(["bias"], ["scale_factor", "saturation"]) == ["saturation"]


def test_held_out_truths_that_follow_the_gyro_are_set_aside_or_leave_the_effects_undecided():
    from gyrodenoise.discrepancy.truth_rule import truth_rule, with_truth_rule

    follows, clean = run("follows"), run("exact")
    named = ["scale_factor", "quantization"]
    # one held-out truth follows: it is set aside, the other judges the transfer, the effects are decided
    some = truth_rule(_contexts("a"), _contexts("gh"), {"a": clean, "g": follows, "h": clean})
    assert some.holdout_followed == {"g": [[2.0, 5.0], [5.0, 10.0]]} and some.holdout_kept == ["h"]
    assert some.decided and some.withheld(named) == [] and "held-out g set aside" in some.note()
    # every held-out truth follows: nothing independent to judge transfer on, so not decided (gaps on all)
    every = truth_rule(_contexts("a"), _contexts("g"), {"a": clean, "g": follows})
    assert every.holdout_kept == ["g"] and not every.decided and every.withheld(named) == ["scale_factor"]
    assert "not decided (it follows the gyro on every held-out sequence (g))" in every.note()
    both = truth_rule(_contexts("a"), _contexts("gh"), {"a": follows, "g": follows, "h": clean})
    assert both.note().startswith("effects judged against the ground truth: not decided (it follows the gyro on a)")
    assert both.note().endswith("; held-out g set aside (its ground truth follows the gyro)")

    calls = []

    def select(hold, candidates):  # what the selection was run on, and what it would name
        calls.append(([fc.name for fc in hold], candidates))
        return len(calls), named if candidates is None else [c for c in named if c in candidates]

    fit, hold = _contexts("a"), _contexts("gh")
    result, rule, withheld = with_truth_rule(select, fit, hold, {"a": clean, "g": follows, "h": clean}, [], None)
    assert calls == [(["g", "h"], None), (["h"], None)] and result == 2 and withheld == []  # rerun on h alone
    calls.clear()
    result, rule, withheld = with_truth_rule(select, fit, _contexts("g"), {"a": clean, "g": follows}, [], None)
    assert calls[1][0] == ["g"] and sorted(calls[1][1]) == ["quantization", "saturation"]  # truth-free rerun
    assert withheld == ["scale_factor"] and not rule.decided
    calls.clear()
    with_truth_rule(select, fit, hold, {"a": clean, "g": clean, "h": clean}, [], None)
    assert len(calls) == 1  # nothing followed: one selection


def test_report_says_what_was_withheld_and_why():
    flagged = {"truth_rate_hz": 200.0, "noise_density": DENSITY, "bands": run("follows")["bands"]}
    report = {"truth_check": {"b": {**flagged, "follows_gyro_bands_hz": followed_bands(flagged)}}}
    report["truth_followed"] = {"fit_sequences": {"b": [[2.0, 5.0]]}, "withheld": ["scale_factor"]}
    text = "\n".join(_truth_caution(report))
    assert "not decided" in text and "withheld: scale_factor" in text and "quantization, saturation" in text
    report["truth_followed"]["withheld"] = []
    assert "cannot be seen in the residual" in "\n".join(_truth_caution(report))
    # a held-out truth that follows the gyro: set aside when another is left, else the transfer is not judged
    aside = {"fit_sequences": {}, "holdout_sequences": {"b": [[2.0, 5.0]]}, "holdout_used": ["c"], "withheld": []}
    report["truth_followed"] = {**aside, "decided": True}
    text = "\n".join(_truth_caution(report))
    assert "held-out b was set aside" in text and "not decided" not in text
    report["truth_followed"] = {**aside, "holdout_used": ["b"], "decided": False}
    text = "\n".join(_truth_caution(report))
    assert "every held-out sequence's truth follows the gyro" in text and "not decided" in text
    report["truth_followed"]["fit_sequences"] = {"a": [[2.0, 5.0]]}
    text = "\n".join(_truth_caution(report))
    assert "compared band (a) and every held-out sequence's truth follows the gyro" in text


def test_a_second_selection_on_other_held_out_sequences_reuses_the_null_distribution(monkeypatch):
    from types import SimpleNamespace

    from gyrodenoise.discrepancy import workflow

    nulls = []

    def fake_null(sel_base, fit, candidates, draws, seed):
        nulls.append(candidates)
        return SimpleNamespace(thresholds=lambda floor: {})

    monkeypatch.setattr(workflow, "null_distribution", fake_null)
    monkeypatch.setattr(workflow, "select_effects", lambda *a, **k: SimpleNamespace(nuisance_refit=None))
    monkeypatch.setattr(workflow, "apply_transfer_check", lambda sel, holdout: None)
    monkeypatch.setattr(workflow.bias_instability, "check", lambda *a, **k: None)
    cache: dict = {}
    fit = _contexts("a")
    workflow.decide(fit, _contexts("gh"), null_draws=5, null_cache=cache)
    workflow.decide(fit, _contexts("h"), null_draws=5, null_cache=cache)  # held-out set aside: same null
    assert nulls == [None]
    workflow.decide(fit, _contexts("h"), candidates=["quantization"], null_draws=5, null_cache=cache)
    workflow.decide(fit, _contexts("h"), null_draws=5, seed=1, null_cache=cache)
    workflow.decide(fit, _contexts("h"), null_draws=5)  # no cache: computed again
    assert nulls == [None, ["quantization"], None, None]


def test_a_selection_that_refitted_the_truths_error_level_is_decided_again_on_a_null_drawn_at_that_level(
    monkeypatch,
):
    """The null re-simulations draw the reconstruction error at the level the contexts hold: when the selection
    refitted it (a missed time offset had swollen it), the null is drawn again and the selection rerun with its
    thresholds; the cache keeps both nulls apart."""
    from types import SimpleNamespace

    from gyrodenoise.discrepancy import workflow

    nulls, thresholds_seen = [], []

    def fake_null(sel_base, fit, candidates, draws, seed):
        nulls.append(len(nulls))
        level = {"time_offset": float(len(nulls))}
        return SimpleNamespace(thresholds=lambda floor: level)

    def fake_select(*a, thresholds=None, **k):
        if k.get("candidates", a[2] if len(a) > 2 else None) == []:
            return SimpleNamespace(nuisance_refit=None)  # the base model
        thresholds_seen.append(thresholds)
        return SimpleNamespace(nuisance_refit={"first_fit": [9.0] * 3, "model": ["bias", "time_offset"]})

    monkeypatch.setattr(workflow, "null_distribution", fake_null)
    monkeypatch.setattr(workflow, "select_effects", fake_select)
    monkeypatch.setattr(workflow, "apply_transfer_check", lambda sel, holdout: None)
    monkeypatch.setattr(workflow.bias_instability, "check", lambda *a, **k: None)
    cache: dict = {}
    workflow.decide(_contexts("a"), _contexts("g"), null_draws=5, null_cache=cache)
    assert nulls == [0, 1] and thresholds_seen == [{"time_offset": 1.0}, {"time_offset": 2.0}]
    workflow.decide(_contexts("a"), _contexts("h"), null_draws=5, null_cache=cache)  # both from the cache
    assert nulls == [0, 1] and thresholds_seen[-1] == {"time_offset": 2.0}


def test_the_cli_sets_aside_a_held_out_flight_whose_truth_follows_the_gyro(tmp_path, capsys):
    """End to end on data the workflow did not make (gyrodenoise.testworld, null sensor): the fit flight and one
    held-out flight measured by a Vicon-like tracker, a second held-out flight by the tracker fused with the gyro.
    The fused one is set aside; the verdict is decided on the other. The console says so in words (names and
    bands, as report.md), not as a printed Python dict or list."""
    import json

    from gyrodenoise.discrepancy.__main__ import main
    from gyrodenoise.testworld import MOCAP_PRESETS, make_sequence

    for name, seed, mocap in (("fit", 1, "vicon"), ("clean", 2, "vicon"), ("fused", 3, "euroc-fused")):
        make_sequence(tmp_path / "data", "procedural", None, duration=40.0, seed=seed, name=name,
                      mocap=MOCAP_PRESETS[mocap])  # fmt: skip
    args = ["--root", str(tmp_path / "data"), "--fit", "fit", "--holdout", "clean", "fused", "--null-draws", "0"]
    args += ["--candidates", "scale_factor,quantization", "--gyro-noise-density", "1.6968e-4"]
    assert main([*args, "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    tf = report["truth_followed"]
    assert list(tf["holdout_sequences"]) == ["fused"] and tf["holdout_used"] == ["clean"] and tf["decided"]
    assert report["holdout_sequences"] == ["clean"] and list(report["gap_after"]["per_sequence"]) == ["clean"]
    assert report["verdict"].endswith("held-out fused set aside (its ground truth follows the gyro)")
    assert "not decided" not in report["verdict"]
    out = capsys.readouterr().out
    caution = next(line for line in out.splitlines() if line.startswith("caution:"))
    bands = ", ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in report["truth_check"]["fused"]["follows_gyro_bands_hz"])
    assert caution.startswith(f"caution: the ground truth follows the gyro in fused {bands};"), caution
    summary = next(line for line in out.splitlines() if "; not identifiable: " in line)
    assert summary.endswith("not identifiable: " + (", ".join(report["not_identifiable"]) or "none")), summary
    assert not any(c in caution + summary for c in "[]{}'"), out
    assert "The held-out fused was set aside" in (tmp_path / "out" / "report.md").read_text()
    from gyrodenoise.sim.error_model_file import load_error_model

    entries, _ = load_error_model(tmp_path / "out" / "error_model.yaml")  # the fitted model, for the simulator
    assert [e["name"] for e in entries][:2] == ["bias", "white_noise"]


@pytest.mark.parametrize(
    "text", ["1.6968e-4", "1.6968e-4 rad/s/sqrt(Hz)", "0.00972deg/s/sqrt(Hz)", "0.583 deg/sqrt(h)", "35deg/h/√Hz"]
)
def test_the_noise_density_is_read_in_the_units_datasheets_use(text):
    from gyrodenoise.discrepancy.__main__ import noise_density

    assert noise_density(text) == pytest.approx(1.6968e-4, rel=2e-3)  # EuRoC's ADIS16448, however it is written


@pytest.mark.parametrize("text", ["0.00972", "1.7e-4 deg/s", "-1e-4", "lots"])
def test_a_noise_density_in_another_unit_or_none_is_refused(text, capsys):
    from gyrodenoise.discrepancy.__main__ import parse_args

    with pytest.raises(SystemExit):  # 0.00972 without a unit: the deg/s/sqrt(Hz) figure read as rad/s/sqrt(Hz)
        parse_args(["--root", ".", "--fit", "A", "--holdout", "B", "--out", "o", "--gyro-noise-density", text])
    assert "--gyro-noise-density" in capsys.readouterr().err
