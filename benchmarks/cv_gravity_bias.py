"""Round 7 of the EuRoC recipe selection: the flight's gyro bias tracked from gravity, the attitude still open loop.

    python benchmarks/cv_gravity_bias.py [--root runs/cv7/reports/accuracy_runs/euroc_cv7]

The rule is written in benchmarks/queues/cv_round7.txt (committed before its runs and before any EuRoC figure of
the tracker). For each fold k: the ref fold model of seed 100+k (retrained by that queue) and the calibrated model
its run fitted; on the held-out flight, whole, each source's corrected gyro minus the causal bias estimate of
`gyrodenoise.bias_tracker` for every gain pair of the grid, integrated open loop and scored with the AOE 3D.
Fold k is scored with the gains that minimise the mean of the other five folds (nested). The tracker is adopted
only if the six paired differences (network + tracker - network) have a 95% t-interval below 0; only then are
the test flights scored (shipped `euroc` and each of its members, with the gains that minimise the mean over all
six folds). Writes --out .md and .json. CPU only; ~3 min (~6 with the test).
"""

from __future__ import annotations

import argparse
import itertools
import json
import platform
import time
from pathlib import Path

import hydra
import numpy as np
from cv_ensemble_figure import aoe_deg, find_runs, fold_ensemble_and_calibrated, logged_figure

from gyrodenoise.ablation_stats import PairedDiff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.bias_tracker import track_bias
from gyrodenoise.config import compose_config
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.pretrained import load_model
from gyrodenoise.tables import markdown_table

K_P = (0.03, 0.1, 0.3, 1.0)
K_I = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2)
GRID = list(itertools.product(K_P, K_I))
SOURCES = ("network", "calibrated")
SEED = 100
ROUND2 = Path("reports/accuracy_runs/euroc_cv2")
COLLECTED = Path("reports/accuracy_runs/euroc_cv7")


def grid_aoe(seq, gyro: np.ndarray, acc: np.ndarray | None = None) -> list[float]:
    """AOE 3D (deg) of the open-loop integration of gyro - tracked bias, for every gain pair of GRID; the tracker
    is fed `acc` (default: the flight's accelerometer)."""
    kp, ki = np.array(GRID).T
    biases = track_bias(gyro, seq.acc if acc is None else acc, seq.dt, kp, ki)
    return [aoe_deg(seq, gyro - b) for b in biases]


def plain_and_tracked(seq, gyro: np.ndarray, gains: tuple[float, float], acc: np.ndarray | None = None) -> dict:
    """AOE 3D (deg) of gyro as it is and minus the tracked bias at one gain pair (fed `acc`, default the flight's)."""
    kp, ki = np.array([gains[0]]), np.array([gains[1]])
    bias = track_bias(gyro, seq.acc if acc is None else acc, seq.dt, kp, ki)[0]
    return {"plain_deg": aoe_deg(seq, gyro), "tracked_deg": aoe_deg(seq, gyro - bias)}


def nested_choice(grid_by_fold: list[list[float]], fold: int) -> int:
    """Index of the gain pair with the lowest mean AOE over the folds other than `fold`."""
    others = [g for j, g in enumerate(grid_by_fold) if j != fold]
    return int(np.argmin(np.mean(others, axis=0)))


def cross_validation(root: Path) -> list[dict]:
    runs = find_runs([root])
    folds = []
    for k in range(6):
        seq, net, cal = fold_ensemble_and_calibrated(k, runs, "ref", seeds=(SEED,))
        model = runs[("ref", k, SEED + k)]
        row = {
            "fold": k,
            "flight": seq.name,
            "logged_val_deg": logged_figure(model, [COLLECTED]),
            "round2_val_deg": logged_figure(model, [ROUND2]),
        }
        for source, gyro in (("network", net), ("calibrated", cal)):
            row[source] = {"plain_deg": aoe_deg(seq, gyro), "grid_deg": grid_aoe(seq, gyro)}
        print(f"fold {k} {seq.name}: network {row['network']['plain_deg']:.2f} deg", flush=True)
        folds.append(row)
    apply_nested_gains(folds, SOURCES)
    return folds


