"""How much training data the 12-parameter calibrated model needs: leave-one-sequence-out cross-validation.

    python benchmarks/calibrated_cv.py [--datasets tumvi euroc]

For each fold k (dataset.cv_fold=k) the calibrated model is fitted (`gyrodenoise.baseline.fit_calibrated`, the
same L-BFGS fit as `python -m gyrodenoise.fit_calibrated` and every training's safety net) on the other training
sequences, either their first `train_duration_s` (the paper's split, 50 s) or whole, and scored on the held-out
sequence whole (open-loop AOE, deg); the raw IMU integrated as it comes is scored on the same sequence. Writes
benchmarks/results/calibrated_cv.{md,json}. Deterministic; ~1 s per fit on the 2-core VM.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import hydra
import numpy as np

from gyrodenoise.ablation_stats import paired_diff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.baseline import evaluate_on, fit_calibrated
from gyrodenoise.config import compose_config
from gyrodenoise.data.sequence import Sequence
from gyrodenoise.models.denoiser import CalibratedImu
from gyrodenoise.provenance import machine_description

OUT = Path("benchmarks/results/calibrated_cv")
DURATIONS = {"first 50 s": "50", "whole": "null"}


def fit_fold(
    dataset: str, fold: int, duration: str, g_sensitivity: bool = False
) -> tuple[CalibratedImu, list[Sequence]]:
    """The calibrated model (with its g-sensitivity term if asked) fitted on the training sequences of `fold` (their
    first `duration` s, or "null": whole) and the held-out sequence's parts (whole; split only at ground-truth gaps)."""
    overrides = [f"dataset={dataset}", f"dataset.cv_fold={fold}", f"dataset.train_duration_s={duration}"]
    cfg = compose_config("train", overrides)
    dm = hydra.utils.instantiate(cfg.dataset)
    dm.setup("fit")
    held_out = [s for s, g in zip(dm.val_part, dm.val_groups, strict=True) if g == "val"]
    return fit_calibrated(dm.train_part, loss=dict(cfg.loss), g_sensitivity=g_sensitivity), held_out


def fold_scores(dataset: str, fold: int) -> dict[str, float | str]:
    """{'held-out': name, 'raw IMU': AOE, 'first 50 s': AOE, 'whole': AOE} on the held-out sequence of `fold`."""
    out: dict[str, float | str] = {}
    for label, duration in DURATIONS.items():
        model, held_out = fit_fold(dataset, fold, duration)
        out[label] = float(np.mean(list(evaluate_on(model, held_out).values())))
    out["held-out"] = held_out[0].name
    out["raw IMU"] = evaluate_on(None, held_out)[held_out[0].name]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", nargs="+", default=["tumvi", "euroc"])
    args = ap.parse_args()
    results: dict[str, list[dict]] = {}
    md = [
        "# The calibrated model's training data: first 50 s or whole sequences (leave-one-sequence-out)",
        "",
        f"`python benchmarks/calibrated_cv.py --datasets {' '.join(args.datasets)}` ({machine_description()}).",
        "Held-out sequence AOE (deg, 3D), open loop; the calibrated model fitted on the other training sequences.",
        "",
    ]
    for ds in args.datasets:
        n_folds = len(compose_config("train", [f"dataset={ds}"]).dataset.train_seqs)
        rows = [fold_scores(ds, k) for k in range(n_folds)]
        results[ds] = rows
        whole = {str(k): r["whole"] for k, r in enumerate(rows)}
        first = {str(k): r["first 50 s"] for k, r in enumerate(rows)}
        raw = {str(k): r["raw IMU"] for k, r in enumerate(rows)}
        d_first, d_raw = paired_diff(whole, first)[0], paired_diff(whole, raw)[0]
        md += [
            f"## {ds}",
            "",
            "| fold | held-out | raw IMU | calibrated, first 50 s | calibrated, whole |",
            "|---|---|---|---|---|",
            *(
                f"| {k} | {r['held-out']} | {r['raw IMU']:.2f} | {r['first 50 s']:.2f} | {r['whole']:.2f} |"
                for k, r in enumerate(rows)
            ),
            f"| **mean** | | {np.mean(list(raw.values())):.2f} | {np.mean(list(first.values())):.2f} "
            f"| {np.mean(list(whole.values())):.2f} |",
            "",
            f"- whole - first 50 s: {d_first.mean:+.2f} deg, 95% t-interval [{d_first.t_ci[0]:+.2f}, "
            f"{d_first.t_ci[1]:+.2f}] ({d_first.verdict}; {d_first.n} folds)",
            f"- whole - raw IMU: {d_raw.mean:+.2f} deg, 95% t-interval [{d_raw.t_ci[0]:+.2f}, {d_raw.t_ci[1]:+.2f}] "
            f"({d_raw.verdict})",
            "",
        ]
    write_text(OUT.with_suffix(".md"), "\n".join(md))
    write_json(OUT.with_suffix(".json"), {"machine": machine_description(), "folds": results})
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
