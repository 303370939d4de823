"""What an effect sees of a sequence: `SignalContext` when it is simulated (the simulator's internal
rate), `FitContext` when it is detected (a measured sequence at the IMU rate, with the true rate
reconstructed from the ground truth). Plain data, no imports from the rest of the package, so
both the simulator (`sim.effects`) and the detector (`discrepancy`) can build on it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class SignalContext:
    """What an effect sees when it is applied (high internal rate)."""

    t: np.ndarray  # (M,) s since power-on / sequence start
    omega: np.ndarray  # (M, 3) true body rate
    alpha: np.ndarray  # (M, 3) true body angular acceleration
    f: np.ndarray  # (M, 3) true specific force
    rate_hz: float
    kinematics_at: Any = None  # callable t -> Kinematics, for the time offset
    # the simulator's output sample is the mean of this many consecutive samples of the signal (1: the signal is
    # at the output rate already); an effect stated as seen in the output (a vibration line) undoes that mean
    output_mean_of: int = 1


@dataclass
class FitContext:
    """One measured sequence as the detector sees it (IMU rate)."""

    name: str
    t: np.ndarray  # (N,) s since the first IMU sample
    gyro: np.ndarray  # (N, 3) measured
    omega: np.ndarray  # (N, 3) true rate from the smooth ground-truth fit
    alpha: np.ndarray
    f: np.ndarray
    rate_hz: float
    extra: dict = field(default_factory=dict)

    @property
    def residual(self) -> np.ndarray:
        return self.gyro - self.omega