def apply_nested_gains(folds: list[dict], sources: tuple[str, ...]) -> None:
    """Per source, give each fold the gains chosen on the other folds and its AOE with them (in place)."""
    for source in sources:
        grids = [f[source]["grid_deg"] for f in folds]
        for k, f in enumerate(folds):
            g = nested_choice(grids, k)
            f[source]["nested_gains"] = list(GRID[g])
            f[source]["tracked_deg"] = grids[k][g]


def decision(folds: list[dict]) -> dict:
    d = PairedDiff(
        tuple(str(f["fold"]) for f in folds),
        tuple(f["network"]["tracked_deg"] - f["network"]["plain_deg"] for f in folds),
    )
    adopted = bool(d.t_ci[1] < 0)
    all_folds = int(np.argmin(np.mean([f["network"]["grid_deg"] for f in folds], axis=0)))
    return {
        "diff_mean": d.mean,
        "diff_t_ci": list(d.t_ci),
        "verdict": d.verdict,
        "adopted": adopted,
        "gains_all_folds": list(GRID[all_folds]),
        "decision": "the tracker is adopted as an option" if adopted else "not adopted: open loop stays as it is",
    }


def test_flights(gains: tuple[float, float], acc_offset: np.ndarray | None = None) -> list[dict]:
    """Shipped `euroc` (its ensemble and each member) with and without the tracker, once; the tracker is fed the
    accelerometer minus `acc_offset` (m/s^2, body frame) when one is given."""
    dm = hydra.utils.instantiate(compose_config("train", ["dataset=euroc"]).dataset)
    ensemble = load_model("euroc")[0]
    rows = []
    for name in dm.test_names:
        seq = dm.load(name)
        members = [predict_gyro(m, seq.imu).numpy() for m in ensemble.members]
        sources = {"ensemble": np.mean(members, axis=0), **{f"member {i}": g for i, g in enumerate(members)}}
        acc = seq.acc if acc_offset is None else seq.acc - acc_offset
        row = {"flight": name} | {label: plain_and_tracked(seq, gyro, gains, acc) for label, gyro in sources.items()}
        print(f"test {name}: ensemble {row['ensemble']['plain_deg']:.2f} -> {row['ensemble']['tracked_deg']:.2f}")
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, default=Path("runs/cv7/reports/accuracy_runs/euroc_cv7"))
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/cv_gravity_bias"))
    args = ap.parse_args()
    start = time.time()
    folds = cross_validation(args.root)
    dec = decision(folds)
    print(json.dumps(dec), flush=True)
    test = test_flights(tuple(dec["gains_all_folds"])) if dec["adopted"] else []
    result = run_info("cv_gravity_bias.py", "cv_round7.txt") | {"grid": GRID, "folds": folds, "decision": dec}
    save(args.out, result | {"test": test, "wall_s": time.time() - start}, report)


def run_info(script: str, rule: str) -> dict:
    """The command, the rule file and the machine of a round's figure."""
    return {
        "command": f"python benchmarks/{script}",
        "rule": f"benchmarks/queues/{rule}",
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
    }


def save(out: Path, result: dict, render) -> None:
    """out.json and out.md (rendered by `render`), each written whole; the markdown is printed too."""
    text = render(result)
    write_json(out.with_suffix(".json"), result)
    write_text(out.with_suffix(".md"), text)
    print(text)


