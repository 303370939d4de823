"""Identifiability as a number: the delta BIC an effect of a stated magnitude would earn on this
motion, from the Fisher information of its regressors given the effects already in the model.

For a regression effect with k columns X_c, fitted beside the columns X_o of the current model, the
information on its coefficients is the Schur complement S = X_c'X_c - X_c'X_o (X_o'X_o)^+ X_o'X_c
(weighted rows, so in units of the noise). With true coefficients c the likelihood-ratio statistic
n log(RSS_0 / RSS_1) is noncentral chi-square with k degrees of freedom and noncentrality
lambda = c'Sc / s2, so

    E[delta BIC] = lambda + k - (k + nonlinear parameters) log n.

Stated for every coefficient at +-m with random signs (E[lambda] = m^2 tr(S) / s2) and for the
least identifiable coefficient alone at m (lambda = m^2 / SE_max^2); `min_magnitude` is the m at
which the first reaches the decision threshold. The magnitude m is the effect's `REFERENCE`
(datasheet units in the report). An effect is identifiable at m when its expected delta BIC clears
the threshold the selection applies to it; it is tried at all (`testable`) when it would be
identifiable at the largest plausible magnitude (`PRIOR`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from gyrodenoise.discrepancy.design import Design, fit_rows
from gyrodenoise.sim.effects import SensorBandwidth


@dataclass
class Identifiability:
    effect: str
    reference: float  # SI, per coefficient
    reference_datasheet: float
    unit: str
    k: int  # coefficients (all sequences)
    n: int  # rows of the fit
    threshold: float
    expected_delta_bic: float  # every coefficient at +-reference, random signs
    expected_delta_bic_weakest: float  # only the least identifiable coefficient at reference
    min_magnitude: float  # SI: expected delta BIC (all coefficients) reaches the threshold
    min_magnitude_datasheet: float
    se_min: float  # SI: standard errors of the coefficients, best and worst
    se_max: float
    identifiable: bool  # at the reference magnitude
    expected_delta_bic_at_prior: float  # every coefficient at the largest plausible magnitude (PRIOR)
    testable: bool  # identifiable at the largest plausible magnitude: worth trying at all

    def as_dict(self) -> dict:
        return {k: (float(v) if isinstance(v, np.floating) else v) for k, v in asdict(self).items()}

    def sentence(self) -> str:
        verdict = "identifiable" if self.identifiable else "not identifiable"
        return (
            f"{self.effect}: {verdict} at {self.reference_datasheet:.3g} {self.unit} (expected delta BIC "
            f"{self.expected_delta_bic:+.1f}, least identifiable coefficient alone "
            f"{self.expected_delta_bic_weakest:+.1f}, "
            f"threshold {self.threshold:.1f}; smallest magnitude expected to clear it "
            f"{self.min_magnitude_datasheet:.3g} {self.unit})"
        )


def schur_information(design: Design, given: list[str], name: str) -> np.ndarray:
    """Information on `name`'s coefficients (weighted units) left after fitting `given`."""
    o, c = design.indices(given), design.cols[name].ravel()
    S = design.G[np.ix_(c, c)]
    if len(o):
        Goo = design.G[np.ix_(o, o)]
        Goc = design.G[np.ix_(o, c)]
        S = S - Goc.T @ np.linalg.pinv(Goo, rcond=1e-12, hermitian=True) @ Goc
    return (S + S.T) / 2


