"""The three gyro sources inside an attitude filter: does the denoiser still help once gravity is used?

    python benchmarks/ahrs_fusion.py [--jobs 2]

Rule written before any figure: benchmarks/queues/ahrs_fusion.txt. Filter: `ahrs.filters.Mahony` (IMU form:
accelerometer tilt correction k_P, integral gyro-bias term k_I), fed each source's gyro and the raw accelerometer,
started from the ground truth. For each source (raw IMU, calibrated model, denoiser ensemble) the gains are the
grid point with the lowest mean held-out AOE over the 6 EuRoC cross-validation folds (fold models trained without
the held-out flight); the 5 test flights are then scored once with those gains (shipped `euroc`,
`euroc-calibrated`, raw). Writes --out .md and .json. CPU only, one Python loop per sample inside `ahrs`:
~15 min on the 2-core VM with --jobs 2. Needs `pip install ahrs` (the `bench` extra).
"""

from __future__ import annotations

import argparse
import itertools
import math
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from ahrs.filters import Mahony
from bias_hindsight import cv_cases, test_cases
from cv_ensemble_figure import aoe_deg
from error_by_window import world_up_in_body
from scipy.spatial.transform import Rotation

from gyrodenoise.ablation_stats import PairedDiff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.metrics import aoe
from gyrodenoise.tables import markdown_table

K_P = (0.01, 0.03, 0.1, 0.3, 1.0)
K_I = (1e-4, 1e-3, 1e-2)
SOURCES = ("raw", "calibrated", "ensemble")
LABELS = {"ref ensemble": "ensemble", "euroc": "ensemble", "calibrated": "calibrated", "euroc-calibrated": "calibrated"}


def mahony(seq, gyro: np.ndarray, k_p: float, k_i: float) -> np.ndarray:
    """(N, 3, 3) body-to-world rotations of the Mahony filter over the flight."""
    q0 = Rotation.from_matrix(seq.rot[0]).as_quat(scalar_first=True)
    f = Mahony(gyr=gyro, acc=seq.acc, frequency=seq.rate_hz, k_P=k_p, k_I=k_i, q0=q0)
    return Rotation.from_quat(f.Q, scalar_first=True).as_matrix()


def scores(seq, gyro: np.ndarray, k_p: float, k_i: float) -> dict:
    """AOE 3D and RMS tilt error (deg) of the filter over the ground-truth samples."""
    est = mahony(seq, gyro, k_p, k_i)
    up_true, up_est = world_up_in_body(seq), est[:, 2, :]
    tilt = np.arccos(np.clip(np.sum(up_true * up_est, axis=1), -1.0, 1.0))[seq.gt_mask]
    return {
        "aoe_deg": math.degrees(aoe(seq.rot, est, seq.gt_mask)[0]),
        "tilt_deg": math.degrees(float(np.sqrt(np.mean(tilt**2)))),
    }


def _task(args: tuple) -> tuple:
    key, seq, gyro, k_p, k_i = args
    return key, scores(seq, gyro, k_p, k_i)


def cases_with_raw(cases: list) -> list[tuple[object, dict[str, np.ndarray]]]:
    """(flight, {source: gyro}) with the raw IMU added and the model labels named by source."""
    return [(seq, {"raw": seq.gyro, **{LABELS[k]: g for k, g in models.items()}}) for _, seq, models in cases]


def run(tasks: list[tuple], jobs: int) -> dict:
    with ProcessPoolExecutor(jobs) as pool:
        return dict(pool.map(_task, tasks, chunksize=1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/ahrs_fusion"))
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    start = time.time()
    cv = cases_with_raw(cv_cases())
    grid = list(itertools.product(K_P, K_I))
    tasks = [((s, i, g), seq, models[s], *g) for i, (seq, models) in enumerate(cv) for s in SOURCES for g in grid]
    cv_scores = run(tasks, args.jobs)
    gains, cv_rows = {}, []
    for s in SOURCES:
        figure = {g: float(np.mean([cv_scores[(s, i, g)]["aoe_deg"] for i in range(len(cv))])) for g in grid}
        gains[s] = min(grid, key=figure.get)
        cv_rows.append({"source": s, "grid": [[*g, v] for g, v in figure.items()], "chosen": list(gains[s])})
    print("gains chosen on the folds:", gains, flush=True)
    test = cases_with_raw(test_cases())
    test_scores = run(
        [((s, i, gains[s]), seq, models[s], *gains[s]) for i, (seq, models) in enumerate(test) for s in SOURCES],
        args.jobs,
    )
    result = {
        "command": "python benchmarks/ahrs_fusion.py",
        "rule": "benchmarks/queues/ahrs_fusion.txt",
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": None,
        "cv_grid": cv_rows,
        "flights": [],
    }
    for set_name, cases, filtered in (("cross-validation", cv, cv_scores), ("test", test, test_scores)):
        for i, (seq, models) in enumerate(cases):
            row = {"set": set_name, "flight": seq.name}
            for s in SOURCES:
                row[s] = {"open_loop_aoe_deg": aoe_deg(seq, models[s]), **filtered[(s, i, gains[s])]}
            result["flights"].append(row)
    result["comparisons"] = comparisons(result["flights"])
    result["wall_s"] = time.time() - start
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result, gains))
    print(report(result, gains))


