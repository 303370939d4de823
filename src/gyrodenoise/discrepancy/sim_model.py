"""The model a discrepancy run ends with, as a simulator configuration.

The workflow names the missing effects and re-simulates with them to show the gap shrink; this writes that
model (the base model's fitted levels plus the named effects' parameters, SI units) in the format of the
simulated dataset's `generation` settings, so the next simulation includes the effects the data asked for:

    python -m gyrodenoise.train dataset=sim dataset.generation.error_model_file=REPORT_DIR/error_model.yaml

`rate_hz` records the fitted recordings' rate: a simulation at another rate warns (effects above that rate's
Nyquist frequency were never measured). The turn-on bias is the mean over the fit sequences, and its spread between
them becomes `bias_jitter_rad_s`: the report's `bias_spread` (`bias_spread.py`: over the fit and held-out sequences,
the estimates' own errors taken out; their plain standard deviation gave ~5e-5 rad/s where every sequence had the
same bias), or, in a report written before it, the fit sequences' plain standard deviation (null with one fitted
sequence and no `bias_spread`, or where `bias_spread` has no value: a spread it cannot measure, so the simulated
dataset keeps its own setting; `bias_jitter_unset_because` then says why, from `bias_spread`'s reason).
Lines of the raw gyro above the compared band that are in every fitted recording are added as band-limited
vibrations (`gyro_lines.simulator_vibration`): the truth cannot judge them, but a simulator of this gyro needs them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from gyrodenoise.atomic import write_text
from gyrodenoise.sim.effects import SIM_EFFECTS, effect_from_config


def simulator_model(report: dict) -> dict:
    """{'error_model': [{name, units: si, params}], 'bias_jitter_rad_s': ..., 'source': ...} from a report dict;
    every entry is checked to build (`sim.effects.effect_from_config`)."""
    entries = []
    jitter: float | None = None  # one fitted sequence says nothing of the spread: the simulator's setting stays
    reason: str | None = None  # why the report has no spread (`bias_spread`), beside the null
    for name, params in (report.get("base_params") or {}).items():
        params = dict(params)
        if name == "bias":  # per sequence in the data; the simulator draws it around the mean
            per_seq = np.asarray(params.pop("bias_per_sequence", [params["bias"]]), dtype=float)
            params["bias"] = per_seq.mean(0).tolist()
            spread = report.get("bias_spread")  # the estimates' own errors taken out (`bias_spread`)
            if spread is not None:  # its value null where no spread could be estimated: its 'reason' says why
                tau = spread.get("between_sequence_rad_s")
                jitter = None if tau is None else float(tau)
                reason = None if tau is not None else spread.get("reason")
            elif len(per_seq) > 1:  # a report written before: the plain spread, those errors included
                jitter = float(per_seq.std(0, ddof=1).mean())
        entries.append(_entry(name, params))
    for e in report.get("named_effects") or []:
        entries.append(_entry(e["name"], e["params"]))
    for line in report.get("gyro_lines_above_band") or []:  # seen in the gyro alone, above the compared band
        if line.get("simulator_vibration"):
            entries.append(_entry("vibration", line["simulator_vibration"]))
    return {
        "error_model": entries,
        "bias_jitter_rad_s": jitter,
        # null: the simulated dataset keeps its own setting; why the report measured none
        **({"bias_jitter_unset_because": reason} if reason else {}),
        # the rate of the fitted recordings: what lies above its Nyquist frequency was never measured
        "rate_hz": report.get("rate_hz"),
        "source": f"{report.get('command', 'python -m gyrodenoise.discrepancy')}: {report.get('verdict', '')}",
    }


def _entry(name: str, params: dict) -> dict:
    keep = {k: v for k, v in params.items() if k in SIM_EFFECTS[name].DEFAULTS}  # fit-only keys (errors) left out
    entry = {"name": name, "units": "si", "params": keep}
    effect_from_config(entry)  # raises on anything the simulator would not accept
    return entry


def write_simulator_model(path: str | Path, report: dict) -> Path:
    return write_text(path, yaml.safe_dump(simulator_model(report), sort_keys=False))
