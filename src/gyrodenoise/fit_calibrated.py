"""Hydra entry point: fit the 12-parameter calibrated-IMU model alone (seconds, no training loop).

    python -m gyrodenoise.fit_calibrated dataset=tumvi test=false dataset.train_duration_s=null  # the shipped `tumvi`
    python -m gyrodenoise.fit_calibrated dataset=tumvi test=false dataset.cv_fold=0   # score on a held-out room

The same fit as every training's safety net (`gyrodenoise.baseline.fit_calibrated`: the training loss,
L-BFGS, float64, whole training parts), written as a model file that loads like any other (model.pt) with a
summary.json: the AOE on each validation group ("val": the held-out sequence under cross-validation or the
end of the training sequences; "val_tail": the end of the other training sequences under cross-validation)
and on the test sequences when `test=true` and they exist. Config `fit_calibrated`: the training config with
`model=calibrated`; only its `dataset` and `loss` groups and `model.g_sensitivity` are used (no trainer, no optimiser).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from gyrodenoise.atomic import write_json
from gyrodenoise.baseline import evaluate_on, fit_calibrated
from gyrodenoise.cli_errors import hydra_key_hints, torch_threads, user_errors
from gyrodenoise.data.datamodule import TAIL_NAME_NOTE
from gyrodenoise.job_log import console_to_job_log
from gyrodenoise.metrics import AOE_DEFINITION
from gyrodenoise.paths import invoked_command
from gyrodenoise.pretrained import save_model
from gyrodenoise.provenance import machine_description


def fit(cfg: DictConfig) -> dict:
    """The fit, its scores and files; torch's CPU threads are `threads` (SLURM's cpus-per-task by default, as in
    train) for its length, and as they were after."""
    with torch_threads(cfg.get("threads")):
        return _fit(cfg)


def _fit(cfg: DictConfig) -> dict:
    out_dir = Path(cfg.paths.output_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    dm = hydra.utils.instantiate(cfg.dataset)
    dm.check_sequences(test=bool(cfg.get("test")))
    dm.setup("fit")
    start = time.time()
    g_sensitivity = bool(cfg.model.get("g_sensitivity", False))
    model = fit_calibrated(
        dm.train_part, loss=OmegaConf.to_container(cfg.loss, resolve=True), g_sensitivity=g_sensitivity
    )
    fit_s = time.time() - start
    scores: dict[str, dict[str, float]] = {}
    for group in dict.fromkeys(dm.val_groups):
        seqs = [s for s, g in zip(dm.val_part, dm.val_groups, strict=True) if g == group]
        scores[group] = evaluate_on(model, seqs)
    if cfg.get("test") and dm.test_names:
        dm.setup("test")
        scores["test"] = evaluate_on(model, dm.test_part)
    means = {g: float(np.mean(list(per_seq.values()))) for g, per_seq in scores.items()}
    command = invoked_command("fit_calibrated")
    summary = {
        "command": command,
        **dm.model_meta(),
        "cv_fold": dm.cv_fold,
        "fit_s": fit_s,
        "machine": machine_description(),
        "aoe_deg": means,
        "aoe_deg_per_sequence": scores,
    }
    save_model(
        model,
        {"name": "calibrated", "g_sensitivity": g_sensitivity},
        out_dir / "model.pt",
        meta={
            **dm.model_meta(),
            "fit": "baseline.fit_calibrated",
            "val_aoe_deg": means.get("val"),
            "test": {f"test/aoe_deg/{k}": v for k, v in scores.get("test", {}).items()},
            "machine": summary["machine"],
            "command": command,
        },
    )
    write_json(out_dir / "summary.json", summary)
    for group, per_seq in scores.items():
        cells = ", ".join(f"{k} {v:.2f}" for k, v in per_seq.items())
        print(f"{group} AOE {means[group]:.3f} deg ({cells})")
    if scores:
        print(f"({AOE_DEFINITION} {TAIL_NAME_NOTE})")
    else:
        print(
            "no validation or test data to score on (whole training sequences and test=false): score the fit on a "
            "held-out sequence with dataset.cv_fold=K, or on the test sequences with test=true"
        )
    print(f"fitted in {fit_s:.1f} s; outputs in {out_dir}")
    return summary


@hydra_key_hints("fit_calibrated")
@hydra.main(version_base="1.3", config_path="conf", config_name="fit_calibrated")
def main(cfg: DictConfig) -> float:
    with console_to_job_log(), user_errors():
        summary = fit(cfg)
    return summary["aoe_deg"].get("val", math.nan)


if __name__ == "__main__":
    main()
