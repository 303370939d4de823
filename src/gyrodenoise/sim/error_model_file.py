"""Read an error-model file: the `error_model` list of the simulated dataset's `generation` settings, as a
discrepancy run writes it (`gyrodenoise.discrepancy.sim_model`). Here, in the simulator, because the simulator
must not import the detector."""

from __future__ import annotations

import warnings
from pathlib import Path

import yaml

from gyrodenoise.sim.effects import effects_from_config


class ErrorModelRateWarning(UserWarning):
    """An error model fitted on recordings at one rate, simulated at another."""


def _rate_mismatch_warning(path: Path, fitted: object, rate_hz: float) -> None:
    """Warn when the file says it was fitted at another rate than `rate_hz` (files without `rate_hz`, written before it
    was recorded or by hand, are taken as they are)."""
    if isinstance(fitted, int | float) and abs(fitted - rate_hz) > 0.01 * fitted:
        warnings.warn(
            f"{path}: fitted on recordings at {fitted:g} Hz, simulated at {rate_hz:g} Hz: what lies between "
            f"{min(fitted, rate_hz) / 2:g} and {max(fitted, rate_hz) / 2:g} Hz was never measured (give "
            f"dataset.generation.rate_hz={fitted:g} to simulate the measured IMU)",
            ErrorModelRateWarning,
            stacklevel=3,
        )


def load_error_model(path: str | Path, rate_hz: float | None = None) -> tuple[list[dict], float | None]:
    """(error_model entries, bias_jitter_rad_s or None) of a file written by `write_simulator_model` (or any YAML
    with an `error_model` list). `rate_hz`: the rate it will be simulated at; another than the file's warns."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"error model file {path} not found (written by python -m gyrodenoise.discrepancy)")
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict) or not isinstance(data.get("error_model"), list):
        raise ValueError(f"{path}: expected a mapping with an 'error_model' list of {{name, units, params}} entries")
    effects_from_config(data["error_model"], f"{path}: error_model")  # refuse what the simulator would not take
    if rate_hz is not None:
        _rate_mismatch_warning(path, data.get("rate_hz"), rate_hz)
    return data["error_model"], data.get("bias_jitter_rad_s")
