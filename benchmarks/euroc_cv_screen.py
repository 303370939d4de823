"""The rule of a EuRoC cross-validation screen applied to its runs: each arm against ref, 6 folds.

    python benchmarks/euroc_cv_screen.py nobn            # benchmarks/queues/euroc_nobn_cv.txt
    python benchmarks/euroc_cv_screen.py acc_input       # benchmarks/queues/euroc_acc_input_cv.txt
    python benchmarks/euroc_cv_screen.py acc_diff_round  # benchmarks/queues/euroc_acc_diff_round.txt
    python benchmarks/euroc_cv_screen.py whole_diff_round  # benchmarks/queues/euroc_whole_diff_round.txt
    python benchmarks/euroc_cv_screen.py reg             # benchmarks/queues/euroc_reg_cv.txt

Per arm and fold k: d_k = the mean held-out-flight AOE of the arm's runs (seed 100+k in a screen; 100+k, 200+k and
300+k in a round) minus the mean of ref's three CPU runs on that fold (rounds 2 and 3, seeds 100+k, 200+k, 300+k).
An arm is a candidate only if the 95% t-interval of its six d_k lies below 0. The fold models' test AOE is shown for
information. Writes benchmarks/results/<name>.{md,json}.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gyrodenoise.ablation_stats import paired_diff
from gyrodenoise.atomic import write_json, write_text

RUNS = Path("reports/accuracy_runs")
RESULTS = Path("benchmarks/results")
FOLDS = range(6)


@dataclass(frozen=True)
class Screen:
    name: str  # result in RESULTS/name.{md,json}, rule in benchmarks/queues/name.txt
    title: str
    arms: dict[str, str]  # run-name prefix -> what the arm is
    decision: str  # the sentence the rule adds for an arm's interval
    runs: str = ""  # the runs' folder under RUNS (default: name)
    seeds: tuple[int, ...] = (100,)  # seed = s + k on fold k
    training: str = "the first 50 s of the other five flights"
    # other recipes' runs of the same seeds, set against the arm for information: label -> (folder, run-name prefix)
    information: dict[str, tuple[str, str]] | None = None


SCREENS = {
    "nobn": Screen(
        "euroc_nobn_cv",
        "EuRoC without batch norm at the 6-fold cross-validation protocol (a screen)",
        {"nobn": "without batch norm"},
        "",
    ),
    "acc_input": Screen(
        "euroc_acc_input_cv",
        "EuRoC: the network's accelerometer input at the 6-fold cross-validation protocol (a screen)",
        {"diff": "the accelerometer's first difference", "none": "no accelerometer (gyro only)"},
        "for `none`, an interval above 0 would resolve that the accelerometer input helps (the paper's design)",
    ),
    "acc_diff_round": Screen(
        "euroc_acc_diff_round",
        "EuRoC: the accelerometer's first difference at 3 seeds per fold (round 2's design)",
        {"diff": "the accelerometer's first difference"},
        "a candidate is not shipped by this round (streaming/export support and the 8-seed ensemble come first)",
        runs="euroc_acc_input_cv",
        seeds=(100, 200, 300),
    ),
    "whole_diff_round": Screen(
        "euroc_whole_diff_round",
        "EuRoC: whole training flights with the accelerometer's first difference, 3 seeds per fold",
        {"wdiff": "whole training flights, the accelerometer's first difference"},
        "a candidate is not shipped by this round (streaming/export support and the 8-seed ensemble come first)",
        runs="euroc_whole_diff",
        seeds=(100, 200, 300),
        training="the other five flights whole",
        information={"whole": ("euroc_cv{2|3}", "whole"), "diff": ("euroc_acc_input_cv", "diff")},
    ),
    "reg": Screen(
        "euroc_reg_cv",
        "EuRoC: stronger regularisation at the 6-fold cross-validation protocol (a screen)",
        {"wd05": "Adam weight decay 0.5 (default 0.1)", "do25": "dropout 0.25 (default 0.1)"},
        "",
    ),
}


def read(path: Path) -> dict:
    if not path.is_file():
        raise SystemExit(f"{path}: run not there yet")
    s = json.loads(path.read_text())
    return {
        "val": s["val"]["val/aoe_deg"],
        "test": s["test"].get("test/aoe_deg"),
        "held_out": s["config"]["dataset"]["train_seqs"][s["config"]["dataset"]["cv_fold"]],
        "wall_s": s.get("queue", {}).get("process_wall_time_s"),
        "machine": s["machine"],
    }


def run_path(folder: str, prefix: str, fold: int, seed: int) -> Path:
    """The summary of run `<prefix>_f<fold>_s<seed + fold>`; folder "euroc_cv{2|3}": rounds 2 (seeds 100+k, 200+k)
    and 3 (seeds 300+k), where ref's and whole's CPU runs are."""
    if folder == "euroc_cv{2|3}":
        folder = f"euroc_cv{2 if seed < 300 else 3}"
    return RUNS / folder / f"{prefix}_f{fold}_s{seed + fold}.json"


def _mean_run(runs: list[dict]) -> dict:
    """One fold's runs of an arm as one: mean val and test AOE, each run's val kept for the table."""
    return {
        **runs[0],
        "val": float(np.mean([r["val"] for r in runs])),
        "test": float(np.mean([r["test"] for r in runs])),
        "vals": [r["val"] for r in runs],
        "walls": [r["wall_s"] for r in runs if r["wall_s"]],
    }


def interval(d) -> str:
    return f"{d.mean:+.2f} deg, 95% t-interval [{d.t_ci[0]:+.2f}, {d.t_ci[1]:+.2f}]"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("screen", choices=sorted(SCREENS))
    screen = SCREENS[parser.parse_args().screen]
    ref = {k: [read(run_path("euroc_cv{2|3}", "ref", k, s)) for s in (100, 200, 300)] for k in FOLDS}
    folder = RUNS / (screen.runs or screen.name)
    per_seed = {
        a: {k: [read(folder / f"{a}_f{k}_s{s + k}.json") for s in screen.seeds] for k in FOLDS} for a in screen.arms
    }
    arms = {a: {k: _mean_run(runs[k]) for k in FOLDS} for a, runs in per_seed.items()}
    ref_val = {str(k): float(np.mean([r["val"] for r in ref[k]])) for k in FOLDS}
    ref_test = {str(k): float(np.mean([r["test"] for r in ref[k]])) for k in FOLDS}
    d_val = {a: paired_diff({str(k): runs[k]["val"] for k in FOLDS}, ref_val)[0] for a, runs in arms.items()}
    d_test = {a: paired_diff({str(k): runs[k]["test"] for k in FOLDS}, ref_test)[0] for a, runs in arms.items()}
    candidate = {a: d_val[a].t_ci[1] < 0 for a in arms}
    held_out = arms[next(iter(arms))]
    members = {k: " / ".join(f"{r['val']:.2f}" for r in ref[k]) for k in FOLDS}
    seeds = " / ".join(f"{s}+k" for s in screen.seeds)
    arm_cols = [f"{a} (seed {seeds}) | d" for a in arms]

    def shown(run: dict) -> str:  # one seed: its AOE; several: each, then their mean
        return (
            f"{run['val']:.2f}"
            if len(run["vals"]) == 1
            else " / ".join(f"{v:.2f}" for v in run["vals"]) + (f" (mean {run['val']:.2f})")
        )

    rows = [
        f"| {k} | {held_out[k]['held_out']} | {members[k]} | {ref_val[str(k)]:.2f} | "
        + " | ".join(f"{shown(runs[k])} | {runs[k]['val'] - ref_val[str(k)]:+.2f}" for runs in arms.values())
        + f" | {ref_test[str(k)]:.2f} | "
        + " | ".join(f"{runs[k]['test']:.2f}" for runs in arms.values())
        + " |"
        for k in FOLDS
    ]
    n_cols = 4 + 2 * len(arms) + 1 + len(arms)
    walls = [w for runs in arms.values() for r in runs.values() for w in r["walls"]]
    machines = sorted({r["machine"] for runs in per_seed.values() for rs in runs.values() for r in rs})
    md = [
        f"# {screen.title}",
        "",
        f"Rule and runs: `benchmarks/queues/{screen.name}.txt` (written before the runs). Figures:",
        f"`python benchmarks/euroc_cv_screen.py {parser.parse_args().screen}`. Held-out flight AOE (deg, 3D), final "
        "weights of 600-epoch runs",
        f"trained on {screen.training}; ref = rounds 2-3 of reports/accuracy.md ("
        + ("same protocol" if screen.training == Screen.training else "trained on the first 50 s of the other five")
        + ",",
        "2-core VM, one thread per run).",
    ]
    if len(arms) > 1:
        md += ["", "Arms: " + "; ".join(f"`{a}` = {what}" for a, what in screen.arms.items()) + "."]
    md += [
        "",
        "| fold | held-out flight | ref runs (seeds 100+k / 200+k / 300+k) | ref mean | "
        + " | ".join(arm_cols)
        + " | ref test (mean) | "
        + " | ".join(f"{a} test" for a in arms)
        + " |",
        "|" + "---|" * n_cols,
        *rows,
        "",
    ]
    for a, runs in arms.items():
        val_mean = np.mean([r["val"] for r in runs.values()])
        md += [
            f"- held-out figure: ref {np.mean(list(ref_val.values())):.2f}, {a} {val_mean:.2f} deg; d = {a} - ref mean "
            f"{interval(d_val[a])} (6 folds)",
            f"- test (information): d {d_test[a].mean:+.2f} [{d_test[a].t_ci[0]:+.2f}, {d_test[a].t_ci[1]:+.2f}]",
            f"- decision: {a} is a candidate for an ensemble round"
            if candidate[a]
            else f"- decision: {a} is not a candidate: ref stays and no round follows",
        ]
    if screen.decision:
        md.append(f"- the rule also says: {screen.decision}")
    info = {}
    for label, (other_folder, prefix) in (screen.information or {}).items():
        other = {
            str(k): float(np.mean([read(run_path(other_folder, prefix, k, s))["val"] for s in screen.seeds]))
            for k in FOLDS
        }
        for a, runs in arms.items():
            d = paired_diff({str(k): runs[k]["val"] for k in FOLDS}, other)[0]
            info[f"d_val_{a}_vs_{label}"] = {"mean": d.mean, "t_ci": list(d.t_ci), label: other}
            md.append(
                f"- information, decides nothing: {a} - {label} (same seeds, per fold: "
                + ", ".join(f"{runs[k]['val'] - other[str(k)]:+.2f}" for k in FOLDS)
                + f") {interval(d)}"
            )
    md.append(
        f"- machine: {'; '.join(machines)}; process wall per run {min(walls):.0f}-{max(walls):.0f} s "
        "(two runs at once, one thread each)"
    )
    out = RESULTS / screen.name
    write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
    summary = {
        "ref": ref,
        **arms,
        **{
            key: {"mean": d[a].mean, "t_ci": list(d[a].t_ci)}
            for a in arms
            for key, d in ((f"d_val_{a}", d_val), (f"d_test_{a}", d_test))
        },
        "candidate": candidate,
        **info,
    }
    write_json(out.with_suffix(".json"), summary)
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
