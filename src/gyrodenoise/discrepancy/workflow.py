"""The discrepancy workflow: fit the base model, compare, select missing effects, re-simulate, and
measure the gap before and after on held-out sequences.

Gap on a held-out sequence: the sensor constants come from the fit sequences; per-sequence
nuisances (bias, random-walk knots, vibration phase) are refitted on the held-out sequence itself,
as any calibration would do at start-up. Four numbers: the residual RMS and the 10-s drift of the
measured vs the model gyro (what the deterministic model predicts), and the Allan-deviation and
spectral gaps between measured and re-simulated residuals (what the stochastic model reproduces).
A stochastic effect (white noise, a band-limited vibration) cannot lower the first two; it shows
in the last two.
"""

from __future__ import annotations

import numpy as np

from gyrodenoise.allan import allan_taus, pooled_allan
from gyrodenoise.discrepancy import bias_instability
from gyrodenoise.discrepancy.bias_spread import bias_spread
from gyrodenoise.discrepancy.compare import cross_correlations, drift_vs_truth_deg, spectrum, window_drift_deg
from gyrodenoise.discrepancy.design import band_power
from gyrodenoise.discrepancy.fitted_model import per_sequence_refit
from gyrodenoise.discrepancy.lack_of_fit import lack_of_fit
from gyrodenoise.discrepancy.null import DRAWS, NullDistribution, null_distribution
from gyrodenoise.discrepancy.rank import MIN_DRIFT_DEG, MIN_GAIN, Selection, residuals_after, select_effects
from gyrodenoise.discrepancy.reconstruction import band_limit
from gyrodenoise.discrepancy.resimulate import left_by_model, simulate_like, walk_named, without_walk_knots
from gyrodenoise.discrepancy.spectral import psd_gap
from gyrodenoise.discrepancy.transfer import apply_transfer_check
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import EFFECTS, SIM_EFFECTS

DRIFT_WINDOWS_S = (1.0, 10.0, 60.0)
SIM_DRAWS = 4  # re-simulations per held-out sequence for the Allan and spectral gaps
NO_EFFECT = "no missing effect found"
NOT_IDENTIFIABLE = "not identifiable from this motion"


def allan_gap(
    meas_res: list[np.ndarray], sim_res: list[np.ndarray], rate_hz: float, f_max: float | None = None
) -> float:
    """Mean |log10(ADEV measured / ADEV simulated)| over cluster times and axes. `f_max`: both are
    limited to the trusted band [0, f_max] and compared at cluster times >= 1 / f_max."""
    taus = allan_taus(min(len(r) for r in meas_res), rate_hz, per_octave=2)
    if f_max is not None and f_max < rate_hz / 2:
        meas_res = [band_limit(r, rate_hz, f_max) for r in meas_res]
        sim_res = [band_limit(r, rate_hz, f_max) for r in sim_res]
        taus = taus[taus >= 1.0 / f_max]
    a = pooled_allan(meas_res, rate_hz, taus)
    b = pooled_allan(sim_res, rate_hz, taus)
    ok = np.isfinite(a) & np.isfinite(b) & (a > 0) & (b > 0)
    return float(np.mean(np.abs(np.log10(a[ok] / b[ok]))))


