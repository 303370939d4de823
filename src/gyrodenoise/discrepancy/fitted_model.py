"""The selected model (`Selection`), its parameters (with standard errors) and its prediction on another sequence.

`fill_params` turns the greedy selection's fit (`rank.select_effects`) into effect parameters: the
regression effects' coefficients, the stochastic effects' levels (white noise, random walk, the
refitted band-limited vibration, the sensor low-pass's corner), and the effects named from the data
directly (quantization lattice, saturation plateau). `per_sequence_refit` predicts the residual of a
sequence the model was not fitted on: sensor constants kept, per-sequence nuisances refitted there.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gyrodenoise.allan import root_with_se
from gyrodenoise.discrepancy.design import (
    Design,
    FitResult,
    band_edges,
    band_limited,
    fit_rows,
    noise_weights,
    nuisance_of,
    residuals_after,
    row_masks,
    sensor_view,
    set_saturation_mask,
)
from gyrodenoise.discrepancy.spectral import BandFit, FloorShapeFit, FloorShapeProfile, fit_band, fit_floor
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import EFFECTS, Effect, Quantization, Saturation

QUANT_LATTICE_FRACTION = 0.95  # share of samples on one lattice for quantization to be named

__all__ = ["Selection", "fill_params", "per_sequence_refit", "predict"]


@dataclass
class Selection:
    base: list[str]
    selected: list[str]  # base regression effects + named ones, in order of addition
    named: list[str]  # effects added on top of the base model (regression + stochastic)
    steps: list[dict]
    not_identifiable: list[str]
    effects: dict[str, Effect]  # all candidate instances (nonlinear parameters set)
    fitted: dict[str, Effect] = field(default_factory=dict)  # named + base with fitted parameters
    params: dict[str, dict] = field(default_factory=dict)
    se: dict[str, dict] = field(default_factory=dict)
    sigma: np.ndarray | None = None
    saturation: dict | None = None
    design: Design | None = None
    result: FitResult | None = None
    band: BandFit | None = None  # band-limited vibration (spectral fit on the final residual)
    floor_shape: FloorShapeFit | None = None  # named sensor low-pass, where the floor's profile gave its standard error
    identifiability: dict[str, dict] = field(default_factory=dict)  # candidate -> numbers (first step)
    thresholds: dict[str, float] = field(default_factory=dict)  # candidate -> delta BIC it had to clear
    # a named time offset against a sensor low-pass of the same delay (`identifiability.delay_or_lowpass`):
    # separable or not, and which one the data preferred when separable
    delay_or_lowpass: dict | None = None
    # quantization is named from the raw samples, not by regression: the lattice step and the share of samples on it
    lattice: dict | None = None
    # named sensor constants refitted on the held-out sequences (`transfer.transfer_check`): chi-square, Birge ratio
    transfer: dict[str, dict] = field(default_factory=dict)
    # the selected model refitted on each sequence and each half (`replicates.replicates_of`), made once: the held-out
    # check and the bias spread both read it
    replicates: object | None = None
    # the reconstruction error's level of the first pass and the model whose residual moved it (`rank.select_effects`
    # then selected again with the refitted level); None: no second pass
    nuisance_refit: dict | None = None
    # the flicker floor's check after the selection (`bias_instability.check`); None: not run
    instability: dict | None = None

    @property
    def equivalences(self) -> list[str]:
        """Named effects that this motion cannot tell from another (sentences for the report)."""
        d = self.delay_or_lowpass
        if d is None or d["separable"] or d.get("removed_by_backward_check"):  # a removed offset: equivalent to none
            return []
        return [d["sentence"]]

    @property
    def cautions(self) -> list[str]:
        """Named effects that another explanation may hide behind on this data (sentences for the report). Behind a
        noisy ground truth, the choice between a time offset and a low-pass rests on charging the low-pass what it
        gains by smoothing the truth's own noise (`lowpass_choice.truth_error_smoothing`), and its statistic has a
        sampling spread of its own: the cross term of the two explanations' difference with the noise, of standard
        deviation ~2 sqrt(lambda) for an expected delta BIC lambda. A margin over the threshold within that spread is
        said.
        A named effect whose searched parameter ended at an end of its search (`Effect.at_search_edge`) is said too:
        a blind trial's scale asymmetry, before the vocabulary had it, was named a warm-up bias of tau 2 s."""
        edges = [(n, self.effects[n].at_search_edge()) for n in self.named if n in self.effects]
        out = [
            f"{n} was named with {edge}: its best value may lie beyond the search, and it may stand in for an effect "
            "the vocabulary lacks"
            for n, edge in edges
            if edge is not None
        ]
        d = self.delay_or_lowpass
        if d is None or d.get("truth_error_smoothing_bic", 0.0) <= 0 or "delta_bic_lowpass_vs_offset" not in d:
            return out
        if d.get("removed_by_backward_check"):  # the offset the choice kept is no longer named: no choice to caution
            return out
        if d["kept"] == "both":  # the pair against the better one of them: the droop at the pair's corner
            thr = d["threshold"]  # one parameter more: the detection threshold
            margin = abs(d["delta_bic_both_vs_one"] - thr)
            spread = 2.0 * np.sqrt(max(d["both_expected_delta_bic"], 0.0))
            if margin >= spread:
                return out
            return out + [
                f"sensor_bandwidth ({d['both_corner_hz']:.1f} Hz) with time_offset ({1e3 * d['both_delay_s']:.2f} ms) "
                f"was preferred to one of them alone by a margin of {margin:.0f} in delta BIC (threshold {thr:g}, "
                f"after charging the low-pass {d['truth_error_smoothing_bic']:.0f} for smoothing the ground truth's "
                f"own noise), within the statistic's spread on this motion (~{spread:.0f}): it may be one of them"
            ]
        # the switch between the two single explanations has a threshold of its own (`lowpass_choice.SWITCH_THRESHOLD`;
        # runs before session 54 recorded only the detection threshold, which it was then)
        thr = d.get("switch_threshold", d["threshold"])
        margin = abs(d["delta_bic_lowpass_vs_offset"] - thr)
        spread = 2.0 * np.sqrt(max(d["expected_delta_bic"], 0.0))
        if margin >= spread:
            return out
        delay, corner = f"{1e3 * d['delay_s']:.2f} ms", f"{d['lowpass_corner_hz']:.1f} Hz"
        if d["kept"] == "sensor_bandwidth":
            kept, other = f"sensor_bandwidth ({corner})", f"a time offset of {delay}"
        else:
            kept, other = f"time_offset ({delay})", f"a sensor low-pass of corner {corner}"
        return out + [
            f"{kept} was preferred to {other} by a margin of {margin:.0f} in delta BIC (threshold {thr:g}, after "
            f"charging the low-pass {d['truth_error_smoothing_bic']:.0f} for smoothing the ground truth's own noise), "
            f"within the statistic's spread on this motion (~{spread:.0f}): it may be {other}"
        ]

    @property
    def below_practical(self) -> list[dict]:
        """Candidates of the last step that clear their threshold but not the practical minimum: there
        (statistically), too small to matter (what they close on the held-out sequences is recorded)."""
        last = next((st for st in reversed(self.steps) if "candidates" in st), None)
        if last is None or last.get("added"):
            return []
        return [
            c
            for c in last["candidates"]
            if c.get("threshold") is not None and c["delta_bic"] >= c["threshold"] and c["effect"] not in self.named
        ]

    @property
    def band_vibration(self) -> bool:
        """Whether the named vibration is the band-limited (stochastic) variant."""
        return "vibration" in self.selected and self.effects["vibration"].stochastic

    @property
    def corner_hz(self) -> float | None:
        """Corner of the named sensor low-pass (None: not named)."""
        return float(self.effects["sensor_bandwidth"].params["corner_hz"]) if "sensor_bandwidth" in self.named else None


