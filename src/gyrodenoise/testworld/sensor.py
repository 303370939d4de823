"""The test world's IMU: hidden effects in continuous time at a high internal rate, a sensor bandwidth,
sampling at the output rate, quantisation and time stamps.

Gyro model on the internal grid (body frame, SI):
    y(t) = M w(t) + G f(t) + N(w(t)) + b + b_rw(t) + b_f(t) + v(t) + n(t),   then clipped at +-saturation,
with M = I + scale factor + misalignment, G the g-sensitivity, N the quadratic non-linearity, b_rw a
Wiener process, b_f a flicker (1/f) bias (`flicker_bias`), v the vibration and n white noise of the given
density. The bandwidth then turns y(t)
into samples:
  - "integrate": each sample is the mean of y over its period (midpoint rule on the internal grid;
    response sin(pi f T) / (pi f T)), window centred on the sample time (no delay);
  - "integrate-trailing": the same over the period ending at the sample time (delay T/2);
  - "butterN:FHz" / "besselN:FHz": a causal N-pole low-pass at the internal rate, then decimation
    (a datasheet-like anti-alias filter; its group delay is real and recorded in truth.json).
The output is quantised last. A time offset is a stamp error: the sample taken at t is stamped t + delta.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy import signal

from gyrodenoise.testworld.motion import MotionSource
from gyrodenoise.testworld.spec import Effects

_IIR = re.compile(r"^(butter|bessel)(\d+):(\d+(?:\.\d*)?)\s*Hz$")


@dataclass(frozen=True)
class Bandwidth:
    """How the sensor turns the continuous signal into samples. Parse with `Bandwidth.parse`."""

    kind: str  # "integrate" | "butter" | "bessel"
    window: str = "centred"  # integrate: "centred" | "trailing"
    order: int = 2
    corner_hz: float = 0.0

    @classmethod
    def parse(cls, text: str) -> Bandwidth:
        text = text.strip()
        if text == "integrate":
            return cls("integrate")
        if text == "integrate-trailing":
            return cls("integrate", window="trailing")
        m = _IIR.match(text)
        if m and int(m.group(2)) >= 1 and float(m.group(3)) > 0:
            return cls(m.group(1), order=int(m.group(2)), corner_hz=float(m.group(3)))
        raise ValueError(
            f"bandwidth {text!r}: expected 'integrate', 'integrate-trailing', 'butterN:FHz' or 'besselN:FHz' "
            "(e.g. bessel2:60Hz)"
        )

    def sos(self, fs: float) -> np.ndarray:
        if self.kind == "butter":
            return signal.butter(self.order, self.corner_hz, fs=fs, output="sos")
        # norm="mag": -3 dB at the corner, as a datasheet states it
        return signal.bessel(self.order, self.corner_hz, fs=fs, output="sos", norm="mag")

    def start_up_s(self, rate_hz: float) -> float:
        """Motion a filter needs before the first sample (its start-up, run on the internal grid); 0 for the
        integrating sensor, whose window fits in the period before the first sample."""
        period = 1.0 / rate_hz
        return 0.0 if self.kind == "integrate" else np.ceil(0.5 / period) * period

    def check(self, rate_hz: float, internal_hz: float) -> None:
        if self.kind != "integrate" and not self.corner_hz < internal_hz / 4:
            raise ValueError(f"bandwidth corner {self.corner_hz} Hz too high for the internal rate {internal_hz} Hz")

    def response(self, f: np.ndarray, rate_hz: float, internal_hz: float) -> np.ndarray:
        """|H(f)| of the sensor (before sampling), as realised on the internal grid."""
        f = np.asarray(f, dtype=np.float64)
        if self.kind == "integrate":
            m = int(round(internal_hz / rate_hz))
            x = np.pi * f / internal_hz  # mean of m samples: Dirichlet kernel, -> sinc(f T) for large m
            with np.errstate(invalid="ignore", divide="ignore"):
                return np.where(f == 0, 1.0, np.abs(np.sin(m * x) / (m * np.sin(x))))
        _, h = signal.freqz_sos(self.sos(internal_hz), worN=f, fs=internal_hz)
        return np.abs(h)

    def delay_s(self, rate_hz: float, internal_hz: float) -> float:
        """Group delay at low frequency: how late the samples are w.r.t. their sample times."""
        if self.kind == "integrate":
            return 0.0 if self.window == "centred" else 0.5 / rate_hz
        b, a = signal.sos2tf(self.sos(internal_hz))
        _, gd = signal.group_delay((b, a), w=[0.1], fs=internal_hz)
        return float(gd[0]) / internal_hz

    def describe(self, rate_hz: float, internal_hz: float) -> dict:
        freqs = [1.0, 5.0, 10.0, 20.0, 30.0, 50.0, 80.0, 100.0]
        gains = self.response(np.array(freqs), rate_hz, internal_hz).tolist()
        return {
            "kind": self.kind if self.kind != "integrate" else f"integrate-{self.window}",
            "order": self.order if self.kind != "integrate" else None,
            "corner_hz": self.corner_hz if self.kind != "integrate" else None,
            "internal_rate_hz": internal_hz,
            "group_delay_s": self.delay_s(rate_hz, internal_hz),
            "gain_at_hz": {f"{f:g}": g for f, g in zip(freqs, gains, strict=True)},
        }


@dataclass
class ImuSamples:
    t: np.ndarray  # (N,) true sample times, s (motion time)
    stamp_ns: np.ndarray  # (N,) written time stamps, int64 ns
    gyro: np.ndarray  # (N, 3) rad/s
    acc: np.ndarray  # (N, 3) m/s^2
    omega_true: np.ndarray  # (N, 3) true body rate at the sample times (instantaneous)
    info: dict


@dataclass(frozen=True)
class AccelModel:
    """The accelerometer is not under test: specific force + constant bias + white noise."""

    noise_density: float = 2.0e-3  # m/s^2/sqrt(Hz), ADIS16448-like
    bias: tuple[float, float, float] = (0.05, -0.08, 0.1)  # m/s^2


def simulate_imu(
    motion: MotionSource,
    effects: Effects,
    t_first: float,
    n: int,
    t0_ns: int,
    rng: dict[str, np.random.Generator],
    rate_hz: float = 200.0,
    bandwidth: Bandwidth | None = None,
    oversample: int = 20,
    stamp_jitter_s: float = 0.0,
    accel: AccelModel | None = None,
) -> ImuSamples:
    """`n` samples at `rate_hz` from motion time `t_first`. Stamps are t0_ns + the sample time in ns.

    `rng` holds one generator per random process ("noise", "walk", "vibration", "acc", "stamps"), so
    switching one effect on does not change the others' realisations."""
    bandwidth = bandwidth or Bandwidth.parse("integrate")
    accel = accel or AccelModel()
    period_ns = int(round(1e9 / rate_hz))
    T = period_ns * 1e-9
    fs = oversample / T
    bandwidth.check(rate_hz, fs)
    first_ns = int(round(t_first * 1e9))
    t = (first_ns + np.arange(n, dtype=np.int64) * period_ns) * 1e-9  # sample times, exact ns

    # internal grid: M points per period; integrate: the midpoints of the M sub-intervals of each window
    if bandwidth.kind == "integrate":
        start = t[0] - (T / 2 if bandwidth.window == "centred" else T) + 0.5 / fs
        warm = 0
    else:
        warm = int(round(bandwidth.start_up_s(rate_hz) / T)) * oversample  # filter start-up before the first sample
        start = t[0] - warm / fs
    grid = start + np.arange(warm + n * oversample) / fs
    kin = motion.evaluate(grid)
    y = _gyro_continuous(kin.omega, kin.specific_force, grid, effects, rng, fs)
    a = (
        kin.specific_force
        + np.asarray(accel.bias)
        + accel.noise_density * np.sqrt(fs) * rng["acc"].normal(size=grid.shape + (3,))
    )
    gyro, acc = _sample(y, bandwidth, oversample, warm, fs), _sample(a, bandwidth, oversample, warm, fs)
    q = float(effects.get("quantization"))
    if q > 0:
        gyro = q * np.round(gyro / q)

    delta = float(effects.get("time_offset"))
    stamp = t0_ns + first_ns + np.arange(n, dtype=np.int64) * period_ns + int(round(delta * 1e9))
    if stamp_jitter_s > 0:
        jitter = np.clip(rng["stamps"].normal(0.0, stamp_jitter_s, n), -0.4 * T, 0.4 * T)
        stamp = stamp + np.round(jitter * 1e9).astype(np.int64)
    return ImuSamples(
        t=t,
        stamp_ns=stamp,
        gyro=gyro,
        acc=acc,
        omega_true=motion.evaluate(t).omega,
        info={
            "rate_hz": rate_hz,
            "period_ns": period_ns,
            "bandwidth": bandwidth.describe(rate_hz, fs),
            "stamp_jitter_s": stamp_jitter_s,
            "accelerometer": {"noise_density_m_s2_sqrt_hz": accel.noise_density, "bias_m_s2": list(accel.bias)},
        },
    )


