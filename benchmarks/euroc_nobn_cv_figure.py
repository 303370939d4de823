"""The rule of benchmarks/queues/euroc_nobn_cv.txt applied to its runs: EuRoC without batch norm, 6 folds.

    python benchmarks/euroc_nobn_cv_figure.py

Per fold k: d_k = the nobn run's held-out-flight AOE minus the mean of ref's three CPU runs on that fold
(rounds 2 and 3, seeds 100+k, 200+k, 300+k). nobn is a candidate for an ensemble round only if the 95%
t-interval of the six d_k lies below 0. The fold models' test AOE is shown for information. Writes
benchmarks/results/euroc_nobn_cv.{md,json}.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gyrodenoise.ablation_stats import paired_diff
from gyrodenoise.atomic import write_json, write_text

RUNS = Path("reports/accuracy_runs")
OUT = Path("benchmarks/results/euroc_nobn_cv")
FOLDS = range(6)


def read(path: Path) -> dict:
    s = json.loads(path.read_text())
    return {
        "val": s["val"]["val/aoe_deg"],
        "test": s["test"].get("test/aoe_deg"),
        "held_out": s["config"]["dataset"]["train_seqs"][s["config"]["dataset"]["cv_fold"]],
        "wall_s": s.get("queue", {}).get("process_wall_time_s"),
        "machine": s["machine"],
    }


def main() -> int:
    nobn, ref = {}, {}
    for k in FOLDS:
        path = RUNS / "euroc_nobn_cv" / f"nobn_f{k}_s{100 + k}.json"
        if not path.is_file():
            raise SystemExit(f"{path}: run not there yet")
        nobn[k] = read(path)
        ref[k] = [read(RUNS / f"euroc_cv{2 if s < 300 else 3}" / f"ref_f{k}_s{s + k}.json") for s in (100, 200, 300)]
    ref_val = {str(k): float(np.mean([r["val"] for r in ref[k]])) for k in FOLDS}
    ref_test = {str(k): float(np.mean([r["test"] for r in ref[k]])) for k in FOLDS}
    d_val = paired_diff({str(k): nobn[k]["val"] for k in FOLDS}, ref_val)[0]
    d_test = paired_diff({str(k): nobn[k]["test"] for k in FOLDS}, ref_test)[0]
    candidate = d_val.t_ci[1] < 0
    members = {k: " / ".join(f"{r['val']:.2f}" for r in ref[k]) for k in FOLDS}
    rows = [
        f"| {k} | {nobn[k]['held_out']} | {members[k]} | {ref_val[str(k)]:.2f} "
        f"| {nobn[k]['val']:.2f} | {nobn[k]['val'] - ref_val[str(k)]:+.2f} | {ref_test[str(k)]:.2f} "
        f"| {nobn[k]['test']:.2f} |"
        for k in FOLDS
    ]
    walls = [r["wall_s"] for r in nobn.values() if r["wall_s"]]
    md = [
        "# EuRoC without batch norm at the 6-fold cross-validation protocol (a screen)",
        "",
        "Rule and runs: `benchmarks/queues/euroc_nobn_cv.txt` (written before the runs). Figures:",
        "`python benchmarks/euroc_nobn_cv_figure.py`. Held-out flight AOE (deg, 3D), final weights of 600-epoch runs",
        "trained on the first 50 s of the other five flights; ref = rounds 2-3 of reports/accuracy.md (same protocol,",
        "2-core VM, one thread per run).",
        "",
        "| fold | held-out flight | ref runs (seeds 100+k / 200+k / 300+k) | ref mean | nobn (seed 100+k) | d "
        "| ref test (mean) | nobn test |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"- held-out figure: ref {np.mean(list(ref_val.values())):.2f}, nobn "
        f"{np.mean([r['val'] for r in nobn.values()]):.2f} deg; d = nobn - ref mean {d_val.mean:+.2f} deg, 95% "
        f"t-interval [{d_val.t_ci[0]:+.2f}, {d_val.t_ci[1]:+.2f}] (6 folds)",
        f"- test (information): d {d_test.mean:+.2f} [{d_test.t_ci[0]:+.2f}, {d_test.t_ci[1]:+.2f}]",
        "- decision: "
        + (
            "nobn is a candidate for an ensemble round"
            if candidate
            else "nobn is not a candidate: ref stays and no round follows"
        ),
        f"- machine: {nobn[0]['machine']}; process wall per nobn run {min(walls):.0f}-{max(walls):.0f} s "
        "(two runs at once, one thread each)",
    ]
    write_text(OUT.with_suffix(".md"), "\n".join(md) + "\n")
    write_json(
        OUT.with_suffix(".json"),
        {
            "nobn": nobn,
            "ref": ref,
            "d_val": {"mean": d_val.mean, "t_ci": list(d_val.t_ci)},
            "d_test": {"mean": d_test.mean, "t_ci": list(d_test.t_ci)},
            "candidate": candidate,
        },
    )
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