def fill_params(sel: Selection, fcs: list[FitContext]) -> None:
    """Parameters with standard errors for the selected effects, and the stochastic ones."""
    design, res = sel.design, sel.result
    se_all = res.se()
    for name in sel.selected:
        e = sel.effects[name]
        if e.stochastic:
            continue
        idx = design.cols[name]
        p, s = e.params_from_fit(res.coef[idx], se_all[idx])
        sel.params[name], sel.se[name] = p, s
    no_rw = [n for n in sel.selected if n != "bias_random_walk"]
    resid_no_rw = residuals_after(design, res, no_rw)
    resid_all = residuals_after(design, res, sel.selected)
    # stochastic effects: white noise always (base or named); random walk if selected; quantisation
    sel.params["white_noise"], sel.se["white_noise"] = _white_noise(fcs, resid_all)
    corner = sel.corner_hz
    if band_limited(fcs) or corner is not None or nuisance_of(fcs) is not None:
        # the level of the floor in the trusted band (at 0 Hz under a named low-pass): first
        # differences would read the reconstruction error or the low-pass's droop instead
        nu = nuisance_of(fcs, corner)
        c, c_se = fit_floor(resid_all, fcs[0].rate_hz, row_masks(fcs), band_edges(fcs), corner, nu)
        dens = np.sqrt(c / 2)
        sel.params["white_noise"], sel.se["white_noise"] = {"density": dens}, {"density": c_se / (4 * dens)}
    if corner is not None:
        # the corner stays the selection's. Its standard error: where the motion alone chose it (it replaced a time
        # offset, `lowpass_choice.choose`), from that fit's profile; else (spectrum and motion together) from the
        # curvature of the floor's profile on the final residual
        by_motion = sel.delay_or_lowpass or {}
        if by_motion.get("kept") == "sensor_bandwidth":
            se = by_motion["lowpass_corner_se_hz"]
        elif by_motion.get("kept") == "both":
            # beside a time offset: the pair's profile; the offset's SE takes the corner's part (they share the delay)
            se = by_motion["both_corner_se_hz"]
            off = sel.se.get("time_offset", {}).get("delta")
            if off is not None:
                sel.se["time_offset"]["delta"] = np.hypot(off, by_motion["both_delay_se_from_corner_s"])
        else:
            prof = FloorShapeProfile(
                resid_all, fcs[0].rate_hz, row_masks(fcs), band_edges(fcs), None, nuisance_of(fcs), named=True
            )
            sel.floor_shape = prof.fit(corner) if prof.ok else None
            se = sel.floor_shape.corner_se_hz if sel.floor_shape is not None else np.nan
        sel.params["sensor_bandwidth"] = {"corner_hz": np.asarray(corner)}
        sel.se["sensor_bandwidth"] = {"corner_hz": np.asarray(se)}
    if sel.band_vibration:
        # the band refitted on the final residual, with standard errors; the white-noise level is
        # its floor (the first-difference estimate above would include the band's power)
        v = sel.effects["vibration"].params  # the selection step's fit: the start
        start = [(float(v["frequency_hz"]), float(v["bandwidth_hz"]))]
        band = fit_band(
            resid_all,
            fcs[0].rate_hz,
            row_masks(fcs),
            with_errors=True,
            starts=start,
            bands=band_edges(fcs),
            floor_corner_hz=corner,
            nuisance=nuisance_of(fcs, corner),
        )
        if band is not None:  # None: no excess left to start from; keep the selection step's fit
            sel.band = band
            sel.params["vibration"], sel.se["vibration"] = band.params()
            sel.effects["vibration"].params.update(sel.params["vibration"])
            sel.params["white_noise"] = {"density": band.white_noise_density}
            dens_se = band.floor_se / (2 * np.sqrt(2 * np.maximum(band.floor, 1e-300)))
            sel.se["white_noise"] = {"density": dens_se}
        else:
            sel.params["vibration"] = {k: v.copy() for k, v in sel.effects["vibration"].params.items()}
            sel.se["vibration"] = {}
    if "white_noise" not in sel.base and "white_noise" in sel.effects:
        sel.named.append("white_noise")
    if "bias_random_walk" in sel.selected:
        if nuisance_of(fcs) is None:
            p, s = sel.effects["bias_random_walk"].estimate(fcs, resid_no_rw)
        else:
            # a reconstructed true rate adds the derivative of a noisy angle, whose Allan variance
            # swamps the walk's at the cluster times a flight offers: read K from the knots instead
            p, s = _walk_from_knots(sel)
        sel.params["bias_random_walk"], sel.se["bias_random_walk"] = p, s
    if "quantization" in sel.effects and "quantization" not in sel.base:
        q, frac = Quantization.lattice_step(np.concatenate([fc.gyro for fc in fcs]))
        sel.lattice = {"step": float(q), "fraction": float(frac), "required_fraction": QUANT_LATTICE_FRACTION}
        sigma_min = float(np.min(sel.sigma))
        # a lattice that holds nearly every sample, with a step not far below the noise
        if frac >= QUANT_LATTICE_FRACTION and q > 1e-3 * sigma_min:
            sel.named.append("quantization")
            sel.params["quantization"], sel.se["quantization"] = {"step": np.asarray(q)}, {"step": np.asarray(0.0)}
    sat = sel.saturation
    if sat is not None and "saturation" not in sel.base:
        if sat["plateau_samples"] >= Saturation.MIN_PLATEAU and sat["beyond_samples"] >= Saturation.MIN_PLATEAU:
            sel.named.append("saturation")
            sel.params["saturation"], sel.se["saturation"] = (
                {"limit": np.asarray(sat["limit"])},
                {"limit": np.asarray(0.0)},
            )
        elif sat["beyond_samples"] < Saturation.MIN_PLATEAU:
            sel.not_identifiable = sorted({*sel.not_identifiable, "saturation"})
    for name in sel.base:
        if name == "quantization":
            q, _ = Quantization.lattice_step(np.concatenate([fc.gyro for fc in fcs]))
            sel.params[name], sel.se[name] = {"step": np.asarray(q)}, {"step": np.asarray(0.0)}
    if "white_noise" not in sel.base and "white_noise" not in sel.named:
        del sel.params["white_noise"], sel.se["white_noise"]  # not part of this model
    for name, p in sel.params.items():
        kw = {k: v for k, v in p.items() if k in EFFECTS[name].DEFAULTS}
        sel.fitted[name] = EFFECTS[name](**kw)


