"""Flicker (1/f) noise for the simulator: the flat floor of an Allan deviation plot, which datasheets quote as
"bias instability" or "in-run bias stability".

A 1/f process has no finite-order state, so it is approximated, as is usual, by a sum of independent first-order
Gauss-Markov processes whose correlation times are log-spaced, each of the same variance: their Lorentzian spectra
then add up to a 1/f spectrum between the shortest and the longest (a constant share of the power per octave of
correlation time). The sum is scaled so that its Allan deviation, computed in closed form, is flat at the asked
floor between the averaging times `tau_min` and `tau_max` (within ~1 %); in that band its two-sided PSD is the
IEEE Std 952 flicker spectrum B^2 / (2 pi f) with floor = 0.664 B (within ~2 %). Beyond the band the Allan
deviation falls off (tau^-1/2 above it, tau^+1/2 below it, as a Gauss-Markov process's does).

Conventions as the rest of the simulator: the floor in the signal's unit (rad/s for a gyro, m/s^2 for an
accelerometer), times in s; each process starts in its stationary state, so the statistics do not depend on the
time since power-on (the long terms add an offset of about `stationary_std`, as a turn-on bias would).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import signal

# the Allan floor of a B^2 / (2 pi f) spectrum is sqrt(2 ln 2 / pi) B (IEEE Std 952, Annex C)
IEEE_FLOOR_PER_B = float(np.sqrt(2.0 * np.log(2.0) / np.pi))
PER_DECADE = 2  # correlation times per decade: the floor's ripple is ~1 % peak to peak (4 % at 1 per decade)
# the bank reaches past the band at both ends: a Gauss-Markov term's Allan deviation peaks at tau ~ 1.9 T and falls
# off slowly, so without the extra terms the floor sags by ~10 % towards the band's ends
SHORT_REACH = 30.0  # shortest correlation time tau_min / 30
LONG_REACH = 10.0  # longest 10 tau_max
MAX_SPAN = 1e8  # tau_max / tau_min: 2 terms per decade, ~20 terms


def correlation_times(tau_min: float, tau_max: float) -> np.ndarray:
    """The bank's correlation times (s), log-spaced, PER_DECADE per decade, from tau_min / SHORT_REACH to
    tau_max LONG_REACH."""
    lo, hi = tau_min / SHORT_REACH, tau_max * LONG_REACH
    return np.geomspace(lo, hi, int(np.ceil(PER_DECADE * np.log10(hi / lo))) + 1)


def gauss_markov_allan_variance(tau: np.ndarray, corr_time: float, variance: float) -> np.ndarray:
    """Allan variance at averaging times tau of a first-order Gauss-Markov process (stationary variance `variance`,
    correlation time `corr_time`): (2 q T / tau) (1 - T (3 - 4 e^-x + e^-2x) / (2 tau)), x = tau / T. A rate random
    walk (2 q tau / 3 T) for tau << T, white noise (2 q T / tau) for tau >> T."""
    x = np.asarray(tau, dtype=np.float64) / corr_time
    small = x < 1e-2  # the bracket cancels to ~x^2 / 3 there: its series (next term ~x^6, 1e-12 relative)
    xl = np.where(small, 1.0, x)
    bracket = 1.0 - (3.0 - 4.0 * np.exp(-xl) + np.exp(-2.0 * xl)) / (2.0 * xl)
    series = x**2 / 3 - x**3 / 4 + 7 * x**4 / 60 - x**5 / 24
    return (2.0 * variance / x) * np.where(small, series, bracket)


@lru_cache(maxsize=64)
def _unit_term_variance(tau_min: float, tau_max: float) -> float:
    """Each term's variance for an Allan floor of 1: the bank's Allan deviation is set to the geometric mean of its
    largest and smallest values over [tau_min, tau_max], so the ripple lies evenly about the floor."""
    taus = np.geomspace(tau_min, tau_max, 400)
    adev = np.sqrt(sum(gauss_markov_allan_variance(taus, t, 1.0) for t in correlation_times(tau_min, tau_max)))
    return float(1.0 / (adev.max() * adev.min()))


def term_variance(floor: np.ndarray, tau_min: float, tau_max: float) -> np.ndarray:
    """Stationary variance of each term for an Allan floor `floor` (per axis)."""
    return np.asarray(floor, dtype=np.float64) ** 2 * _unit_term_variance(float(tau_min), float(tau_max))


def allan_deviation(tau: np.ndarray, floor: float, tau_min: float, tau_max: float) -> np.ndarray:
    """The bank's Allan deviation at averaging times tau (closed form; the ideal a simulation estimates)."""
    q = float(term_variance(floor, tau_min, tau_max))
    return np.sqrt(sum(gauss_markov_allan_variance(tau, t, q) for t in correlation_times(tau_min, tau_max)))


def psd(f: np.ndarray, floor: float, tau_min: float, tau_max: float) -> np.ndarray:
    """The bank's two-sided PSD at frequencies f (Hz): the sum of the terms' Lorentzians 2 q T / (1 + (2 pi f T)^2)
    (white noise of density N has N^2 in this convention, as `WhiteNoise` draws it)."""
    q = float(term_variance(floor, tau_min, tau_max))
    f = np.asarray(f, dtype=np.float64)
    return sum(2.0 * q * t / (1.0 + (2.0 * np.pi * f * t) ** 2) for t in correlation_times(tau_min, tau_max))


def stationary_std(floor: np.ndarray, tau_min: float, tau_max: float) -> np.ndarray:
    """Standard deviation of the bank's value at any one time (per axis): sqrt(terms x term variance)."""
    return np.sqrt(len(correlation_times(tau_min, tau_max)) * term_variance(floor, tau_min, tau_max))


def draw(
    floor: np.ndarray, tau_min: float, tau_max: float, n: int, rate_hz: float, rng: np.random.Generator
) -> np.ndarray:
    """(n, 3) samples at `rate_hz` of the bank with Allan floor `floor` (per axis), each term in its stationary
    state at the first sample. The exact discretisation of each term: x_k = a x_(k-1) + sqrt(1 - a^2) sqrt(q) e_k,
    a = exp(-1 / (rate T)), whatever the rate. These are point samples: a term whose correlation time is below the
    sample interval puts its whole variance into each sample, where a sensor's averaging over the interval would
    leave less (at 10 Hz with tau_min 1 s the Allan deviation at 0.1 s is 1.28 times the floor). The simulator draws
    at its internal rate and averages to the output: there the floor holds to 3 % down to tau_min = one output
    period (200 Hz, oversample 10)."""
    sd = np.sqrt(term_variance(np.broadcast_to(floor, (3,)), tau_min, tau_max))
    out = np.zeros((n, 3))
    for t in correlation_times(tau_min, tau_max):
        a = float(np.exp(-1.0 / (rate_hz * t)))
        x0 = rng.standard_normal(3) * sd
        e = rng.standard_normal((n, 3)) * (sd * np.sqrt(1.0 - a * a))
        x, _ = signal.lfilter([1.0], [1.0, -a], e, axis=0, zi=(a * x0)[None, :])
        out += x
    return out
