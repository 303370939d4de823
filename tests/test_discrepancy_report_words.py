"""The discrepancy report says what an effect named without regression rests on, and reads the gap table in words."""

from __future__ import annotations

import warnings

import numpy as np

from gyrodenoise.discrepancy.report import (
    _agreement,
    _corner_se_words,
    _decisions_md,
    _gap_words,
    _raw_sample_evidence_md,
    _simulator_model_md,
)


def test_quantization_is_reported_with_its_lattice():
    report = {
        "named_effects": [
            {"name": "time_offset", "delta_bic": 353.0},
            {
                "name": "quantization",
                "lattice": {"step": np.radians(0.04), "fraction": 0.993, "required_fraction": 0.95},
            },
        ]
    }
    (line,) = [ln for ln in _raw_sample_evidence_md(report) if ln]
    assert "not fitted (so no delta BIC)" in line and "99.3% of the fit sequences' samples" in line
    assert "step 0.04 deg/s" in line and ">= 95%" in line
    assert _raw_sample_evidence_md({"named_effects": [{"name": "time_offset"}]}) == []


def test_gap_words_say_when_the_drift_grows():
    before = {"residual_rms_rad_s": 0.048403, "drift_10s_median_deg": 0.6359, "allan_gap_log10": 0.934}
    after = {"residual_rms_rad_s": 0.04828, "drift_10s_median_deg": 0.6501, "allan_gap_log10": 0.806}
    text = _gap_words(before, after)[0]
    assert "residual RMS -0.3%" in text and "drift +2.2% (it grows" in text and "Allan-deviation gap -13.7%" in text
    after["drift_10s_median_deg"] = 0.6
    assert "it grows" not in _gap_words(before, after)[0]


def test_a_corner_read_from_the_motion_says_what_its_se_is_made_of():
    d = {"kept": "sensor_bandwidth", "lowpass_corner_se_white_hz": 0.0254, "lowpass_corner_se_colour_factor": 1.27}
    (line,) = _corner_se_words({"delay_or_lowpass": d})
    assert "0.0254 Hz with the rows taken as white, times 1.27" in line
    assert _corner_se_words({"delay_or_lowpass": d | {"kept": "time_offset"}}) == []
    assert _corner_se_words({"delay_or_lowpass": None}) == []


def test_a_corner_read_beside_a_time_offset_says_both_parts_of_its_se():
    d = {
        "kept": "both",
        "delay_s": 0.00797,
        "both_corner_se_white_hz": 3.03,
        "both_corner_se_colour_factor": 0.97,
        "both_delay_se_from_corner_s": 0.000335,
    }
    (line,) = _corner_se_words({"delay_or_lowpass": d})
    assert "beside a time offset" in line and "7.97 ms" in line
    assert "3.03 Hz with the rows taken as white, times 0.97" in line and "corner's part, 0.335 ms" in line


def test_a_corner_read_beside_a_time_offset_the_final_check_removed_does_not_name_the_offset():
    d = {
        "kept": "both",
        "removed_by_backward_check": "time_offset",
        "delay_s": 0.00797,
        "both_corner_se_white_hz": 3.03,
        "both_corner_se_colour_factor": 0.97,
        "both_delay_se_from_corner_s": 0.000335,
    }
    (line,) = _corner_se_words({"delay_or_lowpass": d})
    assert "which the final backward check then removed" in line and "3.03 Hz" in line
    assert "ms" not in line and "time offset's standard error" not in line


def test_the_held_out_agreement_says_what_its_p_is_against():
    t = {"separable_on_held_out": True, "birge_ratio": 2.13, "p_value": 5.3e-6, "se_factor": 2.13}
    assert _agreement(t) == "R 2.13, p 5.3e-06; SE x2.13"  # one fit sequence: against the regression's errors
    spread = {"birge_ratio": 1.54, "p_value": 0.21}
    assert _agreement(t | {"p_value": 0.12, "fit_sequences": spread}) == (
        "R 2.13, p 0.12 against the fit sequences' spread (R 1.54, p 0.21 against their halves); SE x2.13"
    )


def test_the_simulator_model_says_the_bias_spread_and_what_was_taken_out():
    b = {
        "between_sequence_rad_s": 3.42e-5, "observed_std_rad_s": 6.24e-5, "estimation_std_rad_s": [4.03e-5] * 3,
        "se_inflation": 1.76, "sequences": 5,
    }  # fmt: skip
    text = " ".join(_simulator_model_md({"simulator_model": "error_model.yaml", "bias_spread": b}))
    assert "between the 5 sequences (fit and held-out): 0.002 deg/s" in text and "x1.76" in text
    assert "alone spread by 0.0036 deg/s" in text
    assert "turn-on bias's spread" not in " ".join(_simulator_model_md({"simulator_model": "error_model.yaml"}))