def gap(sel: Selection, fcs: list[FitContext], seed: int = 0) -> dict:
    """Measured vs model on sequences `fcs`: residual RMS, 10-s drift, Allan-deviation gap (measured
    vs re-simulated gyro - true rate) and spectral gap (`spectral.psd_gap` of what the deterministic
    model leaves, measured vs re-simulated). The simulated statistics pool SIM_DRAWS draws per
    sequence (closer to the model's expectation), each from a generator seeded by (seed, sequence,
    draw)."""
    res, drifts, sims, meas, sim_noise = [], [], [], [], []
    per_seq = {}
    ones = np.ones(3)
    in_band = []
    for s, fc in enumerate(fcs):
        pred = per_sequence_refit(sel, fc)
        free = without_walk_knots(sel, fc) if walk_named(sel) else None
        for k in range(SIM_DRAWS):
            y_sim, _ = simulate_like(sel, fc, np.random.default_rng([seed, s, k]), pred, walk_free=free)
            sims.append(y_sim - fc.omega)
            sim_noise.append(left_by_model(sel, fc, y_sim, pred))
        e = fc.residual - pred
        res.append(e)
        in_band.append(band_power(fc, e, ones))
        d = window_drift_deg(fc.gyro, fc.omega + pred, 1.0 / fc.rate_hz, 10.0)
        drifts.append(d)
        meas.append(fc.residual)
        per_seq[fc.name] = {
            "residual_rms_rad_s": float(np.sqrt(np.mean(e**2))),
            "drift_10s_median_deg": float(np.median(d)) if len(d) else float("nan"),
        }
    allres = np.concatenate(res)
    alld = np.concatenate(drifts)
    f_hi = min(fc.extra.get("band_hz") or fc.rate_hz / 2 for fc in fcs)
    weights = [len(fc.t) for fc in fcs]
    return {
        "residual_rms_rad_s": float(np.sqrt(np.mean(allres**2))),
        # what the comparison can trust: the residual in the trusted band (Parseval), and that band
        "residual_rms_in_band_rad_s": float(np.sqrt(np.average(in_band, weights=weights))),
        "band_hz": f_hi,
        "residual_rms_per_axis_rad_s": np.sqrt(np.mean(allres**2, 0)).tolist(),
        "drift_10s_median_deg": float(np.median(alld)) if len(alld) else float("nan"),
        "allan_gap_log10": allan_gap(meas, sims, fcs[0].rate_hz, f_hi),
        "psd_gap_log10": psd_gap(res, sim_noise, fcs[0].rate_hz, f_max=f_hi),
        "per_sequence": per_seq,
    }


def comparisons(sel_base: Selection, sel: Selection, fcs: list[FitContext], seed: int = 0) -> dict:
    """Arrays for the plots and the statistics of step (2), on sequences `fcs`."""
    rate = fcs[0].rate_hz
    out: dict = {"rate_hz": rate, "names": [fc.name for fc in fcs]}
    meas = [fc.residual for fc in fcs]
    sim_b, sim_a, res_b, res_a, left_b, left_a = [], [], [], [], [], []
    for s, fc in enumerate(fcs):
        yb, pb = simulate_like(sel_base, fc, np.random.default_rng([seed + 1, s]))
        ya, pa = simulate_like(sel, fc, np.random.default_rng([seed + 1, s]))
        sim_b.append(yb - fc.omega)
        sim_a.append(ya - fc.omega)
        res_b.append(fc.residual - pb)
        res_a.append(fc.residual - pa)
        left_b.append(left_by_model(sel_base, fc, yb, pb))
        left_a.append(left_by_model(sel, fc, ya, pa))
    taus = allan_taus(min(len(r) for r in meas), rate)
    out["allan"] = {
        "tau_s": taus,
        "measured": pooled_allan(meas, rate, taus),
        "sim_before": pooled_allan(sim_b, rate, taus),
        "sim_after": pooled_allan(sim_a, rate, taus),
    }
    # spectra of what the models leave unexplained: measured vs simulated (deterministic part removed)
    f, pm = spectrum(np.concatenate(res_b), rate)
    out["spectrum"] = {
        "f_hz": f,
        "measured": pm,
        "sim_before": spectrum(np.concatenate(left_b), rate)[1],
        "sim_after": spectrum(np.concatenate(left_a), rate)[1],
        "measured_after": spectrum(np.concatenate(res_a), rate)[1],
    }
    out["residual_series"] = {"t": fcs[0].t, "before": res_b[0], "after": res_a[0], "name": fcs[0].name}
    drift = {}
    for w in DRIFT_WINDOWS_S:
        if min(len(fc.t) for fc in fcs) / rate < w + 1:
            continue
        dt = 1.0 / rate
        drift[f"{w:g}"] = {
            "measured": np.concatenate([drift_vs_truth_deg(fc.gyro, fc.extra["rot"], dt, w) for fc in fcs]),
            "sim_before": np.concatenate(
                [drift_vs_truth_deg(fc.omega + s, fc.extra["rot"], dt, w) for fc, s in zip(fcs, sim_b, strict=True)]
            ),
            "sim_after": np.concatenate(
                [drift_vs_truth_deg(fc.omega + s, fc.extra["rot"], dt, w) for fc, s in zip(fcs, sim_a, strict=True)]
            ),
        }
    out["drift"] = drift
    out["cross_correlation_base_residual"] = cross_correlations(fcs, res_b)
    out["cross_correlation_final_residual"] = cross_correlations(fcs, res_a)
    return out