def _gyro_continuous(
    omega: np.ndarray,
    f: np.ndarray,
    t: np.ndarray,
    effects: Effects,
    rng: dict[str, np.random.Generator],
    fs: float,
) -> np.ndarray:
    y = omega @ effects.sensor_matrix().T + f @ effects.g_matrix().T
    k = effects.nonlinearity_k()
    if effects.has("nonlinearity"):
        y += k * (omega * np.abs(omega) if effects.get("nonlinearity", "shape") == "odd" else omega**2)
    y += effects.get("bias")
    walk = np.asarray(effects.get("bias_random_walk"))
    if (walk > 0).any():
        y += np.cumsum(walk * np.sqrt(1.0 / fs) * rng["walk"].normal(size=y.shape), axis=0)
    if effects.has("bias_instability"):
        floor = np.asarray(effects.get("bias_instability"))
        y += flicker_bias(len(t), fs, floor, float(effects.get("bias_instability", "tau_max")), rng["flicker"])
    if effects.has("vibration"):
        y += band_noise(
            len(t),
            fs,
            float(effects.get("vibration", "center")),
            float(effects.get("vibration", "width")),
            np.asarray(effects.get("vibration", "level")),
            rng["vibration"],
        )
    white = np.asarray(effects.get("white_noise"))
    if (white > 0).any():
        y += white * np.sqrt(fs) * rng["noise"].normal(size=y.shape)  # density -> per-sample std at fs
    if effects.has("saturation"):
        lim = float(effects.get("saturation"))
        y = np.clip(y, -lim, lim)
    return y


