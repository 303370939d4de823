"""What more seeds would buy the EuRoC cross-validation: the paired differences of the committed rounds split into the
part that changes from one held-out flight to the next and the part that changes with the seed.

    python benchmarks/cv_power.py     # benchmarks/results/cv_power.{md,json}; reads committed run summaries only

Per arm and fold k, at each seed s run in both: d[k, s] = held-out-flight AOE of the arm minus that of ref at the
same seed (rounds 2-4 and the accelerometer rounds: separate trainings; round 8: the same fold model with and without
the gravity-aided bias tracker). `gyrodenoise.ablation_stats.fold_seed_spread` splits d into the fold's own effect
(sd between folds, which no number of seeds averages away) and the seed's (sd within a fold), and gives the smallest
difference a t-test over six fold means finds with 80 % power at 1, 3, 10 and infinitely many seeds per fold. The
same on log AOE (100 ln(arm/ref): a relative difference). This designs the next round; it re-decides none of the
committed ones.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from euroc_cv_screen import read, run_path  # a sibling script: run as python benchmarks/cv_power.py

from gyrodenoise import plots
from gyrodenoise.ablation_stats import FoldSeedSpread, fold_seed_spread
from gyrodenoise.atomic import write_json, write_text

REF_RUNS = "euroc_cv{2|3}"  # ref's and whole's CPU runs of rounds 2 (seeds 100+k, 200+k) and 3 (300+k)
OUT = Path("benchmarks/results/cv_power")
FOLDS = range(6)
SEEDS = (100, 200, 300)  # seed s + k on fold k
TRAINED_ARMS = {  # run-name prefix -> (folder under reports/accuracy_runs, what the arm is)
    "whole": (REF_RUNS, "whole training flights (rounds 2-3)"),
    "tilt": ("euroc_cv4", "tilt augmentation (round 4)"),
    "diff": ("euroc_acc_input_cv", "the accelerometer's first difference (its round)"),
    "wdiff": ("euroc_whole_diff", "whole flights with the first difference (its round)"),
}
SEED_COUNTS = (1, 3, 10, math.inf)


def trained_pairs(prefix: str, folder: str) -> tuple[np.ndarray, np.ndarray]:
    """(arm, ref) held-out AOE, (6 folds, 3 seeds), read as the screens read them."""
    arm = np.array([[read(run_path(folder, prefix, k, s))["val"] for s in SEEDS] for k in FOLDS])
    ref = np.array([[read(run_path(REF_RUNS, "ref", k, s))["val"] for s in SEEDS] for k in FOLDS])
    return arm, ref


def tracker_pairs() -> tuple[np.ndarray, np.ndarray]:
    """Round 8 (fixed gains, seeds 400+k and 500+k): (tracked, plain) held-out AOE of the same fold models."""
    folds = json.loads(Path("benchmarks/results/cv_tracker_confirm.json").read_text())["folds"]
    runs = {f["fold"]: f["runs"] for f in folds}
    tracked = np.array([[runs[k][str(s + k)]["tracked_deg"] for s in (400, 500)] for k in FOLDS])
    plain = np.array([[runs[k][str(s + k)]["plain_deg"] for s in (400, 500)] for k in FOLDS])
    return tracked, plain


def row(label: str, s: FoldSeedSpread, scale=lambda x: x) -> str:
    mde = " | ".join(f"{scale(s.detectable(n)):.2f}" for n in SEED_COUNTS)
    need = s.seeds_for(s.mean)
    return (
        f"| {label} | {s.n_seeds} | {scale(s.mean):+.2f} | {scale(s.between_sd):.2f} "
        f"({scale(s.between_sd_upper()):.2f}) | {scale(s.within_sd):.2f} | "
        f"{s.interaction_f:.1f} (p {s.interaction_p:.3f}) | {mde} | {'never' if math.isinf(need) else f'{need:.0f}'} |"
    )


def figure(raw: dict[str, FoldSeedSpread]):
    """The detectable difference against the seeds per fold, one line per arm, its measured |mean d| marked."""
    fig, ax = plots.subplots(figsize=(7.0, 4.2))
    seeds = np.geomspace(1, 300, 80)
    for i, (label, s) in enumerate(raw.items()):
        color = f"C{i}"
        ax.plot(seeds, [s.detectable(n) for n in seeds], color=color, label=label.split(":")[0])
        ax.axhline(abs(s.mean), color=color, linestyle=":", linewidth=1)
    ax.set_xscale("log")
    ax.set_xlabel("seeds per fold (6 folds)")
    ax.set_ylabel("detectable difference, 80 % power (deg)")
    ax.set_title("held-out flight AOE: what more seeds buy (dotted: each arm's measured |mean d|)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def percent(x: float) -> float:
    """A difference of natural-log AOE in log-percent (100 ln ratio: ~% for small values, symmetric for large)."""
    return 100.0 * x


def main() -> int:
    # no options; --help shows what it does instead of running it (it writes committed files)
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    pairs = {f"{prefix}: {what}": trained_pairs(prefix, folder) for prefix, (folder, what) in TRAINED_ARMS.items()}
    pairs["tracker: gravity-aided bias tracker on the same models (round 8)"] = tracker_pairs()
    raw = {label: fold_seed_spread(a - r) for label, (a, r) in pairs.items()}
    log = {label: fold_seed_spread(np.log(a) - np.log(r)) for label, (a, r) in pairs.items()}
    _, ref = trained_pairs("whole", REF_RUNS)
    ref_seed_sd = ref.std(axis=1, ddof=1)

    head = (
        "| arm - ref | seeds per fold | mean d | sd between folds (upper end of its 95 % interval) | "
        "sd within a fold (seed) | F (p: no fold effect) | "
        + " | ".join(f"detectable at {'inf' if math.isinf(n) else n} seeds" for n in SEED_COUNTS)
        + " | seeds per fold to detect the mean d |"
    )
    sep = "|" + "---|" * (7 + len(SEED_COUNTS))
    md = [
        "# What more seeds would buy the EuRoC cross-validation",
        "",
        "`python benchmarks/cv_power.py` (reads the committed run summaries of reports/accuracy.md's rounds; "
        "2-core VM, seconds). Held-out-flight AOE of 600-epoch runs, 6 folds, paired by seed. 'detectable': the "
        "smallest true mean difference a t-test over the six fold means finds with 80 % power (95 % two-sided) at "
        "that many seeds per fold; 'inf' is the fold effect alone. The last column: the seeds per fold at which the "
        "measured mean d would be detectable if it were the truth ('never': the fold effect alone is larger). A "
        "design aid for the next round: it re-decides no committed round.",
        "",
        "![detectable difference against seeds per fold](cv_power.png)",
        "",
        "## In degrees",
        "",
        head,
        sep,
        *[row(label, s) for label, s in raw.items()],
        "",
        "## On log AOE: 100 ln(arm / ref), ~% for small values",
        "",
        head,
        sep,
        *[row(label, s, percent) for label, s in log.items()],
        "",
        "ref's own seed-to-seed sd per fold (seeds 100/200/300+k, deg): "
        + ", ".join(f"{k}: {v:.2f}" for k, v in zip(FOLDS, ref_seed_sd, strict=True))
        + ".",
        "",
    ]
    result = {
        "command": "python benchmarks/cv_power.py",
        "seed_counts": [None if math.isinf(n) else n for n in SEED_COUNTS],
        "arms": {
            label: {
                scale: {
                    "n_folds": s.n_folds,
                    "n_seeds": s.n_seeds,
                    "mean": s.mean,
                    "between_sd": s.between_sd,
                    "between_sd_upper_95": s.between_sd_upper(),
                    "within_sd": s.within_sd,
                    "interaction_f": s.interaction_f,
                    "interaction_p": s.interaction_p,
                    "detectable": [s.detectable(n) for n in SEED_COUNTS],
                    "seeds_to_detect_mean": s.seeds_for(s.mean),
                }
                for scale, s in (("deg", raw[label]), ("log", log[label]))
            }
            for label in raw
        },
        "ref_seed_sd_deg": ref_seed_sd.tolist(),
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_json(OUT.with_suffix(".json"), result)
    write_text(OUT.with_suffix(".md"), "\n".join(md))
    plots.save(figure(raw), OUT.with_suffix(".png"))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