def _walk_from_knots(sel: Selection) -> tuple[dict, dict]:
    """Rate random walk K per axis from the fitted random-walk knots: the increments of the bias path between knots h
    apart have variance K^2 times their layout's `knot_increment_variance` (about 1.17 h), plus their estimation
    variance (from the fit's covariance), which is taken off. Returns ({'density'}, {'density'} standard error)."""
    e, design, res = sel.effects["bias_random_walk"], sel.design, sel.result
    cov = np.zeros((design.p, design.p))
    cov[np.ix_(res.idx, res.idx)] = res.cov
    layouts = [(e.n_knots(fc), knot_increment_variance(e, fc)) for fc in design.fcs]
    k2, k2_se = np.zeros(3), np.zeros(3)
    for a in range(3):
        incs, noise, walk_var = [], [], []
        for cols, (nk, var) in zip(np.atleast_2d(design.cols["bias_random_walk"]), layouts, strict=True):
            # a shorter sequence has fewer knots: its 3 nk columns come first, then the design's padding
            c = cols[a * nk : (a + 1) * nk]
            path = np.concatenate([[0.0], res.coef[c]])  # the first knot is the bias itself
            D = np.zeros((nk, nk))  # increments as a linear map of the knot coefficients
            D[np.arange(nk), np.arange(nk)] = 1.0
            D[np.arange(1, nk), np.arange(nk - 1)] = -1.0
            incs.append(np.diff(path))
            noise.append(np.diag(D @ cov[np.ix_(c, c)] @ D.T))
            walk_var.append(var)
        d, v, g = np.concatenate(incs), np.concatenate(noise), np.concatenate(walk_var)
        k2[a] = max(float(np.sum(d**2 - v)), 0.0) / float(np.sum(g))
        k2_se[a] = float(np.sqrt(2.0 / len(d)) * np.sum(d**2)) / float(np.sum(g))
    k, se = root_with_se(k2, k2_se)
    return {"density": k}, {"density": se}


