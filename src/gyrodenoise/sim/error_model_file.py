"""Read an error-model file: the `error_model` list of the simulated dataset's `generation` settings, as a
discrepancy run writes it (`gyrodenoise.discrepancy.sim_model`). Here, in the simulator, because the simulator
must not import the detector."""

from __future__ import annotations

from pathlib import Path

import yaml

from gyrodenoise.sim.effects import effects_from_config


def load_error_model(path: str | Path) -> tuple[list[dict], float | None]:
    """(error_model entries, bias_jitter_rad_s or None) of a file written by `write_simulator_model` (or any YAML
    with an `error_model` list)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"error model file {path} not found (written by python -m gyrodenoise.discrepancy)")
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict) or not isinstance(data.get("error_model"), list):
        raise ValueError(f"{path}: expected a mapping with an 'error_model' list of {{name, units, params}} entries")
    effects_from_config(data["error_model"], f"{path}: error_model")  # refuse what the simulator would not take
    return data["error_model"], data.get("bias_jitter_rad_s")
