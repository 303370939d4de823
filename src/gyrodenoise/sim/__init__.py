"""IMU simulator: smooth trajectories, the error-effect library, and ASL output.

from gyrodenoise.sim import handheld_trajectory, simulate_imu, write_asl, EFFECTS
"""

from gyrodenoise.sim.effects import EFFECTS, Effect, build_effect, effect_from_config, noise_model
from gyrodenoise.sim.imu import SimulatedImu, simulate_imu, write_asl
from gyrodenoise.sim.trajectory import (
    SmoothTrajectory,
    constant_rate_trajectory,
    drone_trajectory,
    handheld_trajectory,
    yaw_only_trajectory,
)

__all__ = [
    "EFFECTS",
    "Effect",
    "SimulatedImu",
    "SmoothTrajectory",
    "build_effect",
    "constant_rate_trajectory",
    "drone_trajectory",
    "effect_from_config",
    "handheld_trajectory",
    "noise_model",
    "simulate_imu",
    "write_asl",
    "yaw_only_trajectory",
]
