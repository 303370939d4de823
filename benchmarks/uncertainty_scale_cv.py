"""A spread scale for the shipped EuRoC ensemble, fitted on cross-validation (issue 13, item 2).

    python benchmarks/uncertainty_scale_cv.py [--round7 runs/cv7/reports/accuracy_runs/euroc_cv7]
                                              [--round8 runs/cv8/reports/accuracy_runs/euroc_cv8]

The rule is written in benchmarks/queues/uncertainty_scale.txt (committed before this script first ran). For each
fold k, the ensemble of the three ref fold models of seeds 100+k (round 7) and 400+k, 500+k (round 8), trained
without flight k, is run on flight k whole; its spread (sample std over the members) predicts the error of every
1-s increment and the open-loop integration of its mean gives the actual one (`gyrodenoise.uncertainty`).
r_k = RMS(actual) / RMS(predicted); the scale is the median of the six r_k, adopted when the 95% t-interval of
log r_k excludes 0. Each member's held-out AOE is checked against the val/aoe_deg its run logged.
Writes --out .md, .json and .png. CPU only; ~1 min.
"""

from __future__ import annotations

import argparse
import math
import platform
import time
from pathlib import Path

import numpy as np
from cv_ensemble_figure import SUMMARY_TOLERANCE_DEG, aoe_deg, find_runs, fold_run_paths, held_out_flight, logged_figure

from gyrodenoise import plots
from gyrodenoise.ablation_stats import PairedDiff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.models.ensemble import EnsembleCorrection, predict_with_spread
from gyrodenoise.pretrained import load_model
from gyrodenoise.tables import markdown_table
from gyrodenoise.uncertainty import calibration, pooled

SEEDS = (100, 400, 500)  # member seeds minus the fold: round 7's run and round 8's two
COLLECTED = [Path("reports/accuracy_runs/euroc_cv7"), Path("reports/accuracy_runs/euroc_cv8")]
RULE = "benchmarks/queues/uncertainty_scale.txt"


def score_fold(fold: int, runs: dict, window_s: float):
    """(row of numbers, calibration result) of fold `fold`'s 3-member ensemble on its held-out flight."""
    paths = fold_run_paths(runs, fold, SEEDS)
    seq = held_out_flight(fold)
    models = []
    for path in paths.values():
        model = load_model(path)[0]
        figure, logged = aoe_deg(seq, predict_gyro(model, seq.imu).numpy()), logged_figure(path, COLLECTED)
        if logged is not None and abs(figure - logged) > SUMMARY_TOLERANCE_DEG:
            raise SystemExit(f"{path}: held-out AOE {figure:.3f} deg here, {logged:.3f} in its summary")
        models.append(model)
    gyro, std = predict_with_spread(EnsembleCorrection(models), seq.imu)
    cal = calibration(gyro, std, seq.dt, seq.rot, seq.gt_mask, window_s=window_s)
    s = cal.summary()
    row = {
        "fold": fold,
        "flight": seq.name,
        "members": [f"ref_f{fold}_s{s}" for s in paths],
        "ensemble_aoe_deg": aoe_deg(seq, gyro),
        "windows": s["windows"],
        "spearman": s["spearman"],
        "rms_actual_deg": s["rms_actual_deg"],
        "rms_predicted_deg": s["rms_predicted_deg"],
        "ratio": s["rms_ratio"],
    }
    print(f"fold {fold} {seq.name}: ratio {row['ratio']:.2f}, Spearman {row['spearman']:+.2f}", flush=True)
    return row, cal


