"""Benchmark of the discrepancy workflow on data with hidden effects.

For every effect of the vocabulary, at two magnitudes and several seeds: generate 'measured' data
(hand-held trajectories; base model + the hidden effect, simulated at 10x the IMU rate and averaged
down), run the greedy selection with the base model only, and record what was named, the parameter
error and the held-out gap. Vibration has two rows: the sinusoid (`vibration`) and the band-limited
noise (`vibration_band`, named `vibration` with bandwidth_hz > 0; its parameter check also asks for
the centre frequency and bandwidth within tolerance). Then the null case (nothing hidden) over many
seeds: the false-positive rate. Writes <out>/discrepancy_hidden_effects.{json,md} (default
benchmarks/results).

    python benchmarks/discrepancy_hidden_effects.py [--seeds 3] [--null-seeds 40] [--duration 40] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gyrodenoise.discrepancy.hidden import CASES, run_case
from gyrodenoise.paths import portable_command, portable_path

OUT = Path(__file__).parent / "results"


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--null-seeds", type=int, default=40)
    p.add_argument("--duration", type=float, default=40.0)
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args()
    t0 = time.time()
    runs = []
    for name in CASES:
        for m in (0, 1):
            for seed in range(args.seeds):
                with tempfile.TemporaryDirectory() as d:
                    r = run_case(d, name, m, 1000 + seed, duration_s=args.duration)
                r["ok_named"] = r["named_labels"] == [name]
                r["ok_gap"] = ("gap_metric" not in r) or r["gap_after"] < r["gap_before"]
                runs.append(r)
                print(name, m, seed, r["named_labels"], r["rel_error"], flush=True)
    nulls = []
    for seed in range(args.null_seeds):
        with tempfile.TemporaryDirectory() as d:
            nulls.append(run_case(d, "none", 0, 5000 + seed, duration_s=args.duration))
    fpr = float(np.mean([len(r["named"]) > 0 for r in nulls]))
    vocab = list(CASES)
    confusion = {h: {n: 0 for n in [*vocab, "nothing"]} for h in vocab}
    for r in runs:
        for n in r["named_labels"] or ["nothing"]:
            confusion[r["effect"]][n] += 1
    result = {
        "command": "python " + portable_command(sys.argv),
        "machine": f"{platform.node()} ({platform.processor() or platform.machine()}, {os.cpu_count()} CPU threads)",
        "wall_time_s": time.time() - t0,
        "settings": {k: portable_path(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
        "confusion": confusion,
        "null_false_positive_rate": fpr,
        "null_named": [r["named"] for r in nulls],
        "runs": runs,
    }
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    (out / "discrepancy_hidden_effects.json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [
        "# Discrepancy workflow: hidden-effect benchmark",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; wall time {result['wall_time_s']:.0f} s.  ",
        f"{args.seeds} seeds x 2 magnitudes per effect, 3 fit + 1 held-out hand-held sequences of "
        f"{args.duration:g} s each.",
        "",
        f"**Null case (nothing hidden): false-positive rate {100 * fpr:.1f}% over {args.null_seeds} seeds.**",
        "",
        "| hidden effect | named exactly | parameter within tol | gap shrinks | median rel. error (small / large) |",
        "|---|---|---|---|---|",
    ]
    for name in vocab:
        rs = [r for r in runs if r["effect"] == name]
        med = []
        for m in (0, 1):
            errs = [r["rel_error"] for r in rs if r["magnitude"] == m and r["rel_error"] is not None]
            med.append(f"{np.median(errs):.3f}" if errs else "-")
        lines.append(
            f"| {name} | {sum(r['ok_named'] for r in rs)}/{len(rs)} | {sum(r['ok_param'] for r in rs)}/{len(rs)} | "
            f"{sum(r['ok_gap'] for r in rs)}/{len(rs)} | {' / '.join(med)} |"
        )
    lines += ["", "## Confusion matrix (rows: hidden; columns: named)", ""]
    cols = [*vocab, "nothing"]
    lines.append("| hidden \\ named | " + " | ".join(c.replace("_", " ") for c in cols) + " |")
    lines.append("|---" * (len(cols) + 1) + "|")
    for h in vocab:
        lines.append(f"| {h} | " + " | ".join(str(confusion[h][c] or "") for c in cols) + " |")
    (out / "discrepancy_hidden_effects.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
