"""Collect ablation runs into tables: mean +- std over seeds per setting, or paired differences per seed.

    python -m gyrodenoise.ablation multirun/ablation_activation/2026-01-01_10-00-00 \
        --out reports/ablation_activation
    python -m gyrodenoise.ablation multirun/act multirun/bn --keys model.batch_norm \
        --where model.act=gelu --out reports/ablation_batchnorm
    python -m gyrodenoise.ablation reports/ablation_runs/reference reports/ablation_runs/activation \
        --reference model.act=gelu --out reports/ablation_euroc/paired/activation
    python -m gyrodenoise.ablation --report   # reports/ablation_euroc.md from reports/ablation_runs/

A run is either a Hydra run folder (summary.json, .hydra/overrides.yaml + config.yaml) or a committed
summary JSON file (any *.json outside a Hydra run folder: the summary.json that gyrodenoise.train writes,
with its `overrides` and resolved `config`), so that runs made in different sessions accumulate.
A run's *setting* (arm) is the value of each ablated key: the key's command-line/sweep override when the
run has one (config-group choices such as +model/shape=wide), else its value in the run's resolved
config. By default the ablated keys are the overridden keys whose value differs between runs, except the
seed and the experiment. Without --reference: PREFIX.md (Markdown table), PREFIX.csv and PREFIX.png
(validation and test AOE per setting: every seed and mean +- std). With --reference (or --claim): paired
differences against the reference arm, seed by seed (gyrodenoise.ablation_report); a folder named after
a claim of gyrodenoise.ablation_stats.CLAIMS (reports/ablation_runs/activation) brings that claim's keys,
reference and expected outcomes, and its sibling reference/ folder when the reference arm is not among
the runs given. Two runs of the same arm and seed are both kept, with a warning, and their mean is that
seed's value in the pairs (a repeat is not an independent sample). Files are written atomically.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path

from gyrodenoise import ablation_report as rep
from gyrodenoise import tables
from gyrodenoise.ablation_runs import (
    Setting,
    ablated_keys,
    find_runs,
    group,
    matching,
    parse_where,
    plus_minus,
    with_ext,
)
from gyrodenoise.atomic import write_bytes, write_text
from gyrodenoise.paths import portable_path

COLUMNS = [  # (split, header, csv name, digits)
    ("val", "val AOE (deg)", "val_aoe", 2),
    ("test", "test AOE (deg)", "test_aoe", 2),
    ("val_last", "last val AOE (deg)", "val_aoe_last", 2),
    ("best_epoch", "best epoch", "best_epoch", 0),
]


def markdown_table(settings: Sequence[Setting], keys: Sequence[str]) -> str:
    head = [*keys, "seeds", *(c[1] for c in COLUMNS), "val / test per seed", "train s/run"]
    rows = []
    for s in settings:
        n = s.stats("val")[2]
        cells = [plus_minus(*s.stats(split)[:2], digits) for split, _, _, digits in COLUMNS]
        runs = sorted(s.runs, key=lambda r: str(r.seed))
        per_seed = ", ".join(f"{r.metric('val'):.2f} / {r.metric('test'):.2f}" for r in runs)
        rows.append([*s.values, str(n), *cells, per_seed, f"{s.wall_s():.0f}"])
    return tables.markdown_table(head, rows)


def csv_text(settings: Sequence[Setting], keys: Sequence[str]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    stat_cols = [f"{name}_{x}" for _, _, name, _ in COLUMNS for x in ("mean", "std")]
    w.writerow(
        [*keys, "n_seeds", *stat_cols, "seeds", "val_aoe_per_seed", "test_aoe_per_seed", "train_wall_time_s_mean"]
    )
    for s in settings:
        stats = [f"{v:.4f}" for split, *_ in COLUMNS for v in s.stats(split)[:2]]
        runs = sorted(s.runs, key=lambda r: str(r.seed))
        w.writerow(
            [
                *s.values,
                s.stats("val")[2],
                *stats,
                " ".join(str(r.seed) for r in runs),
                " ".join(f"{r.metric('val'):.4f}" for r in runs),
                " ".join(f"{r.metric('test'):.4f}" for r in runs),
                f"{s.wall_s():.1f}",
            ]
        )
    return buf.getvalue()


def mean_curve(setting: Setting) -> tuple[list[int], list[float]]:
    """Validation AOE vs epoch, averaged over the seeds that validated at each epoch."""
    by_epoch: dict[int, list[float]] = {}
    for r in setting.runs:
        for epoch, v in r.curve():
            by_epoch.setdefault(epoch, []).append(v)
    epochs = sorted(by_epoch)
    return epochs, [statistics.fmean(by_epoch[e]) for e in epochs]


def plot_png(settings: Sequence[Setting], keys: Sequence[str], title: str) -> bytes:
    from gyrodenoise.plots import subplots

    labels = [
        # '$' escaped: matplotlib would read '${...}' (an interpolation in a value) as mathtext and fail
        ", ".join(f"{k.split('.')[-1].split('/')[-1]}={v}" for k, v in zip(keys, s.values, strict=True)).replace(
            "$", r"\$"
        )
        for s in settings
    ]
    rules = sorted({str(r.summary.get("selection", "best_val")) for s in settings for r in s.runs})
    kept = {"last": "final weights", "best_val": "best validation checkpoint"}
    kept_by = " / ".join(kept.get(rule, rule) for rule in rules)
    fig, axes = subplots(1, 3, figsize=(max(11.0, 1.2 * len(settings) + 7), 4.2))
    for ax, split in zip(axes[:2], ("val", "test"), strict=True):
        for i, s in enumerate(settings):
            ys = [r.metric(split) for r in s.runs]
            ax.plot([i] * len(ys), ys, "o", color="0.6", ms=4, zorder=1)
            m, sd, _ = s.stats(split)
            err = [0.0 if not math.isfinite(sd) else sd]
            ax.errorbar([i], [m], yerr=err, fmt="s", color="C0", capsize=4, ms=6, zorder=2)
        ax.set_title(f"{split} AOE (deg), {kept_by}:\nseeds (grey), mean ± std (blue)", fontsize=9)
        ax.set_xticks(range(len(settings)))
        ax.set_xticklabels(["\n".join(lb.split(", ")) for lb in labels], fontsize=7)
        if max(len(lb) for lb in labels) > 12 * len(keys) or len(settings) > 5:  # long labels: slant them
            ax.tick_params(axis="x", labelrotation=30)
            for label in ax.get_xticklabels():
                label.set(ha="right", rotation_mode="anchor")
        ax.grid(axis="y", alpha=0.3)
    ax = axes[2]
    for i, (s, label) in enumerate(zip(settings, labels, strict=True)):
        epochs, ys = mean_curve(s)
        if epochs:
            ax.plot(epochs, ys, "-o", ms=2, color=f"C{i % 10}", label=label)
    ax.set_title("validation AOE during training (mean over seeds)", fontsize=9)
    ax.set_xlabel("epoch")
    ax.set_ylabel("deg")
    ax.set_yscale("log")
    ax.grid(alpha=0.3, which="both")
    if ax.lines:
        ax.legend(fontsize=7)
    else:  # e.g. runs shorter than trainer.check_val_every_n_epoch
        ax.text(0.5, 0.5, "no validation during the fits", ha="center", va="center", transform=ax.transAxes)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    return buf.getvalue()


def repeated_seed_notes(settings: Sequence[Setting], keys: Sequence[str]) -> list[str]:
    """A note per setting whose runs repeat a seed: its spread is then not a seed spread (runs that differ in a
    key not tabulated, or the same run twice)."""
    notes = []
    for s in settings:
        seeds = [str(r.seed) for r in s.runs]
        if repeated := sorted({x for x in seeds if seeds.count(x) > 1}):
            label = ", ".join(f"{k}={v}" for k, v in zip(keys, s.values, strict=True))
            notes.append(
                f"{label}: {len(seeds)} runs but seed(s) {', '.join(repeated)} repeated: they differ in a key not in "
                "the table (--keys to add it, --where to filter) or are the same run twice; the ± is no seed spread"
            )
    return notes


def collect(
    dirs: Sequence[Path],
    out: Path,
    keys: Sequence[str] | None = None,
    where: Sequence[tuple[str, str]] = (),
    title: str | None = None,
) -> list[Setting]:
    runs, unfinished = find_runs(dirs)
    runs = matching(runs, where)
    if not runs:
        raise ValueError(f"no finished run (summary.json) under {[str(d) for d in dirs]} matches {list(where)}")
    keys = list(keys) if keys else ablated_keys(runs)
    if not keys:
        raise ValueError("the runs do not differ in any overridden key: name the ablated keys with --keys")
    settings = group(runs, keys)
    title = title or f"Ablation over {', '.join(keys)} ({len(runs)} runs)"
    md = [f"# {title}\n", f"Runs: {', '.join(portable_path(d) for d in dirs)}", ""]
    if where:
        md += [f"Filter: {', '.join(f'{k}={v}' for k, v in where)}", ""]
    md += [markdown_table(settings, keys)]
    for note in repeated_seed_notes(settings, keys):
        md += [note, ""]
        print(f"warning: {note}")
    if unfinished:
        left_out = ", ".join(portable_path(d) for d in unfinished)
        md += [f"Unfinished runs left out (no summary.json): {left_out}", ""]
        print(f"unfinished runs left out (no summary.json; rerun one in its folder to resume it): {left_out}")
    write_text(with_ext(out, ".md"), "\n".join(md))
    write_text(with_ext(out, ".csv"), csv_text(settings, keys))
    write_bytes(with_ext(out, ".png"), plot_png(settings, keys, title))
    return settings


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m gyrodenoise.ablation", description=__doc__.split("\n\n")[0])
    p.add_argument("dirs", nargs="*", type=Path, help="run folders / summary JSON files (searched recursively)")
    p.add_argument("--out", type=Path, help="output prefix: writes PREFIX.md, .csv and .png (--report: the .md)")
    p.add_argument("--keys", default=None, help="comma-separated ablated keys (default: the swept ones)")
    p.add_argument("--where", action="append", default=[], metavar="KEY=VALUE", help="keep matching runs only")
    p.add_argument("--title", default=None)
    p.add_argument(
        "--reference",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="the reference arm: paired differences of every other arm against it, seed by seed",
    )
    p.add_argument("--claim", default=None, help="a claim of ablation_stats.CLAIMS: its keys, reference, expectations")
    p.add_argument(
        "--report", action="store_true", help="write the whole report from DIR (default reports/ablation_runs)"
    )
    p.add_argument("--tables", type=Path, default=None, help="--report: folder of the per-claim tables")
    p.add_argument("--appendix", type=Path, default=None, help="--report: text kept verbatim at the end")
    a = p.parse_args(argv)

    try:
        if a.report:
            return rep.report_cli(a)
        if not a.dirs or a.out is None:
            p.error("give run folders and --out (or --report)")
        keys = [k.strip().lstrip("+") for k in a.keys.split(",")] if a.keys else None
        if a.reference or a.claim or rep.claim_of(a.dirs):
            return rep.paired_cli(a, keys)
        settings = collect(a.dirs, a.out, keys, parse_where(a.where), a.title)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(with_ext(a.out, ".md").read_text())
    print(f"wrote {a.out}.md, .csv, .png ({len(settings)} settings)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
