"""Which named effects has a trained denoiser learned? Regress its correction on the effect library.

The model's gyro output is C_hat w_imu + w_tilde. C_hat - I is read directly as scale factor
(diagonal) and misalignment (off-diagonal); w_tilde is treated as a 'residual' and passed through
the same greedy BIC selection as measured data. The correction undoes the sensor's errors, so its
parameters carry the opposite sign of the sensor's.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from gyrodenoise.discrepancy.design import without_reconstruction
from gyrodenoise.discrepancy.rank import select_effects
from gyrodenoise.sim.context import FitContext
from gyrodenoise.sim.effects import EFFECTS

DETERMINISTIC = [
    "scale_factor",
    "misalignment",
    "g_sensitivity",
    "time_offset",
    "vibration",
    "warmup_bias",
    "nonlinearity",
    "nonlinearity_even",
    "scale_asymmetry",
    "bias_random_walk",
]


def network_effects(model: str | Path | tuple[Any, dict], fcs: list[FitContext], bic_threshold: float = 10.0) -> dict:
    """`model`: a shipped name or a model file, or (model, metadata) as `pretrained.load_model` gave them."""
    from gyrodenoise.models.denoiser import predict_gyro
    from gyrodenoise.pretrained import load_model

    net, meta = load_model(model) if isinstance(model, str | Path) else model
    C = net.C_hat.detach().double().cpu().numpy()
    wrapped, explained = [], []
    for fc in fcs:
        imu = np.concatenate([fc.gyro, fc.extra["acc"]], axis=1)
        w_tilde = predict_gyro(net, imu).numpy() - fc.gyro @ C.T
        # residual := w_tilde (the FitContext residual is gyro - omega)
        extra = without_reconstruction(fc.extra)
        wrapped.append(replace(fc, gyro=fc.omega + w_tilde, extra=extra))
    # w_tilde is a function of the IMU samples alone: no reconstruction error, the whole spectrum
    sel = select_effects(
        wrapped, base=["bias"], candidates=DETERMINISTIC, bic_threshold=bic_threshold, trusted_band=False
    )
    learned = []
    for step in sel.steps:
        if "added" in step:
            c = next(c for c in step["candidates"] if c["effect"] == step["added"])
            explained.append({"effect": step["added"], "explained_fraction": c["gain"], "delta_bic": c["delta_bic"]})
    for name in sel.named:
        if name == "white_noise":
            continue
        e = EFFECTS[name]
        ds = {}
        for k, v in sel.params[name].items():
            unit, factor = e.DATASHEET.get(k, ("SI", 1.0))
            ds[k] = {"value": (np.asarray(v) * factor).tolist(), "unit": unit}
        learned.append(
            {"name": name, "params": {k: np.asarray(v).tolist() for k, v in sel.params[name].items()}, "datasheet": ds}
        )
    off = C - np.diag(np.diag(C))
    return {
        "model": meta["name"],  # the shipped name or a portable path, never this machine's install folder
        "model_dataset": meta.get("dataset"),
        "C_hat": C.tolist(),
        "C_hat_as_effects": {
            "scale_factor_ppm": ((np.diag(C) - 1.0) * 1e6).tolist(),
            "misalignment_mrad": [off[i, j] * 1e3 for i, j in [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]],
        },
        "w_tilde_rms_rad_s": float(np.sqrt(np.mean(np.concatenate([w.residual for w in wrapped]) ** 2))),
        "learned_effects": learned,
        "selection": explained,
        "note": "parameters are those of the correction (opposite sign of the sensor's error)",
    }
