"""Round 5 of the EuRoC recipe selection: the calibrated model's fast response plus the ensemble's slow part.

    python benchmarks/cv_slow_part.py

The rule is written in benchmarks/queues/cv_round5.txt (committed before any figure of the candidate). For each
fold k: the 3-member ensemble of ref (seeds 100+k, 200+k, 300+k, rounds 2-3) and the calibrated model fitted by
the same runs on the same training flights; on the held-out flight, whole, slow-T = calibrated + the causal mean
over the past T seconds of (ensemble - calibrated), expanding from the first sample while fewer than T s exist.
AOE 3D per fold; figure = mean over folds; T* = the lowest figure; slow-T* replaces the plain ensemble only if
the paired-by-fold difference has a 95% t-interval below 0. Writes --out .md and .json. CPU only; ~2 min.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
from cv_ensemble_figure import ROUND3_ROOTS, aoe_deg, find_runs, fold_ensemble_and_calibrated, round_decision

from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.tables import markdown_table

WINDOWS_S: tuple[float | None, ...] = (2.0, 10.0, 30.0, 100.0, None)  # None: the whole past


def causal_mean(x: np.ndarray, n: int | None) -> np.ndarray:
    """Mean of x over its last n samples (rows) at each sample, over all samples so far while fewer than n
    exist; n None: over the whole past."""
    c = np.cumsum(x, axis=0)
    count = np.arange(1, len(x) + 1, dtype=float)[:, None]
    if n is None or n >= len(x):
        return c / count
    out = c / count
    out[n:] = (c[n:] - c[:-n]) / n
    return out


def label(window_s: float | None) -> str:
    return "slow-all" if window_s is None else f"slow-{window_s:g}s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/cv_slow_part"))
    args = ap.parse_args()
    start = time.time()
    runs = find_runs(ROUND3_ROOTS)
    folds = []
    for k in range(6):
        seq, ens, cal = fold_ensemble_and_calibrated(k, runs)
        rate_hz = 1.0 / float(np.median(seq.dt))
        row = {"fold": k, "held_out": seq.name, "ensemble": aoe_deg(seq, ens), "calibrated": aoe_deg(seq, cal)}
        for w in WINDOWS_S:
            n = None if w is None else round(w * rate_hz)
            row[label(w)] = aoe_deg(seq, cal + causal_mean(ens - cal, n))
        folds.append(row)
        print(k, seq.name, {key: round(v, 2) for key, v in row.items() if isinstance(v, float)}, flush=True)
    candidates = [label(w) for w in WINDOWS_S]
    result = {
        "command": "python benchmarks/cv_slow_part.py",
        "rule": "benchmarks/queues/cv_round5.txt",
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": time.time() - start,
        "folds": folds,
        **round_decision(folds, candidates),
    }
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result, candidates))
    print(result["decision"], {k: round(v, 2) for k, v in result["figure"].items()})


def report(result: dict, candidates: list[str]) -> str:
    keys = ["ensemble", "calibrated", *candidates]
    rows = [[str(f["fold"]), f["held_out"], *[f"{f[k]:.2f}" for k in keys]] for f in result["folds"]]
    rows.append(["", "**mean**", *[f"**{result['figure'][k]:.2f}**" for k in keys]])
    lo, hi = result["diff_t_ci"]
    return "\n".join(
        [
            "# Round 5 of the EuRoC selection: calibrated fast response + the ensemble's slow part",
            "",
            f"`{result['command']}` on {result['machine']}, {result['wall_s']:.0f} s. Rule: `{result['rule']}` "
            "(written before any figure of the candidate). Held-out-flight AOE 3D (deg), each flight whole. "
            "slow-T: calibrated + causal mean over the past T of (ensemble - calibrated).",
            "",
            markdown_table(["fold", "held-out flight", *keys], rows),
            "",
            f"- T* (lowest figure, chosen on these folds): {result['chosen']}; {result['chosen']} − ensemble per fold "
            f"{result['diff_mean']:+.2f} deg, 95% t-interval [{lo:+.2f}, {hi:+.2f}] ({result['verdict']})",
            "",
            f"**Decision by the rule: {result['decision']}.**",
            "",
        ]
    )


if __name__ == "__main__":
    main()
