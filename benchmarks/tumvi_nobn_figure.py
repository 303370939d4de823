"""The rule of benchmarks/queues/tumvi_nobn.txt applied to its runs: TUM-VI denoiser without batch norm vs ref.

    python benchmarks/tumvi_nobn_figure.py [--runs reports/accuracy_runs/tumvi_nobn]

Reads the collected summaries (<arm>_f<fold>_s<seed>.json), pairs the arms by fold and seed, and writes
benchmarks/results/tumvi_nobn.{md,json}: every run's held-out-room AOE and its own calibrated baseline's, each
arm's figure (mean over its runs), the paired differences with 95% t-intervals, and the decision of the rule.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np

from gyrodenoise.ablation_stats import PairedDiff, paired_diff
from gyrodenoise.atomic import write_json, write_text

OUT = Path("benchmarks/results/tumvi_nobn")
NAME = re.compile(r"(?P<arm>[a-z]+)_f(?P<fold>\d)_s(?P<seed>\d+)\.json")
ARMS = ("ref", "nobn")


def load(folder: Path, arms: tuple[str, ...] = ARMS) -> dict[str, dict[str, dict]]:
    """arm -> 'f<fold>_s<seed>' -> {'model': held-out AOE, 'calibrated': its calibrated baseline's, ...}."""
    runs: dict[str, dict[str, dict]] = {a: {} for a in arms}
    for path in sorted(folder.glob("*.json")):
        m = NAME.fullmatch(path.name)
        if m is None or m["arm"] not in runs:
            raise SystemExit(f"{path}: not a run of this queue (expected <{'|'.join(arms)}>_f<fold>_s<seed>.json)")
        s = json.loads(path.read_text())
        runs[m["arm"]][f"f{m['fold']}_s{m['seed']}"] = {
            "model": s["val"]["val/aoe_deg"],
            "calibrated": s["calibrated_baseline"]["calibrated_val_aoe_deg"],
            "val_tail": s["val"].get("val_tail/aoe_deg"),
            "wall_s": s["queue"]["process_wall_time_s"],
            "machine": s["machine"],
        }
    return runs


def fmt(d: PairedDiff) -> str:
    return f"{d.mean:+.2f} [{d.t_ci[0]:+.2f}, {d.t_ci[1]:+.2f}] ({d.verdict})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=Path, default=Path("reports/accuracy_runs/tumvi_nobn"))
    args = ap.parse_args()
    runs = load(args.runs)
    model = {a: {k: r["model"] for k, r in runs[a].items()} for a in ARMS}
    calibrated = {a: {k: r["calibrated"] for k, r in runs[a].items()} for a in ARMS}
    nobn_vs_ref = paired_diff(model["nobn"], model["ref"])[0]
    vs_cal = {a: paired_diff(model[a], calibrated[a])[0] for a in ARMS}
    better = nobn_vs_ref.t_ci[1] < 0
    ships = [a for a in ARMS if vs_cal[a].t_ci[1] < 0 and (a == "ref" or better)]
    decision = (
        f"{' and '.join(ships)} beats its calibrated baselines: the rule lets it replace the calibrated `tumvi` default"
        if ships
        else "no denoiser recipe beats the calibrated baseline: `tumvi` stays the calibrated model"
    )
    rows = [
        f"| {k} | {runs['ref'][k]['model']:.2f} | {runs['nobn'][k]['model']:.2f} | {runs['ref'][k]['calibrated']:.2f} "
        f"| {runs['ref'][k]['val_tail'] or float('nan'):.2f} | {runs['nobn'][k]['val_tail'] or float('nan'):.2f} |"
        for k in sorted(runs["ref"].keys() & runs["nobn"].keys())
    ]
    machines = sorted({r["machine"] for a in ARMS for r in runs[a].values()})
    md = [
        "# TUM-VI: a denoiser without batch norm against ref (leave-one-room-out)",
        "",
        "Rule and runs: `benchmarks/queues/tumvi_nobn.txt` (written before the runs). Figures:",
        f"`python benchmarks/tumvi_nobn_figure.py --runs {args.runs}`. Held-out room AOE (deg, 3D) of the final",
        "weights of each 600-epoch run; 'calibrated' is the 12-parameter baseline each run fits on the same split",
        "(the same for both arms of a fold); val_tail is the end of the training rooms (the paper's validation).",
        "",
        "| fold, seed | ref | nobn | calibrated | ref val_tail | nobn val_tail |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
        f"- figure (mean over runs): ref {np.mean(list(model['ref'].values())):.2f}, "
        f"nobn {np.mean(list(model['nobn'].values())):.2f}, "
        f"calibrated {np.mean(list(calibrated['ref'].values())):.2f} deg",
        f"- nobn - ref: {fmt(nobn_vs_ref)}",
        *(f"- {a} - its calibrated baseline: {fmt(vs_cal[a])}" for a in ARMS),
        f"- decision: {decision}",
        f"- machine: {', '.join(machines)}; process wall per run "
        f"{min(r['wall_s'] for a in ARMS for r in runs[a].values()):.0f}-"
        f"{max(r['wall_s'] for a in ARMS for r in runs[a].values()):.0f} s (two runs at once, one thread each)",
    ]
    write_text(OUT.with_suffix(".md"), "\n".join(md) + "\n")
    write_json(
        OUT.with_suffix(".json"),
        {
            "runs": runs,
            "nobn_minus_ref": {"mean": nobn_vs_ref.mean, "t_ci": list(nobn_vs_ref.t_ci), "n": nobn_vs_ref.n},
            "minus_calibrated": {a: {"mean": d.mean, "t_ci": list(d.t_ci), "n": d.n} for a, d in vs_cal.items()},
            "decision": decision,
        },
    )
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
