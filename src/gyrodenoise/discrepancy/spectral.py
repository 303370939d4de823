"""Band-limited vibration: detection and fit in the frequency domain.

A band-limited vibration (`Vibration` with bandwidth_hz > 0) is stochastic: it changes the residual's
power spectral density, not its mean, so no regressor can fit it. It is compared with the current
model through the Whittle likelihood of the residual's periodograms, which is what the time-domain
Gaussian likelihood of the regression effects becomes for a stationary residual; the two are on
the same scale, so the band-limited variant enters the same greedy BIC selection and threshold.

PSD model, per axis a (one-sided, (rad/s)^2/Hz), shared by all sequences (sensor constants):

    without the band:  S_a(f) = c_a                                  (white-noise floor)
    with the band:     S_a(f) = c_a + P_a g(f; f0, bw)              (g: `Vibration.band_psd`)

P_a is the band's variance (A_a^2 / 2 in the library's amplitude). For given (f0, bw) the levels
(c_a, P_a >= 0) are found by Fisher scoring of the Whittle likelihood
    log L = -sum_j [log S(f_j) + I(f_j) / S(f_j)]
over the Fourier frequencies f_j of each sequence's (lightly tapered) periodogram I; (f0, bw) are
then found by maximising this profile likelihood (Nelder-Mead), started from the band where the
Welch PSD of the residual exceeds the floor by more than half of its peak excess.

- Only frequencies in [F_MIN_HZ, rate/2) enter: below 1 Hz the residual holds the slow effects
  (bias random walk, warm-up, errors of the ground-truth fit) that the regression effects model.
- bw >= BW_MIN_WELCH_BINS Welch bins (the main lobe of the Hann window): narrower excess is a line,
  which the sinusoidal variant (a regression) explains better.
- Delta BIC = 2 (log L_band - log L_floor) - 5 log n (f0, bw and one amplitude per axis), n the
  number of rows of the regression (3 per sample), as for the other candidates.
- Standard errors: Fisher information of the Whittle likelihood (amplitudes, floor) and the
  curvature of the profile likelihood (f0, bw); where the sequences disagree more than that (real
  vibration changes with the flight), the spread of the per-sequence estimates is used instead.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import optimize, signal

from gyrodenoise.sim.effects import SensorBandwidth, Vibration

F_MIN_HZ = 1.0
WELCH_NPERSEG = 512
BW_MIN_WELCH_BINS = 4.0  # Hann main lobe: a line is never wider than 4 Welch bins
TAPER = 0.1  # Tukey taper of the periodograms (less leakage of strong low-frequency content)
BAND_PARAMS = 5  # f0, bw, one amplitude per axis (the floor is the base model's white noise)
X_SUPPORT = 6.0  # band-pass prototype variable beyond which the band's PSD is negligible
# a levels fit stops when an iteration's Fisher-predicted gain in log L (score . step / 2) is below this, a millionth
# of a nat (what decides anything here differs by 1e-3 and more): behind an exact truth the nuisance level has almost
# no information and under the ridge crept ~1e-7 per iteration, gaining 1e-8 to 2e-7 of log L each time, so every
# fit ran all its 50 iterations (session 56: ~2 iterations instead, log L within 1.3e-6 of the 50-iteration fits)
LEVELS_LL_TOL = 1e-6


@dataclass
class Nuisance:
    """The reconstruction error of the true rate as a nuisance term of the residual's spectrum
    (`reconstruction`): per sequence its PSD, f -> (len f, 3) (None: exact ground truth), and the
    sensor's floor when it is known from outside the band (None: fitted)."""

    psd: list[Callable[[np.ndarray], np.ndarray] | None]
    floor: np.ndarray | None = None
    # the fixed floor read again through a sensor low-pass of a given corner (keyword corner_hz; None: flat); None
    # where it was not read inside the trusted band (`reconstruction.floor_through_corner`)
    floor_at: Callable[..., np.ndarray | None] | None = None


