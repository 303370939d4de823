"""The accelerometer's error effects beyond the constant bias and white noise that `simulate_imu` gives it
(`acc_bias`, `acc_noise_density`): scale factor, misalignment, bias random walk and bias instability.

They act on the true specific force (m/s^2, body frame) at the simulator's internal rate, before the output's
period mean, as the gyro's effects act on the rate; the time offset of the gyro's list delays both sensors. Their
vocabulary (`ACC_EFFECTS`) is separate from the gyro's: the same names with the accelerometer's units, and
`simulate_imu` refuses an effect of one list in the other (a gyro scale factor would scale the rate, silently).
Simulated only: the discrepancy workflow compares gyros.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gyrodenoise.sim.context import SignalContext
from gyrodenoise.sim.effects import (
    G0,
    BiasInstability,
    BiasRandomWalk,
    Effect,
    build_from,
    effects_from_config,
    misalignment_matrix,
)

ACC_EFFECTS: dict[str, type[Effect]] = {}
MG = 1e-3 * G0  # m/s^2


def _register(cls: type[Effect]) -> type[Effect]:
    ACC_EFFECTS[cls.name] = cls
    return cls


class AccelerometerEffect(Effect):
    """An error of the accelerometer: `apply` maps its output so far (m/s^2) given the true specific force sig.f."""


@_register
class AccScaleFactor(AccelerometerEffect):
    """Scale-factor error s per axis: a_i = (1 + s_i) f_i."""

    name = "scale_factor"
    stage = 1
    REPEATED = None  # each responds to the true specific force: the scales add
    DATASHEET = {"scale": ("ppm", 1e6)}
    DEFAULTS = {"scale": np.zeros(3)}

    def apply(self, sig, y, rng):
        return y + self.params["scale"] * sig.f


@_register
class AccMisalignment(AccelerometerEffect):
    """Axis misalignment: a = (I + M) f with M off-diagonal; `angles` = M[xy, xz, yx, yz, zx, zy] (as the gyro's)."""

    name = "misalignment"
    stage = 1
    REPEATED = None  # each responds to the true specific force: the angles add
    DATASHEET = {"angles": ("mrad", 1e3)}
    DEFAULTS = {"angles": np.zeros(6)}

    def matrix(self) -> np.ndarray:
        return misalignment_matrix(self.params["angles"])

    def apply(self, sig, y, rng):
        return y + sig.f @ self.matrix().T


@_register
class AccBiasRandomWalk(AccelerometerEffect):
    """Bias random walk K (m/s^3/sqrt(Hz) = m/s^2/sqrt(s), Kalibr's accelerometer_random_walk): db/dt = K xi(t).
    Datasheet unit mg/sqrt(h): the bias's standard deviation after one hour. Allan deviation K sqrt(tau / 3)."""

    name = "bias_random_walk"
    REPEATED = BiasRandomWalk.REPEATED
    DATASHEET = {"density": ("mg/sqrt(h)", 60.0 / MG)}
    DEFAULTS = {"density": np.zeros(3)}

    def apply(self, sig, y, rng):
        # the gyro's random walk, drawn the same way (steps of K sqrt(dt) at the internal rate)
        return BiasRandomWalk(density=self.params["density"]).apply(sig, y, rng)


@_register
class AccBiasInstability(AccelerometerEffect, BiasInstability):
    """Bias instability: the flat floor `instability` (m/s^2; datasheet mg, "in-run bias stability") of the Allan
    deviation between the averaging times `tau_min` and `tau_max` (s); the gyro's `bias_instability` in the
    accelerometer's units."""

    DATASHEET = {"instability": ("mg", 1.0 / MG), "tau_min": ("s", 1.0), "tau_max": ("s", 1.0)}


def build_acc_effect(name: str, **params: Any) -> Effect:
    """The accelerometer effect `name` (of ACC_EFFECTS) with parameters in SI, checked as `build_effect` checks the
    gyro's."""
    return build_from(ACC_EFFECTS, name, params)


def acc_effects_from_config(entries: list, where: str) -> list[Effect]:
    """An accelerometer error-model list ({name, units: si | datasheet, params} entries, as the gyro's)."""
    return effects_from_config(entries, where, ACC_EFFECTS)


def check_acc_effects(gyro_effects: list[Effect], acc_effects: list[Effect]) -> None:
    """One line for an effect given to the other sensor's list (it would act on the other sensor's input)."""
    for i, e in enumerate(acc_effects):
        if not isinstance(e, AccelerometerEffect):
            raise ValueError(
                f"acc_effects[{i}] is the gyro effect {e.name!r}; build accelerometer effects with "
                "gyrodenoise.sim.accel.build_acc_effect (or acc_effects_from_config)"
            )
    for i, e in enumerate(gyro_effects):
        if isinstance(e, AccelerometerEffect):
            raise ValueError(f"effects[{i}] is the accelerometer effect {e.name!r}; give it in acc_effects")


def apply_acc_error_model(effects: list[Effect], sig: SignalContext, rng: np.random.Generator) -> np.ndarray:
    """Accelerometer output (before its constant bias and white noise) of the true specific force sig.f: stage 1
    (scale, misalignment: each responds to the true specific force, not to the others), then stage 2 (the bias
    terms), each stage in name order as the gyro's."""
    y = sig.f.copy()
    for stage in (1, 2):
        for e in sorted((e for e in effects if e.stage == stage), key=lambda e: e.name):
            y = e.apply(sig, y, rng)
    return y
