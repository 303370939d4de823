"""The rule of benchmarks/queues/tumvi_round2.txt applied to its runs: can a TUM-VI denoiser beat calibration?

    python benchmarks/tumvi_round2_figure.py [--runs reports/accuracy_runs/tumvi_round2]
        [--round1 reports/accuracy_runs/tumvi_nobn]

Per run, d = held-out-room AOE minus that of the calibrated baseline the run fits on its own training data.
The decision uses the fold means of d (3 folds; the two seeds of a fold share their data): an arm qualifies
when their t-interval lies below 0 at 97.5% (95% with a Bonferroni factor for the two arms). Round 1's nobn
arm is shown on the same footing for comparison only. Writes benchmarks/results/tumvi_round2.{md,json}.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from tumvi_nobn_figure import load

from gyrodenoise.ablation_stats import paired_diff, t_interval
from gyrodenoise.atomic import write_json, write_text

OUT = Path("benchmarks/results/tumvi_round2")
ARMS = ("nobnwhole", "nobnsmall")
CONFIDENCE = 0.975  # 95% over two arms (Bonferroni)


def fold_means(runs: dict[str, dict]) -> dict[int, float]:
    """Fold -> mean over its seeds of d = model - calibrated."""
    by_fold: dict[int, list[float]] = {}
    for key, r in runs.items():
        by_fold.setdefault(int(key[1 : key.index("_")]), []).append(r["model"] - r["calibrated"])
    return {k: float(np.mean(v)) for k, v in sorted(by_fold.items())}


def verdict(runs: dict[str, dict]) -> dict:
    """The rule's figure for one arm, and the 6-run interval of round 1's kind (information)."""
    folds = fold_means(runs)
    d = np.array(list(folds.values()))
    lo, hi = t_interval(float(d.mean()), float(d.std(ddof=1)), len(d), CONFIDENCE)
    per_run = paired_diff({k: r["model"] for k, r in runs.items()}, {k: r["calibrated"] for k, r in runs.items()})[0]
    return {
        "aoe": float(np.mean([r["model"] for r in runs.values()])),
        "calibrated": float(np.mean([r["calibrated"] for r in runs.values()])),
        "fold_d": folds,
        "d": float(d.mean()),
        "t_ci_975_folds": [lo, hi],
        "qualifies": bool(hi < 0),
        "runs_d_t_ci_95": [per_run.mean, *per_run.t_ci],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=Path, default=Path("reports/accuracy_runs/tumvi_round2"))
    ap.add_argument("--round1", type=Path, default=Path("reports/accuracy_runs/tumvi_nobn"))
    args = ap.parse_args()
    runs = load(args.runs, ARMS)
    missing = [a for a in ARMS if len(runs[a]) != 6]
    if missing:
        raise SystemExit(f"{args.runs}: arms {missing} do not have their 6 runs yet")
    round1 = load(args.round1, ("ref", "nobn"))["nobn"]
    arms = {a: verdict(runs[a]) for a in ARMS}
    info = verdict(round1)
    qualified = [a for a in ARMS if arms[a]["qualifies"]]
    winner = min(qualified, key=lambda a: arms[a]["aoe"]) if qualified else None
    decision = (
        f"{winner} qualifies: it replaces the calibrated `tumvi` default, as a 4-seed ensemble on all three rooms"
        if winner
        else "no arm qualifies: `tumvi` stays the calibrated model"
    )
    keys = sorted(runs[ARMS[0]])
    rows = [
        f"| {k} | {runs['nobnwhole'][k]['model']:.2f} | {runs['nobnwhole'][k]['calibrated']:.2f} "
        f"| {runs['nobnsmall'][k]['model']:.2f} | {runs['nobnsmall'][k]['calibrated']:.2f} "
        f"| {round1[k]['model']:.2f} |"
        for k in keys
    ]

    def line(name: str, v: dict) -> str:
        folds = " / ".join(f"{x:+.2f}" for x in v["fold_d"].values())
        lo, hi = v["t_ci_975_folds"]
        m, rlo, rhi = v["runs_d_t_ci_95"]
        return (
            f"| {name} | {v['aoe']:.2f} | {v['calibrated']:.2f} | {folds} | {v['d']:+.2f} [{lo:+.2f}, {hi:+.2f}] "
            f"| {m:+.2f} [{rlo:+.2f}, {rhi:+.2f}] |"
        )

    walls = [r["wall_s"] for a in ARMS for r in runs[a].values()]
    machines = sorted({r["machine"] for a in ARMS for r in runs[a].values()})
    md = [
        "# TUM-VI round 2: nobn with whole rooms or a 0.2 deg/s output scale, against calibration",
        "",
        "Rule and runs: `benchmarks/queues/tumvi_round2.txt` (written before the runs). Figures:",
        f"`python benchmarks/tumvi_round2_figure.py --runs {args.runs}`. Held-out room AOE (deg, 3D), final weights",
        "of 600-epoch runs; 'calibrated' is the 12-parameter baseline each run fits on its own training data",
        "(for nobnwhole, the whole rooms too). Round 1's nobn (50 s per room, same folds and seeds) for comparison.",
        "",
        "| fold, seed | nobnwhole | its calibrated | nobnsmall | its calibrated | round 1 nobn |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
        "d = denoiser - its calibrated baseline (deg); the rule: fold means of d, t-interval at 97.5%, below 0.",
        "",
        "| arm | AOE | calibrated | d per fold (0 / 1 / 2) | mean d [97.5% t, 3 folds] | mean d [95% t, 6 runs] |",
        "|---|---|---|---|---|---|",
        *(line(a, arms[a]) for a in ARMS),
        line("round 1 nobn (information)", info),
        "",
        f"- decision: {decision}",
        f"- machine: {', '.join(machines)}; process wall per run {min(walls):.0f}-{max(walls):.0f} s "
        "(two runs at once, one thread each)",
    ]
    write_text(OUT.with_suffix(".md"), "\n".join(md) + "\n")
    write_json(OUT.with_suffix(".json"), {"runs": runs, "arms": arms, "round1_nobn": info, "decision": decision})
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