def decide(rows: list[dict]) -> dict:
    """The rule: s = median r_k (2 decimals); adopted if the t-interval of log r_k excludes 0."""
    logs = PairedDiff(tuple(str(r["fold"]) for r in rows), tuple(math.log(r["ratio"]) for r in rows))
    lo, hi = logs.t_ci
    adopted = bool(lo > 0 or hi < 0)
    scale = round(float(np.median([r["ratio"] for r in rows])), 2)
    return {
        "scale_median": scale,
        "log_ratio_mean": logs.mean,
        "log_ratio_t_ci": [lo, hi],
        "ratio_t_ci": [math.exp(lo), math.exp(hi)],
        "adopted": adopted,
        "spread_scale": scale if adopted else 1.0,
        "decision": f"`euroc` ships with spread_scale = {scale:.2f}"
        if adopted
        else "not resolved: `euroc` keeps spread_scale = 1",
    }


def report(result: dict) -> str:
    rows = [
        [
            str(r["fold"]),
            r["flight"],
            " / ".join(r["members"]),
            f"{r['ensemble_aoe_deg']:.2f}",
            str(r["windows"]),
            f"{r['spearman']:+.2f}",
            f"{r['rms_predicted_deg']:.3f}",
            f"{r['rms_actual_deg']:.3f}",
            f"**{r['ratio']:.2f}**",
        ]
        for r in result["folds"]
    ]
    d, p = result["decision"], result["pooled"]
    head = ["fold", "held-out flight", "members", "ensemble AOE (deg)", "1-s windows", "Spearman"]
    head += ["RMS predicted (deg)", "RMS actual (deg)", "r_k = actual / predicted"]
    return "\n".join(
        [
            "# A spread scale for the EuRoC ensemble, fitted on cross-validation",
            "",
            f"Command: `{result['command']}`  ",
            f"Machine: {result['machine']}; {result['wall_s']:.0f} s. Rule: `{RULE}` (committed before this ran).",
            "",
            "Each fold's ensemble (3 ref models trained without the held-out flight) on that flight, whole; "
            "predicted 1-s increment error from the members' spread (constant over the window), actual from "
            "the open-loop integration of their mean.",
            "",
            markdown_table(head, rows),
            "",
            f"- Scale (the rule): median r_k = **{d['scale_median']:.2f}**; log r_k mean {d['log_ratio_mean']:+.3f}, "
            f"95% t-interval [{d['log_ratio_t_ci'][0]:+.3f}, {d['log_ratio_t_ci'][1]:+.3f}] "
            f"(ratio [{d['ratio_t_ci'][0]:.2f}, {d['ratio_t_ci'][1]:.2f}]).",
            f"- Decision: {d['decision']}.",
            f"- Information, not used by the rule: all {p['windows']} windows pooled, Spearman {p['spearman']:+.2f}, "
            f"RMS ratio {p['ratio']:.2f} (fold 0's extrapolation weighs most in a pooled figure).",
            "",
            f"![pooled calibration]({Path(result['out']).name}.png)",
            "",
        ]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--round7", type=Path, default=Path("runs/cv7/reports/accuracy_runs/euroc_cv7"))
    ap.add_argument("--round8", type=Path, default=Path("runs/cv8/reports/accuracy_runs/euroc_cv8"))
    ap.add_argument("--window-s", type=float, default=1.0)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/uncertainty_scale_cv"))
    args = ap.parse_args()
    start = time.time()
    runs = find_runs([args.round7, args.round8])
    scored = [score_fold(k, runs, args.window_s) for k in range(6)]
    rows = [r for r, _ in scored]
    allr = pooled([c for _, c in scored])
    result = {
        "command": f"python benchmarks/uncertainty_scale_cv.py --round7 {args.round7} --round8 {args.round8}",
        "rule": RULE,
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": time.time() - start,
        "window_s": args.window_s,
        "folds": rows,
        "decision": decide(rows),
        "pooled": {
            "windows": len(allr.actual),
            "spearman": allr.spearman,
            "ratio": allr.summary()["rms_ratio"],
        },
        "out": str(args.out),
    }
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result))
    plots.save(
        plots.calibration_figure(allr, f"fold ensembles (K=3) on their held-out flights, {args.window_s:g}-s windows"),
        args.out.with_suffix(".png"),
    )
    print(result["decision"]["decision"])


if __name__ == "__main__":
    main()
