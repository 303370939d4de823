"""Allan variance of rate samples and the white-noise + rate-random-walk fit to it.

Numpy only: the simulator's effect library (`BiasRandomWalk.estimate`) and the discrepancy
workflow both use it."""

from __future__ import annotations

import numpy as np


def allan_taus(n: int, rate_hz: float, per_octave: int = 4) -> np.ndarray:
    m = np.unique(np.round(np.logspace(0, np.log10(max(n // 9, 2)), 1 + per_octave * 12)).astype(int))
    return m / rate_hz


def allan_variance(x: np.ndarray, rate_hz: float, taus: np.ndarray) -> np.ndarray:
    """Overlapping Allan variance of rate samples x (N, ...) at the cluster times `taus` (s)."""
    x = np.asarray(x, dtype=np.float64)
    theta = np.concatenate([np.zeros((1, *x.shape[1:])), np.cumsum(x, axis=0)]) / rate_hz
    out = np.full((len(taus), *x.shape[1:]), np.nan)
    n = len(x)
    for i, tau in enumerate(taus):
        m = int(round(tau * rate_hz))
        if m < 1 or 2 * m >= n:
            continue
        d = theta[2 * m :] - 2 * theta[m:-m] + theta[: -2 * m]
        out[i] = (d**2).mean(0) / (2 * tau**2)
    return out


def pooled_allan(residuals: list[np.ndarray], rate_hz: float, taus: np.ndarray) -> np.ndarray:
    """Allan deviation pooled over sequences (variances averaged with the sequence lengths)."""
    avs, ws = [], []
    for r in residuals:
        av = allan_variance(r, rate_hz, taus)
        avs.append(np.nan_to_num(av))
        ws.append(np.where(np.isnan(av), 0.0, len(r)))
    w = np.sum(ws, 0)
    return np.sqrt(np.where(w > 0, np.sum([a * b for a, b in zip(avs, ws, strict=True)], 0) / np.maximum(w, 1), np.nan))


def root_with_se(square: np.ndarray, square_se: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A level and its standard error from an estimate of its square (an Allan-variance term) and that estimate's:
    sqrt of the square clipped at 0, and the delta method's se / (2 level), or sqrt(se) where the level is 0."""
    level = np.sqrt(np.clip(square, 0.0, None))
    return level, np.where(level > 0, square_se / (2 * np.maximum(level, 1e-30)), np.sqrt(square_se))


def fit_allan_noise(
    residuals: list[np.ndarray], rate_hz: float, angle_noise: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit AVAR(tau) = N^2 / tau + K^2 tau / 3 per axis (white noise + rate random walk).

    Weighted least squares, each tau weighted by the inverse of its variance's uncertainty
    (relative std ~ sqrt(2 tau / T) for T s of data). `angle_noise`: also a 3 Q^2 / tau^2 term, the
    Allan variance of a rate that is the derivative of a noisy angle (quantisation noise in IEEE
    terms; here a true rate reconstructed from a noisy ground truth), which otherwise leaks into K.
    Returns (N^2, K^2, std of K^2), each (3,).
    """
    n_total = sum(len(r) for r in residuals)
    taus = allan_taus(min(len(r) for r in residuals), rate_hz, per_octave=2)
    av = pooled_allan(residuals, rate_hz, taus) ** 2
    T = n_total / rate_hz
    rel = np.sqrt(2 * taus / T + 1.0 / (n_total / 2))
    A = np.stack([1 / taus, taus / 3] + ([3 / taus**2] if angle_noise else []), 1)
    n2, k2, k2_se = np.zeros(3), np.zeros(3), np.zeros(3)
    for i in range(3):
        ok = np.isfinite(av[:, i])
        w = 1.0 / (rel[ok] * av[ok, i])
        Aw = A[ok] * w[:, None]
        coef, *_ = np.linalg.lstsq(Aw, av[ok, i] * w, rcond=None)
        cov = np.linalg.pinv(Aw.T @ Aw)
        n2[i], k2[i], k2_se[i] = coef[0], coef[1], np.sqrt(cov[1, 1])
    return n2, k2, k2_se
