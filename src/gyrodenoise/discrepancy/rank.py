"""Fit effects to the residual (measured - true rate), rank them by BIC, select greedily, and tell
which effects the motion cannot identify.

All regression effects are linear in their coefficients once their nonlinear parameter (a
frequency, a time constant, a range) is set by `Effect.prepare`. The weighted normal equations
(Gram matrix) of all columns are built once per selection step; any subset is then a small solve.
Rows are the three axes of every sample, weighted by 1/sigma_axis (white-noise level per axis).

Vibration has two variants. The sinusoid is a regression effect like the others. The band-limited
one is stochastic: it is scored by the Whittle likelihood of the residual's spectrum with and
without a band term (`gyrodenoise.discrepancy.spectral`), which is on the scale of the regression's
Gaussian likelihood, so both variants compete in the same step under the same BIC threshold; the
better one is the vibration candidate's score. Once the band-limited variant is named it has no
columns; it is refitted on the final residual, and the white-noise level then comes from the same
spectral fit (first differences would count the band's power as white noise).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gyrodenoise.discrepancy.spectral import BAND_PARAMS, BandFit, fit_band
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import EFFECTS, Effect, Quantization, Saturation

# nonlinear parameters searched by `prepare` (counted in the BIC penalty)
NONLINEAR_PARAMS = {"vibration": 1, "warmup_bias": 1, "bias_random_walk": 1}
COEF_SCALE: dict[str, float] = {}  # coefficient scale for identifiability, where not the prior's bound
IDENTIFIABLE_SE_FRACTION = 0.1  # identifiable: SE below this fraction of the largest plausible value
QUANT_LATTICE_FRACTION = 0.95


def row_mask(fc: FitContext) -> np.ndarray:
    """(N, 3) bool: rows used in the fits (samples near a saturation limit are left out)."""
    m = fc.extra.get("row_mask")
    return np.ones((len(fc.t), 3), dtype=bool) if m is None else m


def set_saturation_mask(fcs: list[FitContext], limit: float, sigma: np.ndarray, band: float = 15.0) -> None:
    """Leave out samples whose true rate is beyond or within `band` noise stds of the limit: there
    the output says only 'at least the limit', and clipped noise biases it. The band widens by the
    change of rate over one sample (the output filter averages across the limit)."""
    for fc in fcs:
        near = np.abs(fc.omega) > limit - band * sigma - np.abs(fc.alpha) / fc.rate_hz
        fc.extra["row_mask"] = ~near


def row_masks(fcs: list[FitContext]) -> list[np.ndarray | None]:
    return [fc.extra.get("row_mask") for fc in fcs]


def noise_weights(residuals: list[np.ndarray]) -> np.ndarray:
    """Per-axis white-noise std from first differences (insensitive to slow effects)."""
    d = np.concatenate([np.diff(r, axis=0) for r in residuals])
    return np.maximum(d.std(0) / np.sqrt(2), 1e-12)


class Design:
    """Weighted Gram matrix of every column of `effects` over the sequences `fcs`."""

    def __init__(self, fcs: list[FitContext], effects: dict[str, Effect], sigma: np.ndarray) -> None:
        self.fcs, self.effects, self.sigma = fcs, effects, sigma
        self.cols: dict[str, np.ndarray] = {}  # effect -> global column indices ((S, k) if per sequence)
        p = 0
        self.k = {name: e.columns(fcs[0]).shape[2] if not e.stochastic else 0 for name, e in effects.items()}
        for name, e in effects.items():
            k = self.k[name]
            if e.per_sequence and not e.stochastic:
                # column counts may differ per sequence (random-walk knots): take the largest
                k = max(e.columns(fc).shape[2] for fc in fcs)
                self.k[name] = k
                self.cols[name] = p + np.arange(len(fcs) * k).reshape(len(fcs), k)
                p += len(fcs) * k
            else:
                self.cols[name] = p + np.arange(k)
                p += k
        self.p = p
        self.G = np.zeros((p, p))
        self.b = np.zeros(p)
        self.rr = 0.0
        self.n = 0
        for s, fc in enumerate(fcs):
            X, idx = self.local_columns(s, list(effects))
            m = row_mask(fc).reshape(-1)
            X, r = X[m], (fc.residual / sigma).reshape(-1)[m]
            self.G[np.ix_(idx, idx)] += X.T @ X
            self.b[idx] += X.T @ r
            self.rr += float(r @ r)
            self.n += len(r)

    def local_columns(self, s: int, names: list[str], fc: FitContext | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Weighted columns (3N, k) of sequence s for `names`, with their global indices."""
        fc = fc or self.fcs[s]
        blocks, idx = [], []
        for name in names:
            e = self.effects[name]
            if e.stochastic:
                continue
            c = e.columns(fc) / self.sigma[None, :, None]
            gi = self.cols[name][s] if e.per_sequence else self.cols[name]
            if c.shape[2] < len(gi):  # fewer knots in this sequence: pad with empty columns
                c = np.concatenate([c, np.zeros((*c.shape[:2], len(gi) - c.shape[2]))], 2)
            blocks.append(c.reshape(-1, c.shape[2]))
            idx.append(gi)
        if not blocks:
            return np.zeros((3 * len(fc.t), 0)), np.zeros(0, dtype=int)
        return np.concatenate(blocks, 1), np.concatenate(idx)

    def indices(self, names: list[str]) -> np.ndarray:
        out = [self.cols[n].ravel() for n in names if not self.effects[n].stochastic]
        return np.concatenate(out) if out else np.zeros(0, dtype=int)

    def fit(self, names: list[str]) -> FitResult:
        idx = self.indices(names)
        coef = np.zeros(self.p)
        if len(idx) == 0:
            return FitResult(coef, self.rr, 0, np.zeros((0, 0)), idx, self.n)
        G = self.G[np.ix_(idx, idx)]
        w, V = np.linalg.eigh(G)
        keep = w > 1e-10 * max(w.max(), 1e-300)
        Ginv = (V[:, keep] / w[keep]) @ V[:, keep].T
        c = Ginv @ self.b[idx]
        coef[idx] = c
        rss = max(self.rr - float(c @ self.b[idx]), 1e-300)
        k = int(keep.sum())
        s2 = rss / max(self.n - k, 1)
        return FitResult(coef, rss, k, s2 * Ginv, idx, self.n)

    def conditional_se(self, given: list[str], name: str, s2: float) -> np.ndarray:
        """Standard errors of `name`'s coefficients when fitted together with `given` (inf when the
        data cannot separate them: the columns lie in the span of the others)."""
        o, c = self.indices(given), self.cols[name].ravel()
        Gcc = self.G[np.ix_(c, c)]
        if len(o):
            Goo = self.G[np.ix_(o, o)]
            Goc = self.G[np.ix_(o, c)]
            S = Gcc - Goc.T @ np.linalg.pinv(Goo, rcond=1e-12, hermitian=True) @ Goc
        else:
            S = Gcc
        S = (S + S.T) / 2
        w, V = np.linalg.eigh(S)
        scale = max(float(np.trace(Gcc)) / len(c), 1e-300)
        w_safe = np.where(w > 1e-9 * scale, w, 0.0)
        with np.errstate(divide="ignore"):
            var = (V**2 / np.where(w_safe > 0, w_safe, np.nan)[None]).sum(1)
        var = np.where(np.isnan(var), np.inf, var)
        return np.sqrt(s2 * var)


