"""Safety net: the 12-parameter calibrated baseline fitted in seconds, and the check that a trained
denoiser beats it.

A network that does not beat a constant C_hat + bias fitted on the same data with the same loss
should not be used. `fit_calibrated` fits that baseline (`CalibratedImu`) with the training
loss (`IncrementLoss`) on whole training sequences, full batch, by L-BFGS in float64: 12
parameters and a smooth loss need no mini-batches, no augmentation and no schedule.
`evaluate_on` scores any model like the validation does (open-loop integration, AOE), and
`safety_meta` gives the metadata a model file carries (`beats_calibrated`, see
`gyrodenoise.pretrained.not_better_warning`).

    cal = fit_calibrated(dm.train_part, loss=cfg.loss)
    meta.update(safety_meta(model, cal, dm.val_part, calibrated_path=out_dir / "calibrated.pt"))
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from collections.abc import Sequence as Seq
from pathlib import Path

import numpy as np
import torch

from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.data.sequence import Sequence, gt_increments
from gyrodenoise.losses import IncrementLoss
from gyrodenoise.metrics import aoe
from gyrodenoise.models.denoiser import CalibratedImu, predict_gyro
from gyrodenoise.models.ensemble import CorrectionModel
from gyrodenoise.so3 import integrate_gyro


def _loss_terms(sequences: Seq[Sequence], step: int, block: int) -> list[tuple[torch.Tensor, ...]]:
    """Per sequence: (imu (1, n, 6), dt (1, n), dR, mask), n = 1 + a multiple of the longest increment."""
    terms = []
    for seq in sequences:
        n = 1 + ((len(seq) - 1) // block) * block
        if n <= 1:
            continue
        s = seq.slice(0, n)
        dR, ok = gt_increments(s, step)
        if not ok.any():
            continue
        terms.append(
            (
                torch.from_numpy(s.imu)[None],
                torch.from_numpy(s.dt)[None],
                torch.from_numpy(dR)[None],
                torch.from_numpy(ok)[None],
            )
        )
    return terms


def fit_calibrated(
    sequences: Seq[Sequence],
    loss: Mapping | None = None,
    weight_decay: float = 0.0,
    max_iter: int = 100,
    g_sensitivity: bool = False,
) -> CalibratedImu:
    """Fit C_hat and the gyro bias (and G, with g_sensitivity) to the training sequences with the increment loss.

    sequences: the training parts (e.g. `ImuDataModule.train_part`); loss: IncrementLoss options (the
    `loss` config of training); weight_decay: an L2 penalty 0.5 * wd * ||theta||^2, what Adam's coupled
    weight decay of training adds (negligible next to the 1e6-weighted loss, hence 0 by default).
    Each sequence's loss is weighted by its number of increments (as if they were one batch).
    Returns the model in eval mode, float32, with the training data's normalisation buffers.
    """
    try:  # python -m gyrodenoise.fit_calibrated: a bad loss setting in one line (train refuses it before any fit)
        loss_fn = IncrementLoss(**dict(loss or {}))
    except (TypeError, ValueError) as e:
        raise ConfigError(f"the loss of fit_calibrated: {e}") from None
    terms = _loss_terms(sequences, loss_fn.base, max(loss_fn.increments))
    if not terms:
        raise ConfigError(  # a ValueError too
            "fit_calibrated: no training sequence has a ground-truth increment to fit (each needs more samples "
            "inside the ground truth's span than the longest loss increment): check that the ground truth covers the "
            "recording"
        )
    weights = torch.tensor([float(t[3].sum()) for t in terms], dtype=torch.float64)
    weights = weights / weights.sum()
    model = CalibratedImu(g_sensitivity).double()
    opt = torch.optim.LBFGS(
        model.parameters(), lr=1.0, max_iter=max_iter, history_size=20, line_search_fn="strong_wolfe"
    )

    def closure() -> torch.Tensor:
        opt.zero_grad()
        total = sum(w * loss_fn(model(imu), dt, dR, m) for w, (imu, dt, dR, m) in zip(weights, terms, strict=True))
        if weight_decay:
            total = total + 0.5 * weight_decay * sum((p**2).sum() for p in model.parameters())
        total.backward()
        return total

    opt.step(closure)
    model = model.float()
    x = np.concatenate([s.imu for s in sequences])
    model.set_normalization(x.mean(0), x.std(0) + 1e-8)  # unused by the baseline; kept like training does
    return model.eval()


def evaluate_on(model: CorrectionModel | None, sequences: Seq[Sequence]) -> dict[str, float]:
    """{sequence name: AOE (deg, 3D)} of the open-loop integration of the corrected gyro (model None: the raw
    gyro), aligned on ground truth at the first sample (as validation and `gyrodenoise.evaluate` do)."""
    out = {}
    for seq in sequences:
        gyro = seq.gyro if model is None else predict_gyro(model, seq.imu).numpy()
        R = integrate_gyro(seq.rot[0], gyro, seq.dt)
        out[seq.name] = math.degrees(aoe(seq.rot, R, seq.gt_mask)[0])
    return out


def safety_meta(
    model: CorrectionModel,
    calibrated: CorrectionModel,
    val_sequences: Seq[Sequence],
    calibrated_path: str | Path | None = None,
) -> dict:
    """Model-file metadata: both models' mean validation AOE (deg) and whether the model beat the
    calibrated baseline (None when there is no validation data)."""
    if not val_sequences:
        return {"beats_calibrated": None, "calibrated_val_aoe_deg": None, "calibrated_model": calibrated_path}
    model_val = float(np.mean(list(evaluate_on(model, val_sequences).values())))
    cal_val = float(np.mean(list(evaluate_on(calibrated, val_sequences).values())))
    return {
        "beats_calibrated": bool(model_val < cal_val),
        "model_val_aoe_deg_whole": model_val,  # whole validation sequences, as evaluate_on scores them
        "calibrated_val_aoe_deg": cal_val,
        "calibrated_model": None if calibrated_path is None else str(calibrated_path),
    }
