"""The regression machinery of the discrepancy workflow: which rows a fit uses, the weighted Gram
matrix of all candidate columns, and least-squares fits of any subset of effects.

All regression effects are linear in their coefficients once their nonlinear parameter (a
frequency, a time constant, a range) is set by `Effect.prepare`. The weighted normal equations
(Gram matrix) of all columns are built once per selection step; any subset is then a small solve.
Rows are the three axes of every sample, weighted by 1/sigma_axis (noise level per axis); where
the reconstructed true rate is trusted only in a band (`reconstruction`), the rows are the
Fourier coefficients in that band (`fit_rows`). A named sensor low-pass changes what the sensor
sees of the motion (`sensor_view`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property, partial

import numpy as np
from scipy.linalg import orth

from gyrodenoise.discrepancy.reconstruction import (
    band_rows,
    edge_positions,
    edge_rows,
    estimate_band,
    floor_through_corner,
    row_frequencies,
    sensor_floor,
)
from gyrodenoise.discrepancy.spectral import F_MIN_HZ, Nuisance, fit_nuisance, masked_samples, spectra
from gyrodenoise.discrepancy.time_only_rows import cached_rows, rows_key
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import Effect, SensorBandwidth


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


def band_edges(fcs: list[FitContext]) -> list[float | None]:
    """Upper edge of each sequence's trusted band (None: the whole spectrum)."""
    return [fc.extra.get("band_hz") for fc in fcs]


class NoTrustedBand(ValueError):
    """A sequence whose reconstructed true rate is trusted nowhere above the spectral rows' lowest frequency."""


def set_bands(fcs: list[FitContext], residuals: list[np.ndarray]) -> None:
    """Estimate each sequence's trusted band from its base-model residual (once; kept in extra). Samples outside
    `row_mask` (near a saturation limit: the truth beyond the range, the output clipped) are left out of its
    spectrum, as `spectral.spectra` leaves them out: clipped peaks would raise the whole floor."""
    for fc, r in zip(fcs, residuals, strict=True):
        if "band_hz" not in fc.extra:
            x, scale = masked_samples(r, fc.extra.get("row_mask"))
            b = estimate_band(fc, x * np.sqrt(scale))
            if b.f_max_hz <= F_MIN_HZ:  # the spectral rows start there: a fit would have no rows
                raise NoTrustedBand(
                    f"{fc.name}: the ground truth's rate is trusted only up to {b.f_max_hz:g} Hz (limited by "
                    f"{b.limited_by}; the truth spline's knots {b.knot_spacing_s:g} s apart), and the comparison "
                    f"starts at {F_MIN_HZ:g} Hz: nothing to compare. Give a smaller --knot-spacing (the default, "
                    "0.05 s, suits a truth at 100 Hz or more) if the truth's rate allows it; a truth too slow or too "
                    "smooth to follow the gyro above 1 Hz cannot judge its errors"
                )
            fc.extra["band"], fc.extra["band_hz"] = b, b.f_max_hz


# what `set_reconstruction_model` keeps in a context's extra
RECONSTRUCTION_KEYS = ("band", "band_hz", "row_weights", "nuisance_level", "sensor_floor")


def without_reconstruction(extra: dict) -> dict:
    """A context's extra without the reconstruction model (for a 'residual' that is no gyro - truth)."""
    return {k: v for k, v in extra.items() if k not in RECONSTRUCTION_KEYS}