LAYOUT_KNOTS = 16  # a longer layout takes its ends' variances from one this long, the middle's for the rest


def knot_increment_variance(e: Effect, fc: FitContext) -> np.ndarray:
    """E[increment^2] / K^2 (s) of each knot increment of sequence `fc` when its bias path is a random walk of density
    K. Not the spacing h: the least-squares hats beside the bias overshoot the path's own increments (1.17 h inside an
    even layout, up to 1.24 h at its ends; K read from h alone was ~8 % high), and h is the layout's (the recording's
    length over the knot count), not the nominal spacing. The knots are a linear map P of the path, the path the
    cumulative sum L of white steps: the variances are the row sums of squares of D P L (D: the increments). On a
    uniform grid at the sequence's rate over at most LAYOUT_KNOTS knots of its spacing: a knot's estimate
    hardly depends on knots a few spacings away."""
    nk = e.n_knots(fc)
    m = min(nk, LAYOUT_KNOTS)
    h = round((fc.t[-1] - fc.t[0]) / nk * fc.rate_hz) / fc.rate_hz
    grid = np.arange(int(round(m * h * fc.rate_hz)) + 1) / fc.rate_hz
    hats = np.clip(1.0 - np.abs(grid[:, None] - h * np.arange(1, m + 1)[None, :]) / h, 0.0, None)
    P = np.linalg.pinv(np.concatenate([np.ones((len(grid), 1)), hats], 1))[1:]  # (m, N): the knots from the path
    PL = np.cumsum(P[:, ::-1], 1)[:, ::-1] / np.sqrt(fc.rate_hz)  # the knots from the white steps (unit density)
    inc = PL - np.concatenate([np.zeros((1, PL.shape[1])), PL[:-1]])  # the first increment is from 0 (the bias)
    v = (inc**2).sum(1)
    if nk == m:
        return v
    half = m // 2
    return np.concatenate([v[:half], np.full(nk - 2 * half, v[half]), v[m - half :]])