def comparisons(flights: list[dict]) -> list[dict]:
    out = []
    for set_name in ("cross-validation", "test"):
        rows = [f for f in flights if f["set"] == set_name]
        for other in ("calibrated", "raw"):
            for metric in ("aoe_deg", "open_loop_aoe_deg"):
                d = PairedDiff(
                    tuple(f["flight"] for f in rows), tuple(f["ensemble"][metric] - f[other][metric] for f in rows)
                )
                out.append(
                    {
                        "set": set_name,
                        "vs": other,
                        "metric": metric,
                        "mean": d.mean,
                        "t_ci": list(d.t_ci),
                        "verdict": d.verdict,
                    }
                )
    return out


def report(result: dict, gains: dict) -> str:
    lines = [
        "# The gyro sources inside a Mahony attitude filter (EuRoC)",
        "",
        f"`{result['command']}` on {result['machine']}, {result['wall_s']:.0f} s. Rule: `{result['rule']}` (written "
        "before any figure). Filter: `ahrs.filters.Mahony`, IMU form, started from the ground truth. Gains per "
        "source chosen on the 6 cross-validation folds (held-out flight, fold models), then the test flights once: "
        + ", ".join(f"{s} k_P={gains[s][0]:g} k_I={gains[s][1]:g}" for s in SOURCES)
        + ". Figures in deg: AOE 3D with the filter, RMS tilt error with the filter, and the same source's open-loop "
        "AOE (no filter) for comparison. CV rows use fold models; test rows the shipped `euroc` (ensemble), "
        "`euroc-calibrated` and the raw IMU.",
        "",
    ]
    for set_name in ("cross-validation", "test"):
        rows = [f for f in result["flights"] if f["set"] == set_name]
        table = [
            [
                f["flight"],
                *[f"{f[s]['aoe_deg']:.2f} / {f[s]['tilt_deg']:.2f} / {f[s]['open_loop_aoe_deg']:.2f}" for s in SOURCES],
            ]
            for f in rows
        ]
        mean = {
            s: [np.mean([f[s][m] for f in rows]) for m in ("aoe_deg", "tilt_deg", "open_loop_aoe_deg")] for s in SOURCES
        }
        table.append(["**mean**", *[f"**{a:.2f}** / {b:.2f} / {c:.2f}" for a, b, c in (mean[s] for s in SOURCES)]])
        lines += [
            f"## {set_name}",
            "",
            markdown_table(["flight", *[f"{s}: filter AOE / tilt / open-loop AOE" for s in SOURCES]], table),
            "",
        ]
        for c in result["comparisons"]:
            if c["set"] == set_name:
                what = "with the filter" if c["metric"] == "aoe_deg" else "open loop"
                lo, hi = c["t_ci"]
                lines.append(
                    f"- ensemble − {c['vs']}, {what}: {c['mean']:+.2f} deg, 95% t-interval [{lo:+.2f}, {hi:+.2f}] "
                    f"({c['verdict']})"
                )
        lines.append("")
    lines += ["## Gain grid (mean held-out AOE over the 6 folds, deg)", ""]
    lines.append(
        markdown_table(
            ["k_P", "k_I", *SOURCES],
            [
                [
                    f"{kp:g}",
                    f"{ki:g}",
                    *[f"{dict(((a, b), v) for a, b, v in r['grid'])[(kp, ki)]:.2f}" for r in result["cv_grid"]],
                ]
                for kp, ki in itertools.product(K_P, K_I)
            ],
        )
    )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
