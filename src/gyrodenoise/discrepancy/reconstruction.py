"""How far the reconstructed true rate can be trusted: the band of the comparison and the
reconstruction error inside it.

The detector's "true" rate is the derivative of a smooth spline fitted to the ground-truth poses
(`sim.trajectory.SmoothTrajectory`), averaged over each IMU period as the gyro samples it. When those
poses are measured (motion capture, a batch estimate), the reconstructed rate carries two errors that a
gyro error model must not explain:

- ground-truth noise passed by the spline and differentiated: PSD sigma_n^2 K(f), where sigma_n is
  the per-sample orientation noise and K(f) ~ (2 pi f)^2 (2 / gt_rate) |H(f)|^2 the spline's
  transfer to the rate (rising as f^2 up to the spline's corner ~ 1 / (2 knot spacing));
- motion the spline smooths away: (2 pi f)^2 times the PSD of the motion left in the fit residual.

Both are estimated from the ground truth itself: sigma_n from the residual of the poses around the
spline near the ground truth's Nyquist frequency (motion is assumed negligible there), K(f) by
passing unit white noise through the same spline fit (Monte Carlo, cached), the lost motion from the
rest of that residual's spectrum.

Lost motion cannot be told from a sensor error (the gyro saw it, the truth lost it): the comparison
stops where it exceeds TRUST_RATIO of the sensor's own share of the measured residual's spectrum,
[0, f_max] (`f_max_hz`, `limited_by`). The noise part has a known spectral shape: inside the band it
is carried as a nuisance term of the residual's spectrum, S(f) = c A(f) + kappa E(f), with the
level kappa fitted beside the sensor's floor c (`spectral.fit_nuisance`), and the regression rows
are weighted by 1 / sqrt(S) (`row_weights`): generalised least squares. `f_equal_hz` says where
the reconstruction error overtakes the sensor's noise. With an exact ground truth (the package's own
simulator) the band is the whole spectrum, E = 0 and nothing changes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import signal
from scipy.interpolate import make_lsq_spline

from gyrodenoise import fft_threads
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import SensorBandwidth

TRUST_RATIO = 0.5  # lost motion <= this fraction of the sensor's own PSD
WELCH_SECONDS = 2.0  # Welch segment of the band estimate: 0.5 Hz resolution
NOISE_BAND = (0.6, 0.9)  # fraction of the ground truth's Nyquist where sigma_n is read
MC_SECONDS = 120.0  # length of the Monte Carlo noise record for the spline's transfer
MIN_BAND_HZ = 1.0  # never narrower than this: below it only slow effects live
FLOOR_QUANTILE = 0.1  # the sensor floor where the reconstruction error swamps it: this quantile of the PSD
NEGLIGIBLE = 1e-3  # reconstruction error below this fraction of the sensor's PSD: not carried


@dataclass
class ReconstructionBand:
    """The trusted band of one sequence and its reconstruction-error spectrum."""

    name: str
    f_max_hz: float  # upper edge of the compared band [0, f_max]; rate/2: the whole spectrum
    rate_hz: float
    gt_rate_hz: float
    knot_spacing_s: float
    orientation_noise_rad: np.ndarray  # (3,) per-sample noise of the ground-truth orientation
    f_hz: np.ndarray = field(repr=False)  # (F,) Welch grid of the arrays below
    k_rate_w2: np.ndarray = field(repr=False)  # (F,) spline noise transfer to the rate / (2 pi f)^2
    lost_angle_psd: np.ndarray = field(repr=False)  # (F, 3) motion left in the GT fit residual, rad^2/Hz
    residual_psd: np.ndarray = field(repr=False)  # (F, 3) measured residual (gyro - reconstructed rate)
    limited_by: str = ""  # what ends the band: "smoothed-away motion", "ground-truth Nyquist", "none"
    f_equal_hz: float = float("inf")  # lowest frequency where the reconstruction error exceeds the sensor's

    @property
    def whole_spectrum(self) -> bool:
        return self.f_max_hz >= self.rate_hz / 2

    negligible: bool = False  # the reconstruction error is below NEGLIGIBLE of the sensor's PSD everywhere

    @property
    def exact(self) -> bool:
        """No reconstruction error worth carrying (an exact ground truth, e.g. the own simulator's)."""
        return self.negligible and self.whole_spectrum

    def noise_psd(self, f: np.ndarray) -> np.ndarray:
        """(len(f), 3) reconstructed-rate error from ground-truth noise, (rad/s)^2/Hz."""
        f = np.asarray(f, dtype=np.float64)
        kw = np.interp(f, self.f_hz, self.k_rate_w2)
        return ((2 * np.pi * f) ** 2 * kw)[:, None] * self.orientation_noise_rad[None] ** 2

    def error_psd(self, f: np.ndarray) -> np.ndarray:
        """(len(f), 3) reconstructed-rate error: ground-truth noise + smoothed-away motion."""
        f = np.asarray(f, dtype=np.float64)
        lost = np.stack([np.interp(f, self.f_hz, np.nan_to_num(self.lost_angle_psd[:, i])) for i in range(3)], 1)
        return self.noise_psd(f) + (2 * np.pi * f[:, None]) ** 2 * lost

    def error_share(self, lo_hz: float, hi_hz: float) -> list[float]:
        """Per axis, the median over [lo, hi] Hz of the estimated reconstruction error over the
        measured residual's PSD: ~1 where the residual is the reconstruction's error."""
        m = (self.f_hz >= lo_hz) & (self.f_hz <= hi_hz)
        if not m.any():
            return [float("nan")] * 3
        r = self.error_psd(self.f_hz[m]) / np.maximum(self.residual_psd[m], 1e-300)
        return np.median(r, axis=0).tolist()

    def summary(self) -> dict:
        return {
            "name": self.name,
            "f_max_hz": self.f_max_hz,
            "whole_spectrum": self.whole_spectrum,
            "limited_by": self.limited_by,
            "f_equal_hz": self.f_equal_hz,
            "gt_rate_hz": self.gt_rate_hz,
            "knot_spacing_s": self.knot_spacing_s,
            "spline_corner_hz": 1.0 / (2 * self.knot_spacing_s),
            "orientation_noise_mrad": (1e3 * self.orientation_noise_rad).tolist(),
            # what the reconstruction error accounts for just above the band (up to 3 x its edge)
            "error_share_above_band": self.error_share(self.f_max_hz, min(3 * self.f_max_hz, self.rate_hz / 2)),
        }


@lru_cache(maxsize=16)
def spline_noise_transfer(
    gt_rate_hz: float, rate_hz: float, knot_spacing_s: float, degree: int = 5, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(f, K_rate, K_resid): PSDs per unit orientation-noise variance (rad^2) of (a) the rate the
    spline reconstructs from white orientation noise sampled at gt_rate_hz (its mean over each period at rate_hz),
    (b) the fit residual of that noise at the ground-truth samples. Monte Carlo on a uniform grid.
    Small-angle noise on a quaternion spline enters the rate linearly, so a spline of the noise
    itself is the same transfer."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, MC_SECONDS, 1.0 / gt_rate_hz)
    n = rng.standard_normal((len(t), 3))
    k = degree
    inner = np.arange(t[0] + knot_spacing_s, t[-1] - knot_spacing_s / 2, knot_spacing_s)
    knots = np.concatenate([[t[0]] * (k + 1), inner, [t[-1]] * (k + 1)])
    sp = make_lsq_spline(t, n, knots, k=k)
    margin = 2.0  # the spline's ends are less constrained
    ti = np.arange(t[0] + margin, t[-1] - margin, 1.0 / rate_hz)
    half = 0.5 / rate_hz  # the rate's mean over each IMU period, as the compared truth (`compare._context`)
    rate = (sp(ti + half) - sp(ti - half)) / (2 * half)
    keep = (t > margin) & (t < t[-1] - margin)
    resid = (n - sp(t))[keep]
    f, k_rate = signal.welch(rate, fs=rate_hz, nperseg=int(WELCH_SECONDS * rate_hz), axis=0)
    f_gt, k_res = signal.welch(resid, fs=gt_rate_hz, nperseg=int(WELCH_SECONDS * gt_rate_hz), axis=0)
    k_res = np.interp(f, f_gt, k_res.mean(1))
    return f, k_rate.mean(1), k_res


def estimate_band(fc: FitContext, residual: np.ndarray, trust_ratio: float = TRUST_RATIO) -> ReconstructionBand:
    """Trusted band and reconstruction error of sequence `fc` given its base-model residual (gyro -
    rate - bias, (N, 3)).

    Needs the ground-truth fit residual in `fc.extra` (`gt_t`, `gt_rotvec_residual`, `knot_spacing`,
    written by `compare.load_fit_context`); without it the ground truth is taken as exact."""
    rate = fc.rate_hz
    nper = min(int(WELCH_SECONDS * rate), len(residual))
    f, p_imu = signal.welch(residual - residual.mean(0), fs=rate, nperseg=nper, axis=0)
    gt_res = fc.extra.get("gt_rotvec_residual")
    if gt_res is None:
        z = np.zeros_like(p_imu)
        return ReconstructionBand(
            fc.name, rate / 2, rate, np.nan, np.nan, np.zeros(3), f, z[:, 0], z, p_imu, "none", np.inf, True
        )
    gt_t = fc.extra["gt_t"]
    gt_rate = float(1.0 / np.median(np.diff(gt_t)))
    h = float(fc.extra["knot_spacing"])
    f_mc, k_rate, k_res = spline_noise_transfer(round(gt_rate, 3), round(rate, 3), h)
    w2 = (2 * np.pi * f) ** 2
    k_rate = np.interp(f, f_mc, k_rate)
    k_rate_w2 = np.where(f > 0, k_rate / np.maximum(w2, 1e-300), 0.0)
    k_rate_w2[0] = k_rate_w2[1]  # K ~ (2 pi f)^2 2 / gt_rate near 0 Hz
    k_res = np.interp(f, f_mc, k_res)
    # residual of the ground-truth poses around the spline: GT noise + motion the spline cannot follow
    nper_gt = min(int(WELCH_SECONDS * gt_rate), len(gt_res))
    f_gt, p_gt = signal.welch(gt_res - gt_res.mean(0), fs=gt_rate, nperseg=nper_gt, axis=0)
    p_gt = np.stack([np.interp(f, f_gt, p_gt[:, i]) for i in range(3)], 1)
    p_gt[f > gt_rate / 2 * (1 + 1e-6)] = np.nan  # above the GT's Nyquist frequency: nothing is known
    top = (f >= NOISE_BAND[0] * gt_rate / 2) & (f <= NOISE_BAND[1] * gt_rate / 2)
    # noise variance: the residual near the GT's Nyquist, divided by the fit's transfer there
    sigma2 = np.median(p_gt[top] / k_res[top, None], axis=0) if top.any() else np.zeros(3)
    lost_angle = np.clip(p_gt - sigma2[None] * k_res[:, None], 0.0, None)
    noise = sigma2[None] * k_rate[:, None]
    lost = np.where(np.isnan(lost_angle), np.inf, w2[:, None] * np.nan_to_num(lost_angle))
    # the sensor's own share of the residual; where the reconstruction error swamps it, at least
    # the floor the residual shows where it is lowest (a low quantile over frequency)
    hz = (f >= MIN_BAND_HZ) & (f < rate / 2)
    floor = np.quantile(p_imu[hz], FLOOR_QUANTILE, axis=0) if hz.any() else np.zeros(3)
    sensor = np.maximum(p_imu - noise - lost, floor[None])
    bad = np.any(lost > trust_ratio * sensor, axis=1) & (f >= MIN_BAND_HZ)
    if bad.any():
        k = int(np.argmax(bad))
        f_max = float(max(f[k - 1] if k > 0 else f[k], MIN_BAND_HZ))
        limited = "ground-truth Nyquist" if np.isinf(lost[k]).any() else "smoothed-away motion"
    else:
        f_max, limited = rate / 2, "none"
    over = np.any(noise + lost > sensor, axis=1) & (f > 0)
    f_equal = float(f[int(np.argmax(over))]) if over.any() else float("inf")
    negligible = bool(np.all(noise + lost <= NEGLIGIBLE * np.maximum(p_imu, 1e-300)))
    return ReconstructionBand(
        fc.name, f_max, rate, gt_rate, h, np.sqrt(sigma2), f, k_rate_w2, lost_angle, p_imu, limited, f_equal, negligible
    )


def sensor_floor(bands: list[ReconstructionBand], share: float = 0.1, corner_hz: float | None = None) -> np.ndarray:
    """(3,) one-sided PSD of the sensor's noise floor: the median of the measured residual's PSD
    over the frequencies (>= MIN_BAND_HZ) where the estimated reconstruction error is below `share`
    of it, pooled over sequences: inside the compared band if there are enough such frequencies
    there (the level the comparison needs), else anywhere (where the spline rejects the ground
    truth's noise); where there are none at all, its FLOOR_QUANTILE quantile.

    `corner_hz`: the floor is shaped by a sensor low-pass of this corner (`SensorBandwidth.floor_shape`);
    the PSD is divided by that shape first, so the result is the floor's level at 0 Hz, the level a
    shaped spectrum (`spectral.Spectra.shaped`) is compared with. Read flat, a floor that droops
    towards Nyquist gives its level in mid-band instead (0.58 of it for a 40 Hz corner at 200 Hz),
    and a band-limited vibration then takes up the difference."""
    out = np.zeros(3)
    for a in range(3):
        inside, anywhere, low = [], [], []
        for b in bands:
            f, p, clean = _floor_bins(b, a, share)
            if corner_hz is not None:
                p = p / SensorBandwidth.floor_shape(f, corner_hz, b.rate_hz)
            inside.append(p[clean & (f <= b.f_max_hz)])
            anywhere.append(p[clean])
            low.append(p)
        v_in, v_any = np.concatenate(inside), np.concatenate(anywhere)
        if len(v_in) >= 10:
            out[a] = np.median(v_in)
        elif len(v_any) >= 10:
            out[a] = np.median(v_any)
        else:
            out[a] = np.quantile(np.concatenate(low), FLOOR_QUANTILE)
    return out


def floor_read_in_band(bands: list[ReconstructionBand], share: float = 0.1) -> bool:
    """Whether `sensor_floor` reads the floor inside the compared band on every axis (enough frequencies there
    where the reconstruction error is below `share` of the residual): then the floor's shape is visible there too."""
    return all(
        sum(int((clean & (f <= b.f_max_hz)).sum()) for b in bands for f, _, clean in [_floor_bins(b, a, share)]) >= 10
        for a in range(3)
    )


def floor_through_corner(bands: list[ReconstructionBand], corner_hz: float | None) -> np.ndarray | None:
    """The sensor floor read through a low-pass of `corner_hz` (`sensor_floor`; None: flat) where it is read inside
    the compared band (`floor_read_in_band`), else None: outside the band its shape says nothing of the band's."""
    return sensor_floor(bands, corner_hz=corner_hz) if floor_read_in_band(bands) else None


def _floor_bins(b: ReconstructionBand, axis: int, share: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(f, residual PSD, clean) on the Welch bins in [MIN_BAND_HZ, Nyquist) of one axis; clean: the estimated
    reconstruction error is below `share` of the residual there."""
    ok = (b.f_hz >= MIN_BAND_HZ) & (b.f_hz < b.rate_hz / 2)
    p = b.residual_psd[ok, axis]
    return b.f_hz[ok], p, b.error_psd(b.f_hz[ok])[:, axis] < share * p


def band_bins(n: int, rate_hz: float, f_max_hz: float | None) -> np.ndarray:
    """Frequencies of the Fourier bins of an n-sample record that `band_rows` keeps."""
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    if f_max_hz is None or f_max_hz >= rate_hz / 2:
        return f
    return f[: int(np.searchsorted(f, f_max_hz, side="right"))]


def band_rows(x: np.ndarray, rate_hz: float, f_max_hz: float | None, force: bool = False) -> np.ndarray:
    """Rows of x (N, ...) restricted to the band [0, f_max]: real parts of its Fourier coefficients
    there, then their imaginary parts (the mean's left out), scaled so that white noise of variance
    s^2 gives rows of variance s^2 (Parseval). The same linear map applies to the residual and to
    every regressor, so a regression on these rows is the regression of the band-limited signals,
    with one row per independent observation (the BIC's n). None or f_max >= rate/2: x unchanged
    (unless `force`: then the whole spectrum as Fourier rows)."""
    if not force and (f_max_hz is None or f_max_hz >= rate_hz / 2):
        return x
    n = len(x)
    m = len(band_bins(n, rate_hz, f_max_hz))
    X = fft_threads.rfft(x)[:m] * np.sqrt(2.0 / n)
    X[0] /= np.sqrt(2.0)  # the mean: one real observation
    nyq = n % 2 == 0 and m == n // 2 + 1
    if nyq:
        X[-1] /= np.sqrt(2.0)  # so is the Nyquist bin
    return np.concatenate([X.real, X[1 : m - 1 if nyq else m].imag], axis=0)


def edge_positions(mask: np.ndarray) -> np.ndarray:
    """Sample indices where a record of used samples `mask` (N,) starts or stops: 0 (where the
    Fourier transform wraps the record around) and every change of the mask."""
    m = np.asarray(mask, dtype=bool)
    return np.concatenate([[0], 1 + np.flatnonzero(m[1:] != m[:-1])])


def edge_rows(n: int, rate_hz: float, f_max_hz: float | None, positions: np.ndarray) -> np.ndarray:
    """(rows, q) `band_rows` of unit impulses at sample `positions` of an n-sample record.

    Why they matter: the reconstructed rate's error is the derivative of the spline's angle error,
    a blue process. Over an interval [a, b) its Fourier sum is the angle error's jump
    theta(b) e^{-i w b} - theta(a) e^{-i w a} plus i w times the angle error's transform; the
    jump is the same size in every bin (an impulse at the edge), so at low frequencies, where the
    error's own spectrum ~ f^2 is small and the rows weigh most, it dominates the rows. Every
    place where the compared record starts or stops (its ends, every gap of left-out samples) adds
    one such impulse of unknown size: nuisance columns, projected out of every fit (`design.fit_rows`).
    """
    f = band_bins(n, rate_hz, f_max_hz)
    m = len(f)
    k = np.arange(m)[:, None]
    X = np.exp(-2j * np.pi * k * np.asarray(positions)[None, :] / n) * np.sqrt(2.0 / n)
    X[0] /= np.sqrt(2.0)
    nyq = n % 2 == 0 and m == n // 2 + 1
    if nyq:
        X[-1] /= np.sqrt(2.0)
    return np.concatenate([X.real, X[1 : m - 1 if nyq else m].imag], axis=0)


def row_frequencies(n: int, rate_hz: float, f_max_hz: float | None) -> np.ndarray:
    """Frequency of each row of `band_rows` (real parts, then imaginary parts)."""
    f = band_bins(n, rate_hz, f_max_hz)
    nyq = n % 2 == 0 and len(f) == n // 2 + 1
    return np.concatenate([f, f[1 : len(f) - 1 if nyq else len(f)]])


def band_limit(x: np.ndarray, rate_hz: float, f_max_hz: float | None) -> np.ndarray:
    """x (N, ...) with everything above f_max removed (FFT, zero phase). None or >= rate/2: x."""
    if f_max_hz is None or f_max_hz >= rate_hz / 2:
        return x
    X = np.fft.rfft(x, axis=0)
    X[np.fft.rfftfreq(len(x), 1.0 / rate_hz) > f_max_hz] = 0.0
    return np.fft.irfft(X, len(x), axis=0)


def draw_error(fc: FitContext, rng: np.random.Generator) -> np.ndarray | None:
    """One draw (N, 3) of the reconstructed rate's error of sequence `fc`: Gaussian with the PSD
    kappa E(f) of its band (`fc.extra['band']`, level `fc.extra['nuisance_level']`), zero above
    the band's edge (it is not compared there). None: no error to draw (exact ground truth)."""
    b = fc.extra.get("band")
    kappa = fc.extra.get("nuisance_level")
    if b is None or b.exact or kappa is None:
        return None
    n = len(fc.t)
    f = np.fft.rfftfreq(n, 1.0 / fc.rate_hz)
    psd = np.where((f <= b.f_max_hz)[:, None], kappa * b.error_psd(f), 0.0)
    w = np.fft.rfft(rng.standard_normal((n, 3)), axis=0)
    return np.fft.irfft(w * np.sqrt(psd * fc.rate_hz / 2), n, axis=0)
