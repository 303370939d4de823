"""gyrodenoise: learn to denoise a low-cost IMU gyroscope; open-loop attitude estimation.

The Python API in one place (docs/python-api.md); each name lives in the module given here and is imported from
it on first use, so `import gyrodenoise` stays light:

    load_model, available_models   a shipped model by name, a model file or a run folder -> (model, metadata)
    load_sequence                  an ASL sequence folder (IMU + ground truth, aligned) through the cache
    correct_arrays                 your own t, gyro, acc arrays, checked (units, rate, gaps) and corrected
    correct_gyro                   an (N, 6) rad/s, m/s^2 array through a loaded model, unchecked
    integrate_gyro                 open-loop attitude from a gyro, (N, 3, 3) rotation matrices
    aoe, roe                       absolute / relative orientation errors (rad) against a ground truth
    compose_config                 the train / evaluate configs with overrides, for `gyrodenoise.train.train(cfg)`
                                   and `gyrodenoise.evaluate.evaluate(cfg)`
    StreamingCorrector             the onboard corrector, one sample at a time
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_API = {
    "load_model": "gyrodenoise.pretrained",
    "available_models": "gyrodenoise.pretrained",
    "load_sequence": "gyrodenoise.data.cache",
    "correct_arrays": "gyrodenoise.correct",
    "correct_gyro": "gyrodenoise.correct",
    "integrate_gyro": "gyrodenoise.so3",
    "aoe": "gyrodenoise.metrics",
    "roe": "gyrodenoise.metrics",
    "compose_config": "gyrodenoise.config",
    "StreamingCorrector": "gyrodenoise.streaming",
}
__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'gyrodenoise' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_API])