def _tolist(x):
    return None if x is None else np.asarray(x).tolist()


def decide(
    fit: list[FitContext],
    holdout: list[FitContext],
    base: list[str] = ("bias", "white_noise"),
    candidates: list[str] | None = None,
    bic_threshold: float = 10.0,
    min_gain: float = MIN_GAIN,
    null_draws: int = DRAWS,
    seed: int = 0,
    null_cache: dict | None = None,
) -> tuple[Selection, Selection, NullDistribution | None]:
    """The base model, the null distribution of every candidate's delta BIC under it (`null.py`;
    null_draws = 0: none, the fixed `bic_threshold` decides) and the greedy selection with those
    thresholds and the practical minimum `min_gain` on the held-out sequences.
    `null_cache`: a dict kept by a caller that decides again on the same fit sequences with other held-out
    ones; the null distribution depends on the fit sequences only, so it is computed once per candidate list.
    Returns (base selection, final selection, null distribution)."""
    base = list(base)
    candidates, judge_floor = bias_instability.split_candidates(candidates)
    sel_base = select_effects(fit, base, candidates=[], bic_threshold=bic_threshold, holdout=holdout)
    cache = null_cache if null_cache is not None else {}

    def null_of(level: str) -> NullDistribution:
        key = (tuple(base), None if candidates is None else tuple(candidates), null_draws, seed, level)
        if key not in cache:  # drawn with the reconstruction error's level the contexts hold now
            cache[key] = null_distribution(sel_base, fit, candidates, null_draws, seed)
        return cache[key]

    null = null_of("base fit") if null_draws > 0 else None
    thresholds = None if null is None else null.thresholds(bic_threshold)
    sel = select_effects(fit, base, candidates, bic_threshold, min_gain, thresholds=thresholds, holdout=holdout)
    if null is not None and sel.nuisance_refit is not None:
        # the selection refitted the reconstruction error's level (a missed effect had swollen it): the null
        # re-simulations drew the error at the swollen level, so they are drawn again at the refitted one
        null = null_of("refitted")
        thresholds = null.thresholds(bic_threshold)
        sel = select_effects(fit, base, candidates, bic_threshold, min_gain, thresholds=thresholds, holdout=holdout)
    apply_transfer_check(sel, holdout)
    vocabulary = list(EFFECTS) if candidates is None else candidates
    if judge_floor and "white_noise" in base + vocabulary:  # the floor is judged beside white noise
        sel.instability = bias_instability.check(sel, fit, holdout, min_gain, seed)
    return sel_base, sel, null


def verdict_text(named: list[str], equivalences: list[str], cautions: list[str]) -> str:
    """The report's verdict: what was named, with what it cannot be told from and the cautions in brackets."""
    verdict = NO_EFFECT if not named else "named: " + ", ".join(named)
    if equivalences or cautions:
        verdict += " (" + "; ".join(equivalences + cautions) + ")"
    return verdict


