"""Round 3 of the EuRoC recipe selection: score fold ENSEMBLES on the held-out flight (reports/accuracy.md).

    python benchmarks/cv_ensemble_figure.py runs/cv2/reports/accuracy_runs/euroc_cv2 \\
        runs/cv3/reports/accuracy_runs/euroc_cv3 --seeds 100 200 300

The rule is written in benchmarks/queues/cv_round3.txt (committed before its runs). The model folders are
the cross-validation runs' Hydra run folders, named `<recipe>_f<k>_s<seed>` with a model.pt inside. For each
fold k and recipe, the members are the runs of seeds s + k (s in --seeds); each member and the ensemble (the
mean of the members' corrected gyro, what `model=ensemble` computes) are integrated open loop over the
held-out flight, whole, and scored with the AOE 3D, the figure the runs logged as val/aoe_deg (a member's
figure is checked against its committed summary). The candidate replaces the incumbent only if the
paired-by-fold difference of the ensemble figures has a 95 % t-interval below 0. CPU only; ~2 min.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import re
import sys
import time
from pathlib import Path

import hydra
import numpy as np

from gyrodenoise.ablation_stats import PairedDiff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.config import compose_config
from gyrodenoise.metrics import aoe
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.pretrained import load_model
from gyrodenoise.so3 import integrate_gyro
from gyrodenoise.tables import markdown_table

RUN_NAME = re.compile(r"(?P<recipe>[a-z0-9]+)_f(?P<fold>\d+)_s(?P<seed>\d+)$")
SUMMARY_TOLERANCE_DEG = 0.05  # float32 network, float64 integration: members reproduce their logged figure


def find_runs(roots: list[Path]) -> dict[tuple[str, int, int], Path]:
    """(recipe, fold, seed) -> model.pt of every run folder under `roots`."""
    runs = {}
    for root in roots:
        for model in sorted(root.glob("*/model.pt")):
            m = RUN_NAME.match(model.parent.name)
            if m:
                runs[(m["recipe"], int(m["fold"]), int(m["seed"]))] = model
    return runs


def held_out_flight(fold: int):
    """The flight that fold `fold` validates on, whole, with the dataset's ground-truth choices."""
    dm = hydra.utils.instantiate(compose_config("train", ["dataset=euroc", f"dataset.cv_fold={fold}"]).dataset)
    return dm.load(dm.cv_holdout)


REGENERATE = (
    "The model files are not in the repository (their runs' summaries are, in reports/accuracy_runs/). Retrain "
    "them with the queue that made them, collecting the summaries aside (with --collect . the runs whose summary is "
    "committed are skipped), e.g. `python benchmarks/run_queue.py benchmarks/queues/cv_round2.txt --jobs 1 "
    "--threads 1 --out runs/cv2 --collect runs/cv2-summaries` (cv_round3.txt into runs/cv3, cv_round7.txt into "
    "runs/cv7). Runs retrained after the code changed differ from the committed ones by seed-sized amounts "
    "(reports/accuracy.md, round 7)."
)
ROUND3_ROOTS = [Path("runs/cv2/reports/accuracy_runs/euroc_cv2"), Path("runs/cv3/reports/accuracy_runs/euroc_cv3")]
ROUND3_SEEDS = (100, 200, 300)


def fold_run_paths(runs: dict, fold: int, seeds, recipe: str = "ref") -> dict[int, Path]:
    """{seed + fold: model.pt} of the fold's runs of `recipe`; a missing run stops with how to retrain it."""
    paths = {s + fold: runs.get((recipe, fold, s + fold)) for s in seeds}
    missing = [s for s, p in paths.items() if p is None]
    if missing:
        raise SystemExit(f"fold {fold}: missing {recipe} runs of seeds {missing}. {REGENERATE}")
    return paths


def fold_ensemble_and_calibrated(fold: int, runs: dict, recipe: str = "ref", seeds=ROUND3_SEEDS):
    """(held-out flight, mean corrected gyro of the fold's members of seeds s + fold, the corrected gyro of the
    calibrated model the first member's run fitted on the same training flights)."""
    paths = list(fold_run_paths(runs, fold, seeds, recipe).values())
    seq = held_out_flight(fold)
    ens = np.mean([predict_gyro(load_model(p)[0], seq.imu).numpy() for p in paths], axis=0)
    cal = predict_gyro(load_model(paths[0].parent / "calibrated.pt")[0], seq.imu).numpy()
    return seq, ens, cal


def round_decision(folds: list[dict], candidates: list[str]) -> dict:
    """The rule of rounds 5-6: figure = mean over the folds; the candidate with the lowest figure replaces the plain
    ensemble only if the paired-by-fold difference (candidate - ensemble) has a 95% t-interval below 0."""
    figure = {key: float(np.mean([f[key] for f in folds])) for key in ["ensemble", "calibrated", *candidates]}
    best = min(candidates, key=figure.get)
    d = PairedDiff(tuple(str(f["fold"]) for f in folds), tuple(f[best] - f["ensemble"] for f in folds))
    return {
        "figure": figure,
        "chosen": best,
        "diff_mean": d.mean,
        "diff_t_ci": list(d.t_ci),
        "verdict": d.verdict,
        "decision": f"{best} replaces the plain ensemble" if d.t_ci[1] < 0 else "the plain ensemble stays",
    }


def aoe_deg(seq, gyro: np.ndarray) -> float:
    return math.degrees(aoe(seq.rot, integrate_gyro(seq.rot[0], gyro, seq.dt), seq.gt_mask)[0])