@dataclass
class FitResult:
    coef: np.ndarray
    rss: float
    k: int
    cov: np.ndarray
    idx: np.ndarray
    n: int

    @property
    def bic(self) -> float:
        return self.n * np.log(self.rss / self.n) + self.k * np.log(self.n)

    def se(self) -> np.ndarray:
        out = np.zeros_like(self.coef)
        out[self.idx] = np.sqrt(np.clip(np.diag(self.cov), 0, None))
        return out


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

    @property
    def band_vibration(self) -> bool:
        """Whether the named vibration is the band-limited (stochastic) variant."""
        return "vibration" in self.selected and self.effects["vibration"].stochastic


def residuals_after(design: Design, res: FitResult, names: list[str], fcs: list[FitContext] | None = None):
    """Per-sequence residuals (unweighted) after removing the fitted columns of `names`."""
    out = []
    for s, fc in enumerate(fcs or design.fcs):
        X, idx = design.local_columns(s, names, fc)
        pred = (X @ res.coef[idx]).reshape(-1, 3) * design.sigma
        out.append(fc.residual - pred)
    return out


def _identifiable(design: Design, given: list[str], name: str, s2: float) -> tuple[bool, float]:
    e = design.effects[name]
    se = design.conditional_se(given, name, s2)
    if e.per_sequence:
        # many nuisance columns (knots, phases): identifiable when some direction is new
        best = float(np.min(se)) if len(se) else np.inf
        return bool(np.isfinite(best)), best
    scale = COEF_SCALE.get(name, e.PRIOR[1])
    worst = float(np.max(se)) if len(se) else np.inf
    return bool(worst < IDENTIFIABLE_SE_FRACTION * scale), worst