@dataclass
class Spectra:
    """Periodograms of the residuals of several sequences, bins of [F_MIN_HZ, rate/2), all
    sequences' bins together sorted by frequency."""

    f: np.ndarray  # (M,) Hz, ascending
    I: np.ndarray  # (M, 3) one-sided periodogram, (rad/s)^2/Hz
    seq: np.ndarray  # (M,) sequence index of each bin
    rate_hz: float
    n_seq: int
    # floor shape A(f) the periodogram was divided by (a sensor low-pass); None: flat
    shape: np.ndarray | None = None
    # (M, 3) reconstruction-error PSD at each bin (`reconstruction`), a nuisance term with a fitted
    # level; None: an exact ground truth
    E: np.ndarray | None = None
    # (3,) the sensor's floor when it is known from elsewhere (where the reconstruction error
    # swamps it in the band, `reconstruction.sensor_floor`); fixed in the nuisance fits
    floor: np.ndarray | None = None
    cum: np.ndarray = field(init=False, repr=False)  # (M + 1, 3) cumulative sums of I

    def __post_init__(self) -> None:
        order = np.argsort(self.f, kind="stable")
        self.f, self.I, self.seq = self.f[order], self.I[order], self.seq[order]
        if self.shape is not None:
            self.shape = self.shape[order]
        if self.E is not None:
            self.E = self.E[order]
        self.cum = np.concatenate([np.zeros((1, 3)), np.cumsum(self.I, 0)])

    def subset(self, s: int) -> Spectra:
        m = self.seq == s
        shape = None if self.shape is None else self.shape[m]
        E = None if self.E is None else self.E[m]
        return Spectra(self.f[m], self.I[m], np.zeros(int(m.sum()), dtype=int), self.rate_hz, 1, shape, E, self.floor)

    def shaped(self, corner_hz: float | None) -> Spectra:
        """The periodogram divided by the floor shape of a sensor low-pass of corner `corner_hz`
        (`SensorBandwidth.floor_shape`): a shaped floor becomes a flat one, and the Whittle
        likelihood gains -sum log A (`_fit_levels`). None or inf: self."""
        if corner_hz is None or not np.isfinite(corner_hz):
            return self
        a = SensorBandwidth.floor_shape(self.f, corner_hz, self.rate_hz)
        E = None if self.E is None else self.E / a[:, None]
        return Spectra(self.f, self.I / a[:, None], self.seq, self.rate_hz, self.n_seq, a, E, self.floor)

    @property
    def log_shape(self) -> float:
        """sum over bins and axes of log A (0 for a flat floor)."""
        return 0.0 if self.shape is None else 3.0 * float(np.log(self.shape).sum())

    def support(self, f0: float, bw: float) -> slice:
        """Bins where the band's PSD shape is above ~1e-14 of its peak (|x| < X_SUPPORT of the
        band-pass prototype); elsewhere the model is the floor alone."""
        lo, hi = Vibration.band_edges(f0, bw, self.rate_hz)
        b, q = hi - lo, lo * hi
        edges = [(x * b + np.sqrt((x * b) ** 2 + 4 * q)) / 2 for x in (-X_SUPPORT, X_SUPPORT)]
        ia, ib = np.searchsorted(self.f, edges)
        return slice(int(ia), int(ib))


@dataclass
class BandFit:
    """Band-limited vibration fitted to the residual spectra (SI units)."""

    frequency_hz: float
    bandwidth_hz: float
    power: np.ndarray  # (3,) band variance per axis, (rad/s)^2
    floor: np.ndarray  # (3,) one-sided white-noise PSD per axis, (rad/s)^2/Hz
    loglik: float
    loglik_floor: float  # flat floor only
    n_bins: int
    power_se: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    floor_se: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    frequency_se: float = float("nan")
    bandwidth_se: float = float("nan")
    amplitude_se: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    per_sequence: list[dict] = field(default_factory=list)
    f_hi_hz: float = float("inf")  # upper edge of the compared band (the trusted band)
    mean_psd: np.ndarray | None = None  # (3,) mean periodogram over the compared bins
    kappa: np.ndarray | None = None  # (3,) level of the reconstruction-error nuisance fitted beside the band
    # log L with the band's level kept at a level fitted elsewhere (`fit_band(fixed_power=...)`)
    loglik_kept: float | None = None

    @property
    def amplitude(self) -> np.ndarray:
        """The library's amplitude A (band RMS = A / sqrt(2))."""
        return np.sqrt(2 * np.clip(self.power, 0, None))

    @property
    def white_noise_density(self) -> np.ndarray:
        """Floor as a white-noise density N (rad/s/sqrt(Hz)): one-sided PSD = 2 N^2."""
        return np.sqrt(self.floor / 2)

    def delta_bic(self, n: int) -> float:
        return 2 * (self.loglik - self.loglik_floor) - BAND_PARAMS * np.log(n)

    def explained(self, sigma: np.ndarray, rate_hz: float) -> float:
        """Share of the (1/sigma^2-weighted) residual power that the band carries."""
        w = 1 / sigma**2
        width = min(self.f_hi_hz, rate_hz / 2)
        if self.mean_psd is not None:  # all the residual's power in the compared bins (floor, nuisance, band)
            total = self.mean_psd * (width - F_MIN_HZ)
            return float((w * self.power).sum() / (w * np.maximum(total, self.power)).sum())
        return float((w * self.power).sum() / (w * (self.power + self.floor * width)).sum())

    def params(self) -> tuple[dict, dict]:
        p = {
            "frequency_hz": np.asarray(self.frequency_hz),
            "amplitude": self.amplitude,
            "bandwidth_hz": np.asarray(self.bandwidth_hz),
        }
        se = {
            "frequency_hz": np.asarray(self.frequency_se),
            "amplitude": self.amplitude_se,
            "bandwidth_hz": np.asarray(self.bandwidth_se),
        }
        return p, se


