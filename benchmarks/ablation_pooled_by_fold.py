"""The confirmation's "for information" figure, seeds 0-11 pooled, with the seeds clustered by held-out flight.

reports/ablation_confirm.md pools the six-fold seeds (0-5) with the fresh ones (6-11) for information; seed s holds out
flight s mod 6, so the twelve paired differences are two per fold, and a t-interval over twelve counts them as
independent while two runs of one fold share its held-out flight and its training flights. Here: the paired
difference arm - reference on the test AOE per seed, the mean of the two seeds of each fold, and the t-interval over
the six fold means (5 degrees of freedom), beside the interval over the twelve seeds.

    python benchmarks/ablation_pooled_by_fold.py [--out benchmarks/results/ablation_pooled_by_fold.md]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import stats

from gyrodenoise.atomic import write_text

RUNS = (Path("reports/ablation_runs"), Path("reports/ablation_confirm_runs"))
FOLDS = 6
KEY = "test/aoe_deg"


def arm_of(run: dict) -> str:
    """The arm's own overrides: the experiment's, without the seed and the fold."""
    keep = [o for o in run["overrides"] if not o.startswith(("seed=", "dataset.cv_fold=", "experiment="))]
    return " ".join(keep) or "reference"


def load() -> dict[str, dict[int, float]]:
    """{arm: {seed: test AOE}} over both run folders (a seed appears in one of them)."""
    out: dict[str, dict[int, float]] = {}
    for root in RUNS:
        for f in sorted(root.glob("*/*.json")):
            run = json.loads(f.read_text())
            arm = "reference" if f.parent.name == "reference" else arm_of(run)
            out.setdefault(arm, {})[int(run["seed"])] = float(run["test"][KEY])
    return out


def t_interval(x: np.ndarray) -> tuple[float, float, float]:
    half = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
    return float(x.mean()), float(x.mean() - half), float(x.mean() + half)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/ablation_pooled_by_fold.md"))
    args = ap.parse_args()
    runs = load()
    ref = runs.pop("reference")
    lines = [
        "# The confirmation's pooled figure, seeds clustered by held-out flight",
        "",
        "`python benchmarks/ablation_pooled_by_fold.py` (2-core VM, seconds), from the run JSONs under "
        + " and ".join(f"`{r}/`" for r in RUNS)
        + f"; test AOE, arm - reference (deg), seed s holds out flight s mod {FOLDS}.",
        "",
        "| arm | seeds | mean | 95 % t over the seeds (n - 1 df) | 95 % t over the fold means (5 df) |",
        "|---|---|---|---|---|",
    ]
    for arm, by_seed in sorted(runs.items()):
        seeds = sorted(s for s in by_seed if s in ref)
        if len(seeds) < 2 * FOLDS:  # the arms of the six-fold report only: not pooled in the confirmation
            continue
        d = np.array([by_seed[s] - ref[s] for s in seeds])
        folds = np.array([d[[i for i, s in enumerate(seeds) if s % FOLDS == k]].mean() for k in range(FOLDS)])
        m, lo, hi = t_interval(d)
        _, flo, fhi = t_interval(folds)
        lines.append(f"| {arm} | {len(seeds)} | {m:+.2f} | [{lo:+.2f}, {hi:+.2f}] | [{flo:+.2f}, {fhi:+.2f}] |")
    write_text(args.out, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