def report(result: dict) -> str:
    dec = result["decision"]
    lines = [
        "# Round 7: the gyro bias tracked from gravity, attitude open loop (EuRoC cross-validation)",
        "",
        f"`{result['command']}` on {result['machine']}, {result['wall_s']:.0f} s. Rule: `{result['rule']}` (written "
        "before its runs and before any EuRoC figure of the tracker). Held-out flight whole, AOE 3D (deg), open-loop "
        "integration of the source's corrected gyro minus the causal bias estimate of "
        "`gyrodenoise.bias_tracker.GravityBiasTracker`; each fold uses the gains chosen on the other five folds.",
        "",
    ]
    table = []
    for f in result["folds"]:
        n, c = f["network"], f["calibrated"]
        check = f"{f['logged_val_deg']:.2f} / {f['round2_val_deg']:.2f}" if f["round2_val_deg"] is not None else "-"
        table.append(
            [
                str(f["fold"]),
                f["flight"],
                check,
                f"{n['plain_deg']:.2f}",
                f"{n['tracked_deg']:.2f} ({n['nested_gains'][0]:g}, {n['nested_gains'][1]:g})",
                f"{c['plain_deg']:.2f}",
                f"{c['tracked_deg']:.2f} ({c['nested_gains'][0]:g}, {c['nested_gains'][1]:g})",
            ]
        )
    mean = {
        (s, k): float(np.mean([f[s][k] for f in result["folds"]]))
        for s in SOURCES
        for k in ("plain_deg", "tracked_deg")
    }
    table.append(
        [
            "",
            "**mean**",
            "",
            f"**{mean[('network', 'plain_deg')]:.2f}**",
            f"**{mean[('network', 'tracked_deg')]:.2f}**",
            f"{mean[('calibrated', 'plain_deg')]:.2f}",
            f"{mean[('calibrated', 'tracked_deg')]:.2f}",
        ]
    )
    lo, hi = dec["diff_t_ci"]
    lines += [
        markdown_table(
            [
                "fold",
                "held-out flight",
                "logged val / round 2's run of the same seed",
                "network",
                "network + tracker (k_P, k_I)",
                "calibrated",
                "calibrated + tracker (k_P, k_I)",
            ],
            table,
        ),
        "",
        f"network + tracker − network: {dec['diff_mean']:+.2f} deg, 95% t-interval [{lo:+.2f}, {hi:+.2f}] "
        f"({dec['verdict']}): **{dec['decision']}**. Gains on all six folds: k_P={dec['gains_all_folds'][0]:g}, "
        f"k_I={dec['gains_all_folds'][1]:g}.",
        "",
    ]
    lines += test_section(result["test"])
    lines += ["## Gain grid (mean held-out AOE over the 6 folds, deg; information)", ""]
    grid_mean = {s: np.mean([f[s]["grid_deg"] for f in result["folds"]], axis=0) for s in SOURCES}
    lines.append(
        markdown_table(
            ["k_P", "k_I", *SOURCES],
            [
                [f"{kp:g}", f"{ki:g}", *[f"{grid_mean[s][i]:.2f}" for s in SOURCES]]
                for i, (kp, ki) in enumerate(result["grid"])
            ],
        )
    )
    return "\n".join(lines) + "\n"


def test_section(test: list[dict]) -> list[str]:
    """Markdown lines of the once-only test table (open loop -> with the tracker), or none without a test."""
    if not test:
        return []
    labels = [k for k in test[0] if k != "flight"]
    rows = [[t["flight"], *[f"{t[k]['plain_deg']:.2f} → {t[k]['tracked_deg']:.2f}" for k in labels]] for t in test]
    rows.append(
        [
            "**mean**",
            *[
                f"**{np.mean([t[k]['plain_deg'] for t in test]):.2f} → "
                f"{np.mean([t[k]['tracked_deg'] for t in test]):.2f}**"
                for k in labels
            ],
        ]
    )
    return [
        "## Test flights, once (shipped `euroc`, V1_01 against the recomputed ground truth)",
        "",
        "Open loop → with the tracker, the ensemble and each of its members.",
        "",
        markdown_table(["flight", *labels], rows),
        "",
    ]


if __name__ == "__main__":
    main()