def masked_samples(r: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(x, scale): r (N, 3) less the kept samples' mean, zero outside `mask` (None: all kept), and per axis the
    factor N / kept that gives a periodogram of x the power per sample of the kept samples alone."""
    m = np.ones(r.shape, dtype=bool) if mask is None else mask
    keep = np.maximum(m.sum(0), 1)
    return np.where(m, r - np.where(m, r, 0).sum(0) / keep, 0.0), len(r) / keep


def spectra(
    residuals: list[np.ndarray],
    rate_hz: float,
    masks: list[np.ndarray] | None = None,
    bands: list[float | None] | None = None,
    nuisance: Nuisance | None = None,
) -> Spectra:
    """Tapered periodograms of each residual (N, 3). Masked samples (False in `masks`, e.g. near a
    saturation limit) are set to zero and the power rescaled by the fraction kept. `bands`: upper
    edge per sequence of the band where the reconstructed rate is trusted (`reconstruction`); the
    bins above it are left out. `nuisance`: the reconstruction error, carried as a nuisance term."""
    fs, Is, seqs, Es = [], [], [], []
    with_e = nuisance is not None and any(e is not None for e in nuisance.psd)
    for s, r in enumerate(residuals):
        x, scale = masked_samples(r, None if masks is None else masks[s])
        n = len(x)
        w = signal.windows.tukey(n, TAPER)
        X = np.fft.rfft(x * w[:, None], axis=0)
        f = np.fft.rfftfreq(n, 1 / rate_hz)
        I = 2 * np.abs(X) ** 2 / (rate_hz * np.sum(w**2)) * scale
        ok = (f >= F_MIN_HZ) & (f < rate_hz / 2) & (f <= _band_edge(bands, s, rate_hz))
        fs.append(f[ok])
        Is.append(I[ok])
        seqs.append(np.full(int(ok.sum()), s))
        if with_e:
            e = nuisance.psd[s]
            Es.append(np.zeros((int(ok.sum()), 3)) if e is None else e(f[ok]))
    E = np.concatenate(Es) if with_e else None
    if E is not None and not np.any(E > 0):
        E = None
    floor = None if E is None else nuisance.floor
    return Spectra(
        np.concatenate(fs), np.concatenate(Is), np.concatenate(seqs), rate_hz, len(residuals), E=E, floor=floor
    )


def _fit_levels_nuisance(
    sp: Spectra,
    band: tuple[float, float] | None,
    theta: np.ndarray | None = None,
    iters: int = 60,
    fixed_floor: np.ndarray | None = None,
    fixed_power: np.ndarray | None = None,
) -> tuple[np.ndarray, float, np.ndarray]:
    """Whittle fit with the reconstruction error as a nuisance term: S = c + P g(f; band) + kappa E(f)
    per axis, all levels >= 0 (projected Fisher scoring). Returns (theta (3, 3): rows c, P, kappa;
    log L; Fisher information of (c, P) (3, 2, 2), the nuisance level profiled out). `fixed_power`:
    the band's level P is given (3,), only the floor and the nuisance's level are fitted; without a
    nuisance (sp.E None, an exact ground truth) its column is zero and stays out of the fit."""
    I, E = sp.I, sp.E
    G = np.zeros_like(I) if band is None else Vibration.band_psd(sp.f, band[0], band[1], sp.rate_hz)[:, None]
    if band is not None and sp.shape is not None:
        G = G / sp.shape[:, None]
    G = np.broadcast_to(G, I.shape)
    B = np.stack([np.ones_like(I), G, np.zeros_like(I) if E is None else E], -1)  # (M, 3 axes, 3 levels)
    floor = sp.floor if fixed_floor is None else fixed_floor
    free = np.array([floor is None, band is not None and fixed_power is None, E is not None])
    if theta is None or theta.shape[0] < 3:
        lo = sp.f <= np.quantile(sp.f, 0.2)  # where the error is smallest: a floor start
        c = np.median(I[lo], axis=0) / np.log(2) if lo.any() else I.mean(0)
        th = np.stack([c if floor is None else floor, np.zeros(3), np.full(3, 1.0)])
    else:
        th = theta.copy()
        if floor is not None:
            th[0] = floor
    if band is None:
        th[1] = 0.0
    elif fixed_power is not None:
        th[1] = np.asarray(fixed_power, dtype=np.float64)
    Bt = np.ascontiguousarray(B.transpose(1, 0, 2))  # (3 axes, M, 3 levels): per-axis products run as BLAS matmuls
    for _ in range(iters):
        S = _model_psd(Bt, th)
        W = 1 / S**2
        score = np.matmul(((I - S) * W).T[:, None, :], Bt)[:, 0, :].T  # (levels, axes)
        info = _fisher(Bt, W)
        step = np.zeros_like(th)
        for a in range(3):
            act = free & ~((th[:, a] <= 0) & (score[:, a] < 0))  # on a bound with a pull outwards: fixed
            if act.any():
                Fa = info[a][np.ix_(act, act)] + 1e-12 * np.eye(int(act.sum())) * np.trace(info[a]) / 3
                step[act, a] = np.linalg.solve(Fa, score[act, a])
        gain = 0.5 * float((score * step).sum())
        new = th + step
        new[0] = np.maximum(new[0], 0.2 * th[0])  # damped: the floor stays positive
        new[2] = np.clip(new[2], 0.2 * th[2], 5.0 * th[2] + 1e-12)  # and so does the nuisance's level
        new = np.maximum(new, 0.0)
        done = np.all(np.abs(new - th) <= 1e-8 * (np.abs(th) + th[0:1] + 1e-300))
        th = new
        if done or gain < LEVELS_LL_TOL:
            break
    S = _model_psd(Bt, th)
    ll = float(-(np.log(S) + I / S).sum()) - sp.log_shape
    info = _fisher(Bt, 1 / S**2)[:, :2, :2]
    return th, ll, info


def _model_psd(Bt: np.ndarray, th: np.ndarray) -> np.ndarray:
    """(M, 3) PSD sum_k B[m, a, k] th[k, a] of the levels `th` (3 levels, 3 axes), Bt the basis as (axes, M, levels)."""
    return np.maximum(np.matmul(Bt, th.T[:, :, None])[..., 0].T, 1e-300)


def _fisher(Bt: np.ndarray, W: np.ndarray) -> np.ndarray:
    """(3 axes, 3, 3) Fisher information sum_m B[m, a, k] B[m, a, l] W[m, a] of the levels (the einsum
    "mak,mal,ma->akl", as batched matmuls: three to four times faster on the whole spectrum's bins)."""
    return np.matmul(Bt.transpose(0, 2, 1), Bt * W.T[:, :, None])


def _band_edge(bands: list[float | None] | None, s: int, rate_hz: float) -> float:
    b = None if bands is None else bands[s]
    return rate_hz / 2 if b is None else min(float(b), rate_hz / 2)


def _fit_levels(
    sp: Spectra, band: tuple[float, float] | None, theta: np.ndarray | None = None, iters: int = 50
) -> tuple[np.ndarray, float, np.ndarray]:
    """Whittle fit of (c_a, P_a >= 0) per axis for the PSD c + P g(f; band), band = (f0, bw) or None
    for the floor alone. Returns (theta (2, 3), log L, Fisher information (3, 2, 2)). Bins outside
    the band's support enter through their count and sum only."""
    if sp.E is not None:
        return _fit_levels_nuisance(sp, band, theta, iters)
    M = len(sp.f)
    if band is None:  # flat floor: closed form
        c = sp.I.mean(0)
        info = np.zeros((3, 2, 2))
        info[:, 0, 0] = M / c**2
        return np.stack([c, np.zeros(3)]), float(-(M * (np.log(c) + 1)).sum()) - sp.log_shape, info
    sl = sp.support(*band)
    I = sp.I[sl]
    G = Vibration.band_psd(sp.f[sl], band[0], band[1], sp.rate_hz)[:, None]
    if sp.shape is not None:  # the band is not low-passed by the sensor's floor shape: divide it too
        G = G / sp.shape[sl, None]
    n_out = M - len(I)
    sum_out = sp.cum[-1] - (sp.cum[sl.stop] - sp.cum[sl.start])
    if theta is None:
        c = np.quantile(sp.I, 0.5, axis=0) / np.log(2)  # median of an exponential = ln 2 x mean
        P = np.clip(((I - c) * G).sum(0) / max(float((G**2).sum()), 1e-300), 0, None)
    else:
        c, P = theta[0].copy(), theta[1].copy()
    for _ in range(iters):
        S = c + P * G
        W = 1 / S**2
        R = (I - S) * W
        sc, sp_ = R.sum(0) + (sum_out - n_out * c) / c**2, (G * R).sum(0)
        fcc, fcp, fpp = W.sum(0) + n_out / c**2, (G * W).sum(0), (G**2 * W).sum(0)
        det = np.maximum(fcc * fpp - fcp**2, 1e-300)
        dc, dP = (fpp * sc - fcp * sp_) / det, (fcc * sp_ - fcp * sc) / det
        at0 = (P <= 0) & (dP < 0)  # on the boundary P = 0: the floor alone
        dc = np.where(at0, sc / fcc, dc)
        dP = np.where(at0, 0.0, dP)
        c_new = np.maximum(c + dc, 0.2 * c)  # damped: the floor stays positive
        P_new = np.maximum(P + dP, 0.0)
        done = np.all(np.abs(c_new - c) <= 1e-8 * c) and np.all(np.abs(P_new - P) <= 1e-8 * (P + c))
        c, P = c_new, P_new
        if done:
            break
    S = c + P * G
    W = 1 / S**2
    fcc, fcp, fpp = W.sum(0) + n_out / c**2, (G * W).sum(0), (G**2 * W).sum(0)
    info = np.stack([np.stack([fcc, fcp], -1), np.stack([fcp, fpp], -1)], 1)
    ll = -(np.log(S) + I / S).sum() - (n_out * np.log(c) + sum_out / c).sum() - sp.log_shape
    return np.stack([c, P]), float(ll), info


def _bounds(rate_hz: float) -> tuple[float, float, float]:
    """(lowest band edge, highest band edge, smallest bandwidth)."""
    return F_MIN_HZ / 2, 0.49 * rate_hz, BW_MIN_WELCH_BINS * rate_hz / WELCH_NPERSEG


def _clip_band(f0: float, bw: float, rate_hz: float, f_hi: float | None = None) -> tuple[float, float]:
    lo_min, hi_max, bw_min = _bounds(rate_hz)
    if f_hi is not None:  # a band beyond the compared bins would be fitted to nothing
        hi_max = max(min(hi_max, f_hi), lo_min + bw_min)
    bw = float(np.clip(bw, bw_min, hi_max - lo_min))
    f0 = float(np.clip(f0, lo_min + bw / 2, hi_max - bw / 2))
    return f0, bw


def initial_guesses(
    residuals: list[np.ndarray], rate_hz: float, n_peaks: int = 2, f_max: float | None = None
) -> list[tuple[float, float]]:
    """(f0, bw) starts: the band around each of the largest peaks of the Welch excess over the floor
    (summed over axes, relative to each axis's median level), where the excess is above half the
    peak's; f0 its centre, bw its width."""
    P = 0.0
    n_tot = 0
    for r in residuals:
        f, p = signal.welch(r - r.mean(0), fs=rate_hz, nperseg=min(WELCH_NPERSEG, len(r)), axis=0)
        P = P + p * len(r)
        n_tot += len(r)
    P = P / n_tot
    ok = (f >= F_MIN_HZ) & (f <= (rate_hz / 2 if f_max is None else f_max))
    if ok.sum() < 3:
        return []
    floor = np.median(P[ok], axis=0)
    e = np.where(ok, (P / np.maximum(floor, 1e-300) - 1).sum(1), -np.inf)
    df = f[1] - f[0]
    out = []
    for _ in range(n_peaks):
        k = int(np.argmax(e))
        if not np.isfinite(e[k]) or e[k] <= 0:
            break
        half = e[k] / 2
        a = k
        while a > 0 and e[a - 1] > half:
            a -= 1
        b = k
        while b < len(e) - 1 and e[b + 1] > half:
            b += 1
        out.append(_clip_band((f[a] + f[b]) / 2, f[b] - f[a] + df, rate_hz))
        e[max(a - 2, 0) : b + 3] = -np.inf
    return out


class _Profile:
    """Profile Whittle likelihood over (f0, log bw), levels refitted at each point."""

    def __init__(self, sp: Spectra) -> None:
        self.sp = sp
        self.theta: np.ndarray | None = None
        self.best = (-np.inf, 0.0, 0.0, None, None)

    def __call__(self, u: np.ndarray) -> float:
        f0, bw = _clip_band(float(u[0]), float(np.exp(min(u[1], 20.0))), self.sp.rate_hz, float(self.sp.f[-1]))
        theta, ll, info = _fit_levels(self.sp, (f0, bw), self.theta)
        if ll > self.best[0]:
            self.best = (ll, f0, bw, theta, info)
            self.theta = theta
        return -ll


def _maximise(sp: Spectra, starts: list[tuple[float, float]], maxfev: int = 150) -> _Profile:
    prof = _Profile(sp)
    for f0, bw in starts:
        prof.theta = None
        u0 = np.array([f0, np.log(bw)])
        simplex = np.array([u0, u0 + [max(bw / 4, 0.2), 0.0], u0 + [0.0, 0.3]])
        optimize.minimize(
            prof,
            u0,
            method="Nelder-Mead",
            options={"initial_simplex": simplex, "maxfev": maxfev, "xatol": 1e-2, "fatol": 0.05},
        )
    return prof


def fit_band(
    residuals: list[np.ndarray],
    rate_hz: float,
    masks: list[np.ndarray] | None = None,
    with_errors: bool = False,
    starts: list[tuple[float, float]] | None = None,
    bands: list[float | None] | None = None,
    floor_corner_hz: float | None = None,
    nuisance: Nuisance | None = None,
    fixed_band: bool = False,
    fixed_power: np.ndarray | None = None,
) -> BandFit | None:
    """Maximum-Whittle-likelihood band-limited vibration (see the module docstring); None when the
    residuals show no excess to start from. `with_errors`: standard errors (a few more fits).
    `starts`: (f0, bw) to start from (default: `initial_guesses`). `bands`: trusted band per
    sequence (`spectra`). `floor_corner_hz`: the floor is shaped by a sensor low-pass of this
    corner (`Spectra.shaped`). `fixed_band`: keep the first start's centre and width, fit levels only;
    `fixed_power` (with `fixed_band`): also the log-likelihood with the band's level per axis kept at
    these values, only the floor (and the nuisance's level) fitted (`BandFit.loglik_kept`): how well
    a band fitted elsewhere explains these spectra."""
    f_hi = min(_band_edge(bands, s, rate_hz) for s in range(len(residuals)))
    starts = initial_guesses(residuals, rate_hz, f_max=f_hi) if starts is None else starts
    if not starts:
        return None
    sp = spectra(residuals, rate_hz, masks, bands, nuisance).shaped(floor_corner_hz)
    if len(sp.f) < 10 * BAND_PARAMS:
        return None
    _, ll0, _ = _fit_levels(sp, None)
    if fixed_band:  # centre and width as given: only the levels are fitted
        f0, bw = _clip_band(*starts[0], rate_hz, float(sp.f[-1]))
        theta, ll, _ = _fit_levels(sp, (f0, bw))
        kept = None if fixed_power is None else _fit_levels_nuisance(sp, (f0, bw), fixed_power=fixed_power)[1]
        mean_psd = (sp.I * (1.0 if sp.shape is None else sp.shape[:, None])).mean(0)
        fit = BandFit(f0, bw, theta[1], theta[0], ll, ll0, len(sp.f), f_hi_hz=f_hi, mean_psd=mean_psd)
        fit.loglik_kept = kept
        return fit
    prof = _maximise(sp, starts)
    ll, f0, bw, theta, info = prof.best
    mean_psd = (sp.I * (1.0 if sp.shape is None else sp.shape[:, None])).mean(0)
    kappa = theta[2] if len(theta) > 2 else None
    fit = BandFit(f0, bw, theta[1], theta[0], ll, ll0, len(sp.f), f_hi_hz=f_hi, mean_psd=mean_psd, kappa=kappa)
    if with_errors:
        _errors(fit, sp, info, prof)
    return fit


def _errors(fit: BandFit, sp: Spectra, info: np.ndarray, prof: _Profile) -> None:
    cov = np.linalg.pinv(info)  # (3, 2, 2): per axis (c, P)
    fit.floor_se = np.sqrt(np.clip(cov[:, 0, 0], 0, None))
    fit.power_se = np.sqrt(np.clip(cov[:, 1, 1], 0, None))
    # curvature of the profile log-likelihood in (f0, bw)
    x0 = np.array([fit.frequency_hz, fit.bandwidth_hz])
    h = np.array([0.02, 0.02]) * fit.bandwidth_hz

    def ll(x):
        prof.theta = np.stack([fit.floor, fit.power])
        return -prof(np.array([x[0], np.log(x[1])]))

    H = np.zeros((2, 2))
    for i in range(2):
        for j in range(i, 2):
            ei, ej = np.eye(2)[i] * h[i], np.eye(2)[j] * h[j]
            H[i, j] = H[j, i] = (ll(x0 + ei + ej) - ll(x0 + ei - ej) - ll(x0 - ei + ej) + ll(x0 - ei - ej)) / (
                4 * h[i] * h[j]
            )
    with np.errstate(invalid="ignore"):
        c = np.linalg.inv(-H) if np.all(np.linalg.eigvalsh(-H) > 0) else np.full((2, 2), np.nan)
    f_se, bw_se = np.sqrt(np.abs(np.diag(c)))
    amp = fit.amplitude
    a_se = np.where(amp > 0, fit.power_se / np.maximum(amp, 1e-300), np.sqrt(2 * fit.power_se))
    # spread between sequences: per-sequence fits started from the pooled one
    if sp.n_seq >= 2:
        per = []
        for s in range(sp.n_seq):
            ps = _maximise(sp.subset(s), [(fit.frequency_hz, fit.bandwidth_hz)], maxfev=80).best
            per.append({"frequency_hz": ps[1], "bandwidth_hz": ps[2], "amplitude": np.sqrt(2 * ps[3][1])})
        fit.per_sequence = per
        k = np.sqrt(sp.n_seq)
        f_se = np.nanmax([f_se, np.std([p["frequency_hz"] for p in per], ddof=1) / k])
        bw_se = np.nanmax([bw_se, np.std([p["bandwidth_hz"] for p in per], ddof=1) / k])
        a_se = np.maximum(a_se, np.std([p["amplitude"] for p in per], axis=0, ddof=1) / k)
    fit.frequency_se, fit.bandwidth_se, fit.amplitude_se = float(f_se), float(bw_se), a_se


def psd_gap(
    measured: list[np.ndarray],
    simulated: list[np.ndarray],
    rate_hz: float,
    per_octave: int = 3,
    f_max: float | None = None,
) -> float:
    """Mean |log10(PSD measured / PSD simulated)| over axes and 1/`per_octave`-octave bands of
    [F_MIN_HZ, rate/2): Welch PSDs averaged over the sequences (weighted by their lengths), then
    over the Welch bins of each band (log-spaced like the Allan deviation's cluster times, and
    with little estimation noise left). `f_max`: only up to this frequency (the trusted band)."""

    def welch(xs):
        acc, n = 0.0, 0
        for x in xs:
            f, p = signal.welch(x - x.mean(0), fs=rate_hz, nperseg=min(WELCH_NPERSEG, len(x)), axis=0)
            acc, n = acc + p * len(x), n + len(x)
        return f, acc / n

    f, a = welch(measured)
    _, b = welch(simulated)
    f_hi = rate_hz / 2 if f_max is None else min(f_max, rate_hz / 2)
    n_bands = max(int(np.ceil(per_octave * np.log2(f_hi / F_MIN_HZ))), 1)
    edges = np.geomspace(F_MIN_HZ, f_hi, n_bands + 1)
    k = np.searchsorted(edges, f, side="right") - 1
    ok = (k >= 0) & (k < n_bands) & (f < rate_hz / 2) & (f <= f_hi)
    out = []
    for j in np.unique(k[ok]):
        m = ok & (k == j)
        ra, rb = a[m].mean(0), b[m].mean(0)
        good = (ra > 0) & (rb > 0)
        out.extend(np.abs(np.log10(ra[good] / rb[good])))
    return float(np.mean(out)) if out else float("nan")


# ----------------------------------------------------------------------------- sensor bandwidth

FLOOR_SHAPE_PARAMS = 1  # the corner frequency (the level is the base model's white noise)
CORNER_STEP = 0.02  # step in log corner of the central differences of a profile's curvature
# the corner searches' tolerance in log corner (0.01 %): well below the smallest standard error they report
# (~0.06 %, the time-domain fit behind an exact mocap), so the search does not add to it
CORNER_XATOL = 1e-4


def search_log_corner(fun: Callable[[float], float], grid: np.ndarray) -> float:
    """The log corner that minimises `fun`: the grid's best, then a bounded search between its neighbours (to
    CORNER_XATOL); the grid's best where the search does not improve on it."""
    vals = [fun(float(u)) for u in grid]
    k = int(np.argmin(vals))
    res = optimize.minimize_scalar(
        fun,
        bounds=(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]),
        method="bounded",
        options={"xatol": CORNER_XATOL},
    )
    return float(res.x) if res.fun < vals[k] else float(grid[k])


def corner_se(ll_minus: float, ll: float, ll_plus: float, u: float, h: float = CORNER_STEP) -> float:
    """Standard error (Hz) of a corner exp(u) from a profile log-likelihood at u - h, u, u + h (u = log corner):
    exp(u) / sqrt(-d2 ll / du2), by central differences; nan where the profile is not curved down."""
    d2 = -(ll_plus - 2 * ll + ll_minus) / h**2
    return float(np.exp(u) / np.sqrt(d2)) if d2 > 0 else float("nan")


def local_mean_square(e: np.ndarray, f: np.ndarray, smooth_hz: float) -> np.ndarray:
    """Per column of rows e (M, ...) at frequencies f (M,): each row's local variance, the mean of e^2 over the rows
    within +- `smooth_hz` of its frequency (same shape as e)."""
    order = np.argsort(f, kind="stable")
    fs = f[order]
    lo = np.searchsorted(fs, fs - smooth_hz, side="left")
    hi = np.searchsorted(fs, fs + smooth_hz, side="right")
    c = np.concatenate([np.zeros((1, *e.shape[1:])), np.cumsum(e[order] ** 2, axis=0)])
    n = (hi - lo).reshape(-1, *([1] * (e.ndim - 1)))
    out = np.empty_like(e, dtype=float)
    out[order] = (c[hi] - c[lo]) / n
    return out


def colour_factor(
    rows: list[np.ndarray], slopes: list[np.ndarray], freqs: list[np.ndarray], smooth_hz: float = 0.5
) -> float:
    """How much a least-squares standard error that takes its rows as white understates the real one: the ratio
    sqrt(sum J^2 V / sum J^2 / mean e^2) of the sandwich variance sum J^2 V / (sum J^2)^2 to s2 / sum J^2, from
    Fourier rows e (M, 3) of the residual, the rows J (M, 3) of the fitted values' derivative in the parameter, and
    each row's frequency (M,), one triple per sequence. V is the residual's local variance, its squared rows averaged
    over +- `smooth_hz` (Fourier rows of a stationary residual are nearly uncorrelated, with variance its spectrum).
    1 where the residual is white; above 1 where it has most power where J has (a low-pass colours the gyro's noise
    like the motion it is fitted to)."""
    num = den = ee = 0.0
    m = 0
    for e, J, f in zip(rows, slopes, freqs, strict=True):
        v = local_mean_square(e, f, smooth_hz)
        num += float(np.sum(J**2 * v))
        den += float(np.sum(J**2))
        ee += float(np.sum(e**2))
        m += e.size
    if den <= 0 or ee <= 0:
        return 1.0
    return float(np.sqrt(num / den / (ee / m)))


@dataclass
class FloorShapeFit:
    """A sensor low-pass read from the shape of the noise floor (`SensorBandwidth`)."""

    corner_hz: float
    floor: np.ndarray  # (3,) level at 0 Hz, one-sided (rad/s)^2/Hz
    loglik: float
    loglik_flat: float
    f_hi_hz: float
    corner_se_hz: float = float("nan")
    extra_loglik: float = 0.0  # log-likelihood gain of the corner outside the spectrum (the motion's delay)

    def delta_bic(self, n: int) -> float:
        return 2 * (self.loglik - self.loglik_flat + self.extra_loglik) - FLOOR_SHAPE_PARAMS * np.log(n)

    def explained(self, rate_hz: float) -> float:
        """Share of the in-band floor power the droop removes (what a flat floor would misplace)."""
        f = np.linspace(0.0, min(self.f_hi_hz, rate_hz / 2), 512)
        a = SensorBandwidth.floor_shape(f, self.corner_hz, rate_hz)
        return float(1.0 - np.trapezoid(a, f) / max(f[-1], 1e-300))


class FloorShapeProfile:
    """Whittle log-likelihood of the residual spectra with the floor shaped by a sensor low-pass of
    a given corner (`SensorBandwidth.floor_shape`; with a named band-limited vibration `band` =
    (f0, bw), its power refitted beside the floor). `ok` is False when the floor is fixed by the
    reconstruction's nuisance term: its shape is not judged there (the error rises with frequency
    as the floor's droop falls, and a fixed level cannot tell them apart). `named`: the corner is
    already named, and the profile is read only for its standard error (not asked where the motion
    alone chose the corner, `lowpass_choice.choose`, whose fit gives its own): the fixed floor is
    then read again through each corner's shape (`Nuisance.floor_at`), where it was read inside the
    trusted band."""

    def __init__(
        self,
        residuals: list[np.ndarray],
        rate_hz: float,
        masks: list[np.ndarray] | None = None,
        bands: list[float | None] | None = None,
        band: tuple[float, float] | None = None,
        nuisance: Nuisance | None = None,
        named: bool = False,
    ) -> None:
        self.sp = spectra(residuals, rate_hz, masks, bands, nuisance)
        self.band, self.rate_hz = band, rate_hz
        self.floor_at = None if self.sp.floor is None or nuisance is None or not named else nuisance.floor_at
        if self.floor_at is not None and self.floor_at(corner_hz=None) is None:
            self.floor_at = None  # the floor was read outside the band: its shape is not seen there
        self.ok = len(self.sp.f) >= 20 and (self.sp.floor is None or self.floor_at is not None)
        self.ll_flat = _fit_levels(self._seen(None), band)[1] if self.ok else float("nan")
        self.f_hi = min(_band_edge(bands, s, rate_hz) for s in range(len(residuals)))

    def _seen(self, corner_hz: float | None) -> Spectra:
        """The spectra shaped by a low-pass of `corner_hz` (None: flat), a fixed floor read through the same shape."""
        sp = self.sp.shaped(corner_hz)
        return sp if self.floor_at is None else replace(sp, floor=self.floor_at(corner_hz=corner_hz))

    def loglik(self, corner_hz: float) -> float:
        return _fit_levels(self._seen(corner_hz), self.band)[1]

    def fit(self, corner_hz: float) -> FloorShapeFit:
        """The fit at `corner_hz`, with the standard error of the corner from the profile's curvature."""
        theta, ll, _ = _fit_levels(self._seen(corner_hz), self.band)
        u, h = np.log(corner_hz), CORNER_STEP
        se = corner_se(self.loglik(np.exp(u - h)), ll, self.loglik(np.exp(u + h)), u, h)
        return FloorShapeFit(float(corner_hz), theta[0], ll, self.ll_flat, self.f_hi, se)

    def corner_grid(self) -> np.ndarray:
        """Corners searched: 2 Hz to 50 x the rate (beyond it the floor is flat to 1e-3)."""
        return np.geomspace(2.0, 50.0 * self.rate_hz, 9)


def fit_floor_shape(
    residuals: list[np.ndarray],
    rate_hz: float,
    masks: list[np.ndarray] | None = None,
    bands: list[float | None] | None = None,
    band: tuple[float, float] | None = None,
    nuisance: Nuisance | None = None,
    extra: Callable[[float], float] | None = None,
) -> FloorShapeFit | None:
    """Maximum-likelihood corner of a first-order sensor low-pass: the Whittle log-likelihood of
    the floor's shape (`FloorShapeProfile`) plus `extra(corner)` (a log-likelihood gain of the same
    corner elsewhere, e.g. what its delay of the motion explains), coarse grid then bounded search
    in log corner. None: the floor's shape cannot be read in the trusted band."""
    prof = FloorShapeProfile(residuals, rate_hz, masks, bands, band, nuisance)
    if not prof.ok:
        return None

    def neg(u: float) -> float:
        c = float(np.exp(u))
        return -(prof.loglik(c) + (extra(c) if extra else 0.0))

    u = search_log_corner(neg, np.log(prof.corner_grid()))
    fit = prof.fit(float(np.exp(u)))
    fit.extra_loglik = float(extra(fit.corner_hz)) if extra else 0.0
    return fit


def fit_floor(
    residuals: list[np.ndarray],
    rate_hz: float,
    masks: list[np.ndarray] | None = None,
    bands: list[float | None] | None = None,
    corner_hz: float | None = None,
    nuisance: Nuisance | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Whittle level (3,) of a flat floor (shaped by a low-pass of `corner_hz` if given: its level
    at 0 Hz) over the trusted band, with its standard error: (one-sided PSD, SE)."""
    sp = spectra(residuals, rate_hz, masks, bands, nuisance).shaped(corner_hz)
    c = _fit_levels(sp, None)[0][0]
    return c, c / np.sqrt(max(len(sp.f), 1))


def fit_nuisance(
    residuals: list[np.ndarray],
    rate_hz: float,
    masks: list[np.ndarray] | None,
    bands: list[float | None] | None,
    nuisance: Nuisance | None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """(c, kappa): the sensor's floor (one-sided PSD, (3,)) and the level (3,) of the reconstruction
    error beside it, fitted to the residual spectra in the trusted band. None: no nuisance term."""
    sp = spectra(residuals, rate_hz, masks, bands, nuisance)
    if sp.E is None or len(sp.f) < 10:
        return None
    th, _, _ = _fit_levels(sp, None)
    return th[0], th[2]
