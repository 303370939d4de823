"""The gyro error-effect library: one class per named physical effect.

Each effect has
- parameters in SI (rad/s, s, rad, dimensionless) and a conversion to datasheet units
  (`DATASHEET`: name -> (unit, factor), datasheet value = factor x SI value);
- a prior range of plausible magnitudes (`PRIOR`, SI), used to judge identifiability;
- `apply(sig, rng)`: the effect in continuous time, applied at the simulator's internal rate;
- the detector side: `columns(fc)` (the effect's regressors: residual contribution per unit
  coefficient, shape (N, 3, k)), `prepare(...)` (search of its nonlinear parameter, e.g. a frequency)
  and `params_from_fit(...)` (coefficients -> parameters with standard errors).

`EFFECTS` is the discrepancy workflow's vocabulary; `SIM_EFFECTS` adds the effects that are only simulated (bias
instability). The accelerometer's effects are in `sim.accel`.

Residual convention: r = measured gyro - true body rate. Stages give the order of application:
0 inputs (time offset), 1 sensor response to the true inputs, 2 additive errors, 3 front-end limits,
4 output (after decimation to the IMU rate).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from scipy import signal

from gyrodenoise import fft_threads
from gyrodenoise.allan import fit_allan_noise, root_with_se
from gyrodenoise.sim import flicker
from gyrodenoise.sim.array_memo import ArrayMemo, digest
from gyrodenoise.sim.context import FitContext, SignalContext

# the discrepancy workflow low-passes the same rate at the same corner, and reads the floor shape at the same
# frequencies, many times over (`array_memo`)
_MEMO = ArrayMemo(96 << 20)

DEG = np.pi / 180.0
G0 = 9.80665
_MISALIGN_PAIRS = [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]


# the discrepancy workflow's vocabulary: every effect it can detect and fit
EFFECTS: dict[str, type[Effect]] = {}
# every gyro effect the simulator takes: the vocabulary and the effects only simulated (no detector: a workflow that
# was asked for one would silently leave it out, so it refuses them as unknown instead)
SIM_EFFECTS: dict[str, type[Effect]] = {}


def register(cls: type[Effect]) -> type[Effect]:
    EFFECTS[cls.name] = cls
    SIM_EFFECTS[cls.name] = cls
    return cls


def register_simulated_only(cls: type[Effect]) -> type[Effect]:
    SIM_EFFECTS[cls.name] = cls
    return cls


class Effect:
    name: ClassVar[str] = ""
    stage: ClassVar[int] = 2
    per_sequence: ClassVar[bool] = False  # coefficients fitted separately for each sequence
    stochastic: ClassVar[bool] = False  # no regressors; parameters from the residual's statistics
    DATASHEET: ClassVar[dict[str, tuple[str, float]]] = {}
    PRIOR: ClassVar[tuple[float, float]] = (0.0, np.inf)  # plausible |parameter| range, SI
    DEFAULTS: ClassVar[dict[str, Any]] = {}
    # magnitude (SI, per coefficient) at which identifiability is stated (`discrepancy.identifiability`);
    # None: no regression coefficients to state it for
    REFERENCE: ClassVar[float | None] = None
    # two entries of this effect in one error-model list: what they would do, which `effects_from_config` refuses as
    # not what a user means; None where they act as one entry with their parameters added (or, vibration, as the
    # several lines they are by design)
    REPEATED: ClassVar[str | None] = "the second acts on the output of the first"

    def __init__(self, **params: Any) -> None:
        unknown = set(params) - set(self.DEFAULTS)
        if unknown:
            raise ValueError(
                f"effect {self.name!r}: unknown parameter(s) {sorted(unknown)}; expected {sorted(self.DEFAULTS)}"
            )
        self.params = {k: np.asarray(params.get(k, v), dtype=np.float64) for k, v in self.DEFAULTS.items()}

    # ----------------------------------------------------------------- units
    @classmethod
    def from_datasheet(cls, **values: Any) -> Effect:
        si = {}
        for k, v in values.items():
            unit_factor = cls.DATASHEET.get(k)
            si[k] = np.asarray(v, dtype=np.float64) / (unit_factor[1] if unit_factor else 1.0)
        return cls(**si)

    def datasheet(self) -> dict[str, dict]:
        out = {}
        for k, v in self.params.items():
            unit, factor = self.DATASHEET.get(k, ("SI", 1.0))
            out[k] = {"value": (v * factor).tolist(), "unit": unit}
        return out

    def to_dict(self) -> dict:
        return {"name": self.name, "params": {k: v.tolist() for k, v in self.params.items()}}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{k}={v.tolist()}' for k, v in self.params.items())})"

    # ----------------------------------------------------------------- simulation
    def apply(self, sig: SignalContext, y: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        raise NotImplementedError

    # ----------------------------------------------------------------- detection
    def prepare(self, fcs: list[FitContext], residuals: list[np.ndarray]) -> None:
        """Set the nonlinear parameters (frequency, time constant, limit) from the current residuals."""

    def columns(self, fc: FitContext) -> np.ndarray:
        """(N, 3, k) contribution to the residual per unit coefficient."""
        raise NotImplementedError

    def time_only_key(self) -> tuple | None:
        """Where the columns depend on the sample times alone (not on the motion): what else they depend on, as a
        key (designs over the same samples then share their fit rows: `discrepancy.time_only_rows`). None: they
        follow the motion."""
        return None

    def params_from_fit(self, coef: np.ndarray, se: np.ndarray) -> tuple[dict, dict]:
        """Coefficients (k,) or (n_seq, k) with standard errors -> (params SI, standard errors SI)."""
        raise NotImplementedError

    def magnitude(self) -> float:
        """Size of the main parameter, compared with PRIOR."""
        v = next(iter(self.params.values()))
        return float(np.max(np.abs(v)))

    def at_search_edge(self) -> str | None:
        """A parameter `prepare` searched that ended at an end of its search (e.g. "tau 2 s, the shortest searched"):
        the best value may lie beyond it. None: no searched parameter, or not at an end."""
        return None


def misalignment_matrix(angles: np.ndarray) -> np.ndarray:
    """M (3x3, zero diagonal) of the six angles [xy, xz, yx, yz, zx, zy] (rad): row i, column j is M[i, j]."""
    M = np.zeros((3, 3))
    for (i, j), a in zip(_MISALIGN_PAIRS, np.asarray(angles, dtype=np.float64), strict=True):
        M[i, j] = a
    return M


def _axis_columns(values: np.ndarray) -> np.ndarray:
    """(N, 3) per-axis regressor -> (N, 3, 3) with column i acting on axis i only."""
    n = len(values)
    c = np.zeros((n, 3, 3))
    for i in range(3):
        c[:, i, i] = values[:, i]
    return c


def _mean_over_sequences(coef: np.ndarray, se: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    coef, se = np.atleast_2d(coef), np.atleast_2d(se)
    return coef.mean(0), np.sqrt((se**2).sum(0)) / len(coef)


# ===================================================================== deterministic effects


@register
class Bias(Effect):
    """Constant bias b: y = w + b (per sequence: turn-on bias changes between power cycles)."""

    name = "bias"
    REPEATED = None  # biases add
    per_sequence = True
    DATASHEET = {"bias": ("deg/s", 1 / DEG)}
    PRIOR = (1e-4, 0.2)
    DEFAULTS = {"bias": np.zeros(3)}

    def apply(self, sig, y, rng):
        return y + self.params["bias"]

    def columns(self, fc):
        return _axis_columns(np.ones((len(fc.t), 3)))

    def time_only_key(self):
        return ()

    def params_from_fit(self, coef, se):
        coef = np.atleast_2d(coef)
        m, s = _mean_over_sequences(coef, se)
        return {"bias": m, "bias_per_sequence": coef}, {"bias": s}


class _RateShapeEffect(Effect):
    """An error c_i g(w_i) per axis, one coefficient per axis (`PARAM`), g = `shape` of the true rate."""

    stage = 1
    PARAM: ClassVar[str] = ""
    REPEATED = None  # each responds to the true rate: the coefficients add

    @staticmethod
    def shape(omega: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def apply(self, sig, y, rng):
        return y + self.params[self.PARAM] * self.shape(sig.omega)

    def columns(self, fc):
        return _axis_columns(self.shape(fc.omega))

    def params_from_fit(self, coef, se):
        return {self.PARAM: coef}, {self.PARAM: se}


@register
class ScaleFactor(_RateShapeEffect):
    """Scale-factor error s per axis: y_i = (1 + s_i) w_i."""

    name = "scale_factor"
    PARAM = "scale"
    DATASHEET = {"scale": ("ppm", 1e6)}
    PRIOR = (1e-4, 0.05)
    DEFAULTS = {"scale": np.zeros(3)}
    REFERENCE = 1e-3  # 1000 ppm

    @staticmethod
    def shape(omega: np.ndarray) -> np.ndarray:
        return omega


@register
class Misalignment(Effect):
    """Axis misalignment: y = (I + M) w with M off-diagonal; `angles` = M[xy, xz, yx, yz, zx, zy]."""

    name = "misalignment"
    REPEATED = None  # each responds to the true rate: the angles add
    stage = 1
    DATASHEET = {"angles": ("mrad", 1e3)}
    PRIOR = (1e-4, 0.05)
    DEFAULTS = {"angles": np.zeros(6)}
    REFERENCE = 1e-3  # 1 mrad

    def matrix(self) -> np.ndarray:
        return misalignment_matrix(self.params["angles"])

    def apply(self, sig, y, rng):
        return y + sig.omega @ self.matrix().T

    def columns(self, fc):
        c = np.zeros((len(fc.t), 3, 6))
        for k, (i, j) in enumerate(_MISALIGN_PAIRS):
            c[:, i, k] = fc.omega[:, j]
        return c

    def params_from_fit(self, coef, se):
        return {"angles": coef}, {"angles": se}


@register
class GSensitivity(Effect):
    """Gyro response to specific force: y = w + G f (G 3x3, row i = axis i)."""

    name = "g_sensitivity"
    REPEATED = None  # each responds to the true specific force: the matrices add
    stage = 1
    DATASHEET = {"matrix": ("deg/s/g", G0 / DEG)}
    PRIOR = (1e-5, 2e-3)
    DEFAULTS = {"matrix": np.zeros((3, 3))}
    REFERENCE = 0.5 * DEG / G0  # 0.5 deg/s/g

    def apply(self, sig, y, rng):
        return y + sig.f @ self.params["matrix"].T

    def columns(self, fc):
        c = np.zeros((len(fc.t), 3, 9))
        for i in range(3):
            c[:, i, 3 * i : 3 * i + 3] = fc.f
        return c

    def params_from_fit(self, coef, se):
        return {"matrix": coef.reshape(3, 3)}, {"matrix": se.reshape(3, 3)}


@register
class TimeOffset(Effect):
    """The IMU sample stamped t holds the motion of t - delta (delta > 0: IMU stamps late)."""

    name = "time_offset"
    REPEATED = "the second replaces the first (each reads the motion at t - delta): offsets do not add up"
    stage = 0
    DATASHEET = {"delta": ("ms", 1e3)}
    PRIOR = (2e-4, 0.05)
    DEFAULTS = {"delta": 0.0}
    REFERENCE = 1e-3  # 1 ms
    delta_ref: float = 0.0  # detector: shift at which the secant regressor is taken

    def apply(self, sig, y, rng):
        d = float(self.params["delta"])
        if d == 0.0:
            return y
        if sig.kinematics_at is None:  # no trajectory at hand: first-order shift
            return y - d * sig.alpha
        kin = sig.kinematics_at(sig.t - d)
        sig.omega, sig.alpha, sig.f = kin.omega, kin.alpha, kin.specific_force
        return kin.omega.copy()

    def prepare(self, fcs, residuals):
        # first-order estimate; the regressor is then the secant through w(t - delta_ref), exact at
        # delta = delta_ref, which removes the second-order term a tangent regressor leaves behind
        num = sum(float((-fc.alpha * (r - r.mean(0))).sum()) for fc, r in zip(fcs, residuals, strict=True))
        den = sum(float((fc.alpha**2).sum()) for fc in fcs)
        d = num / den if den > 0 else 0.0
        self.delta_ref = float(np.clip(d, -self.PRIOR[1], self.PRIOR[1]))

    def columns(self, fc):
        kin_at = fc.extra.get("kinematics_at")
        d = self.delta_ref
        if kin_at is None or abs(d) < 1e-6:
            return -fc.alpha[:, :, None]  # w(t - d) = w(t) - d alpha(t) + O(d^2)
        return ((kin_at(fc.t - d).omega - fc.omega) / d)[:, :, None]

    def params_from_fit(self, coef, se):
        return {"delta": np.asarray(coef[0])}, {"delta": np.asarray(se[0])}


@register
class Nonlinearity(_RateShapeEffect):
    """Quadratic scale-factor nonlinearity: y_i = w_i + k_i w_i |w_i|."""

    name = "nonlinearity"
    PARAM = "k"
    # k |w| is a relative error: ppm per deg/s of rate
    DATASHEET = {"k": ("ppm/(deg/s)", 1e6 * DEG)}
    PRIOR = (1e-5, 0.02)
    DEFAULTS = {"k": np.zeros(3)}
    REFERENCE = 5e-4  # 8.7 ppm/(deg/s)

    @staticmethod
    def shape(omega: np.ndarray) -> np.ndarray:
        return omega * np.abs(omega)


@register
class NonlinearityEven(Nonlinearity):
    """Even quadratic nonlinearity: y_i = w_i + k_i w_i^2 (a rectifier, like `scale_asymmetry`, but growing with
    the rate's square; `nonlinearity` is the odd k w |w|, with the same units and ranges)."""

    name = "nonlinearity_even"

    @staticmethod
    def shape(omega: np.ndarray) -> np.ndarray:
        return omega**2


@register
class ScaleAsymmetry(_RateShapeEffect):
    """Scale factor that differs between positive and negative rates: y_i = w_i + a_i |w_i|, i.e. a scale-factor
    error of +a_i on positive rates and -a_i on negative ones (a symmetric part is `scale_factor`). Even in the
    rate, so a rectifier: on a vehicle that turns both ways it adds a motion-dependent bias."""

    name = "scale_asymmetry"
    PARAM = "asymmetry"
    DATASHEET = {"asymmetry": ("ppm", 1e6)}
    PRIOR = (1e-4, 0.05)
    DEFAULTS = {"asymmetry": np.zeros(3)}
    REFERENCE = 1e-3  # 1000 ppm

    @staticmethod
    def shape(omega: np.ndarray) -> np.ndarray:
        return np.abs(omega)


@register
class WarmupBias(Effect):
    """Bias settling after power-on: y = w + A exp(-t / tau), t from the sequence start."""

    name = "warmup_bias"
    REPEATED = "two decays, not one with the amplitudes added"
    DATASHEET = {"amplitude": ("deg/s", 1 / DEG), "tau": ("s", 1.0)}
    PRIOR = (1e-4, 0.2)
    DEFAULTS = {"amplitude": np.zeros(3), "tau": 30.0}
    REFERENCE = 5e-3  # 0.29 deg/s
    TAU_GRID = np.geomspace(2.0, 300.0, 40)

    def apply(self, sig, y, rng):
        return y + self.params["amplitude"] * np.exp(-sig.t / float(self.params["tau"]))[:, None]

    def prepare(self, fcs, residuals):
        # the time constant that explains most of the residual's decay, refit per axis amplitude
        best, best_tau = -np.inf, float(self.params["tau"])
        for tau in self.TAU_GRID:
            gain = 0.0
            for fc, r in zip(fcs, residuals, strict=True):
                e = np.exp(-fc.t / tau)
                e = e - e.mean()  # a per-sequence bias is in every model
                gain += float(((e @ (r - r.mean(0))) ** 2).sum() / max(e @ e, 1e-12))
            if gain > best:
                best, best_tau = gain, float(tau)
        self.params["tau"] = np.asarray(best_tau)

    def columns(self, fc):
        return _axis_columns(np.repeat(np.exp(-fc.t / float(self.params["tau"]))[:, None], 3, 1))

    def at_search_edge(self) -> str | None:
        tau = float(self.params["tau"])
        for end, word in ((self.TAU_GRID[0], "shortest"), (self.TAU_GRID[-1], "longest")):
            if np.isclose(tau, end, rtol=1e-9):
                return f"tau {tau:g} s, the {word} searched"
        return None

    def params_from_fit(self, coef, se):
        return {"amplitude": coef, "tau": self.params["tau"]}, {"amplitude": se}


@register
class Vibration(Effect):
    """Vibration pick-up at `frequency_hz`: a sinusoid of amplitude A_i (random phase per sequence),
    or, with bandwidth_hz > 0, band-limited noise of RMS A_i / sqrt(2) around the frequency
    (Gaussian noise through a 4th-order Butterworth band-pass [f - bw/2, f + bw/2], forward and
    backward).

    Detector: the sinusoid is a regression effect (sin/cos columns at the strongest spectral line,
    phase per sequence). The band-limited variant is stochastic: no regressor can predict it, so it
    is detected and fitted in the frequency domain (`gyrodenoise.discrepancy.spectral`), with the
    power spectral density shape of `band_psd`. An instance with bandwidth_hz > 0 is `stochastic`.

    The amplitude is the line's as seen in the IMU output, which is what the detector fits and a spectrum of a
    recording shows. The simulator averages each output period of its finer internal grid (an anti-alias mean that
    attenuates a line at f by about sinc(f / rate)), so there the pick-up is applied larger by that mean's gain at
    the frequency (`output_gain`), and the output carries the amplitude given. A frequency at or above the output's
    Nyquist frequency, or a band reaching past it, is refused at every oversampling (`rate_problem`)."""

    name = "vibration"
    REPEATED = None  # several lines or bands (`sim_model` writes one per line of the gyro)
    per_sequence = True
    DATASHEET = {"frequency_hz": ("Hz", 1.0), "amplitude": ("deg/s", 1 / DEG), "bandwidth_hz": ("Hz", 1.0)}
    PRIOR = (1e-4, 0.5)
    DEFAULTS = {"frequency_hz": 30.0, "amplitude": np.zeros(3), "bandwidth_hz": 0.0}
    REFERENCE = 1e-3 / np.sqrt(2)  # amplitude 1e-3 rad/s (0.057 deg/s) as sin and cos parts
    BUTTER_ORDER = 4
    BAND_EDGE = 0.499  # x the rate: the band filter's top edge (a Butterworth design needs it under the Nyquist)

    @property
    def stochastic(self) -> bool:  # type: ignore[override]
        return float(self.params["bandwidth_hz"]) > 0

    def magnitude(self) -> float:
        return float(np.max(np.abs(self.params["amplitude"])))

    @classmethod
    def band_edges(cls, frequency_hz: float, bandwidth_hz: float, rate_hz: float) -> tuple[float, float]:
        lo, hi = frequency_hz - bandwidth_hz / 2, frequency_hz + bandwidth_hz / 2
        return max(lo, 1e-3), min(hi, cls.BAND_EDGE * rate_hz)

    @staticmethod
    def output_gain(frequency_hz: float, rate_hz: float, mean_of: int) -> float:
        """Gain at `frequency_hz` of the mean of `mean_of` consecutive samples at `rate_hz` (the simulator's
        output sample): |sin(pi f m / rate) / (m sin(pi f / rate))|, about sinc(f / output rate)."""
        if mean_of <= 1 or frequency_hz <= 0:
            return 1.0
        x = np.pi * frequency_hz / rate_hz
        return float(abs(np.sin(mean_of * x) / (mean_of * np.sin(x))))

    @classmethod
    def rate_problem(
        cls, frequency_hz: float, bandwidth_hz: float, rate_hz: float, oversampled: bool = True
    ) -> str | None:
        """Why this vibration cannot be simulated in an IMU output at `rate_hz` (None: it can), at every oversampling:
        a line at or above the Nyquist frequency cannot appear in the output, and a band reaching past it would fold
        back (oversampled) or be cut (not oversampled: the band filter runs at the output rate, its top edge at
        BAND_EDGE x the rate, where a band that starts above it has no pass band)."""
        f, bw, nyquist = float(frequency_hz), float(bandwidth_hz), rate_hz / 2
        if f >= nyquist:
            return (
                f"effect 'vibration': frequency_hz {f:g} is at or above the IMU's Nyquist frequency "
                f"({nyquist:g} Hz at {rate_hz:g} Hz): its amplitude is the line's in the IMU output, and no "
                "line above that frequency can appear there; give the frequency the line has in the recording"
            )
        if bw > 0 and f + bw / 2 > nyquist * (1 + 1e-9):  # a band fitted up to it: its edge, rounded
            return (
                f"effect 'vibration': bandwidth_hz {bw:g} around frequency_hz {f:g} reaches {f + bw / 2:g} Hz, "
                f"past the IMU's Nyquist frequency ({nyquist:g} Hz at {rate_hz:g} Hz), and would "
                f"{'alias into' if oversampled else 'be cut from'} the output; give bandwidth_hz at most "
                f"{2 * (nyquist - f):g} (the band within the Nyquist frequency), 0 (a line), or a higher rate_hz"
            )
        if bw > 0 and not oversampled and f - bw / 2 >= cls.BAND_EDGE * rate_hz:  # oversampled: no such edge
            return (
                f"effect 'vibration': the band of bandwidth_hz {bw:g} around frequency_hz {f:g} starts above "
                f"{cls.BAND_EDGE:g} x the IMU's rate ({cls.BAND_EDGE * rate_hz:g} Hz), the band filter's top edge: "
                "give bandwidth_hz 0 (a line) or a lower frequency_hz"
            )
        return None

    def apply(self, sig, y, rng):
        f, a, bw = float(self.params["frequency_hz"]), self.params["amplitude"], float(self.params["bandwidth_hz"])
        m = int(sig.output_mean_of)
        if problem := self.rate_problem(f, bw, sig.rate_hz / m, oversampled=m > 1):
            raise ValueError(problem)
        if m > 1:  # the output is the mean of m internal samples: apply the pick-up that leaves `a` in the output
            a = a / self.output_gain(f, sig.rate_hz, m)
        if bw <= 0:
            phase = rng.uniform(0, 2 * np.pi, 3)
            return y + a * np.sin(2 * np.pi * f * sig.t[:, None] + phase)
        lo, hi = self.band_edges(f, bw, sig.rate_hz)
        sos = signal.butter(self.BUTTER_ORDER, [lo, hi], btype="bandpass", fs=sig.rate_hz, output="sos")
        x = signal.sosfiltfilt(sos, rng.standard_normal((len(sig.t), 3)), axis=0)
        return y + x / x.std(0) * a / np.sqrt(2)

    @classmethod
    def band_psd(cls, f: np.ndarray, frequency_hz: float, bandwidth_hz: float, rate_hz: float) -> np.ndarray:
        """One-sided PSD shape (1/Hz, integral 1 over [0, rate/2]) of the band-limited variant:
        |H(f)|^4 of the analog Butterworth band-pass prototype with the edges of `apply` (|H|^2 per
        pass, two passes). Multiply by the band's variance A^2 / 2 for (rad/s)^2/Hz."""
        lo, hi = cls.band_edges(frequency_hz, bandwidth_hz, rate_hz)
        # normalise on a fine grid over the band's support (|x| < 8: gain < 1e-14), within [0, rate/2]
        b, q = hi - lo, lo * hi
        a, z = ((x * b + np.sqrt((x * b) ** 2 + 4 * q)) / 2 for x in (-8.0, 8.0))
        fine = np.linspace(max(a, 0.0), min(z, rate_hz / 2), 4097)
        norm = float(np.trapezoid(cls._band_gain(fine, lo, hi), fine))
        return cls._band_gain(np.asarray(f, dtype=np.float64), lo, hi) / max(norm, 1e-300)

    @classmethod
    def _band_gain(cls, f: np.ndarray, lo: float, hi: float) -> np.ndarray:
        with np.errstate(divide="ignore", over="ignore"):
            x = (f**2 - lo * hi) / (np.maximum(f, 1e-12) * (hi - lo))
            return 1.0 / (1.0 + x ** (2 * cls.BUTTER_ORDER)) ** 2

    def prepare(self, fcs, residuals):
        # strongest spectral line of the residuals (summed periodograms), refined by zero padding
        best_f, best_p = float(self.params["frequency_hz"]), -np.inf
        rate = fcs[0].rate_hz
        for fc, r in zip(fcs, residuals, strict=True):
            x = r - r.mean(0)
            n = len(x)
            nfft = 1 << int(np.ceil(np.log2(4 * n)))
            p = (np.abs(np.fft.rfft(x * np.hanning(n)[:, None], nfft, axis=0)) ** 2).sum(1)
            fr = np.fft.rfftfreq(nfft, 1.0 / rate)
            # only where the reconstructed true rate is trusted (`discrepancy.reconstruction`)
            hi = min(0.48 * rate, fc.extra.get("band_hz") or np.inf)
            ok = (fr > 0.5) & (fr < hi)
            if not ok.any():
                continue
            k = int(np.argmax(np.where(ok, p, -np.inf)))
            # peak relative to the median level: sequences vote by prominence
            prom = p[k] / np.median(p[ok])
            if prom > best_p:
                best_p, best_f = prom, float(fr[k])
        self.params["frequency_hz"] = np.asarray(best_f)

    def columns(self, fc):
        w = 2 * np.pi * float(self.params["frequency_hz"]) * fc.t
        c = np.zeros((len(fc.t), 3, 6))
        for i in range(3):
            c[:, i, i] = np.sin(w)
            c[:, i, 3 + i] = np.cos(w)
        return c

    def params_from_fit(self, coef, se):
        coef, se = np.atleast_2d(coef), np.atleast_2d(se)
        amp = np.sqrt(coef[:, :3] ** 2 + coef[:, 3:] ** 2)
        amp_se = np.sqrt((se[:, :3] ** 2 + se[:, 3:] ** 2) / 2)
        m, s = _mean_over_sequences(amp, amp_se)
        return {"frequency_hz": self.params["frequency_hz"], "amplitude": m, "bandwidth_hz": np.asarray(0.0)}, {
            "amplitude": s
        }


@register
class Saturation(Effect):
    """Measurement range: y = clip(y, -limit, limit) (front end, before the output filter).

    Detector: a plateau, i.e. several samples exactly at the largest reported magnitude while the
    true rate goes beyond it. Saturated samples carry no other information and leave the fits."""

    name = "saturation"
    REPEATED = "only the lower limit clips"
    stage = 3
    stochastic = True  # no regressor: detected by its plateau
    DATASHEET = {"limit": ("deg/s", 1 / DEG)}
    PRIOR = (0.5, 40.0)
    DEFAULTS = {"limit": 1e9}
    MIN_PLATEAU = 10

    def apply(self, sig, y, rng):
        lim = float(self.params["limit"])
        return np.clip(y, -lim, lim)

    def magnitude(self) -> float:
        return float(self.params["limit"])

    @classmethod
    def detect(cls, fcs: list[FitContext], sigma: np.ndarray) -> dict:
        """{'limit', 'plateau_samples', 'beyond_samples'}: samples at the largest reported
        magnitude, and samples whose true rate exceeds it by 5 noise stds."""
        lim = max(float(np.abs(fc.gyro).max()) for fc in fcs)
        tol = 1e-9 * max(lim, 1.0)
        plateau = sum(int((np.abs(fc.gyro) >= lim - tol).sum()) for fc in fcs)
        beyond = sum(int((np.abs(fc.omega) > lim + 5 * sigma).sum()) for fc in fcs)
        return {"limit": lim, "plateau_samples": plateau, "beyond_samples": beyond}


@register
class SensorBandwidth(Effect):
    """The sensor's own bandwidth: a first-order low-pass of corner `corner_hz` on the rate before
    it is sampled (front end, stage 3; the simulator then averages over the sample interval).

    It does two things a detector sees: it delays and attenuates the motion (at low frequencies a
    delay of 1 / (2 pi corner), i.e. what a time offset also does), and it shapes the noise floor
    (`floor_shape`: a flat floor droops towards the Nyquist frequency). Detection is spectral:
    the Whittle likelihood of the residual's spectrum with the shaped floor against the flat one
    (`gyrodenoise.discrepancy.spectral.fit_floor_shape`); the motion part is then `filter_rate`,
    with no free coefficient. corner_hz = inf: no filter."""

    name = "sensor_bandwidth"
    REPEATED = "two low-passes in series, not one corner"
    stage = 3
    stochastic = True
    DATASHEET = {"corner_hz": ("Hz", 1.0)}
    PRIOR = (5.0, 5000.0)
    DEFAULTS = {"corner_hz": np.inf}
    ALIASES = 8  # spectral images folded into [0, rate/2] by the sampling (floor_shape)

    def magnitude(self) -> float:
        return float(self.params["corner_hz"])

    @staticmethod
    def response(f: np.ndarray, corner_hz: float) -> np.ndarray:
        """The continuous low-pass's complex response at frequencies f (Hz)."""
        return 1.0 / (1.0 + 1j * np.asarray(f, dtype=np.float64) / corner_hz)

    @classmethod
    def filter_rate(cls, x: np.ndarray, corner_hz: float, rate_hz: float) -> np.ndarray:
        """x (N, ...) through the continuous low-pass: its response applied to the band-limited signal whose samples
        are x (in the Fourier domain; each end continued by odd reflection for ten time constants and more, and the
        ramp between the padded ends taken out and put back delayed, so the wrap-around adds no jump). A recursion
        discretised by first-order hold matches the phase but droops by sinc^2(f / rate) more, the linear
        interpolation's own response (12 % at 40 Hz of 200): beside a free delay, which takes the phase, a fitted
        corner read that droop and came out 15 % high (a blind trial with a low-pass and a time offset at once)."""
        if not np.isfinite(corner_hz):
            return x
        x = np.asarray(x, dtype=np.float64)
        key = digest(cls.__name__, x, float(corner_hz), float(rate_hz))
        return _MEMO.get(key, lambda: cls._filter_rate(x, float(corner_hz), float(rate_hz)))

    @classmethod
    def _filter_rate(cls, x: np.ndarray, corner_hz: float, rate_hz: float) -> np.ndarray:
        tau_samples = rate_hz / (2 * np.pi * corner_hz)
        pad = min(int(np.ceil(10.0 * tau_samples)) + 64, len(x) - 1)
        # odd reflection about each end: value and slope continue, so the band-limited signal has no kink there;
        # the ramp between the padded record's ends is taken out (the filter passes a ramp delayed by its time
        # constant), so the Fourier transform's wrap-around joins the ends without a jump
        head, tail = 2 * x[:1] - x[pad:0:-1], 2 * x[-1:] - x[-2 : -pad - 2 : -1]
        xp = np.concatenate([head, x, tail], axis=0)
        n = np.arange(len(xp), dtype=np.float64).reshape(-1, *([1] * (x.ndim - 1)))
        slope = (xp[-1:] - xp[:1]) / (len(xp) - 1)
        ramp = xp[:1] + slope * n
        h = cls.response(np.fft.rfftfreq(len(xp), 1.0 / rate_hz), float(corner_hz))
        y = fft_threads.irfft(fft_threads.rfft(xp - ramp) * h.reshape(-1, *([1] * (x.ndim - 1))), len(xp))
        y += ramp - slope * tau_samples
        return y[pad : pad + len(x)]

    def apply(self, sig, y, rng):
        return self.filter_rate(y, float(self.params["corner_hz"]), sig.rate_hz)

    @classmethod
    def floor_shape(cls, f: np.ndarray, corner_hz: float, rate_hz: float) -> np.ndarray:
        """PSD of white noise after the low-pass, the average over the sample interval and the
        sampling, relative to its level at 0 Hz: sum over images k of |G(f + k rate)|^2
        sinc^2((f + k rate) / rate). Flat (1) for corner_hz = inf."""
        f = np.asarray(f, dtype=np.float64)
        if not np.isfinite(corner_hz):
            return np.ones_like(f)
        # the images' frequencies and sinc^2 weights do not depend on the corner, which a fit varies: kept
        images = _MEMO.get(digest("floor_images", f, float(rate_hz), cls.ALIASES), lambda: cls._images(f, rate_hz))
        out = np.zeros_like(f)
        for fk, weight in images:
            out += weight / (1.0 + (fk / corner_hz) ** 2)
        return out

    @classmethod
    def _images(cls, f: np.ndarray, rate_hz: float) -> np.ndarray:
        """(2 ALIASES + 1, 2, ...) f + k rate and sinc^2((f + k rate) / rate), k = -ALIASES..ALIASES."""
        fks = [f + k * rate_hz for k in range(-cls.ALIASES, cls.ALIASES + 1)]
        return np.stack([np.stack([fk, np.sinc(fk / rate_hz) ** 2]) for fk in fks])


# ===================================================================== stochastic effects


@register
class WhiteNoise(Effect):
    """Rate white noise of density N (rad/s/sqrt(Hz)): per-sample std N sqrt(rate) at any rate."""

    name = "white_noise"
    REPEATED = "independent noises add in power, not in density"
    stochastic = True
    DATASHEET = {"density": ("deg/sqrt(h)", 60 / DEG)}  # angle random walk
    PRIOR = (1e-5, 1e-2)
    DEFAULTS = {"density": np.zeros(3)}

    def apply(self, sig, y, rng):
        return y + rng.standard_normal(y.shape) * self.params["density"] * np.sqrt(sig.rate_hz)

    def estimate(self, fcs: list[FitContext], residuals: list[np.ndarray]) -> tuple[dict, dict]:
        # first differences remove everything slow; white noise has var(diff) = 2 sigma^2
        d = np.concatenate([np.diff(r, axis=0) for r in residuals])
        sigma = d.std(0) / np.sqrt(2)
        n = len(d)
        dens = sigma / np.sqrt(fcs[0].rate_hz)
        return {"density": dens}, {"density": dens / np.sqrt(2 * n)}


@register
class BiasRandomWalk(Effect):
    """Rate random walk K (rad/s/sqrt(s) = rad/s^2/sqrt(Hz)): db/dt = K xi(t)."""

    name = "bias_random_walk"
    REPEATED = "independent walks add in power, not in density"
    stochastic = False  # detected with piecewise-linear bias columns; K from the Allan variance
    per_sequence = True
    DATASHEET = {"density": ("deg/h/sqrt(h)", 3600 * 60 / DEG)}
    PRIOR = (1e-6, 1e-2)
    DEFAULTS = {"density": np.zeros(3)}
    knot_spacing_s: float = 10.0

    def apply(self, sig, y, rng):
        dt = 1.0 / sig.rate_hz
        steps = rng.standard_normal(y.shape) * self.params["density"] * np.sqrt(dt)
        return y + np.cumsum(steps, axis=0)

    SPACINGS = (2.0, 5.0, 10.0, 20.0)

    def prepare(self, fcs, residuals):
        # knot spacing with the best BIC on the current residual: a fast walk needs dense knots
        best, best_h = np.inf, self.knot_spacing_s
        n = sum(r.size for r in residuals)
        for h in self.SPACINGS:
            self.knot_spacing_s = h
            rss, k = 0.0, 0
            for fc, r in zip(fcs, residuals, strict=True):
                c = self.columns(fc)
                c = c[:, 0, : c.shape[2] // 3]  # axis-0 hats; the same for every axis
                A = np.concatenate([np.ones((len(c), 1)), c], 1)
                coef, *_ = np.linalg.lstsq(A, r, rcond=None)
                rss += float(((r - A @ coef) ** 2).sum())
                k += 3 * c.shape[1]
            bic = n * np.log(rss / n) + k * np.log(n)
            if bic < best:
                best, best_h = bic, h
        self.knot_spacing_s = best_h

    def time_only_key(self):
        return (self.knot_spacing_s,)

    def n_knots(self, fc) -> int:
        """Knots of sequence `fc`: its length over the spacing, rounded up (so they fall at most the spacing apart)."""
        return max(int(np.ceil((fc.t[-1] - fc.t[0]) / self.knot_spacing_s)), 1)

    def columns(self, fc):
        # hat functions on knots every knot_spacing_s (the first knot left to the bias)
        t = fc.t - fc.t[0]
        n_knots = self.n_knots(fc)
        knots = np.linspace(0.0, t[-1], n_knots + 1)
        h = knots[1] - knots[0]
        hats = np.clip(1.0 - np.abs(t[:, None] - knots[None, 1:]) / h, 0.0, None)  # (N, n_knots)
        c = np.zeros((len(t), 3, 3 * n_knots))
        for i in range(3):
            c[:, i, i * n_knots : (i + 1) * n_knots] = hats
        return c

    def estimate(
        self, fcs: list[FitContext], residuals: list[np.ndarray], angle_noise: bool = False
    ) -> tuple[dict, dict]:
        n2, k2, k2_se = fit_allan_noise(residuals, fcs[0].rate_hz, angle_noise)
        k, se = root_with_se(k2, k2_se)
        return {"density": k}, {"density": se}

    def params_from_fit(self, coef, se):
        return {}, {}

    def magnitude(self) -> float:
        return float(np.max(self.params["density"]))


@register_simulated_only
class BiasInstability(Effect):
    """Bias instability: a flicker (1/f) bias, the flat floor of the Allan deviation that datasheets quote as "bias
    instability" or "in-run bias stability". `instability` is that floor (rad/s; IEEE Std 952's 0.664 B for a
    two-sided PSD B^2 / (2 pi f)), flat between the averaging times `tau_min` and `tau_max` (s) and falling off
    beyond them: a sum of first-order Gauss-Markov processes with log-spaced correlation times (`sim.flicker`),
    each started in its stationary state.

    Not in EFFECTS, the regression's vocabulary: the discrepancy workflow judges it after the selection, from the
    Allan variance's shape against re-simulations (`discrepancy.bias_instability`)."""

    name = "bias_instability"
    REPEATED = "independent floors add in power, not in value"
    stochastic = True
    DATASHEET = {"instability": ("deg/h", 3600 / DEG), "tau_min": ("s", 1.0), "tau_max": ("s", 1.0)}
    PRIOR = (1e-7, 1e-3)
    DEFAULTS = {"instability": np.zeros(3), "tau_min": 1.0, "tau_max": 1000.0}

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        check_flicker_band(self.name, float(self.params["tau_min"]), float(self.params["tau_max"]))

    def apply(self, sig, y, rng):
        floor = np.broadcast_to(self.params["instability"], (3,))
        if not floor.any():
            return y
        tau_min, tau_max = float(self.params["tau_min"]), float(self.params["tau_max"])
        return y + flicker.draw(floor, tau_min, tau_max, len(y), sig.rate_hz, rng)

    def magnitude(self) -> float:
        return float(np.max(self.params["instability"]))


def check_flicker_band(effect: str, tau_min: float, tau_max: float) -> None:
    """One line for a flicker band no bank can have (the averaging times between which the Allan floor is flat)."""
    if not (np.isfinite(tau_min) and np.isfinite(tau_max) and 0 < tau_min < tau_max):
        raise ValueError(
            f"effect {effect!r}: params.tau_max = {tau_max:g} must be above params.tau_min = {tau_min:g} (s, both "
            "above 0): the averaging times between which the Allan deviation is flat at the instability"
        )
    if tau_max / tau_min > flicker.MAX_SPAN:
        raise ValueError(
            f"effect {effect!r}: params.tau_max / params.tau_min = {tau_max / tau_min:.3g} spans more than "
            f"{flicker.MAX_SPAN:.0e} (one Gauss-Markov term per half decade); give a narrower band"
        )


@register
class Quantization(Effect):
    """Output quantisation: y = q round(y / q) (the LSB, applied at the output rate)."""

    name = "quantization"
    REPEATED = "the output is quantised twice"
    stage = 4
    stochastic = True
    DATASHEET = {"step": ("deg/s", 1 / DEG)}
    PRIOR = (1e-5, 0.05)
    DEFAULTS = {"step": 0.0}

    def apply(self, sig, y, rng):
        q = float(self.params["step"])
        return q * np.round(y / q) if q > 0 else y

    @staticmethod
    def lattice_step(values: np.ndarray) -> tuple[float, float]:
        """(step, fraction of samples on the lattice of that step). Unquantised data give ~0."""
        v = np.asarray(values, dtype=np.float64).ravel()
        u = np.unique(v)
        d = np.diff(u)
        d = d[d > 1e-12 * max(np.abs(u).max(), 1.0)]
        if len(d) < 10:
            return 0.0, 0.0
        # the smallest frequent gap is the step; round-off in the files makes gaps q(1 + 1e-9)
        q = float(np.median(np.sort(d)[: max(len(d) // 4, 1)]))
        frac = float(np.mean(np.abs(v / q - np.round(v / q)) < 0.02))
        return q, frac

    def estimate(self, fcs: list[FitContext], residuals: list[np.ndarray]) -> tuple[dict, dict]:
        q, _ = self.lattice_step(np.concatenate([fc.gyro for fc in fcs]))
        return {"step": np.asarray(q)}, {"step": np.asarray(q * 1e-3)}


def build_effect(name: str, **params: Any) -> Effect:
    """The gyro effect `name` (of SIM_EFFECTS) with parameters in SI (those not given keep their defaults), checked
    as a config entry's are (`effect_from_config`)."""
    return build_from(SIM_EFFECTS, name, params)


def build_from(registry: Mapping[str, type[Effect]], name: str, params: Mapping[str, Any]) -> Effect:
    """`build_effect` over another vocabulary (the accelerometer's: `sim.accel`)."""
    if name not in registry:
        raise ValueError(f"unknown effect {name!r}; known effects: {', '.join(sorted(registry))}")
    cls = registry[name]
    unknown = set(params) - set(cls.DEFAULTS)
    if unknown:
        raise ValueError(f"effect {name!r}: unknown parameter(s) {sorted(unknown)}; expected {sorted(cls.DEFAULTS)}")
    return cls(**{k: _param_value(name, k, v, np.shape(cls.DEFAULTS[k]), "si", cls) for k, v in params.items()})


NON_NEGATIVE = frozenset({"density", "step", "frequency_hz", "bandwidth_hz", "instability"})
# 0 would be a division by zero or a sensor that reads 0
POSITIVE = frozenset({"limit", "corner_hz", "tau", "tau_min", "tau_max"})
ENTRY_KEYS = ("name", "units", "params")


def effect_from_config(cfg: dict, registry: Mapping[str, type[Effect]] | None = None) -> Effect:
    """{'name': ..., 'units': 'si'|'datasheet', 'params': {...}} -> Effect.

    Every parameter must be given (a file that omits one has most likely misspelt it), as one number or as many as
    the parameter has (a 3x3 matrix also as 9 numbers), finite, not negative where a negative value means nothing
    (densities, steps, frequencies) and above 0 where 0 does too (limits, corner frequencies, time constants). An
    entry has no other keys than name, units and params, and `units` is required (no unit system is assumed).
    `registry`: the vocabulary (default: the gyro's, SIM_EFFECTS)."""
    registry = SIM_EFFECTS if registry is None else registry
    name = cfg.get("name")
    extra = [k for k in cfg if k not in ENTRY_KEYS]
    if extra:  # a misspelt 'units' would otherwise read datasheet figures as SI
        raise ValueError(
            f"effect {name!r}: unknown key(s) {extra}; an entry has {', '.join(ENTRY_KEYS)}"
            + (" (did you mean 'units'?)" if "unit" in extra else "")
        )
    if name not in registry:
        raise ValueError(f"'name' {name!r} must be one of {', '.join(sorted(registry))}")
    cls = registry[name]
    if "units" not in cfg:  # read as SI, datasheet figures (deg/s, ppm, mrad) were off by orders of magnitude
        figures = ", ".join(f"{k} in {unit}" for k, (unit, _) in cls.DATASHEET.items())
        raise ValueError(
            f"effect {name!r}: no 'units'; add units: si (SI) or units: datasheet ({figures or 'SI'}) to say which "
            "units its params are in"
        )
    units = cfg["units"]
    if units not in ("si", "datasheet"):
        raise ValueError(f"effect {name!r}: 'units' is {units!r}; use 'si' or 'datasheet' (the datasheet units)")
    params = cfg.get("params") or {}
    if not isinstance(params, dict):
        raise ValueError(f"effect {name!r}: 'params' must be a mapping of {sorted(cls.DEFAULTS)}")
    missing, unknown = set(cls.DEFAULTS) - set(params), set(params) - set(cls.DEFAULTS)
    if missing or unknown:
        raise ValueError(
            f"effect {name!r}: 'params' needs exactly {sorted(cls.DEFAULTS)}"
            + (f"; missing {sorted(missing)}" if missing else "")
            + (f"; unknown {sorted(unknown)}" if unknown else "")
        )
    checked = {k: _param_value(name, k, v, np.shape(cls.DEFAULTS[k]), units, cls) for k, v in params.items()}
    return cls.from_datasheet(**checked) if units == "datasheet" else cls(**checked)


def effects_from_config(entries: list, where: str, registry: Mapping[str, type[Effect]] | None = None) -> list[Effect]:
    """Every entry of an error-model list through `effect_from_config`; an error names `where[i]` (the file or the
    config key) and the field. An effect given twice is refused unless its entries add up (`Effect.REPEATED`)."""
    out: list[Effect] = []
    first: dict[str, int] = {}  # effect name -> its first entry's index
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict):
            raise ValueError(f"{where}[{i}] is {entry!r}; expected a mapping {{name, units, params}}")
        try:
            effect = effect_from_config(entry, registry)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{where}[{i}]: {err}") from None
        # a second entry was applied after the first: a second time offset silently replaced the first
        if effect.name in first and effect.REPEATED is not None:
            raise ValueError(
                f"{where}[{i}]: effect {effect.name!r} again, after {where}[{first[effect.name]}]: two entries do not "
                f"act as one with their parameters added ({effect.REPEATED}); give one entry"
            )
        first.setdefault(effect.name, i)
        out.append(effect)
    return out


def _param_value(effect: str, key: str, value: Any, shape: tuple, units: str, cls: type[Effect]) -> np.ndarray:
    where = f"effect {effect!r}: params.{key} = {value!r}"
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where} is not a number or a list of numbers") from None
    size = int(np.prod(shape))
    if a.size == size and a.shape != shape:
        a = a.reshape(shape)
    if a.shape not in ((), shape):
        raise ValueError(f"{where} has {a.size} values; give one number or {size}")
    if not np.isfinite(a).all():
        raise ValueError(f"{where} is not finite")
    unit = cls.DATASHEET.get(key, ("SI", 1.0))[0] if units == "datasheet" else "SI"
    if key in NON_NEGATIVE and (a < 0).any():
        raise ValueError(f"{where} ({unit}) must not be negative")
    if key in POSITIVE and (a <= 0).any():
        raise ValueError(f"{where} ({unit}) must be above 0")
    return a


# ===================================================================== sensor presets

# Noise figures of the datasets' calibration files (EuRoC sensor.yaml, TUM-VI calibration).
SENSORS = {
    "ADIS16448": {"white_noise": 1.6968e-4, "bias_random_walk": 1.9393e-5, "quantization": 0.04 * DEG},
    "BMI160": {"white_noise": 1.6e-4, "bias_random_walk": 2.2e-5, "quantization": DEG / 16.4},
}


def noise_model(sensor: str = "ADIS16448", quantize: bool = False) -> list[Effect]:
    """The sensor's stochastic error model: white noise + bias random walk (+ quantisation)."""
    if sensor not in SENSORS:
        raise ValueError(f"unknown sensor {sensor!r}; presets: {', '.join(SENSORS)}")
    s = SENSORS[sensor]
    out: list[Effect] = [
        WhiteNoise(density=np.full(3, s["white_noise"])),
        BiasRandomWalk(density=np.full(3, s["bias_random_walk"])),
    ]
    if quantize:
        out.append(Quantization(step=s["quantization"]))
    return out
