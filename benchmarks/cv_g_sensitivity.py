"""Round 10 of the recipe selection (issue 13): the calibrated model with a g-sensitivity term, cross-validated.

    python benchmarks/cv_g_sensitivity.py

Rule, written before any figure: benchmarks/queues/cv_round10.txt. For each fold (dataset.cv_fold=k) the calibrated
model (C_hat, b: 12 parameters) and cal+G (C_hat, b, G: w_hat = C_hat w + b + G a, 21 parameters) are fitted the same
way (`gyrodenoise.baseline.fit_calibrated`) on the other training sequences whole, and scored on the held-out one
whole (open-loop AOE 3D, deg). On EuRoC cal+G is also compared with the ref fold ensembles of round 3
(benchmarks/results/cv_ensemble_figure.json). Information: cal+G fitted on the first 50 s, and the fitted G per fold.
Writes benchmarks/results/cv_g_sensitivity.{md,json}. Deterministic; seconds per fit on the 2-core VM.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from calibrated_cv import fit_fold

from gyrodenoise.ablation_stats import paired_diff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.baseline import evaluate_on
from gyrodenoise.config import compose_config
from gyrodenoise.provenance import machine_description

OUT = Path("benchmarks/results/cv_g_sensitivity")
ROUND3 = Path("benchmarks/results/cv_ensemble_figure.json")
DEG_S_PER_G = 9.80665 * 180 / math.pi  # rad/s per m/s^2 -> deg/s per g


def held_out_aoe(dataset: str, fold: int, duration: str, g_sensitivity: bool) -> tuple[float, str, np.ndarray | None]:
    """(held-out AOE deg, held-out name, G in deg/s/g or None)."""
    model, held_out = fit_fold(dataset, fold, duration, g_sensitivity)
    aoe = float(np.mean(list(evaluate_on(model, held_out).values())))
    G = None if model.G is None else model.G.detach().double().numpy() * DEG_S_PER_G
    return aoe, held_out[0].name, G


def _mean_sd(x: np.ndarray) -> str:
    return f"{x.mean():+.3f} ± {x.std(ddof=1):.3f}"


def interval(d) -> str:
    return f"{d.mean:+.2f} deg, 95% t-interval [{d.t_ci[0]:+.2f}, {d.t_ci[1]:+.2f}] ({d.verdict}; {d.n} folds)"


def dataset_section(dataset: str) -> tuple[list[str], dict]:
    n_folds = len(compose_config("train", [f"dataset={dataset}"]).dataset.train_seqs)
    rows = []
    for k in range(n_folds):
        cal, name, _ = held_out_aoe(dataset, k, "null", False)
        calg, _, G = held_out_aoe(dataset, k, "null", True)
        calg50, _, _ = held_out_aoe(dataset, k, "50", True)
        rows.append({"fold": k, "held_out": name, "cal": cal, "cal_g": calg, "cal_g_first50": calg50, "G": G.tolist()})
    cal = {str(r["fold"]): r["cal"] for r in rows}
    calg = {str(r["fold"]): r["cal_g"] for r in rows}
    decisions = {"B_or_C_vs_cal": paired_diff(calg, cal)[0]}
    ens = {}
    if dataset == "euroc":
        ens = {str(f["fold"]): f["ref"]["ensemble"] for f in json.loads(ROUND3.read_text())["folds"]}
        decisions["A_vs_ref_ensembles"] = paired_diff(calg, ens)[0]
    head = "| fold | held-out | calibrated (whole) | cal+G (whole) | d | cal+G (first 50 s, information) |"
    if ens:
        head += " ref fold ensemble (round 3) |"
    md = [f"## {dataset}", "", head, "|---" * (head.count("|") - 1) + "|"]
    for r in rows:
        line = (
            f"| {r['fold']} | {r['held_out']} | {r['cal']:.2f} | {r['cal_g']:.2f} | {r['cal_g'] - r['cal']:+.2f} "
            f"| {r['cal_g_first50']:.2f} |"
        )
        md.append(line + (f" {ens[str(r['fold'])]:.2f} |" if ens else ""))
    mean = lambda key: np.mean([r[key] for r in rows])  # noqa: E731
    md.append(
        f"| **mean** | | {mean('cal'):.2f} | {mean('cal_g'):.2f} | {mean('cal_g') - mean('cal'):+.2f} "
        f"| {mean('cal_g_first50'):.2f} |" + (f" {np.mean(list(ens.values())):.2f} |" if ens else "")
    )
    md += ["", f"- cal+G - calibrated: {interval(decisions['B_or_C_vs_cal'])}"]
    if ens:
        md.append(f"- cal+G - ref fold ensembles: {interval(decisions['A_vs_ref_ensembles'])}")
    G = np.array([r["G"] for r in rows])
    md += [
        "",
        "Fitted G (deg/s/g; row = gyro axis, column = accelerometer axis), mean and sd over the folds:",
        "",
        "| gyro axis | a_x | a_y | a_z |",
        "|---|---|---|---|",
        *(f"| {'xyz'[i]} | " + " | ".join(_mean_sd(G[:, i, j]) for j in range(3)) + " |" for i in range(3)),
        "",
    ]
    return md, {"folds": rows, "decisions": {k: vars(v) for k, v in decisions.items()}}


def main() -> int:
    # no options; --help shows what it does instead of running it (it writes committed files)
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    t0 = time.perf_counter()
    md, results = [], {}
    for ds in ("euroc", "tumvi"):
        section, results[ds] = dataset_section(ds)
        md += section
    wall = time.perf_counter() - t0
    dA = results["euroc"]["decisions"]["A_vs_ref_ensembles"]
    dB = results["euroc"]["decisions"]["B_or_C_vs_cal"]
    dC = results["tumvi"]["decisions"]["B_or_C_vs_cal"]
    below = lambda d: d["t_ci"][1] < 0  # noqa: E731
    verdict = [
        f"- A (EuRoC, cal+G as `euroc`): {'adopted' if below(dA) else 'not adopted'}.",
        f"- B (EuRoC, cal+G as `euroc-calibrated`): {'adopted' if below(dB) else 'not adopted'}.",
        f"- C (TUM-VI, cal+G as `tumvi`): {'adopted' if below(dC) else 'not adopted'}.",
    ]
    header = [
        "# Round 10: the calibrated model with a g-sensitivity term (21 parameters), cross-validated",
        "",
        f"`python benchmarks/cv_g_sensitivity.py` on {machine_description()}, {wall:.0f} s. Rule: "
        "`benchmarks/queues/cv_round10.txt` (written before any figure). Held-out AOE 3D (deg), each held-out "
        "flight or room whole; d = cal+G - calibrated.",
        "",
        "**Decisions by the rule:**",
        "",
        *verdict,
        "",
    ]
    write_text(OUT.with_suffix(".md"), "\n".join(header + md))
    write_json(OUT.with_suffix(".json"), {"machine": machine_description(), "wall_s": wall, **results})
    print("\n".join(header + md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
