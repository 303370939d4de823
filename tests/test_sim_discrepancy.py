"""Discrepancy workflow on data with hidden effects (fast versions; the full confusion matrix over
magnitudes and seeds is benchmarks/discrepancy_hidden_effects.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gyrodenoise.discrepancy.__main__ import build_parser, main
from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.hidden import BASE_NOISE, CASES, make_measured, run_case
from gyrodenoise.discrepancy.rank import select_effects
from gyrodenoise.sim.effects import GSensitivity, ScaleAsymmetry, ScaleFactor, TimeOffset, Vibration

DURATION = 30.0


# the band-limited vibration (both magnitudes, frequency and bandwidth) is in test_discrepancy_vibration.py
@pytest.mark.parametrize("effect", sorted(set(CASES) - {"vibration_band"}))
def test_names_hidden_effect_and_gap_shrinks(effect, tmp_path):
    r = run_case(tmp_path, effect, magnitude=1, seed=11, duration_s=DURATION)
    assert r["named_labels"] == [effect], r
    assert r["rel_error"] < r["tol"], r
    if "gap_metric" in r:
        assert r["gap_after"] < r["gap_before"], r


def test_null_case_names_nothing(tmp_path):
    for seed in range(3):  # the false-positive rate over many seeds is in the benchmark
        r = run_case(tmp_path / str(seed), "none", 0, seed=seed, duration_s=DURATION)
        assert r["named"] == [], r


def test_two_hidden_effects(tmp_path):
    hidden = [
        GSensitivity(matrix=np.diag([1.5e-4, -1e-4, 2e-4])),
        Vibration(frequency_hz=31.0, amplitude=[3e-3, 2e-3, 1e-3]),
    ]
    names = make_measured(tmp_path, hidden, 3, DURATION, seed=5)
    sel = select_effects([load_fit_context(tmp_path, n) for n in names])
    assert sorted(sel.named) == ["g_sensitivity", "vibration"]
    assert np.allclose(np.diag(sel.params["g_sensitivity"]["matrix"]), [1.5e-4, -1e-4, 2e-4], atol=2e-5)
    assert sel.params["vibration"]["frequency_hz"] == pytest.approx(31.0, abs=0.05)


def test_a_scale_factor_that_differs_by_sign_is_named_as_its_two_parts(tmp_path):
    """A datasheet's positive- and negative-rate scale factors s+ and s- are scale_factor (s+ + s-) / 2 and
    scale_asymmetry (s+ - s-) / 2: both named, each with its value."""
    scale, asym = np.array([2e-3, -1e-3, 1.5e-3]), np.array([1e-3, 2e-3, -1.5e-3])
    names = make_measured(tmp_path, [ScaleFactor(scale=scale), ScaleAsymmetry(asymmetry=asym)], 3, DURATION, seed=5)
    sel = select_effects([load_fit_context(tmp_path, n) for n in names])
    assert sorted(sel.named) == ["scale_asymmetry", "scale_factor"]
    for name, key, truth in (("scale_factor", "scale", scale), ("scale_asymmetry", "asymmetry", asym)):
        est, se = sel.params[name][key], sel.se[name][key]
        assert np.all(np.abs(est - truth) < 4 * se), (name, est, se)
        assert np.all(se < 1e-4)


@pytest.mark.parametrize(
    "effect, hidden, trajectory",
    [
        ("g_sensitivity", GSensitivity(matrix=np.diag([2e-4, 2e-4, 2e-4])), "yaw_only"),
        ("time_offset", TimeOffset(delta=0.01), "constant_rate"),
    ],
)
def test_unidentifiable_effects_reported_not_named(effect, hidden, trajectory, tmp_path):
    names = make_measured(tmp_path, [hidden], 2, DURATION, seed=2, trajectory=trajectory)
    sel = select_effects([load_fit_context(tmp_path, n) for n in names])
    assert effect in sel.not_identifiable
    assert effect not in sel.named


def test_cli_writes_report(tmp_path):
    make_measured(tmp_path / "data", [TimeOffset(delta=0.005)], 3, 20.0, seed=1)
    out = tmp_path / "report"
    rc = main(
        [
            "--root",
            str(tmp_path / "data"),
            "--fit",
            "s0",
            "s1",
            "--holdout",
            "s2",
            "--null-draws",
            "8",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    rep = json.loads((out / "report.json").read_text())
    assert [e["name"] for e in rep["named_effects"]] == ["time_offset"]
    assert rep["named_effects"][0]["params"]["delta"] == pytest.approx(0.005, rel=0.05)
    assert rep["gap_after"]["residual_rms_rad_s"] < rep["gap_before"]["residual_rms_rad_s"]
    assert rep["gap_after"]["drift_10s_median_deg"] < rep["gap_before"]["drift_10s_median_deg"]
    for f in ("report.md", "allan.png", "spectrum.png", "residual.png", "drift.png", "gap.png", "unexplained.png"):
        assert (out / f).is_file()
    # the named offset leaves nothing the binned readings see (`lack_of_fit`): a table, no caution
    assert len(rep["lack_of_fit"]["rows"]) == 9 and rep["lack_of_fit"]["caution"] == ""
    assert "## Error the named effects leave unexplained" in (out / "report.md").read_text()
    # where the result came from: the code (this checkout's commit) beside the machine and wall time
    from gyrodenoise.provenance import code_version_text

    assert rep["code"] == code_version_text() and rep["code"].startswith("gyrodenoise ")
    assert f"; {rep['code']})." in (out / "report.md").read_text()


def test_cli_rejects_overlapping_split(tmp_path):
    with pytest.raises(SystemExit):
        main(["--root", str(tmp_path), "--fit", "a", "--holdout", "a", "--out", str(tmp_path / "o")])


def test_help_explains_every_option_and_ends_with_an_example(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for action in build_parser()._actions:
        if not action.option_strings or action.dest == "help":
            continue
        option = action.option_strings[-1]
        # a help text, with the default (or "required"), is what --help prints next to the option
        assert action.help and ("default" in action.help or action.required), f"{option}: no help text/default"
        assert option in text and " ".join(action.help.split()[:3]) in " ".join(text.split()), option
    assert "(default: 0.05 s)" in text  # units and defaults filled in
    example = text.rstrip().split("\n\n")[-1]
    assert example.startswith("example") and "python -m gyrodenoise.discrepancy --root" in example


def test_a_clipped_output_leaves_every_models_fits_and_noise_level(tmp_path):
    """A plateau at the largest magnitude is a property of the data: the samples near it leave the base model's fits
    too (no saturation among its effects), so the noise level that weights them is the sensor's, not the clipped
    stretches' (their first differences are the true rate's changes)."""
    from gyrodenoise.sim.effects import Saturation

    names = make_measured(tmp_path, [Saturation(limit=1.5)], n_seqs=3, duration_s=DURATION, seed=11)
    fcs = [load_fit_context(tmp_path, n) for n in names]
    clipped = sum(int((np.abs(fc.gyro) >= np.abs(fc.gyro).max() - 1e-12).sum()) for fc in fcs)
    assert clipped > 50  # the premise: a plateau
    sel = select_effects(fcs, base=["bias", "white_noise"], candidates=[])
    per_sample = BASE_NOISE * np.sqrt(fcs[0].rate_hz)
    assert np.allclose(sel.sigma, per_sample, rtol=0.1), (sel.sigma, per_sample)
    assert all(fc.extra.get("row_mask") is not None and not fc.extra["row_mask"].all() for fc in fcs)