def identifiability(
    design: Design, given: list[str], name: str, s2: float, threshold: float, nonlinear: int = 0
) -> Identifiability | None:
    """Expected delta BIC of `name` at its REFERENCE magnitude on this design (None: the effect
    states no reference, e.g. per-sequence random-walk knots)."""
    e = design.effects[name]
    ref = type(e).REFERENCE
    if ref is None or e.stochastic:
        return None
    S = schur_information(design, given, name)
    k, n = S.shape[0], design.n
    scale = max(float(np.trace(design.G[np.ix_(design.cols[name].ravel(), design.cols[name].ravel())])) / k, 1e-300)
    w, V = np.linalg.eigh(S)
    ok = w > 1e-9 * scale  # directions the data separate from the model's other columns
    inv_w = np.where(ok, 1.0 / np.where(ok, w, 1.0), np.inf)
    # a coefficient touched by a direction the data cannot see has no finite standard error
    with np.errstate(invalid="ignore"):
        var = np.where(V**2 > 1e-20, V**2 * inv_w[None], 0.0).sum(1)
    se = np.sqrt(s2 * var)
    pen = (k + nonlinear) * np.log(n)
    trace = float(np.clip(w, 0, None)[ok].sum())
    s2 = max(float(s2), 1e-300)
    expected = ref**2 * trace / s2 + k - pen
    with np.errstate(divide="ignore", over="ignore"):
        lam_weakest = np.float64(ref) ** 2 / np.float64(se.max()) ** 2 if np.isfinite(se.max()) else 0.0
    weakest = float(lam_weakest) + k - pen
    need = threshold + pen - k
    m_min = float(np.sqrt(max(need, 0.0) * s2 / trace)) if trace > 0 else np.inf
    unit, factor = _datasheet_unit(e)
    big = float(e.PRIOR[1]) / (np.sqrt(2) if e.name == "vibration" else 1.0)
    at_prior = big**2 * trace / s2 + k - pen
    return Identifiability(
        effect=name,
        reference=float(ref),
        reference_datasheet=float(ref * factor),
        unit=unit,
        k=int(k),
        n=int(n),
        threshold=float(threshold),
        expected_delta_bic=float(expected),
        expected_delta_bic_weakest=float(weakest),
        min_magnitude=m_min,
        min_magnitude_datasheet=float(m_min * factor),
        se_min=float(se.min()),
        se_max=float(se.max()),
        identifiable=bool(expected >= threshold),
        expected_delta_bic_at_prior=float(at_prior),
        testable=bool(at_prior >= threshold and trace > 0),
    )


def _datasheet_unit(e) -> tuple[str, float]:
    """Unit and factor of the effect's main parameter (the first in DATASHEET that is a
    coefficient: for vibration the amplitude, of which a sin/cos coefficient is 1/sqrt(2))."""
    if e.name == "vibration":
        unit, factor = e.DATASHEET["amplitude"]
        return unit, factor * np.sqrt(2)
    key = next(iter(e.DEFAULTS))
    return e.DATASHEET.get(key, ("SI", 1.0))


@dataclass
class DelayOrLowpass:
    """Whether a time offset and a sensor low-pass of the same delay can be told apart on this motion."""

    delay_s: float  # the fitted delay (time offset, IMU stamps late)
    corner_hz: float  # the first-order low-pass with that delay: 1 / (2 pi delay)
    expected_delta_bic: float  # between the two one-parameter explanations, if the low-pass were true
    threshold: float
    separable: bool
    band_hz: float | None  # upper edge of the compared band

    def as_dict(self) -> dict:
        return {k: (float(v) if isinstance(v, np.floating) else v) for k, v in asdict(self).items()}

    def sentence(self) -> str:
        if self.separable:
            return (
                f"time offset and sensor bandwidth separable here (expected delta BIC {self.expected_delta_bic:.1f} "
                f">= {self.threshold:.1f})"
            )
        return (
            f"time offset or sensor bandwidth: not separable in this band (0-{self.band_hz or float('nan'):.1f} Hz; "
            f"expected delta BIC between them {self.expected_delta_bic:.2f} < {self.threshold:.1f}): equivalent "
            f"delay {1e3 * self.delay_s:.2f} ms = first-order corner {self.corner_hz:.1f} Hz"
        )