FLICKER_GRID_HZ = 20.0  # the flicker is drawn on this grid and interpolated: above it, white noise swamps it


def flicker_bias(n: int, fs: float, floor: np.ndarray, tau_max: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) flicker bias on a grid of rate `fs` whose Allan deviation is flat at `floor` (rad/s per axis).

    Frequency-domain synthesis: one-sided PSD h / f with h = floor^2 / (2 ln 2) (the Allan variance of a 1/f
    process is 2 ln 2 h at every cluster time), held flat at h / f_lo below f_lo = 1 / tau_max so the process is
    stationary (the floor falls off for cluster times beyond ~tau_max / 3). Drawn on a coarse grid over a record of at
    least 8 tau_max, so that the slow components are those of a long run, a random stretch of it kept and
    interpolated linearly onto the output grid."""
    if not tau_max > 0:
        raise ValueError(f"bias_instability.tau_max = {tau_max:g} s must be positive")
    grid_hz = min(FLICKER_GRID_HZ, fs)
    need = int(np.ceil(n / fs * grid_hz)) + 2
    m = max(need, int(np.ceil(8 * tau_max * grid_hz)))
    f = np.fft.rfftfreq(m, 1.0 / grid_hz)
    h = np.asarray(floor, dtype=np.float64) ** 2 / (2 * np.log(2))
    psd = h[None, :] / np.maximum(f, 1.0 / tau_max)[:, None]
    psd[0] = 0.0  # zero mean: a constant is the turn-on bias's part
    # unit white noise has a one-sided PSD of 2 / grid_hz: the gain turns it into psd
    x = np.fft.irfft(np.fft.rfft(rng.normal(size=(m, 3)), axis=0) * np.sqrt(psd * grid_hz / 2), m, axis=0)
    start = int(rng.integers(0, m - need + 1))
    coarse_t = (start + np.arange(need)) / grid_hz
    t = start / grid_hz + np.arange(n) / fs
    return np.stack([np.interp(t, coarse_t, x[start : start + need, i]) for i in range(3)], axis=1)


def band_noise(
    n: int, fs: float, center: float, width: float, level: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """(n, 3) vibration of RMS `level` per axis. width 0: a sinusoid at `center` with random phases.

    Otherwise Gaussian noise shaped in the frequency domain: flat power over |f - center| <= 0.4 width,
    cos^2 tapers to zero at 0.6 width, so the half-power points are center +- width/2 and the noise
    bandwidth is exactly `width`. Scaled to the exact RMS of this realisation."""
    if not 0 < center < fs / 2:
        raise ValueError(f"vibration centre {center} Hz must lie in (0, {fs / 2}) Hz, the internal Nyquist band")
    t = np.arange(n) / fs
    if width <= 0:
        phase = rng.uniform(0, 2 * np.pi, 3)
        return np.sqrt(2) * level * np.sin(2 * np.pi * center * t[:, None] + phase)
    spec = np.fft.rfft(rng.normal(size=(n, 3)), axis=0)
    f = np.fft.rfftfreq(n, 1 / fs)
    x = np.clip((np.abs(f - center) - 0.4 * width) / (0.2 * width), 0.0, 1.0)
    power = np.cos(np.pi / 2 * x) ** 2
    power[f <= 0] = 0.0
    v = np.fft.irfft(spec * np.sqrt(power)[:, None], n, axis=0)
    return v / v.std(0) * level


def _sample(y: np.ndarray, bw: Bandwidth, m: int, warm: int, fs: float) -> np.ndarray:
    if bw.kind == "integrate":
        return y.reshape(-1, m, y.shape[1]).mean(1)
    sos = bw.sos(fs)
    zi = signal.sosfilt_zi(sos)[:, :, None] * y[0][None, None, :]  # start in steady state at the first value
    z, _ = signal.sosfilt(sos, y, axis=0, zi=zi)
    return z[warm::m]
