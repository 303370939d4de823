"""EMA models with their batch-norm statistics recomputed for the averaged weights, scored like the run.

Lightning's EMAWeightAveraging (callbacks=ema) averages the batch-norm running statistics along with the
weights (use_buffers=True); statistics averaged over 100 epochs need not belong to the averaged weights.
This recomputes them on the run's own training crops (weight_averaging.recompute_batch_norm: the cumulative
mean over `--batches` training batches, drawn as in training, dropout and augmentation included) and
validates and tests the result with the run's data configuration, beside the EMA and the raw final
weights the run itself reported (summary.json: val/test and val_raw_final/test_raw_final). The decision
rule is fixed in benchmarks/queues/ema.txt.

    python benchmarks/ema_bn_recompute.py RUN_DIR [RUN_DIR ...] [--batches 50] [--out FILE]

RUN_DIR: a training output directory holding model.pt, summary.json and .hydra/config.yaml.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path

import hydra
import lightning as L
import torch
from omegaconf import OmegaConf

from gyrodenoise import atomic
from gyrodenoise.ablation_stats import paired_diff
from gyrodenoise.lit import DenoiserModule
from gyrodenoise.paths import portable_command, portable_path
from gyrodenoise.pretrained import load_model
from gyrodenoise.weight_averaging import recompute_batch_norm, training_inputs

OUT = Path(__file__).parent / "results" / "ema_bn_recompute.json"


def score_run(run_dir: Path, batches: int, seed: int) -> dict:
    cfg = OmegaConf.load(run_dir / ".hydra" / "config.yaml")
    summary = json.loads((run_dir / "summary.json").read_text())
    L.seed_everything(seed, workers=True)
    dm = hydra.utils.instantiate(cfg.dataset)
    dm.setup("fit")
    model, _ = load_model(run_dir / "model.pt")
    module = DenoiserModule.from_config(cfg)
    module.model.load_state_dict(model.state_dict())  # the EMA weights and normalisation of model.pt
    t0 = time.time()
    recompute_batch_norm(module.model, training_inputs(dm, batches))
    bn_s = time.time() - t0
    module.model.eval()
    trainer = L.Trainer(
        accelerator="cpu", logger=False, enable_checkpointing=False, enable_progress_bar=False, callbacks=[]
    )
    val = trainer.validate(module, datamodule=dm, verbose=False)[0]
    test = trainer.test(module, datamodule=dm, verbose=False)[0]
    return {
        "run": portable_path(run_dir),
        "seed": summary.get("seed"),
        "bn_batches": batches,
        "bn_recompute_s": bn_s,
        "val_ema_bn": val["val/aoe_deg"],
        "test_ema_bn": test["test/aoe_deg"],
        "val_ema": summary["val"]["val/aoe_deg"],
        "test_ema": summary["test"]["test/aoe_deg"],
        "val_raw": summary["val_raw_final"]["val/aoe_deg"],
        "test_raw": summary["test_raw_final"]["test/aoe_deg"],
        "test_ema_bn_per_sequence": {k.split("/")[-1]: v for k, v in test.items() if k.startswith("test/aoe_deg/")},
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--batches", type=int, default=50, help="training batches for the statistics")
    p.add_argument("--seed", type=int, default=0, help="seed of the crops drawn for the statistics")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args()
    for r in args.runs:
        for f in ("model.pt", "summary.json", ".hydra/config.yaml"):
            if not (r / f).is_file():
                sys.exit(f"{r}: no {f}; give training output directories (model.pt, summary.json, .hydra/).")
    rows = [score_run(r, args.batches, args.seed) for r in args.runs]
    diffs = {}
    for split in ("val", "test"):
        for other in ("raw", "ema"):
            d, _, _ = paired_diff(
                {str(r["seed"]): r[f"{split}_ema_bn"] for r in rows},
                {str(r["seed"]): r[f"{split}_{other}"] for r in rows},
            )
            diffs[f"{split}: ema_bn - {other}"] = {
                "mean": d.mean,
                "t_interval_95": list(d.t_ci),
                "verdict": d.verdict,
            }
    result = {
        "command": "python benchmarks/ema_bn_recompute.py " + portable_command(sys.argv[1:]),
        "machine": f"{platform.node()} ({platform.machine()}, {torch.get_num_threads()} threads)",
        "runs": rows,
        "paired": diffs,
    }
    atomic.write_json(args.out, result)
    print(f"{'seed':>4} {'val raw/ema/ema+bn':>22} {'test raw/ema/ema+bn':>22}")
    for r in rows:
        print(
            f"{r['seed']:>4} {r['val_raw']:6.2f} {r['val_ema']:6.2f} {r['val_ema_bn']:6.2f}  "
            f"{r['test_raw']:6.2f} {r['test_ema']:6.2f} {r['test_ema_bn']:6.2f}"
        )
    for k, v in diffs.items():
        lo, hi = v["t_interval_95"]
        print(f"{k}: {v['mean']:+.2f} [{lo:+.2f}, {hi:+.2f}] {v['verdict']}" if math.isfinite(lo) else k)


if __name__ == "__main__":
    main()
