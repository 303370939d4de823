"""Rank candidate effects by BIC and select them greedily; tell what the motion cannot identify.

Each step (`score_step`) prepares every remaining candidate on the current residual and scores it:
regression effects by the BIC gain of their columns (`design.Design`), stochastic ones by the
Whittle likelihood of the residual's spectrum (`spectral`), which is on the scale of the
regression's Gaussian likelihood:

- vibration has two variants, the sinusoid (regression) and band-limited noise (spectral); the
  better one is the candidate's score. Once the band-limited variant is named it has no columns; it
  is refitted on the final residual, and the white-noise level then comes from the same spectral fit.
- sensor_bandwidth (a low-pass of the sensor) is scored by the shape of the noise floor plus what
  the implied delay of the motion explains (`design.sensor_view`, no free coefficient).

A candidate is named when its delta BIC clears its threshold (a null distribution's quantile,
`null.py`, or the fixed `bic_threshold`) and it is practically meaningful: it closes at least
`min_gain` of the residual power in the trusted band (of the held-out sequences, when given). A
band-limited vibration is noise, judged on the held-out spectra: its level refitted there must carry
that share, and with the level fitted on the fit sequences (a sensor constant) it must raise their
Whittle likelihood (`_holdout_band_share`). For a regression effect whose
coefficients are sensor constants (not refitted per sequence), closing `min_drift_deg` of the
held-out median 10-s attitude drift of the model gyro against the measured gyro is the alternative
practical minimum (`_holdout_gain`): an effect can matter for attitude while carrying little power.
Effects whose expected delta BIC even at their largest plausible magnitude falls short of their
threshold are not identifiable from this motion and are not tried; every effect's expected delta
BIC at a stated reference magnitude is reported (`identifiability`). A named time offset may be a
sensor low-pass: `lowpass_choice.choose` decides between them once the greedy steps end.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from gyrodenoise.discrepancy import lowpass_choice
from gyrodenoise.discrepancy.compare import window_drift_deg
from gyrodenoise.discrepancy.design import (
    RECONSTRUCTION_KEYS,
    Design,
    FitResult,
    band_edges,
    band_power,
    n_rows,
    noise_weights,
    nuisance_of,
    residuals_after,
    row_masks,
    sensor_view,
    set_bands,
    set_reconstruction_model,
    set_row_weights,
    set_saturation_mask,
    without_reconstruction,
)
from gyrodenoise.discrepancy.fitted_model import Selection, fill_params, predict
from gyrodenoise.discrepancy.identifiability import identifiability
from gyrodenoise.discrepancy.spectral import (
    BAND_PARAMS,
    BandFit,
    FloorShapeFit,
    fit_band,
    fit_floor_shape,
)
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import EFFECTS, Effect, Saturation

# nonlinear parameters searched by `prepare` (counted in the BIC penalty)
NONLINEAR_PARAMS = {"vibration": 1, "warmup_bias": 1, "bias_random_walk": 1}
MIN_GAIN = 0.01  # practical minimum: 1% of the residual power in the trusted band
MIN_DRIFT_DEG = 0.1  # or (sensor-constant regression effects): 0.1 deg of held-out median 10-s drift
DRIFT_WINDOW_S = 10.0
CORNER_FLAT = 50.0  # x rate: a fitted corner above this is no low-pass at all
KAPPA_TOLERANCE = 0.5  # reconstruction-error level refitted on the selected model's residual: rerun beyond this

__all__ = ["Selection", "residuals_after", "score_step", "select_effects"]


@dataclass
class StepScores:
    design: Design
    current: FitResult
    residuals: list[np.ndarray]
    scores: list[dict]  # one per candidate (the better variant), by delta BIC, largest first
    not_identifiable: dict[str, dict]
    identifiability: dict[str, dict]
    band: BandFit | None = None
    floor_shape: FloorShapeFit | None = None


def score_step(
    fcs: list[FitContext],
    effects: dict[str, Effect],
    selected: list[str],
    remaining: list[str],
    sigma: np.ndarray,
    band_vibration: bool,
    thresholds: Mapping[str, float] | None = None,
    bic_threshold: float = 10.0,
    raw: list[FitContext] | None = None,
) -> StepScores:
    """Prepare and score every candidate in `remaining` against the model `selected` on sequences
    `fcs` (already seen through a named sensor low-pass; `raw`: the same without it, for the
    sensor-bandwidth candidate). Candidates whose expected delta BIC at their largest plausible
    magnitude is below their threshold are left out (`not_identifiable`)."""
    raw = fcs if raw is None else raw
    rate = fcs[0].rate_hz
    regress = [c for c in remaining if not effects[c].stochastic]
    design0 = Design(fcs, {n: effects[n] for n in selected}, sigma)
    cur0 = design0.fit(selected)
    resid = residuals_after(design0, cur0, selected)
    for c in regress:
        effects[c].prepare(fcs, resid)
    design = Design(fcs, {n: effects[n] for n in selected + regress}, sigma)
    cur = design.fit(selected)
    s2 = cur.rss / max(cur.n - cur.k, 1)
    scores, not_ident, ident = [], {}, {}
    for c in regress:
        thr = (thresholds or {}).get(c, bic_threshold)
        idf = identifiability(design, selected, c, s2, thr, NONLINEAR_PARAMS.get(c, 0))
        if idf is not None:
            ident[c] = idf.as_dict()
        if idf is None:  # no reference magnitude (per-sequence knots): identifiable when some direction is new
            ok = bool(np.isfinite(design.conditional_se(selected, c, s2)).any())
        else:  # numbers at the reference magnitude are reported; tried if plausible magnitudes would show
            ok = idf.testable
        if not ok:
            not_ident[c] = ident.get(c, {"degenerate": True})
            continue
        res = design.fit(selected + [c])
        dk = res.k - cur.k + NONLINEAR_PARAMS.get(c, 0)
        dbic = cur.n * np.log(cur.rss / res.rss) - dk * np.log(cur.n)
        score = {"effect": c, "delta_bic": float(dbic), "gain": float(1 - res.rss / cur.rss), "k": dk}
        if c == "vibration":
            score["variant"] = "sinusoid"
        scores.append(score)
    corner = _named_corner(effects, selected)
    band = None
    vib = effects.get("vibration")
    if band_vibration and "vibration" in remaining:
        nu = nuisance_of(fcs, corner)
        band = fit_band(resid, rate, row_masks(fcs), bands=band_edges(fcs), floor_corner_hz=corner, nuisance=nu)
        if band is not None:
            scores.append(
                {
                    "effect": "vibration",
                    "variant": "band-limited",
                    "delta_bic": band.delta_bic(cur.n),
                    "gain": band.explained(sigma, rate),
                    "k": BAND_PARAMS,
                }
            )
    floor = None
    if "sensor_bandwidth" in remaining:
        named_band = None
        if vib is not None and "vibration" in selected and vib.stochastic:
            named_band = (float(vib.params["frequency_hz"]), float(vib.params["bandwidth_hz"]))
        rss_of: dict[float, float] = {}
        rate_only = not {"time_offset", "g_sensitivity"} & set(selected)

        def motion_gain(corner: float) -> float:
            # the motion part of the low-pass (its delay and droop): the model seen through the
            # filter, as a Gaussian log-likelihood gain on the regression's rows
            # less what smoothing the ground truth's own noise gains it (`truth_error_smoothing`)
            view = [sensor_view(fc, corner, rate_only) for fc in raw]
            rss = Design(view, {n: effects[n] for n in selected}, sigma).fit(selected).rss
            rss_of[corner] = rss + float(lowpass_choice.truth_error_smoothing(raw, sigma, np.array([corner]))[0])
            return 0.5 * cur.n * np.log(cur.rss / rss_of[corner])

        floor = fit_floor_shape(
            resid, rate, row_masks(fcs), band_edges(fcs), named_band, nuisance_of(fcs), extra=motion_gain
        )
        if floor is None:
            not_ident["sensor_bandwidth"] = {"reason": "the noise floor is not visible in the trusted band"}
        elif floor.corner_hz < CORNER_FLAT * rate:
            rss_lp = rss_of.get(floor.corner_hz, cur.rss)
            gain = max(floor.explained(rate), 1 - rss_lp / cur.rss)
            scores.append(
                {"effect": "sensor_bandwidth", "delta_bic": float(floor.delta_bic(cur.n)), "gain": float(gain), "k": 1}
                | {"corner_hz": floor.corner_hz}
            )
    # one score per effect: the better variant (the other one is kept for the report)
    best_of: dict[str, dict] = {}
    for sc in scores:
        if sc["effect"] not in best_of or sc["delta_bic"] > best_of[sc["effect"]]["delta_bic"]:
            best_of[sc["effect"]] = sc
    for sc in scores:
        if sc is not best_of[sc["effect"]]:
            best_of[sc["effect"]]["other_variant"] = {"variant": sc["variant"], "delta_bic": sc["delta_bic"]}
    scores = sorted(best_of.values(), key=lambda d: -d["delta_bic"])
    return StepScores(design, cur, resid, scores, not_ident, ident, band, floor)


def _named_corner(effects: dict[str, Effect], selected: list[str]) -> float | None:
    if "sensor_bandwidth" not in selected:
        return None
    return float(effects["sensor_bandwidth"].params["corner_hz"])


def _holdout_gain(
    design: Design,
    effects: dict[str, Effect],
    names: list[str],
    extra: str,
    sigma: np.ndarray,
    holdout: list[FitContext],
    corner: float | None,
    sat_limit: float | None,
) -> tuple[float, float | None]:
    """What `extra` closes on the held-out sequences, the model `names` fitted with and without it
    on the fit sequences, per-sequence nuisances refitted on each held-out sequence:

    - the share of the held-out residual power in the trusted band. A per-sequence effect is
      refitted there too, which closes k / n of the power by chance (k its columns per sequence,
      n the rows): that share is taken off;
    - the reduction (deg) of the median DRIFT_WINDOW_S attitude drift of the model gyro (true rate +
      prediction) against the measured gyro (`compare.window_drift_deg`, windows of all held-out
      sequences pooled). None for a per-sequence effect: refitted on the held-out sequence itself,
      its knots or offsets would absorb the drift of the noise there by construction."""
    with_c = design.fit(names + [extra])
    without = design.fit(names)
    p0 = p1 = 0.0
    chance = []
    d0, d1 = [], []
    per_seq = effects[extra].per_sequence
    for h in holdout:
        v = sensor_view(h, corner)
        pred0 = predict(design, without, effects, names, sigma, v, sat_limit)
        pred1 = predict(design, with_c, effects, names + [extra], sigma, v, sat_limit)
        p0 += band_power(v, v.residual - pred0, sigma)
        p1 += band_power(v, v.residual - pred1, sigma)
        if per_seq:
            chance.append(design.k[extra] / n_rows(v))
        else:
            dt = 1.0 / v.rate_hz
            d0.append(window_drift_deg(v.gyro, v.omega + pred0, dt, DRIFT_WINDOW_S))
            d1.append(window_drift_deg(v.gyro, v.omega + pred1, dt, DRIFT_WINDOW_S))
    gain = float(1.0 - p1 / max(p0, 1e-300) - (np.mean(chance) if chance else 0.0))
    d0, d1 = (np.concatenate(d) if d else np.empty(0) for d in (d0, d1))
    drift = float(np.median(d0) - np.median(d1)) if len(d0) else None
    return gain, drift


def practical(
    gain: float, drift_deg: float | None, min_gain: float = MIN_GAIN, min_drift_deg: float = MIN_DRIFT_DEG
) -> bool:
    """The practical minimum on the held-out sequences: at least `min_gain` of the in-band residual
    power closed, or at least `min_drift_deg` of the median 10-s drift (when it is defined)."""
    return gain >= min_gain or (drift_deg is not None and drift_deg >= min_drift_deg)


def _holdout_band_share(
    design: Design,
    effects: dict[str, Effect],
    names: list[str],
    sigma: np.ndarray,
    holdout: list[FitContext],
    corner: float | None,
    sat_limit: float | None,
    band: BandFit,
) -> tuple[float, float]:
    """(share, transfer): whether the band the fit sequences show is a property of the sensor that
    the held-out flights share.

    share: of the held-out in-band residual power, what a band of the fitted centre and width
    carries with its level refitted there (0 when it does not raise their Whittle likelihood).
    transfer: the gain in the held-out Whittle log-likelihood when the band keeps the level fitted
    on the fit sequences (a sensor constant, like the regression effects' coefficients; floor and
    reconstruction-error level refitted). A band whose level is that of one fit flight's motion,
    not of the sensor, shows in the first and fails the second: the held-out spectra then fit
    better without it, and a re-simulation with it would widen the gap it is meant to close."""
    res = design.fit(names)
    views = [sensor_view(h, corner) for h in holdout]
    resid = [v.residual - predict(design, res, effects, names, sigma, v, sat_limit) for v in views]
    rate = holdout[0].rate_hz
    fit = fit_band(
        resid,
        rate,
        row_masks(views),
        starts=[(band.frequency_hz, band.bandwidth_hz)],
        bands=band_edges(views),
        floor_corner_hz=corner,
        nuisance=nuisance_of(views, corner),
        fixed_band=True,
        fixed_power=band.power,
    )
    if fit is None:
        return 0.0, float("nan")
    transfer = float(fit.loglik_kept - fit.loglik_floor)
    if fit.loglik <= fit.loglik_floor:
        return 0.0, transfer
    return fit.explained(sigma, rate), transfer


def select_effects(
    fcs: list[FitContext],
    base: list[str] = ("bias", "white_noise"),
    candidates: list[str] | None = None,
    bic_threshold: float = 10.0,
    min_gain: float = MIN_GAIN,
    min_drift_deg: float = MIN_DRIFT_DEG,
    max_added: int = 6,
    rw_knot_spacing_s: float = 10.0,
    band_vibration: bool | None = None,
    trusted_band: bool = True,
    thresholds: Mapping[str, float] | None = None,
    holdout: list[FitContext] | None = None,
    nuisance_residuals: list[np.ndarray] | None = None,
) -> Selection:
    """Greedy forward selection: add the candidate with the largest delta BIC that clears its
    threshold (`thresholds[name]`, default `bic_threshold`) and closes at least `min_gain` of the
    residual power in the trusted band (on `holdout` for regression effects, when given; there, for
    a sensor-constant effect, reducing the median 10-s drift by `min_drift_deg` also counts:
    `practical`); refit; repeat until none does.

    `band_vibration`: also try the band-limited variant of `vibration` (a stochastic term of the
    noise spectrum). Default: when white noise is part of the model (base or candidates), i.e. when
    the residual is modelled as noise at all; a fit of a deterministic signal (a network's
    correction, `network.py`) leaves it out.

    `trusted_band`: compare only in the band where the reconstructed true rate is trusted
    (`reconstruction.estimate_band`, from the base model's residual; kept in each context's extra).
    The level of the reconstruction error that weights the rows is fitted on that residual too, where
    a missing effect whose residual is as blue as that error (a time offset's: delay x angular
    acceleration) is read as reconstruction error. So it is refitted on the selected model's
    residual, and if it moved by more than KAPPA_TOLERANCE the selection is run once more with that
    level and the rows' weights it gives (`nuisance_residuals`; the bands stay those of the base
    residual). Not when a low-pass was named on the way: its residual carries the truth's error
    filtered, which the error model does not describe."""
    base = list(base)
    for n in base + list(candidates or []):
        if n not in EFFECTS:
            raise ValueError(f"unknown effect {n!r}; the vocabulary is {', '.join(sorted(EFFECTS))}")
    if candidates is None:
        candidates = [n for n in EFFECTS if n not in base]
    candidates = [c for c in candidates if c not in base]
    effects = {n: EFFECTS[n]() for n in base + candidates}
    if "bias_random_walk" in effects:
        effects["bias_random_walk"].knot_spacing_s = rw_knot_spacing_s
    scorable = [c for c in candidates if not effects[c].stochastic or c == "sensor_bandwidth"]
    selected = [b for b in base if not effects[b].stochastic]
    if band_vibration is None:
        band_vibration = "white_noise" in effects
    band_vibration = band_vibration and "vibration" in scorable
    thresholds = dict(thresholds or {})

    # the white-noise level per axis weights the rows
    sigma = noise_weights([fc.residual for fc in fcs])
    # a plateau at the largest magnitude is a property of the data, whatever the model: the samples near it leave
    # every model's fits (base included) and the trusted band's spectra, whose floor clipped peaks would raise
    plateau = Saturation.detect(fcs, sigma)
    clipped = plateau["plateau_samples"] >= Saturation.MIN_PLATEAU
    if clipped:
        set_saturation_mask(fcs, plateau["limit"], sigma)
        # the noise level again without the clipped stretches (their differences are the true rate's changes)
        sigma = noise_weights([fc.residual for fc in fcs], row_masks(fcs))
        set_saturation_mask(fcs, plateau["limit"], sigma)
        plateau = Saturation.detect(fcs, sigma)
    saturation = None
    if "saturation" in effects:
        saturation = plateau
        effects["saturation"].params["limit"] = np.asarray(saturation["limit"])
    sat_limit = float(plateau["limit"]) if saturation is not None and clipped else None
    if trusted_band:
        # the band where the reconstructed true rate can be trusted, from the base model's residual
        d0 = Design(fcs, {n: effects[n] for n in selected}, sigma)
        resid0 = residuals_after(d0, d0.fit(selected), selected) if nuisance_residuals is None else nuisance_residuals
        # and the reconstruction error as a weighted nuisance; the rows' weights then come from the
        # sensor's floor in the band, not from first differences (which read the reconstruction error)
        sigma_band = set_reconstruction_model(fcs, resid0)
        if sigma_band is not None:
            sigma = sigma_band
        for h in holdout or []:
            if "band_hz" not in h.extra:
                set_bands([h], [h.residual - h.residual.mean(0)])
            kappa = fcs[0].extra.get("nuisance_level")
            if kappa is not None:
                set_row_weights([h], fcs[0].extra["sensor_floor"], kappa)
    steps: list[dict] = []
    while True:
        corner = _named_corner(effects, selected)
        view = [sensor_view(fc, corner) for fc in fcs]
        remaining = [c for c in scorable if c not in selected]
        st = score_step(view, effects, selected, remaining, sigma, band_vibration, thresholds, bic_threshold, fcs)
        design, cur = st.design, st.current
        step = {"model": list(selected), "rss_weighted": cur.rss, "n": cur.n, "candidates": st.scores}
        steps.append(step)
        added = len(selected) - len([b for b in base if not effects[b].stochastic])
        if not st.scores or added >= max_added:
            break
        best = None
        for sc in st.scores:
            thr = thresholds.get(sc["effect"], bic_threshold)
            sc["threshold"] = thr
            # the practical minimum of a regression effect is judged on the held-out sequences (power OR
            # drift) when there are some: its in-sample power share alone would veto an effect that
            # matters for attitude while carrying little power
            judged_on_holdout = bool(holdout) and sc.get("variant") != "band-limited"
            judged_on_holdout = judged_on_holdout and not effects[sc["effect"]].stochastic
            if sc["delta_bic"] < thr or (sc["gain"] < min_gain and not judged_on_holdout):
                continue
            if holdout and sc.get("variant") == "band-limited":
                # noise cannot be predicted: the band must be there in the held-out spectra too, at a
                # practical share of their in-band power
                hg, dll = _holdout_band_share(design, effects, selected, sigma, holdout, corner, sat_limit, st.band)
                sc["holdout_gain"] = hg
                sc["holdout_transfer_dloglik"] = dll
                if hg < min_gain or not dll > 0:
                    continue
            elif judged_on_holdout:
                hg, hd = _holdout_gain(design, effects, selected, sc["effect"], sigma, holdout, corner, sat_limit)
                sc["holdout_gain"] = hg
                sc["holdout_drift_reduction_deg"] = hd
                if not practical(hg, hd, min_gain, min_drift_deg):
                    continue
            best = sc
            break
        if best is None:
            break
        step["added"] = best["effect"]
        if best.get("variant") == "band-limited":
            step["added_variant"] = "band-limited"
            # from now on a stochastic term of the noise model: no columns (refitted at the end)
            effects["vibration"].params.update(
                frequency_hz=np.asarray(st.band.frequency_hz),
                bandwidth_hz=np.asarray(st.band.bandwidth_hz),
                amplitude=st.band.amplitude,
            )
        if best["effect"] == "sensor_bandwidth":
            effects["sensor_bandwidth"].params["corner_hz"] = np.asarray(best["corner_hz"])
        selected.append(best["effect"])
    final = design.fit(selected)  # the last step added nothing: its design holds the model
    band_check = {"thresholds": thresholds, "bic_threshold": bic_threshold, "min_gain": min_gain, "steps": steps}
    if band_vibration and "vibration" in selected and effects["vibration"].stochastic:
        design, final = _recheck_band(design, final, view, effects, selected, sigma, fcs, corner, **band_check)
    delay_lp = None
    if "time_offset" in selected and "sensor_bandwidth" in scorable and "sensor_bandwidth" not in selected:
        design, final, view, delay_lp = lowpass_choice.choose(
            design, final, effects, selected, sigma, fcs, thresholds.get("sensor_bandwidth", bic_threshold)
        )
        if delay_lp is not None and delay_lp["kept"] in ("sensor_bandwidth", "both"):
            design, final = _recheck_named(design, final, selected, base, thresholds, bic_threshold, steps)
            if "vibration" in selected and effects["vibration"].stochastic:  # the low-pass shapes the floor now
                lp = float(effects["sensor_bandwidth"].params["corner_hz"])
                design, final = _recheck_band(design, final, view, effects, selected, sigma, fcs, lp, **band_check)
    # every named regression effect once more, given all the others: one named early may have stood in for effects
    # named after it (an audit's piecewise-linear bias, a 'bias random walk' of 0 +- 1.5 SE, took the slow part of
    # a scale factor, a g-sensitivity and a time offset at step 1, and stayed)
    design, final = _recheck_named(design, final, selected, base, thresholds, bic_threshold, steps)
    # a time offset the delay-or-low-pass choice kept may be gone now: its record must not name it
    delay_lp = lowpass_choice.after_backward_check(delay_lp, selected)
    if trusted_band and nuisance_residuals is None and corner is None:
        # the reconstruction model again (band, sensor floor, error level), on the selected model's residual (a
        # low-pass the motion named included): the base residual holds the effects' own power
        resid = residuals_after(design, final, selected, view)
        first = fcs[0].extra.get("nuisance_level")
        if _nuisance_moved(fcs, resid):
            for fc in fcs:  # the band, the floor and the level all from the selected model's residual
                for key in RECONSTRUCTION_KEYS:
                    fc.extra.pop(key, None)
            sel = select_effects(
                fcs, base=base, candidates=candidates, bic_threshold=bic_threshold, min_gain=min_gain,
                min_drift_deg=min_drift_deg, max_added=max_added, rw_knot_spacing_s=rw_knot_spacing_s,
                band_vibration=band_vibration, trusted_band=trusted_band, thresholds=thresholds, holdout=holdout,
                nuisance_residuals=resid,
            )  # fmt: skip
            sel.nuisance_refit = {"first_fit": np.asarray(first).tolist(), "model": list(selected)}
            return sel
    sel = Selection(
        base=base,
        selected=selected,
        named=[n for n in selected if n not in base],
        steps=steps,
        not_identifiable=sorted(set(st.not_identifiable) - set(selected)),  # a low-pass may replace an offset
        saturation=saturation,
        effects=effects,
        sigma=sigma,
        design=design,
        result=final,
        identifiability=_final_identifiability(view, effects, selected, sigma, scorable, thresholds, bic_threshold),
        thresholds={c: thresholds.get(c, bic_threshold) for c in scorable},
        delay_or_lowpass=delay_lp,
    )
    fill_params(sel, view)
    if sel.band is not None and sel.band.kappa is not None:
        # the reconstruction error's level beside the named band: the base model's fit had to take
        # the band's power into it (re-simulations draw the error at this level)
        set_row_weights(fcs + list(holdout or []), fcs[0].extra["sensor_floor"], sel.band.kappa)
    return sel


def _nuisance_moved(fcs: list[FitContext], residuals: list[np.ndarray]) -> bool:
    """Whether the reconstruction model refitted on `residuals` (band, sensor floor and the error's level,
    `set_reconstruction_model`) differs from the one that weights the rows now by more than KAPPA_TOLERANCE in the
    floor or the level on some axis. The base residual holds the effects' own power: a strong low-pass left the
    floor 80 times too high and the level at nothing (10 Hz, 3 x 60 s behind the blind trials' mocap)."""
    old_level, old_floor = fcs[0].extra.get("nuisance_level"), fcs[0].extra.get("sensor_floor")
    if old_level is None or old_floor is None:
        return False
    trial = [replace(fc, extra=without_reconstruction(fc.extra)) for fc in fcs]
    if set_reconstruction_model(trial, residuals) is None:
        return False
    new_level, new_floor = trial[0].extra.get("nuisance_level"), trial[0].extra.get("sensor_floor")
    if new_level is None or new_floor is None:
        return False
    ratios = [
        np.maximum(new, 1e-12) / np.maximum(old, 1e-12) for new, old in ((new_level, old_level), (new_floor, old_floor))
    ]
    return bool(any(np.any(np.abs(np.log(r)) > np.log1p(KAPPA_TOLERANCE)) for r in ratios))


def _final_identifiability(
    view: list[FitContext],
    effects: dict[str, Effect],
    selected: list[str],
    sigma: np.ndarray,
    scorable: list[str],
    thresholds: dict[str, float],
    bic_threshold: float,
) -> dict[str, dict]:
    """The reported identifiability: each regression effect's expected delta BIC given the other effects of the
    FINAL model, at the final residual's variance. (Against the base model, a large missing effect swells the
    residual and makes the others look unidentifiable, even ones the selection then names.)"""
    regress = [c for c in scorable if not effects[c].stochastic]
    design = Design(view, {n: effects[n] for n in dict.fromkeys(selected + regress)}, sigma)
    cur = design.fit(selected)
    s2 = cur.rss / max(cur.n - cur.k, 1)
    out = {}
    for c in regress:
        given = [n for n in selected if n != c]
        idf = identifiability(design, given, c, s2, thresholds.get(c, bic_threshold), NONLINEAR_PARAMS.get(c, 0))
        if idf is not None:
            out[c] = idf.as_dict()
    return out


def _recheck_band(
    design: Design,
    final: FitResult,
    view: list[FitContext],
    effects: dict[str, Effect],
    selected: list[str],
    sigma: np.ndarray,
    fcs: list[FitContext],
    corner: float | None,
    thresholds: Mapping[str, float],
    bic_threshold: float,
    min_gain: float,
    steps: list[dict],
) -> tuple[Design, FitResult]:
    """Backward check of a named band-limited vibration: it was scored on the residual of its step; once the
    effects added after it are fitted, and the floor shaped by a sensor low-pass of `corner` if one is named (a
    low-pass shapes the gyro's noise too: a broad band can stand in for that shape before the low-pass is named),
    it must still clear its threshold and practical minimum, or it is removed (colour that another effect
    explains is not vibration)."""
    v = effects["vibration"].params
    resid = residuals_after(design, final, selected)
    band = fit_band(
        resid,
        fcs[0].rate_hz,
        row_masks(fcs),
        starts=[(float(v["frequency_hz"]), float(v["bandwidth_hz"]))],
        bands=band_edges(fcs),
        floor_corner_hz=corner,
        nuisance=nuisance_of(fcs, corner),
    )
    dbic = band.delta_bic(final.n) if band is not None else -np.inf
    gain = band.explained(sigma, fcs[0].rate_hz) if band is not None else 0.0
    if dbic >= thresholds.get("vibration", bic_threshold) and gain >= min_gain:
        return design, final
    selected.remove("vibration")
    v["bandwidth_hz"] = np.asarray(0.0)
    step = {"model": list(selected), "removed": "vibration", "delta_bic_on_final_residual": float(dbic)}
    steps.append(step | ({"floor_corner_hz": corner} if corner is not None else {}))
    design = Design(view, {n: effects[n] for n in selected}, sigma)
    return design, design.fit(selected)


def _recheck_named(
    design: Design,
    final: FitResult,
    selected: list[str],
    base: list[str],
    thresholds: Mapping[str, float],
    bic_threshold: float,
    steps: list[dict],
) -> tuple[Design, FitResult]:
    """Backward check of the named regression effects, each given all the others: one whose delta BIC no longer
    clears its threshold is removed (the weakest first, repeated). Run at the end of every selection, and first once
    a low-pass replaced a named time offset: effects named beside the offset may have stood in for the low-pass's
    magnitude droop, which a delay lacks (a scale factor below 1 does it at low frequencies)."""
    while True:
        named = [n for n in selected if n not in base and design.cols.get(n) is not None and design.cols[n].size]
        scored = []  # (delta BIC, name) of each named effect given the others
        for n in named:
            rest = [m for m in selected if m != n]
            scored.append((float(design.fit(rest).bic - final.bic) - NONLINEAR_PARAMS.get(n, 0) * np.log(final.n), n))
        weak = [(d, n) for d, n in scored if d < thresholds.get(n, bic_threshold)]
        if not weak:
            return design, final
        dbic, name = min(weak)
        selected.remove(name)
        steps.append({"model": list(selected), "removed": name, "delta_bic_on_final_residual": dbic})
        final = design.fit(selected)