def test_the_decisions_say_the_practical_minimum_given():
    """--min-gain 0.005 (half a percent) was written '0%' in report.md (0.015: '2%'), while report.json held 0.005."""
    s = {"bic_threshold": 10.0, "min_gain": 0.005, "min_drift_deg": 0.1}
    assert "practical minimum 0.5% of the in-band" in " ".join(_decisions_md({"settings": s}))
    null = {"draws": 20, "per_candidate": {"time_offset": {"median": 1.0, "q95": 8.0, "threshold": 10.0}}}
    text = " ".join(_decisions_md({"settings": s | {"min_gain": 0.015}, "null": null}))
    assert "at least 1.5% of the residual power" in text
    assert "practical minimum 1% of" in " ".join(_decisions_md({"settings": s | {"min_gain": 0.01}}))


PLOT_TAU = np.logspace(-2, 1, 8)


def plot_arrays() -> dict:
    """The comparisons' arrays (`workflow.comparisons`) the plots draw, flat: 200 Hz, Allan deviation at `PLOT_TAU`,
    spectrum to 100 Hz, a 20-s residual series, no drift windows."""
    f, t = np.linspace(0, 100, 50), np.linspace(0, 20, 100)
    ones = lambda n: np.ones((n, 3))  # noqa: E731
    return {
        "rate_hz": 200.0,
        "allan": {"tau_s": PLOT_TAU, "measured": ones(8), "sim_before": ones(8), "sim_after": ones(8)},
        "spectrum": {k: ones(50) for k in ("measured", "sim_before", "sim_after", "measured_after")} | {"f_hz": f},
        "residual_series": {"t": t, "before": ones(100), "after": ones(100), "name": "c"},
        "drift": {},
    }


def test_the_plots_shade_the_band_the_gaps_compare(tmp_path, monkeypatch):
    """allan.png and spectrum.png shaded as 'not compared' what lay beyond the widest held-out band (7 Hz), while the
    gaps of report.json compare up to the narrowest (6 Hz, `gap_before.band_hz`)."""
    from matplotlib.axes import Axes

    from gyrodenoise.discrepancy.report_plots import plots

    shaded = []
    monkeypatch.setattr(Axes, "axvspan", lambda ax, lo, hi, **kw: shaded.append((kw["label"], lo, hi)))
    gap = {k: 1.0 for k in ("residual_rms_rad_s", "drift_10s_median_deg", "allan_gap_log10")} | {"band_hz": 6.0}
    rows = [{"f_max_hz": 6.0, "whole_spectrum": False}, {"f_max_hz": 7.0, "whole_spectrum": False}]
    plots(tmp_path, plot_arrays(), {"gap_before": gap, "gap_after": gap, "reconstruction": {"holdout": rows}})
    assert {(lo, hi) for label, lo, hi in shaded if "tau" in label} == {(PLOT_TAU[0], 1 / 6.0)}
    assert {(lo, hi) for label, lo, hi in shaded if "reconstruction" in label} == {(6.0, 100.0)}


def test_the_gap_plot_draws_one_metric_and_says_which_were_not_measured(tmp_path, monkeypatch):
    """gap.png with one metric in the gap (one axis: a bare Axes, not an array) ended the report in TypeError ('Axes'
    object is not iterable), and none in ValueError; a metric that is NaN (no 10-s window for the drift) was an
    empty axis, read as 0."""
    from gyrodenoise.discrepancy import report_plots

    figures, save = {}, report_plots.save_figure

    def kept(fig, path, **kw):
        figures[path.name] = fig
        save(fig, path, **kw)

    monkeypatch.setattr(report_plots, "save_figure", kept)
    one = {"residual_rms_rad_s": 0.01}
    assert "gap.png" in report_plots.plots(tmp_path, plot_arrays(), {"gap_before": one, "gap_after": one})
    assert (tmp_path / "gap.png").stat().st_size > 0 and len(figures["gap.png"].axes) == 1

    nan = float("nan")
    before = {"residual_rms_rad_s": 0.01, "drift_10s_median_deg": nan, "allan_gap_log10": nan, "psd_gap_log10": 0.2}
    after = before | {"psd_gap_log10": nan}
    with warnings.catch_warnings():  # a NaN bar set no place on the x axis: the text ran off, tight_layout gave up
        warnings.simplefilter("error", UserWarning)
        report_plots.plots(tmp_path, plot_arrays(), {"gap_before": before, "gap_after": after})
    axes = figures["gap.png"].axes
    said = {ax.get_title(): [(t.get_position()[0], t.get_text()) for t in ax.texts] for ax in axes}
    assert said == {
        "residual RMS (rad/s)": [],
        "median 10-s drift (deg)": [(0, "not measured"), (1, "not measured")],
        "Allan gap (log10)": [(0, "not measured"), (1, "not measured")],
        "spectral gap (log10)": [(1, "not measured")],
    }
    assert "gap.png" not in report_plots.plots(tmp_path, plot_arrays(), {"gap_before": {}, "gap_after": {}})
