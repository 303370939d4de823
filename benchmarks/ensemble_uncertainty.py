"""Is the shipped ensemble's spread a calibrated uncertainty? EuRoC test flights, 1-s windows.

    python benchmarks/ensemble_uncertainty.py --model euroc --out benchmarks/results/ensemble_uncertainty

For each test flight (V1_01 against the recomputed ground truth): the ensemble's corrected gyro and
its per-sample spread (std over the members), the predicted increment error of every 1-s window
from the spread and the actual one against ground truth (`gyrodenoise.uncertainty.calibration`).
Writes OUT.md (Spearman per flight and pooled, reliability table), OUT.json and OUT.png. CPU only.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import hydra

from gyrodenoise import plots
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.config import compose_config
from gyrodenoise.models.ensemble import predict_with_spread
from gyrodenoise.pretrained import load_model
from gyrodenoise.tables import markdown_table
from gyrodenoise.uncertainty import calibration, pooled


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="euroc", help="shipped ensemble name or file (default: %(default)s)")
    ap.add_argument("--window-s", type=float, default=1.0, help="window length in s (default: %(default)s)")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/ensemble_uncertainty"))
    args = ap.parse_args()
    start = time.time()
    cfg = compose_config("train", ["dataset=euroc"])
    dm = hydra.utils.instantiate(cfg.dataset)
    dm.setup("test")
    model, meta = load_model(args.model)
    results, rows = [], []
    for seq in dm.test_part:
        gyro, std = predict_with_spread(model, seq.imu)
        if std is None:
            raise SystemExit(f"{args.model}: a single model has no spread; give an ensemble")
        r = calibration(gyro, std, seq.dt, seq.rot, seq.gt_mask, window_s=args.window_s)
        results.append(r)
        ratio = r.summary()["rms_ratio"]
        rows.append([seq.name, str(len(r.actual)), f"{r.spearman:+.2f}", f"{ratio:.2f}"])
    allr = pooled(results)
    ratio = allr.summary()["rms_ratio"]
    rows.append(["**pooled**", str(len(allr.actual)), f"**{allr.spearman:+.2f}**", f"{ratio:.2f}"])
    bins = [
        [f"{b['rms_predicted_deg']:.4f}", f"{b['rms_actual_deg']:.4f}", str(b["n"])]
        for b in allr.table
        if "rms_predicted_deg" in b
    ]
    md = [
        f"# Ensemble uncertainty: `{meta.get('name', args.model)}` on the EuRoC test flights",
        "",
        f"`python benchmarks/ensemble_uncertainty.py --model {args.model} --out {args.out}` "
        f"({platform.node()}, CPU, {time.time() - start:.0f} s). Windows of {args.window_s:g} s with ground",
        "truth throughout; predicted error from the members' spread (constant-error model over the window),",
        "actual error = ||Log(dR_gt^T dR_est)|| of the open-loop increment. A calibrated spread gives a",
        "positive rank correlation and RMS(actual)/RMS(predicted) = 1.",
        "",
        markdown_table(["flight", "windows", "Spearman (predicted vs actual)", "RMS actual / RMS predicted"], rows),
        "",
        "Reliability (pooled windows binned by predicted error):",
        "",
        markdown_table(["RMS predicted (deg)", "RMS actual (deg)", "windows"], bins),
        "",
        f"![calibration]({args.out.name}.png)",
        "",
    ]
    write_text(args.out.with_suffix(".md"), "\n".join(md))
    write_json(
        args.out.with_suffix(".json"),
        {"spearman_pooled": allr.spearman, "rms_ratio_pooled": ratio, "per_flight": rows, "table": allr.table},
    )
    plots.save(
        plots.calibration_figure(allr, f"{args.model}: EuRoC test, {args.window_s:g}-s windows"),
        args.out.with_suffix(".png"),
    )
    print("\n".join(md[:12]))


if __name__ == "__main__":
    main()
