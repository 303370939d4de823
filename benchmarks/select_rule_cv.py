"""Which weights should a run keep: the final ones (`select=last`) or the best on the end of the training flights
(`select=best_val`)? Judged on the flight neither rule sees, from the validation logs of cross-validation runs.

    python benchmarks/select_rule_cv.py [--roots DIR ...] [--out benchmarks/results/select_rule_cv]

The rule is written in benchmarks/queues/select_rule.txt (committed before this script's first figure). Each run
folder `<recipe>_f<fold>_s<seed>` under the roots holds csv/metrics.csv, with val_tail/aoe_deg (the end of the
training flights) and val/aoe_deg (the held-out flight, whole) at every validation. Per run: e* = the validation
epoch with the lowest val_tail figure; d = held-out AOE at e* - held-out AOE at the last validation (the final
weights). Decision: recipe ref, d averaged per fold, 95% t-interval of the per-fold means below 0 -> best_val.
Writes --out .md and .json. Reads the runs' logs only (no model is run): a few seconds, but the run folders
(runs/cv2 ... runs/cv4, from the queues named in reports/accuracy.md) are not committed: retrain them to rerun this.
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import time
from pathlib import Path

import numpy as np
from cv_ensemble_figure import RUN_NAME

from gyrodenoise.ablation_stats import PairedDiff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.tables import markdown_table

ROOTS = [Path(f"runs/cv{r}/reports/accuracy_runs/euroc_cv{r}") for r in (2, 3, 4)]
DECIDING_RECIPE = "ref"
SELECT_BY, JUDGE_BY = "val_tail/aoe_deg", "val/aoe_deg"


def validations(metrics_csv: Path, epochs: int) -> list[tuple[int, float, float]] | None:
    """(epoch, val_tail AOE, held-out AOE) of every validation during the fit (epochs < `epochs`) in a Lightning CSV
    log, in epoch order; None for a run without an end-of-training-flights group (trained on whole flights:
    best_val has nothing to select by). The row at epoch `epochs` is train.py validating the kept model after the
    fit again (the summary's figure), not a checkpoint of its own: dropped."""
    rows = {}
    with metrics_csv.open(newline="") as f:
        reader = csv.DictReader(f)
        if JUDGE_BY not in (reader.fieldnames or []):
            raise SystemExit(f"{metrics_csv}: no column {JUDGE_BY}; is this a run with dataset.cv_fold set?")
        if SELECT_BY not in reader.fieldnames:
            return None
        for line, row in enumerate(reader, start=2):
            if not row[SELECT_BY] and not row[JUDGE_BY]:
                continue  # a training-loss or learning-rate row
            if not (row[SELECT_BY] and row[JUDGE_BY]):
                raise SystemExit(f"{metrics_csv}:{line}: epoch {row['epoch']} logs one validation group of two")
            if int(row["epoch"]) < epochs:
                rows[int(row["epoch"])] = (float(row[SELECT_BY]), float(row[JUDGE_BY]))
    if not rows:
        raise SystemExit(f"{metrics_csv}: no validation rows")
    return [(e, *rows[e]) for e in sorted(rows)]


def run_figures(folder: Path) -> dict | None:
    """The two rules' epochs and held-out AOEs of one run (None: no end-of-training-flights validation)."""
    summary = folder / "summary.json"
    if not summary.is_file():
        raise SystemExit(f"{summary}: missing; the run's epochs are read from it (an unfinished run?)")
    vals = validations(folder / "csv" / "metrics.csv", int(json.loads(summary.read_text())["epochs"]))
    if vals is None:
        return None
    best = min(vals, key=lambda v: v[1])  # first of equal minima, as ModelCheckpoint keeps the first
    last = vals[-1]
    m = RUN_NAME.match(folder.name)
    return {
        "run": folder.name,
        "recipe": m["recipe"],
        "fold": int(m["fold"]),
        "seed": int(m["seed"]),
        "validations": len(vals),
        "best_epoch": best[0],
        "last_epoch": last[0],
        "heldout_best_val": best[2],
        "heldout_last": last[2],
        "d": best[2] - last[2],
    }


def per_fold(runs: list[dict]) -> PairedDiff:
    """d averaged over each fold's runs; one value per fold."""
    folds = sorted({r["fold"] for r in runs})
    return PairedDiff(
        tuple(str(k) for k in folds), tuple(np.mean([r["d"] for r in runs if r["fold"] == k]) for k in folds)
    )


def per_run(runs: list[dict]) -> PairedDiff:
    return PairedDiff(tuple(r["run"] for r in runs), tuple(r["d"] for r in runs))


def summarise(d: PairedDiff) -> dict:
    return {"n": d.n, "mean": d.mean, "sd": d.sd, "t_ci": list(d.t_ci), "verdict": d.verdict}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--roots", nargs="+", type=Path, default=ROOTS)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/select_rule_cv"))
    args = ap.parse_args()
    start = time.time()
    folders = sorted(
        p.parent.parent
        for root in args.roots
        for p in root.glob("*/csv/metrics.csv")
        if RUN_NAME.match(p.parent.parent.name)
    )
    if not folders:
        raise SystemExit(f"no run folders with csv/metrics.csv under {[str(r) for r in args.roots]}")
    figures = {f.name: run_figures(f) for f in folders}
    runs = [r for r in figures.values() if r is not None]
    skipped = sorted(name for name, r in figures.items() if r is None)
    recipes = sorted({r["recipe"] for r in runs})
    deciding = [r for r in runs if r["recipe"] == DECIDING_RECIPE]
    if len({r["fold"] for r in deciding}) < 2:
        raise SystemExit(f"recipe {DECIDING_RECIPE}: runs of fewer than 2 folds, no interval")
    decide = per_fold(deciding)
    result = {
        "rule": "benchmarks/queues/select_rule.txt",
        "roots": [str(r) for r in args.roots],
        "decision": {
            **summarise(decide),
            "per_fold": dict(zip(decide.seeds, decide.diffs, strict=True)),
            "adopt_best_val": bool(decide.t_ci[1] < 0),
        },
        "all_recipes_per_fold": summarise(per_fold(runs)),
        "per_recipe_per_fold": {rc: summarise(per_fold([r for r in runs if r["recipe"] == rc])) for rc in recipes},
        "per_run": summarise(per_run(runs)),
        "runs": runs,
        "skipped_no_val_tail": skipped,
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": time.time() - start,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result))
    verdict = "best_val becomes the default" if result["decision"]["adopt_best_val"] else "last stays the default"
    print(f"ref, per fold: d = {decide.mean:+.2f} deg [{decide.t_ci[0]:+.2f}, {decide.t_ci[1]:+.2f}]: {verdict}")


def ci(s: dict) -> str:
    return f"{s['mean']:+.2f} [{s['t_ci'][0]:+.2f}, {s['t_ci'][1]:+.2f}]"


def report(result: dict) -> str:
    dec = result["decision"]
    lines = [
        "# Which weights a run keeps: final weights or best on the end of the training flights",
        "",
        f"`python benchmarks/select_rule_cv.py` on {result['machine']}, {result['wall_s']:.0f} s; rule written before "
        "this figure in `benchmarks/queues/select_rule.txt`. From the validation logs (every 50 epochs) of the "
        f"{len(result['runs'])} usable CPU cross-validation runs of rounds 2-4 (600-epoch cosine cycle): per run, "
        "d = held-out-flight AOE (whole, deg) of the weights with the lowest AOE on the end of the training flights "
        "(`select=best_val`) minus that of the final weights (`select=last`). d < 0: best_val did better on the "
        "flight neither rule looked at.",
        "",
        f"**Decision (recipe {DECIDING_RECIPE}, d averaged per fold, 95% t-interval over the "
        f"{dec['n']} folds): d = {ci(dec)} deg: "
        + ("`select: best_val` becomes the default.**" if dec["adopt_best_val"] else "`select: last` stays.**"),
        "",
        "| figure (deciding nothing but the first row) | n | mean d [95% t-interval] (deg) | verdict |",
        "|---|---|---|---|",
        f"| {DECIDING_RECIPE}, per fold (decides) | {dec['n']} | {ci(dec)} | {dec['verdict']} |",
    ]
    for rc, s in result["per_recipe_per_fold"].items():
        if rc != DECIDING_RECIPE:
            lines.append(f"| {rc}, per fold | {s['n']} | {ci(s)} | {s['verdict']} |")
    a, p = result["all_recipes_per_fold"], result["per_run"]
    lines += [
        f"| all recipes, per fold | {a['n']} | {ci(a)} | {a['verdict']} |",
        f"| all recipes, per run | {p['n']} | {ci(p)} | {p['verdict']} |",
        "",
        f"Not usable ({len(result['skipped_no_val_tail'])} runs, trained on the whole flights: no end of the "
        "training flights to validate on, so `best_val` has nothing to select by): "
        + (", ".join(result["skipped_no_val_tail"]) or "none")
        + ".",
        "",
        "Every run:",
        "",
    ]
    rows = [
        [r["run"], str(r["best_epoch"]), f"{r['heldout_best_val']:.2f}", f"{r['heldout_last']:.2f}", f"{r['d']:+.2f}"]
        for r in sorted(result["runs"], key=lambda r: (r["recipe"], r["fold"], r["seed"]))
    ]
    lines.append(markdown_table(["run", "best_val epoch", "held-out AOE, best_val", "held-out AOE, last", "d"], rows))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