def fit_rows(fc: FitContext, X: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows a fit uses: weighted columns X (3N, k) and residual r (3N,) of sequence `fc`, samples
    outside `row_mask` left out. Where the reconstructed true rate is trusted only in a band
    (`fc.extra['band_hz']`) or carries an error of its own (`fc.extra['row_weights']`, see
    `reconstruction`), the rows are the Fourier coefficients in the band, each weighted by
    1 / sqrt(noise + reconstruction-error PSD) relative to the noise floor: generalised least squares."""
    m = row_mask(fc).reshape(-1)
    f_max = fc.extra.get("band_hz")
    w = fc.extra.get("row_weights")
    if w is None and (f_max is None or f_max >= fc.rate_hz / 2):
        return X[m], r[m]
    n, k = len(fc.t), X.shape[1]
    Z = np.where(m[:, None], X, 0.0).reshape(n, 3 * k)
    # most columns act on one axis (`effects._axis_columns`, the random walk's hats): two of every three per-axis
    # columns are zero, and so are their rows; only the others are transformed (the FFT is most of a fit's time)
    live = np.flatnonzero(Z.any(axis=0))
    Xb = np.zeros((len(row_frequencies(n, fc.rate_hz, f_max)), 3 * k))
    Xb[:, live] = band_rows(Z[:, live], fc.rate_hz, f_max, force=True)
    rb = band_rows(np.where(m, r, 0.0).reshape(n, 3), fc.rate_hz, f_max, force=True)
    if w is not None:
        Xb = (Xb.reshape(-1, 3, k) * w[:, :, None]).reshape(-1, 3 * k)
        rb = rb * w
        Xb, rb = without_edges(fc, Xb.reshape(-1, 3, k), rb, w)
    return Xb.reshape(-1, k), rb.reshape(-1)


def spectral_rows(fc: FitContext, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A weighted residual r (N, 3) of sequence `fc` as the Fourier rows (M, 3) a fit weighs (`fit_rows`), with
    each row's frequency (M,). A fit on time samples gets the whole spectrum's rows (left-out samples zeroed):
    the same inner products (Parseval), but rows that are nearly uncorrelated even where r is not white."""
    n, f_max = len(fc.t), fc.extra.get("band_hz")
    if fc.extra.get("row_weights") is None and (f_max is None or f_max >= fc.rate_hz / 2):
        x = np.where(row_mask(fc), r, 0.0)
        return band_rows(x, fc.rate_hz, None, force=True), row_frequencies(n, fc.rate_hz, None)
    _, rb = fit_rows(fc, np.zeros((3 * n, 1)), r.reshape(-1))  # one empty column: the shapes need k >= 1
    return rb.reshape(-1, 3), row_frequencies(n, fc.rate_hz, f_max)


def without_edges(fc: FitContext, Xb: np.ndarray, rb: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted Fourier rows Xb (M, 3, k) and rb (M, 3) of sequence `fc` with the reconstruction
    error's edge impulses projected out, per axis (`reconstruction.edge_rows`: the angle error's
    jumps at the record's ends and at every gap of left-out samples; nuisance columns of every
    model, so they cost every model the same)."""
    n, m = len(fc.t), row_mask(fc)
    Xb, rb = Xb.copy(), rb.copy()
    for a in range(3):
        U = edge_rows(n, fc.rate_hz, fc.extra.get("band_hz"), edge_positions(m[:, a])) * w[:, a, None]
        Q = orth(U, rcond=1e-9)
        Xb[:, a, :] -= Q @ (Q.T @ Xb[:, a, :])
        rb[:, a] -= Q @ (Q.T @ rb[:, a])
    return Xb, rb


def n_rows(fc: FitContext) -> int:
    """How many rows a fit of sequence `fc` uses (`fit_rows`)."""
    f_max, w = fc.extra.get("band_hz"), fc.extra.get("row_weights")
    if w is None and (f_max is None or f_max >= fc.rate_hz / 2):
        return int(row_mask(fc).sum())
    return 3 * len(row_frequencies(len(fc.t), fc.rate_hz, f_max))


def nuisance_of(fcs: list[FitContext], corner_hz: float | None = None) -> Nuisance | None:
    """The reconstruction error of `fcs` as a spectral nuisance term (None: exact ground truth).
    `corner_hz`: a named sensor low-pass shapes the floor; the sensor floor, fixed in the nuisance fits,
    is then read again through that shape (`sensor_floor`): the level at 0 Hz that a spectrum shaped by
    the same corner is compared with."""
    psd = []
    for fc in fcs:
        b = fc.extra.get("band")
        psd.append(None if b is None or b.exact else b.error_psd)
    if all(p is None for p in psd):
        return None
    floor, floor_at = fcs[0].extra.get("sensor_floor"), None
    if floor is not None:
        bands = [fc.extra["band"] for fc in fcs if fc.extra.get("band") is not None]
        if corner_hz is not None and np.isfinite(corner_hz):
            floor = sensor_floor(bands, corner_hz=corner_hz)
        floor_at = partial(floor_through_corner, bands)
    return Nuisance(psd, floor, floor_at)


def set_row_weights(fcs: list[FitContext], floor: np.ndarray, kappa: np.ndarray) -> None:
    """GLS weights of each sequence's Fourier rows: sqrt(c / (c + kappa E(f))) per axis, c the
    sensor's floor and kappa E the fitted reconstruction error (`spectral.fit_nuisance`)."""
    for fc in fcs:
        b = fc.extra.get("band")
        if b is None or b.exact:
            continue
        f = row_frequencies(len(fc.t), fc.rate_hz, fc.extra.get("band_hz"))
        fc.extra["row_weights"] = np.sqrt(floor / (floor + kappa * b.error_psd(f)))
        fc.extra["nuisance_level"] = kappa


def set_reconstruction_model(fcs: list[FitContext], residuals: list[np.ndarray]) -> np.ndarray | None:
    """Bands (`set_bands`), then the sensor floor and the reconstruction error's level fitted on the
    base residuals, and the rows' GLS weights. Returns the per-axis noise std the floor implies at
    the IMU rate (the rows' weights), or None when nothing is band-limited or carries an error."""
    set_bands(fcs, residuals)
    nu = nuisance_of(fcs)
    if nu is None:
        return band_noise_weights(fcs, residuals) if band_limited(fcs) else None
    # the sensor's floor where the reconstruction error does not reach (inside the band it may
    # swamp it), then the error's level beside it in the band
    floor = sensor_floor([fc.extra["band"] for fc in fcs])
    for fc in fcs:
        fc.extra["sensor_floor"] = floor
    nu.floor = floor
    fit = fit_nuisance(residuals, fcs[0].rate_hz, row_masks(fcs), band_edges(fcs), nu)
    if fit is None:
        return band_noise_weights(fcs, residuals)
    floor, kappa = fit
    set_row_weights(fcs, floor, kappa)
    return np.maximum(np.sqrt(floor * fcs[0].rate_hz / 2), 1e-12)


def noise_weights(residuals: list[np.ndarray], masks: list[np.ndarray | None] | None = None) -> np.ndarray:
    """Per-axis white-noise std from first differences (insensitive to slow effects); with `masks`, only the
    differences of two kept samples (a clipped stretch differences the true rate's changes, not the noise)."""
    out = np.zeros(3)
    for a in range(3):
        d = []
        for s, r in enumerate(residuals):
            m = None if masks is None or masks[s] is None else masks[s][:, a]
            da = np.diff(r[:, a])
            d.append(da if m is None else da[m[1:] & m[:-1]])
        d = np.concatenate(d)
        out[a] = d.std() / np.sqrt(2) if len(d) > 1 else 0.0
    return np.maximum(out, 1e-12)


class Design:
    """Weighted Gram matrix of every column of `effects` over the sequences `fcs`."""

    def __init__(self, fcs: list[FitContext], effects: dict[str, Effect], sigma: np.ndarray) -> None:
        self.fcs, self.effects, self.sigma = fcs, effects, sigma
        self.cols: dict[str, np.ndarray] = {}  # effect -> global column indices ((S, k) if per sequence)
        p = 0
        # each effect's columns of each sequence, built once here (building them is much of a design's time) and
        # dropped after: a search keeps many designs
        built = [{name: e.columns(fc) for name, e in effects.items() if not e.stochastic} for fc in fcs]
        self.k = {name: built[0][name].shape[2] if not e.stochastic else 0 for name, e in effects.items()}
        for name, e in effects.items():
            k = self.k[name]
            if e.per_sequence and not e.stochastic:
                # column counts may differ per sequence (random-walk knots): take the largest
                k = max(b[name].shape[2] for b in built)
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
        for s in range(len(fcs)):
            X, idx, r = self._fit_rows(s, built[s])
            built[s] = {}
            self.G[np.ix_(idx, idx)] += X.T @ X
            self.b[idx] += X.T @ r
            self.rr += float(r @ r)
            self.n += len(r)

    def _fit_rows(self, s: int, built: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`fit_rows` of every column of sequence s, with their global indices and the residual's rows. The rows of
        columns that depend on the sample times alone come from `time_only_rows` (the same in every design of a
        search); the others are built here, in one transform. Each shared block is transformed on its own, so a
        design served shared rows is a fresh design to the bit, and one transform of all columns to rounding."""
        fc = self.fcs[s]
        names = [n for n, e in self.effects.items() if not e.stochastic]
        resid = (fc.residual / self.sigma).reshape(-1)
        width = {n: self.cols[n].shape[-1] for n in names}
        keys = {n: rows_key(self.effects[n], fc, self.sigma, width[n]) for n in names}
        moving = [n for n in names if keys[n] is None]
        X, _ = self.local_columns(s, moving, built=built)
        Xr, r = fit_rows(fc, X if X.shape[1] else np.zeros((len(resid), 1)), resid)  # k >= 1 for the shapes
        blocks, start = {}, 0
        for n in moving:
            blocks[n], start = Xr[:, start : start + width[n]], start + width[n]
        for n in names:
            if keys[n] is not None:

                def rows_of(n: str = n) -> np.ndarray:
                    return fit_rows(fc, self.local_columns(s, [n], built=built)[0], resid)[0]

                blocks[n] = cached_rows(*keys[n], rows_of)
        if not names:
            return np.zeros((len(r), 0)), np.zeros(0, dtype=int), r
        X = np.concatenate([blocks[n] for n in names], 1)
        idx = np.concatenate([self.cols[n][s] if self.effects[n].per_sequence else self.cols[n] for n in names])
        return X, idx, r

    def local_columns(
        self, s: int, names: list[str], fc: FitContext | None = None, built: dict[str, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Weighted columns (3N, k) of sequence s for `names`, with their global indices (`built`: the effects'
        columns of this sequence where already built)."""
        fc = fc or self.fcs[s]
        blocks, idx = [], []
        for name in names:
            e = self.effects[name]
            if e.stochastic:
                continue
            c = (built[name] if built is not None else e.columns(fc)) / self.sigma[None, :, None]
            gi = self.cols[name][s] if e.per_sequence else self.cols[name]
            if c.shape[2] < len(gi):  # fewer knots in this sequence: pad with empty columns
                c = np.concatenate([c, np.zeros((*c.shape[:2], len(gi) - c.shape[2]))], 2)
            blocks.append(c.reshape(-1, c.shape[2]))
            idx.append(gi)
        if not blocks:
            return np.zeros((3 * len(fc.t), 0)), np.zeros(0, dtype=int)
        return np.concatenate(blocks, 1), np.concatenate(idx)

    def indices(self, names: list[str]) -> np.ndarray:
        out = [self.cols[n].ravel() for n in names if n in self.effects and not self.effects[n].stochastic]
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


def residuals_after(design: Design, res: FitResult, names: list[str], fcs: list[FitContext] | None = None):
    """Per-sequence residuals (unweighted) after removing the fitted columns of `names`."""
    out = []
    for s, fc in enumerate(fcs or design.fcs):
        X, idx = design.local_columns(s, names, fc)
        pred = (X @ res.coef[idx]).reshape(-1, 3) * design.sigma
        out.append(fc.residual - pred)
    return out


def band_limited(fcs: list[FitContext]) -> bool:
    """Whether any sequence is compared in a band narrower than the whole spectrum."""
    return any(fc.extra.get("band_hz") is not None and fc.extra["band_hz"] < fc.rate_hz / 2 for fc in fcs)


def band_noise_weights(fcs: list[FitContext], residuals: list[np.ndarray]) -> np.ndarray:
    """Per-axis noise std from the trusted band's periodograms (median bin / ln 2: the level of a
    flat floor, robust to a few strong lines), as a per-sample std at the IMU rate."""
    sp = spectra(residuals, fcs[0].rate_hz, row_masks(fcs), band_edges(fcs))
    c = np.median(sp.I, axis=0) / np.log(2)
    return np.maximum(np.sqrt(c * fcs[0].rate_hz / 2), 1e-12)


def band_power(fc: FitContext, r: np.ndarray, sigma: np.ndarray) -> float:
    """Weighted power of residual r (N, 3) of sequence `fc` in its trusted band (mean square of
    the rows a fit would use)."""
    m = row_mask(fc)
    x = np.where(m, r / sigma, 0.0)
    f_max, w = fc.extra.get("band_hz"), fc.extra.get("row_weights")
    if w is None and (f_max is None or f_max >= fc.rate_hz / 2):
        return float(np.mean(x[m] ** 2))
    rows = band_rows(x, fc.rate_hz, f_max, force=True)
    if w is not None:
        rows = without_edges(fc, np.zeros((len(rows), 3, 0)), rows * w, w)[1]
    return float(np.mean(rows**2))


class _Filtered:
    """Kinematics seen through a low-pass, each field filtered when first read (the time offset's regressor reads
    the rate alone)."""

    def __init__(self, kin: object, lp: Callable[[np.ndarray], np.ndarray]) -> None:
        self._kin, self._lp = kin, lp

    @cached_property
    def omega(self) -> np.ndarray:
        return self._lp(self._kin.omega)

    @cached_property
    def alpha(self) -> np.ndarray:
        return self._lp(self._kin.alpha)

    @cached_property
    def specific_force(self) -> np.ndarray:
        return self._lp(self._kin.specific_force)


def sensor_view(fc: FitContext, corner_hz: float | None, rate_only: bool = False) -> FitContext:
    """The sequence as seen through a sensor low-pass of corner `corner_hz` (`SensorBandwidth`):
    the true rate, its derivative and the specific force filtered (every regressor responds to
    what reaches the sensor's output). None or inf: `fc` itself. `rate_only`: filter the true rate
    alone (enough for models whose columns use neither the derivative nor the specific force)."""
    if corner_hz is None or not np.isfinite(corner_hz):
        return fc
    if rate_only:
        return replace(fc, omega=SensorBandwidth.filter_rate(fc.omega, corner_hz, fc.rate_hz))

    def lp(x: np.ndarray) -> np.ndarray:
        return SensorBandwidth.filter_rate(x, corner_hz, fc.rate_hz)

    extra = dict(fc.extra)
    kin_at = fc.extra.get("kinematics_at")
    if kin_at is not None:

        def filtered(tt: np.ndarray) -> _Filtered:
            return _Filtered(kin_at(tt), lp)

        extra["kinematics_at"] = filtered
    return replace(fc, omega=lp(fc.omega), alpha=lp(fc.alpha), f=lp(fc.f), extra=extra)