def select_effects(
    fcs: list[FitContext],
    base: list[str] = ("bias", "white_noise"),
    candidates: list[str] | None = None,
    bic_threshold: float = 10.0,
    min_gain: float = 0.0,
    max_added: int = 6,
    rw_knot_spacing_s: float = 10.0,
    band_vibration: bool | None = None,
) -> Selection:
    """Greedy forward selection: add the candidate with the largest BIC gain, refit, repeat, until no
    candidate gains more than `bic_threshold` and explains at least `min_gain` of the remaining
    weighted residual sum of squares.

    `band_vibration`: also try the band-limited variant of `vibration` (a stochastic term of the
    noise spectrum). Default: when white noise is part of the model (base or candidates), i.e. when
    the residual is modelled as noise at all; a fit of a deterministic signal (a network's
    correction, `network.py`) leaves it out."""
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
    regress = [c for c in candidates if not effects[c].stochastic]
    selected = [b for b in base if not effects[b].stochastic]
    if band_vibration is None:
        band_vibration = "white_noise" in effects
    band_vibration = band_vibration and "vibration" in regress

    # the white-noise level per axis weights the rows
    sigma = noise_weights([fc.residual for fc in fcs])
    saturation = None
    if "saturation" in effects:
        saturation = Saturation.detect(fcs, sigma)
        effects["saturation"].params["limit"] = np.asarray(saturation["limit"])
        if saturation["plateau_samples"] >= Saturation.MIN_PLATEAU:
            set_saturation_mask(fcs, saturation["limit"], sigma)
    steps: list[dict] = []
    not_ident: dict[str, float] = {}
    while True:
        design0 = Design(fcs, {n: effects[n] for n in selected}, sigma)
        cur0 = design0.fit(selected)
        resid = residuals_after(design0, cur0, selected)
        for c in regress:
            if c not in selected:
                effects[c].prepare(fcs, resid)
        remaining = [c for c in regress if c not in selected]
        design = Design(fcs, {n: effects[n] for n in selected + remaining}, sigma)
        cur = design.fit(selected)
        s2 = cur.rss / max(cur.n - cur.k, 1)
        scores = []
        not_ident = {}
        for c in remaining:
            ok, worst = _identifiable(design, selected, c, s2)
            if not ok:
                not_ident[c] = worst
                continue
            res = design.fit(selected + [c])
            dk = res.k - cur.k + NONLINEAR_PARAMS.get(c, 0)
            dbic = cur.n * np.log(cur.rss / res.rss) - dk * np.log(cur.n)
            score = {"effect": c, "delta_bic": float(dbic), "gain": float(1 - res.rss / cur.rss), "k": dk}
            if c == "vibration":
                score["variant"] = "sinusoid"
            scores.append(score)
        band = None
        if band_vibration and "vibration" in remaining:
            band = fit_band(resid, fcs[0].rate_hz, row_masks(fcs))
            if band is not None:
                scores.append(
                    {
                        "effect": "vibration",
                        "variant": "band-limited",
                        "delta_bic": band.delta_bic(cur.n),
                        "gain": band.explained(sigma, fcs[0].rate_hz),
                        "k": BAND_PARAMS,
                    }
                )
        # one score per effect: the better variant (the other one is kept for the report)
        best_of: dict[str, dict] = {}
        for sc in scores:
            if sc["effect"] not in best_of or sc["delta_bic"] > best_of[sc["effect"]]["delta_bic"]:
                best_of[sc["effect"]] = sc
        for sc in scores:
            if sc is not best_of[sc["effect"]]:
                best_of[sc["effect"]]["other_variant"] = {"variant": sc["variant"], "delta_bic": sc["delta_bic"]}
        scores = list(best_of.values())
        scores.sort(key=lambda d: -d["delta_bic"])
        step = {"model": list(selected), "rss_weighted": cur.rss, "n": cur.n, "candidates": scores}
        steps.append(step)
        added = len(selected) - len([b for b in base if not effects[b].stochastic])
        if not scores or added >= max_added:
            break
        best = scores[0]
        if best["delta_bic"] < bic_threshold or best["gain"] < min_gain:
            break
        step["added"] = best["effect"]
        if best.get("variant") == "band-limited":
            step["added_variant"] = "band-limited"
            # from now on a stochastic term of the noise model: no columns (refitted at the end)
            effects["vibration"].params.update(
                frequency_hz=np.asarray(band.frequency_hz),
                bandwidth_hz=np.asarray(band.bandwidth_hz),
                amplitude=band.amplitude,
            )
        selected.append(best["effect"])
    final = design.fit(selected)
    if band_vibration and "vibration" in selected and effects["vibration"].stochastic:
        # backward check: the band was scored on the residual of its step; once the effects added
        # after it are fitted, it must still clear the threshold (colour that a deterministic
        # effect explains is not vibration)
        v = effects["vibration"].params
        resid = residuals_after(design, final, selected)
        band = fit_band(
            resid, fcs[0].rate_hz, row_masks(fcs), starts=[(float(v["frequency_hz"]), float(v["bandwidth_hz"]))]
        )
        dbic = band.delta_bic(final.n) if band is not None else -np.inf
        gain = band.explained(sigma, fcs[0].rate_hz) if band is not None else 0.0
        if dbic < bic_threshold or gain < min_gain:
            selected.remove("vibration")
            v["bandwidth_hz"] = np.asarray(0.0)
            steps.append({"model": list(selected), "removed": "vibration", "delta_bic_on_final_residual": float(dbic)})
            design = Design(fcs, {n: effects[n] for n in selected}, sigma)
            final = design.fit(selected)
    sel = Selection(
        base=base,
        selected=selected,
        named=[n for n in selected if n not in base],
        steps=steps,
        not_identifiable=sorted(not_ident),
        saturation=saturation,
        effects=effects,
        sigma=sigma,
        design=design,
        result=final,
    )
    _fill_params(sel, fcs)
    return sel