def delay_or_lowpass(design: Design, given: list[str], s2: float, delay_s: float, threshold: float) -> DelayOrLowpass:
    """Expected delta BIC between a time offset and a first-order sensor low-pass of corner
    1 / (2 pi delay) (`SensorBandwidth`, the same delay at low frequencies): the motion seen through
    the low-pass minus the motion, less its best fit by the time-offset regressor and the other
    columns `given`, in the fit's weighted rows, over s2. At low frequencies the low-pass is a
    delay plus a magnitude droop of (f / corner)^2 / 2; what is left is that droop (and the phase's
    cubic term), so this is the noncentrality of the low-pass against the delay on this motion and
    band: both have one parameter, so it is their expected delta BIC. A second-order Bessel of the
    same delay droops by a third of it: separable for a first-order low-pass is necessary for it."""
    corner = 1.0 / (2 * np.pi * max(delay_s, 1e-9))
    names = [n for n in given if n != "time_offset"] + ["time_offset"]
    rows_d, rows_o = [], []
    for s, fc in enumerate(design.fcs):
        X, _ = design.local_columns(s, names)
        lp = SensorBandwidth.filter_rate(fc.omega, corner, fc.rate_hz) - fc.omega
        d = (lp / design.sigma[None, :]).reshape(-1)
        Xr, dr = fit_rows(fc, X, d)
        rows_o.append(Xr)
        rows_d.append(dr)
    X, d = np.concatenate(rows_o), np.concatenate(rows_d)
    coef, *_ = np.linalg.lstsq(X, d, rcond=None)
    lam = float(np.sum((d - X @ coef) ** 2) / max(s2, 1e-300))
    edges = [fc.extra.get("band_hz") for fc in design.fcs]
    band = min(edges) if all(e is not None for e in edges) else None
    return DelayOrLowpass(float(delay_s), float(corner), lam, float(threshold), bool(lam >= threshold), band)


def random_walk_identifiability(
    fcs: list,
    sigma: np.ndarray,
    given: dict,
    s2: float,
    density: float | np.ndarray,
    threshold: float,
    nonlinear: int = 1,
) -> dict:
    """Expected delta BIC of a rate random walk of `density` (rad/s/sqrt(s), per axis or one value)
    on these sequences, as the selection detects it: piecewise-linear bias columns on knots
    (`BiasRandomWalk.columns`), fitted beside the effects `given` (name -> Effect, e.g. the per-sequence
    bias). The knot values of a walk are random, b(t_j) - b(0) with covariance K^2 min(t_i, t_j), so
    E[lambda] = tr(S Sigma) / s2 (S the Schur information of the knot columns, `schur_information`);
    E[delta BIC] = E[lambda] + k - (k + nonlinear) log n. The best of the knot spacings the selection
    tries (`BiasRandomWalk.SPACINGS`) is reported. An approximation: what the walk does between knots
    is not counted (the knots cannot fit it either)."""
    from gyrodenoise.sim.effects import BiasRandomWalk

    K2 = np.broadcast_to(np.asarray(density, dtype=float) ** 2, (3,))
    best: dict | None = None
    for h in BiasRandomWalk.SPACINGS:
        rw = BiasRandomWalk()
        rw.knot_spacing_s = h
        design = Design(fcs, {**given, "bias_random_walk": rw}, sigma)
        S = schur_information(design, list(given), "bias_random_walk")
        cols = design.cols["bias_random_walk"]
        p = cols.size
        Sigma = np.zeros((p, p))
        k = 0
        for s, fc in enumerate(fcs):
            t = fc.t - fc.t[0]
            nk = rw.n_knots(fc)
            knots = np.linspace(0.0, t[-1], nk + 1)[1:]
            base = s * cols.shape[1]
            for a in range(3):
                i = base + a * nk + np.arange(nk)
                Sigma[np.ix_(i, i)] = K2[a] * np.minimum(knots[:, None], knots[None, :])
            k += 3 * nk
        lam = float(np.trace(S @ Sigma)) / max(float(s2), 1e-300)
        expected = float(lam + k - (k + nonlinear) * np.log(design.n))
        if best is None or expected > best["expected_delta_bic"]:
            best = {"knot_spacing_s": h, "k": k, "n": design.n, "noncentrality": lam, "expected_delta_bic": expected}
    assert best is not None
    unit, factor = BiasRandomWalk.DATASHEET["density"]
    return best | {
        "density_datasheet": float(np.max(np.sqrt(K2)) * factor),
        "unit": unit,
        "threshold": float(threshold),
        "detectable": bool(best["expected_delta_bic"] >= threshold),
    }