def run(
    fit: list[FitContext],
    holdout: list[FitContext],
    base: list[str] = ("bias", "white_noise"),
    candidates: list[str] | None = None,
    bic_threshold: float = 10.0,
    min_gain: float = MIN_GAIN,
    seed: int = 0,
    null_draws: int = DRAWS,
    null_cache: dict | None = None,
) -> tuple[dict, dict]:
    """Steps (1)-(5), then the check for error the named effects leave unexplained (`lack_of_fit`, a caution when
    found). Returns (report dict, arrays for the plots). `null_cache`: see `decide`."""
    base = list(base)
    sel_base, sel, null = decide(fit, holdout, base, candidates, bic_threshold, min_gain, null_draws, seed, null_cache)
    unexplained = lack_of_fit(sel, holdout, seed, min_share=min_gain)
    cautions = sel.cautions + ([unexplained["caution"]] if unexplained["caution"] else [])
    gap_before = gap(sel_base, holdout, seed)
    gap_after = gap(sel, holdout, seed)
    named = []
    for name in sel.named:
        e = SIM_EFFECTS[name]
        params = {k: np.asarray(v).tolist() for k, v in sel.params[name].items()}
        se = {k: np.asarray(v).tolist() for k, v in sel.se.get(name, {}).items()}
        ds = {}
        for k, v in sel.params[name].items():
            unit, factor = e.DATASHEET.get(k, ("SI", 1.0))
            ds[k] = {"value": (np.asarray(v) * factor).tolist(), "unit": unit}
            if k in sel.se.get(name, {}):
                ds[k]["standard_error"] = (np.asarray(sel.se[name][k]) * factor).tolist()
        step = next((s for s in sel.steps if s.get("added") == name), None)
        cand = next((c for c in (step or {}).get("candidates", []) if c["effect"] == name), {})
        entry = {
            "name": name,
            "params": params,
            "standard_errors": se,
            "datasheet": ds,
            "delta_bic": cand.get("delta_bic"),
            "explained_fraction": cand.get("gain"),
            "holdout_gain": cand.get("holdout_gain"),
            "holdout_drift_reduction_deg": cand.get("holdout_drift_reduction_deg"),
            "holdout_transfer_dloglik": cand.get("holdout_transfer_dloglik"),
            "threshold": cand.get("threshold"),
            "null_p_value": None
            if null is None or cand.get("delta_bic") is None
            else null.p_value(name, cand["delta_bic"]),
        }
        if "variant" in cand:
            entry["variant"] = cand["variant"]
        if name == "vibration" and sel.band is not None:
            entry["per_sequence_fits"] = sel.band.per_sequence
        if name == "quantization" and sel.lattice is not None:
            entry["lattice"] = sel.lattice
        if name == "saturation" and sel.saturation is not None:
            entry["saturation_check"] = sel.saturation
        if name in sel.transfer:
            entry["held_out_agreement"] = sel.transfer[name]
        named.append(entry)
    base_params = {n: {k: np.asarray(v).tolist() for k, v in sel.params[n].items()} for n in base if n in sel.params}
    verdict = verdict_text(sel.named, sel.equivalences, cautions)
    fit_resid = residuals_after(sel_base.design, sel_base.result, sel_base.selected)
    report = {
        "verdict": verdict,
        "named_effects": named,
        "not_identifiable": sel.not_identifiable,
        "not_identifiable_note": NOT_IDENTIFIABLE if sel.not_identifiable else "",
        "gap_before": gap_before,
        "gap_after": gap_after,
        "base_model": base,
        "base_params": base_params,
        # the turn-on bias's spread between the fit sequences, their estimates' own errors taken out (for `sim_model`)
        "bias_spread": bias_spread(sel, holdout),
        "fit_sequences": [fc.name for fc in fit],
        "holdout_sequences": [fc.name for fc in holdout],
        "selection_steps": sel.steps,
        "below_practical": sel.below_practical,
        "settings": {
            "bic_threshold": bic_threshold,
            "min_gain": min_gain,
            "min_drift_deg": MIN_DRIFT_DEG,
            "seed": seed,
            "candidates": candidates,
            "null_draws": null_draws,
        },
        "null": None if null is None else {"draws": null.draws, "per_candidate": null.summary(bic_threshold)},
        "thresholds": sel.thresholds,
        "identifiability": sel.identifiability,
        "delay_or_lowpass": sel.delay_or_lowpass,
        "equivalences": sel.equivalences,
        "cautions": cautions,
        "lack_of_fit": unexplained,
        "bias_instability_check": sel.instability,
        "reconstruction": {
            "fit": [fc.extra["band"].summary() for fc in fit if "band" in fc.extra],
            "holdout": [fc.extra["band"].summary() for fc in holdout if "band" in fc.extra],
            "sensor_floor_psd": _tolist(fit[0].extra.get("sensor_floor")),
            "nuisance_level": _tolist(fit[0].extra.get("nuisance_level")),
            "nuisance_refit": sel.nuisance_refit,
        },
        "noise_sigma_per_axis_rad_s": sel.sigma.tolist(),
        "saturation_check": sel.saturation,
        "cross_correlation_fit_base_residual": cross_correlations(fit, fit_resid),
    }
    arrays = comparisons(sel_base, sel, holdout, seed)
    return report, arrays
