"""TUM-VI: the shipped calibrated model with the gravity-aided bias tracker, over the 3 room folds.

    python benchmarks/tumvi_tracker.py

The rule is written in benchmarks/queues/tumvi_tracker.txt (committed before any TUM-VI figure of the tracker).
For each fold k (held-out room 1, 3 or 5): the calibrated model fitted on the other two rooms whole (the shipped
`tumvi` recipe, benchmarks/calibrated_cv.py's fit); on the held-out room, part by part, its corrected gyro minus
the causal bias estimate of `gyrodenoise.bias_tracker` for every gain pair of round 7's grid, integrated open
loop; AOE 3D averaged over the parts. Fold k is scored with the gains chosen on the other two folds. The tracker
joins the `tumvi` default only if the three paired differences have a 95% t-interval below 0. Information: the
raw IMU with the tracker. Writes --out .md and .json. CPU only; ~1 min.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from calibrated_cv import fit_fold
from cv_ensemble_figure import aoe_deg
from cv_gravity_bias import GRID, apply_nested_gains, grid_aoe

from gyrodenoise.ablation_stats import PairedDiff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.provenance import machine_description
from gyrodenoise.tables import markdown_table

SOURCES = ("calibrated", "raw IMU")
FOLDS = 3


def fold_grid(fold: int) -> dict:
    """Held-out room of `fold`: per source, the open-loop AOE without the tracker and over the gain grid."""
    model, parts = fit_fold("tumvi", fold, "null")
    row: dict = {"fold": fold, "held_out": parts[0].name, "parts": len(parts)}
    for source in SOURCES:
        gyros = [part.gyro if source == "raw IMU" else predict_gyro(model, part.imu).numpy() for part in parts]
        grid = np.mean([grid_aoe(part, g) for part, g in zip(parts, gyros, strict=True)], axis=0)
        plain = np.mean([aoe_deg(part, g) for part, g in zip(parts, gyros, strict=True)])
        row[source] = {"plain_deg": float(plain), "grid_deg": grid.tolist()}
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/tumvi_tracker"))
    args = ap.parse_args()
    start = time.time()
    folds = [fold_grid(k) for k in range(FOLDS)]
    apply_nested_gains(folds, SOURCES)
    d = PairedDiff(
        tuple(str(f["fold"]) for f in folds),
        tuple(f["calibrated"]["tracked_deg"] - f["calibrated"]["plain_deg"] for f in folds),
    )
    best_all = int(np.argmin(np.mean([f["calibrated"]["grid_deg"] for f in folds], axis=0)))
    result = {
        "command": "python benchmarks/tumvi_tracker.py",
        "rule": "benchmarks/queues/tumvi_tracker.txt",
        "machine": machine_description(),
        "grid": GRID,
        "folds": folds,
        "decision": {
            "diff_mean": d.mean,
            "diff_t_ci": list(d.t_ci),
            "verdict": d.verdict,
            "adopted": bool(d.t_ci[1] < 0),
            "gains_all_folds": list(GRID[best_all]),
        },
        "wall_s": time.time() - start,
    }
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result))
    print(json.dumps(result["decision"]))
    print(report(result))


def report(result: dict) -> str:
    dec = result["decision"]
    rows = [
        [
            f"{f['fold']}: {f['held_out']} ({f['parts']} part{'s' if f['parts'] > 1 else ''})",
            *[
                f"{f[s]['plain_deg']:.2f} → {f[s]['tracked_deg']:.2f} ({f[s]['nested_gains'][0]:g}, "
                f"{f[s]['nested_gains'][1]:g})"
                for s in SOURCES
            ],
        ]
        for f in result["folds"]
    ]
    rows.append(
        [
            "**mean**",
            *[
                f"**{np.mean([f[s]['plain_deg'] for f in result['folds']]):.2f} → "
                f"{np.mean([f[s]['tracked_deg'] for f in result['folds']]):.2f}**"
                for s in SOURCES
            ],
        ]
    )
    lo, hi = dec["diff_t_ci"]
    verdict = "the tracker joins the `tumvi` default" if dec["adopted"] else "not adopted: `tumvi` stays as it is"
    grid_mean = {s: np.mean([f[s]["grid_deg"] for f in result["folds"]], axis=0) for s in SOURCES}
    return (
        "\n".join(
            [
                "# TUM-VI: the calibrated default with the gravity-aided bias tracker (3 room folds)",
                "",
                f"`{result['command']}` ({result['machine']}), {result['wall_s']:.0f} s. Rule: `{result['rule']}` "
                "(written before any TUM-VI figure of the tracker). Held-out room whole, AOE 3D (deg) averaged over "
                "its parts, open loop: without → with the tracker (gains chosen on the other two folds).",
                "",
                markdown_table(["fold: held-out room", *SOURCES], rows),
                "",
                f"calibrated + tracker − calibrated: {dec['diff_mean']:+.2f} deg, 95% t-interval "
                f"[{lo:+.2f}, {hi:+.2f}] ({dec['verdict']}): **{verdict}**. Gains on all three folds: "
                f"k_P={dec['gains_all_folds'][0]:g}, k_I={dec['gains_all_folds'][1]:g}.",
                "",
                "## Gain grid (mean held-out AOE over the 3 folds, deg; information)",
                "",
                markdown_table(
                    ["k_P", "k_I", *SOURCES],
                    [
                        [f"{kp:g}", f"{ki:g}", *[f"{grid_mean[s][i]:.2f}" for s in SOURCES]]
                        for i, (kp, ki) in enumerate(result["grid"])
                    ],
                ),
            ]
        )
        + "\n"
    )


if __name__ == "__main__":
    main()
