"""An independent test world for the discrepancy workflow: IMU sequences with known hidden effects.

What it shares with the rest of gyrodenoise: the ASL file format and the effect names written in
truth.json, nothing else. It imports neither `gyrodenoise.sim` nor `gyrodenoise.discrepancy` (nor the
project's readers): a workflow tested on data from its own simulator shares that simulator's trajectory
fit, discretisation and noise model, so agreement proves little. Here instead

- the truth motion is a procedural body rate integrated by a 4th-order Magnus scheme, or a real EuRoC
  ground truth smoothed by a zero-phase Butterworth filter and interpolated by RotationSpline/CubicSpline
  (not a least-squares B-spline);
- the sensor applies its effects in continuous time at a high internal rate, then an integrating or a
  causal low-pass (Butterworth/Bessel) bandwidth, quantisation and stamps;
- the ground truth written to disk is itself measured: a mocap sampling the pose at its own rate and
  phase, with orientation/position noise and stamp jitter, so the rate must be reconstructed as for
  real data.

Layout: units.py (datasheet units <-> SI), spec.py (effect vocabulary, presets), motion.py (kinematics,
procedural motion, Magnus), replay.py (EuRoC replay), sensor.py (IMU), mocap.py (measured ground truth),
asl.py (file format, atomic writes), world.py (`make_sequence`), __main__.py (CLI).
"""

from gyrodenoise.testworld.mocap import MOCAP_PRESETS, MocapConfig
from gyrodenoise.testworld.motion import Kinematics, ProceduralMotion
from gyrodenoise.testworld.replay import EurocReplay
from gyrodenoise.testworld.sensor import Bandwidth
from gyrodenoise.testworld.spec import PRESETS, EffectSpecError
from gyrodenoise.testworld.world import WorldSequence, make_motion, make_sequence

__all__ = [
    "MOCAP_PRESETS",
    "PRESETS",
    "Bandwidth",
    "EffectSpecError",
    "EurocReplay",
    "Kinematics",
    "MocapConfig",
    "ProceduralMotion",
    "WorldSequence",
    "make_motion",
    "make_sequence",
]