def _white_noise(fcs: list[FitContext], residuals: list[np.ndarray]) -> tuple[dict, dict]:
    """White-noise density from first differences (as `WhiteNoise.estimate`), of kept samples only where a
    saturation mask leaves some out."""
    masks = row_masks(fcs)
    n = sum(
        len(r) - 1 if m is None else int((m[1:] & m[:-1]).sum(0).min()) for m, r in zip(masks, residuals, strict=True)
    )
    dens = noise_weights(residuals, masks) / np.sqrt(fcs[0].rate_hz)
    return {"density": dens}, {"density": dens / np.sqrt(2 * max(n, 1))}


def predict(
    design: Design,
    res: FitResult,
    effects: dict[str, Effect],
    names: list[str],
    sigma: np.ndarray,
    fc: FitContext,
    sat_limit: float | None = None,
) -> np.ndarray:
    """Deterministic prediction (N, 3) of the residual of a sequence not used for fitting: sensor
    constants from `res`; per-sequence nuisances (bias, random-walk knots, vibration phase)
    refitted on this sequence, in its trusted band (`fit_rows`)."""
    glob = [n for n in names if not effects[n].per_sequence and not effects[n].stochastic]
    local = [n for n in names if effects[n].per_sequence and not effects[n].stochastic]
    pred = np.zeros((len(fc.t), 3))
    for n in glob:
        pred += np.einsum("nik,k->ni", effects[n].columns(fc), res.coef[design.cols[n]])
    if local:
        cols = [effects[n].columns(fc) for n in local]
        X = (np.concatenate(cols, 2) / sigma[None, :, None]).reshape(3 * len(fc.t), -1)
        r = ((fc.residual - pred) / sigma).reshape(-1)
        if sat_limit is not None:
            set_saturation_mask([fc], sat_limit, sigma)
        Xr, rr = fit_rows(fc, X, r)
        coef, *_ = np.linalg.lstsq(Xr, rr, rcond=None)
        pred += (X @ coef).reshape(-1, 3) * sigma
    if sat_limit is not None:  # the output cannot exceed the range
        pred = np.clip(fc.omega + pred, -sat_limit, sat_limit) - fc.omega
    return pred


def per_sequence_refit(sel: Selection, fc: FitContext, names: list[str] | None = None) -> np.ndarray:
    """Deterministic prediction (N, 3) of the residual gyro - true rate of a sequence not used for
    fitting (`predict`), through the named sensor low-pass if any: the model's gyro is
    fc.omega + prediction."""
    names = sel.selected if names is None else names
    sat = sel.params.get("saturation")
    view = sensor_view(fc, sel.corner_hz)
    pred = predict(
        sel.design, sel.result, sel.effects, names, sel.sigma, view, None if sat is None else float(sat["limit"])
    )
    return pred + (view.omega - fc.omega)
