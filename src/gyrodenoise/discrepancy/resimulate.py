"""Re-simulate a measured sequence's gyro under a selected error model (the held-out gap, the residual checks).

The sensor's deterministic part (sensor constants and refitted per-sequence nuisances) along the measured motion, its
fitted noise (through a named low-pass) and a fresh draw of a named random walk (not the walk's refitted knots, which
are the measured sequence's own draw), a fresh draw of the reconstructed truth's error, then the output stage
(band-limited vibration, saturation, quantization).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gyrodenoise.discrepancy.fitted_model import per_sequence_refit
from gyrodenoise.discrepancy.rank import Selection
from gyrodenoise.discrepancy.reconstruction import draw_error
from gyrodenoise.sim.context import FitContext, SignalContext
from gyrodenoise.sim.effects import EFFECTS, BiasInstability, Quantization, SensorBandwidth, Vibration


def simulate_like(
    sel: Selection,
    fc: FitContext,
    rng: np.random.Generator,
    pred: np.ndarray | None = None,
    truth_error: bool = True,
    walk_free: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Re-simulate the gyro of sequence `fc` with the selected model: deterministic part (sensor
    constants + refitted nuisances; `pred` if already computed) plus the stochastic effects drawn
    from their fitted levels. Returns (simulated gyro, deterministic prediction of the residual).
    A named random walk is drawn afresh, not taken from `pred`'s refitted knots (the prediction returned keeps them):
    the gyro starts from `walk_free`, the prediction without the knots (`without_walk_knots`; computed here if None).

    The white noise is drawn first, so two models simulated with generators of the same seed share
    its draws (common random numbers: their gaps differ by the models, not by the draws).
    truth_error=False: the sensor's reading alone, without the reconstructed truth's error (which the measured
    residual carries on the truth's side, not in the gyro)."""
    if pred is None:
        pred = per_sequence_refit(sel, fc)
    # the walk's refitted knots are this sequence's own realisation of it: the re-simulation draws a fresh one below
    # instead (with both, the re-simulated gyro wandered sqrt(2) times as far as the measured one at long cluster times)
    if walk_named(sel) and walk_free is None:
        walk_free = without_walk_knots(sel, fc)
    y = fc.omega + (walk_free if walk_named(sel) else pred)
    sig = SignalContext(t=fc.t, omega=fc.omega, alpha=fc.alpha, f=fc.f, rate_hz=fc.rate_hz)
    for name in ("white_noise", "bias_random_walk"):
        if name in sel.params and (name != "bias_random_walk" or name in sel.selected):
            noise = EFFECTS[name](density=sel.params[name]["density"]).apply(sig, np.zeros_like(y), rng)
            if name == "white_noise" and sel.corner_hz is not None:  # the floor through the low-pass
                noise = shape_noise(noise, fc.rate_hz, sel.corner_hz)
            y = y + noise
    if "bias_instability" in sel.params:  # a named flicker floor (`bias_instability`)
        y = y + BiasInstability(**sel.params["bias_instability"]).apply(sig, np.zeros_like(y), rng)
    if truth_error:  # the reconstruction error, as the measured residual carries it
        err = draw_error(fc, rng)
        if err is not None:
            y = y + err
    if sel.band_vibration:  # band-limited vibration: noise, drawn like the white noise
        y = Vibration(**sel.params["vibration"]).apply(sig, y, rng)
    if "saturation" in sel.params:
        lim = float(sel.params["saturation"]["limit"])
        y = np.clip(y, -lim, lim)
    if "quantization" in sel.params:
        y = Quantization(step=sel.params["quantization"]["step"]).apply(sig, y, rng)
    return y, pred


def walk_named(sel: Selection) -> bool:
    """Whether `sel` holds a random walk that the re-simulation draws (its knots are then refitted nuisances)."""
    return "bias_random_walk" in sel.params and "bias_random_walk" in sel.selected


def without_walk_knots(sel: Selection, fc: FitContext) -> np.ndarray:
    """The deterministic prediction of sequence `fc` (`per_sequence_refit`) with the random walk's knots left out."""
    return per_sequence_refit(sel, fc, [n for n in sel.selected if n != "bias_random_walk"])


def as_measured(fc: FitContext, gyro: np.ndarray) -> FitContext:
    """Sequence `fc` with a re-simulated gyro; its own copy of `extra` (a refit may set a saturation mask there)."""
    return dataclasses.replace(fc, gyro=gyro, extra=dict(fc.extra))


def left_by_model(sel: Selection, fc: FitContext, y_sim: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """What the deterministic model leaves of a re-simulated gyro `y_sim`, as it leaves of the measured one (whose
    residual is taken minus `pred`, refitted on it). With a named walk the per-sequence nuisances are refitted on
    the re-simulation: its walk is its own draw, which `pred`'s knots (the measured walk's) would leave in it beside
    theirs. Without one `pred` is used as is: the other nuisances, a constant bias and a named vibration's phase, take
    from the measured residual the noise of one or two of its Fourier bins (0 Hz, the line's), not a process's power."""
    if walk_named(sel):
        return y_sim - fc.omega - per_sequence_refit(sel, as_measured(fc, y_sim))
    return y_sim - fc.omega - pred


def shape_noise(x: np.ndarray, rate_hz: float, corner_hz: float) -> np.ndarray:
    """White noise x (N, 3) given the PSD shape of a sensor low-pass (`SensorBandwidth.floor_shape`)."""
    f = np.fft.rfftfreq(len(x), 1.0 / rate_hz)
    gain = np.sqrt(SensorBandwidth.floor_shape(f, corner_hz, rate_hz))
    return np.fft.irfft(np.fft.rfft(x, axis=0) * gain[:, None], len(x), axis=0)
