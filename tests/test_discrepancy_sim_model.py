"""A discrepancy run's model as a simulator configuration (gyrodenoise.discrepancy.sim_model)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.discrepancy.sim_model import simulator_model, write_simulator_model
from gyrodenoise.sim.dataset import generate_sequence, with_error_model_file
from gyrodenoise.sim.error_model_file import ErrorModelRateWarning, load_error_model

REPORT = {
    "command": "python -m gyrodenoise.discrepancy ...",
    "rate_hz": 200.0,
    "verdict": "named: vibration, time_offset, quantization",
    "base_params": {
        "bias": {"bias": [0.01, 0.02, 0.03], "bias_per_sequence": [[0.01, 0.02, 0.03], [0.03, 0.04, 0.05]]},
        "white_noise": {"density": [2e-4, 4e-4, 4e-4]},
    },
    "named_effects": [
        {"name": "vibration", "params": {"frequency_hz": 1.4, "amplitude": [5e-4, 2e-3, 1e-3], "bandwidth_hz": 1.75}},
        {"name": "time_offset", "params": {"delta": -3.8e-4}},
        {"name": "quantization", "params": {"step": 6.98e-4}},
    ],
}


def test_the_fitted_model_becomes_a_simulator_configuration(tmp_path):
    model = simulator_model(REPORT)
    names = [e["name"] for e in model["error_model"]]
    assert names == ["bias", "white_noise", "vibration", "time_offset", "quantization"]
    assert model["error_model"][0]["params"] == {"bias": [0.02, 0.03, 0.04]}  # the mean; the spread below
    assert model["bias_jitter_rad_s"] == pytest.approx(np.std([0.01, 0.03], ddof=1))
    path = write_simulator_model(tmp_path / "error_model.yaml", REPORT)
    entries, jitter = load_error_model(path)
    assert entries == model["error_model"] and jitter == pytest.approx(model["bias_jitter_rad_s"])
    # the simulated dataset reads it in place of its own list, and the cache key follows the content
    gen = with_error_model_file({"seed": 0, "duration_s": 6.0, "error_model": [], "error_model_file": str(path)})
    assert gen["error_model"] == entries and "error_model_file" not in gen
    assert with_error_model_file({"error_model": [], "error_model_file": None}) == {"error_model": []}
    seq = generate_sequence(tmp_path / "sim", "hand_00", gen)  # the simulator accepts every entry
    assert (seq / "mav0" / "imu0" / "data.csv").is_file()
    # the rate it was measured at goes with it: a simulation at another rate is told what was never measured
    assert model["rate_hz"] == 200.0
    with pytest.warns(ErrorModelRateWarning, match="fitted on recordings at 200 Hz, simulated at 400 Hz"):
        with_error_model_file({"rate_hz": 400.0, "error_model": [], "error_model_file": str(path)})


def test_a_bad_error_model_file_is_refused_with_its_path(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.yaml"):
        load_error_model(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("error_model:\n  - {name: white_noise, units: si, params: {sigma: 1}}\n")
    with pytest.raises(ValueError, match="bad.yaml.*white_noise"):
        load_error_model(bad)
    bad.write_text("just text\n")
    with pytest.raises(ValueError, match="'error_model' list"):
        load_error_model(bad)


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        (
            "{name: time_offset, units: Datasheet, params: {delta: 3}}",
            "'units' is 'Datasheet'; use 'si' or 'datasheet'",
        ),
        ("{name: time_offset, units: si, params: {}}", r"needs exactly \['delta'\]; missing \['delta'\]"),
        ("{name: g_sensitivity, units: datasheet}", r"missing \['matrix'\]"),
        ("{name: white_noise, units: si, params: {density: [1.0e-4, 1.0e-4]}}", "has 2 values; give one number or 3"),
        ("{name: white_noise, units: si, params: {density: -1.2e-4}}", "density = -0.00012 .SI. must not be negative"),
        (
            "{name: quantization, units: datasheet, params: {step: -0.04}}",
            r"step = -0.04 \(deg/s\) must not be negative",
        ),
        ("{name: bias, units: si, params: {bias: [a, b, c]}}", "not a number"),
        ("{name: tiem_offset, units: si, params: {delta: 0.003}}", "'name' 'tiem_offset' must be one of"),
    ],
)
def test_error_model_entries_are_checked_field_by_field(tmp_path, entry, message):
    """An error model written by hand: a wrong unit system, a missing, misshapen, negative or non-numeric parameter
    or a misspelt effect is refused with the file, the entry's index and the field, in a few words."""
    f = tmp_path / "model.yaml"
    f.write_text(f"error_model:\n  - {{name: bias, units: si, params: {{bias: [0, 0, 0]}}}}\n  - {entry}\n")
    with pytest.raises(ValueError, match=message) as info:
        load_error_model(f)
    assert str(info.value).startswith(f"{f}: error_model[1]") and len(str(info.value)) < 400
    # a 3x3 matrix may be given as 9 numbers, one number stands for every value
    nine = "[0, 0, 0, 0, 0.1, 0, 0, 0, 0]"
    f.write_text(f"error_model:\n  - {{name: g_sensitivity, units: datasheet, params: {{matrix: {nine}}}}}\n"
                 "  - {name: white_noise, units: si, params: {density: 1.0e-4}}\n")  # fmt: skip
    assert len(load_error_model(f)[0]) == 2


def test_one_fitted_sequence_leaves_the_simulators_bias_spread_as_it_is(tmp_path):
    """One sequence's bias says nothing of the spread between recordings: the file wrote 0.0, which replaced the
    simulated dataset's own setting; it writes null now, which leaves it."""
    bias = {"bias": [0.01, 0.02, 0.03], "bias_per_sequence": [[0.01, 0.02, 0.03]]}
    one = {**REPORT, "base_params": {**REPORT["base_params"], "bias": bias}}
    path = write_simulator_model(tmp_path / "error_model.yaml", one)
    assert load_error_model(path)[1] is None
    gen = with_error_model_file({"bias_jitter_rad_s": 0.005, "error_model": [], "error_model_file": str(path)})
    assert gen["bias_jitter_rad_s"] == 0.005