def logged_figure(model: Path, collected: list[Path]) -> float | None:
    """val/aoe_deg from the run's committed summary (<collect>/<run name>.json), if there is one."""
    for folder in collected:
        f = folder / f"{model.parent.name}.json"
        if f.is_file():
            return json.loads(f.read_text())["val"]["val/aoe_deg"]
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("roots", type=Path, nargs="+", help="folders of run folders <recipe>_f<k>_s<seed>/model.pt")
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 200, 300], help="member seeds minus the fold")
    ap.add_argument("--incumbent", default="ref")
    ap.add_argument("--candidate", default="whole")
    ap.add_argument("--folds", type=int, default=6)
    ap.add_argument(
        "--summaries",
        type=Path,
        nargs="*",
        default=sorted(Path("reports/accuracy_runs").glob("euroc_cv*")),
        help="folders of the runs' committed summary JSONs (to check each member's figure)",
    )
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/cv_ensemble_figure"))
    ap.add_argument("--rule", default="benchmarks/queues/cv_round3.txt", help="the queue file that holds the rule")
    ap.add_argument("--title", default="Round 3 of the EuRoC recipe selection", help="the report's heading")
    args = ap.parse_args()
    start = time.time()
    runs = find_runs(args.roots)
    recipes = [args.incumbent, args.candidate]
    missing = [
        f"{r}_f{k}_s{s + k}"
        for r in recipes
        for k in range(args.folds)
        for s in args.seeds
        if (r, k, s + k) not in runs
    ]
    if missing:
        raise SystemExit(
            f"missing run folders (with model.pt) under {[str(r) for r in args.roots]}: {missing}. {REGENERATE}"
        )
    folds = []
    for k in range(args.folds):
        seq = held_out_flight(k)
        row = {"fold": k, "held_out": seq.name}
        for r in recipes:
            gyros, members = [], {}
            for s in args.seeds:
                path = runs[(r, k, s + k)]
                model, _ = load_model(path)
                gyros.append(predict_gyro(model, seq.imu).numpy())
                figure, logged = aoe_deg(seq, gyros[-1]), logged_figure(path, args.summaries)
                if logged is not None and abs(figure - logged) > SUMMARY_TOLERANCE_DEG:
                    raise SystemExit(f"{path}: held-out AOE {figure:.3f} deg here, {logged:.3f} in its summary")
                members[f"s{s + k}"] = figure
            row[r] = {"members": members, "ensemble": aoe_deg(seq, np.mean(gyros, axis=0))}
        folds.append(row)
        print(k, seq.name, {r: round(row[r]["ensemble"], 2) for r in recipes}, flush=True)

    def figure(r: str, kind: str) -> list[float]:
        if kind == "ensemble":
            return [f[r]["ensemble"] for f in folds]
        return [float(np.mean(list(f[r]["members"].values()))) for f in folds]

    result = {
        "command": "python benchmarks/cv_ensemble_figure.py " + " ".join(sys.argv[1:]),  # as invoked: options too
        "title": args.title,
        "rule": args.rule,
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "wall_s": time.time() - start,
        "folds": folds,
    }
    for kind in ("ensemble", "single"):  # the rule uses the ensemble figure; the single one is for information
        d = PairedDiff(
            tuple(str(k) for k in range(args.folds)),
            tuple(np.subtract(figure(args.candidate, kind), figure(args.incumbent, kind))),
        )
        result[kind] = {
            "figure": {r: float(np.mean(figure(r, kind))) for r in recipes},
            "diff_mean": d.mean,
            "diff_t_ci": list(d.t_ci),
            "verdict": d.verdict,
        }
    replaced = result["ensemble"]["diff_t_ci"][1] < 0
    result["decision"] = (
        f"{args.candidate} replaces {args.incumbent}" if replaced else f"{args.incumbent} stays the EuRoC recipe"
    )
    write_json(args.out.with_suffix(".json"), result)
    write_text(args.out.with_suffix(".md"), report(result, recipes, args.seeds))
    print(result["decision"], {k: result[k]["figure"] for k in ("ensemble", "single")})


def report(result: dict, recipes: list[str], seeds: list[int]) -> str:
    header = ["fold", "held-out flight"]
    for r in recipes:
        header += [f"{r}: members (seeds {'/'.join(f'{s}+k' for s in seeds)})", f"{r}: ensemble"]
    rows = []
    for f in result["folds"]:
        row = [str(f["fold"]), f["held_out"]]
        for r in recipes:
            row += [" / ".join(f"{v:.2f}" for v in f[r]["members"].values()), f"**{f[r]['ensemble']:.2f}**"]
        rows.append(row)
    lines = [
        f"# {result.get('title', 'Round 3 of the EuRoC recipe selection')}: fold ensembles on the held-out flight",
        "",
        f"`{result['command']}` on {result['machine']}, {result['wall_s']:.0f} s. Rule: `{result['rule']}` "
        "(written before the runs). Held-out-flight AOE 3D (deg), each flight whole.",
        "",
        markdown_table(header, rows),
    ]
    for kind, what in (("ensemble", "ensemble figure (the rule)"), ("single", "single-model figure (information)")):
        k = result[kind]
        lo, hi = k["diff_t_ci"]
        figs = ", ".join(f"{r} {v:.2f}" for r, v in k["figure"].items())
        lines.append(
            f"- {what}: {figs}; {recipes[1]} − {recipes[0]} per fold {k['diff_mean']:+.2f} deg, "
            f"95% t-interval [{lo:+.2f}, {hi:+.2f}] ({k['verdict']})"
        )
    lines += ["", f"**Decision by the rule: {result['decision']}.**", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