def _fill_params(sel: Selection, fcs: list[FitContext]) -> None:
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
    wn = EFFECTS["white_noise"]()
    sel.params["white_noise"], sel.se["white_noise"] = wn.estimate(fcs, resid_all)
    if sel.band_vibration:
        # the band refitted on the final residual, with standard errors; the white-noise level is
        # its floor (the first-difference estimate above would include the band's power)
        v = sel.effects["vibration"].params  # the selection step's fit: the start
        start = [(float(v["frequency_hz"]), float(v["bandwidth_hz"]))]
        band = fit_band(resid_all, fcs[0].rate_hz, row_masks(fcs), with_errors=True, starts=start)
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
        p, s = sel.effects["bias_random_walk"].estimate(fcs, resid_no_rw)
        sel.params["bias_random_walk"], sel.se["bias_random_walk"] = p, s
    if "quantization" in sel.effects and "quantization" not in sel.base:
        q, frac = Quantization.lattice_step(np.concatenate([fc.gyro for fc in fcs]))
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


def per_sequence_refit(
    sel: Selection, fc: FitContext, names: list[str] | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Deterministic prediction of the residual on a sequence not used for fitting: the sensor's
    constants stay as fitted; per-sequence nuisances (bias, random-walk knots, vibration phase)
    are refitted on this sequence. Returns (prediction (N, 3), per-sequence coefficients)."""
    names = sel.selected if names is None else names
    design, res = sel.design, sel.result
    glob = [n for n in names if not sel.effects[n].per_sequence and not sel.effects[n].stochastic]
    local = [n for n in names if sel.effects[n].per_sequence and not sel.effects[n].stochastic]
    pred = np.zeros((len(fc.t), 3))
    for n in glob:
        c = sel.effects[n].columns(fc)
        pred += np.einsum("nik,k->ni", c, res.coef[design.cols[n]])
    per_seq = {}
    if local:
        cols = [sel.effects[n].columns(fc) for n in local]
        X = np.concatenate(cols, 2) / sel.sigma[None, :, None]
        X = X.reshape(-1, X.shape[2])
        r = ((fc.residual - pred) / sel.sigma).reshape(-1)
        if "saturation" in sel.params:
            set_saturation_mask([fc], float(sel.params["saturation"]["limit"]), sel.sigma)
        m = row_mask(fc).reshape(-1)
        coef, *_ = np.linalg.lstsq(X[m], r[m], rcond=None)
        pred += (X @ coef).reshape(-1, 3) * sel.sigma
        k0 = 0
        for n, c in zip(local, cols, strict=True):
            per_seq[n] = coef[k0 : k0 + c.shape[2]]
            k0 += c.shape[2]
    if "saturation" in sel.params:  # the output cannot exceed the range
        lim = float(sel.params["saturation"]["limit"])
        pred = np.clip(fc.omega + pred, -lim, lim) - fc.omega
    return pred, per_seq
