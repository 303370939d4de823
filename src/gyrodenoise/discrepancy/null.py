"""Calibrated decisions: the null distribution of every candidate's delta BIC (parametric bootstrap).

The fixed BIC threshold assumes a residual of white Gaussian noise; a reconstructed true rate, a
low-passed sensor or a spline's end effects make it coloured, and a BIC gain of 10 then means
little. Here the fitted base model is re-simulated along the measured sequences: gyro = true rate +
the base model's prediction (per-sequence bias) + its fitted noise + a fresh draw of the
reconstruction error (`reconstruction.draw_error`, the ground-truth noise re-drawn and passed
through the same spline, with the fitted level), and every candidate is scored on it exactly as on
the data (`rank.score_step`: the same preparation of nonlinear parameters, the same band, the same
weights). Over `draws` such worlds, the 95th percentile of each candidate's delta BIC is its
threshold (never below the nominal BIC threshold), and the share of null draws that reach the
observed value is its p-value-like rank.

Cost is kept low: only the first selection step is re-scored (the candidates against the base
model), the regressors are those of the measured sequences (the reconstruction error enters the
residual, where it matters), and the draws use common random numbers: draw d of sequence s is
seeded by (seed, d, s) whatever the candidate, so the candidates are compared on the same worlds.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from gyrodenoise.discrepancy.fitted_model import per_sequence_refit
from gyrodenoise.discrepancy.rank import Selection, score_step
from gyrodenoise.discrepancy.reconstruction import draw_error
from gyrodenoise.sim.context import FitContext, SignalContext
from gyrodenoise.sim.effects import EFFECTS, WhiteNoise

QUANTILE = 0.95
DRAWS = 30


@dataclass
class NullDistribution:
    """Delta BIC of each candidate on `draws` re-simulations of the fitted base model."""

    draws: int
    seed: int
    delta_bic: dict[str, np.ndarray] = field(default_factory=dict)  # candidate -> (draws,), -inf: not scored

    def threshold(self, name: str, floor: float, q: float = QUANTILE) -> float:
        """The q quantile of the candidate's null delta BIC (at least `floor`)."""
        v = self.delta_bic.get(name)
        if v is None or not np.isfinite(v).any():
            return floor
        return float(max(np.quantile(v, q, method="higher"), floor))

    def thresholds(self, floor: float, q: float = QUANTILE) -> dict[str, float]:
        return {n: self.threshold(n, floor, q) for n in self.delta_bic}

    def p_value(self, name: str, observed: float) -> float:
        """(1 + #null draws with delta BIC >= observed) / (1 + draws): the observed value's rank."""
        v = self.delta_bic.get(name, np.zeros(0))
        return float((1 + np.sum(v >= observed)) / (1 + self.draws))

    def summary(self, floor: float) -> dict:
        out = {}
        for n, v in self.delta_bic.items():
            fin = v[np.isfinite(v)]
            out[n] = {
                "threshold": self.threshold(n, floor),
                "median": float(np.median(fin)) if len(fin) else None,
                "q95": float(np.quantile(fin, QUANTILE, method="higher")) if len(fin) else None,
                "max": float(fin.max()) if len(fin) else None,
                "scored_draws": int(len(fin)),
            }
        return out


def null_worlds(sel_base: Selection, fcs: list[FitContext], draw: int, seed: int) -> list[FitContext]:
    """The measured sequences re-simulated under the fitted base model (draw `draw`)."""
    out = []
    dens = sel_base.params.get("white_noise", {}).get("density", np.zeros(3))
    for s, fc in enumerate(fcs):
        rng = np.random.default_rng([seed, draw, s])
        pred = per_sequence_refit(sel_base, fc)
        sig = SignalContext(t=fc.t, omega=fc.omega, alpha=fc.alpha, f=fc.f, rate_hz=fc.rate_hz)
        y = WhiteNoise(density=dens).apply(sig, fc.omega + pred, rng)
        err = draw_error(fc, rng)
        if err is not None:
            y = y + err
        out.append(replace(fc, gyro=y, extra=dict(fc.extra)))
    return out


def null_distribution(
    sel_base: Selection,
    fcs: list[FitContext],
    candidates: list[str] | None = None,
    draws: int = DRAWS,
    seed: int = 0,
    rw_knot_spacing_s: float = 10.0,
) -> NullDistribution:
    """Score every candidate against the base model on `draws` null re-simulations of `fcs`
    (the fit sequences of `sel_base`, bands and weights already set)."""
    base = list(sel_base.base)
    if candidates is None:
        candidates = [n for n in EFFECTS if n not in base]
    candidates = [c for c in candidates if c not in base]
    scorable = [c for c in candidates if not EFFECTS[c]().stochastic or c == "sensor_bandwidth"]
    band_vibration = "white_noise" in base + candidates and "vibration" in scorable
    out = NullDistribution(draws, seed, {c: np.full(draws, -np.inf) for c in scorable})
    for d in range(draws):
        worlds = null_worlds(sel_base, fcs, d, seed)
        effects = {n: EFFECTS[n]() for n in base + scorable}
        if "bias_random_walk" in effects:
            effects["bias_random_walk"].knot_spacing_s = rw_knot_spacing_s
        selected = [b for b in base if not effects[b].stochastic]
        st = score_step(worlds, effects, selected, scorable, sel_base.sigma, band_vibration)
        for sc in st.scores:
            out.delta_bic[sc["effect"]][d] = sc["delta_bic"]
    return out
