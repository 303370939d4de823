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
import json
import math
import statistics
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from gyrodenoise.atomic import write_bytes, write_text
from gyrodenoise.paths import portable_path

SEED_KEY = "seed"
IGNORED_KEYS = {"experiment", "hparams_search"}  # the sweep's own selectors, never a setting
# val: the validation figure of the run's protocol (a held-out training flight with dataset.cv_fold, else
# the end of the training flights); val_tail: the end of the training flights in a cv_fold run
METRICS = {"val": "val/aoe_deg", "test": "test/aoe_deg", "val_tail": "val_tail/aoe_deg"}
MISSING = "-"  # the value of a key a run neither overrides nor has in its config


@dataclass
class Run:
    path: Path  # the Hydra run folder, or the summary JSON file
    overrides: dict[str, str]  # key (without +/++ prefix) -> value as written
    config: dict
    summary: dict
    spelled: dict[str, str] = field(default_factory=dict)  # key -> as written on the command line (+model/shape)

    @property
    def seed(self) -> object:
        if SEED_KEY in self.overrides:
            return self.overrides[SEED_KEY]
        if self.summary.get(SEED_KEY) is not None:
            return self.summary[SEED_KEY]
        return self.config.get(SEED_KEY)

    def value(self, key: str) -> str:
        """The run's value of `key`: its override if any, else its resolved config value."""
        if key in self.overrides:
            return self.overrides[key]
        if "/" in key:  # a config-group choice: the resolved config holds the group's content, not its name
            return MISSING
        node: object = self.config
        for part in key.split("."):
            if not isinstance(node, dict) or part not in node:
                return MISSING
            node = node[part]
        return _fmt_value(node)

    def curve(self) -> list[tuple[int, float]]:
        """(epoch, val AOE) of the validations during fitting, from the CSV log when there is one.

        The last val row of the log is the post-fit validation of the best checkpoint: left out.
        """
        path = self.path / "csv" / "metrics.csv"
        if not path.is_file():
            return []
        with open(path, newline="") as fh:
            rows = [r for r in csv.DictReader(fh) if r.get(METRICS["val"])]
        return [(int(float(r["epoch"])) + 1, float(r[METRICS["val"]])) for r in rows[:-1]]

    def metric(self, split: str) -> float:
        """'val' / 'test': AOE (deg) of the best checkpoint; 'val_last': the last validation AOE of the
        fit (overfitting shows as val_last > val); 'best_epoch': the epoch of the best validation."""
        if split in ("val_last", "best_epoch"):
            curve = self.curve()
            if not curve:
                return math.nan
            return curve[-1][1] if split == "val_last" else float(min(curve, key=lambda p: p[1])[0])
        table = self.summary.get("test" if split == "test" else "val") or {}
        v = table.get(METRICS[split])
        return float(v) if v is not None else math.nan


@dataclass
class Setting:
    values: tuple[str, ...]
    runs: list[Run] = field(default_factory=list)

    def stats(self, split: str) -> tuple[float, float, int]:
        xs = [r.metric(split) for r in self.runs]
        xs = [x for x in xs if math.isfinite(x)]
        if not xs:
            return math.nan, math.nan, 0
        sd = statistics.stdev(xs) if len(xs) > 1 else math.nan
        return statistics.fmean(xs), sd, len(xs)

    def wall_s(self) -> float:
        ts = [float(r.summary.get("train_wall_time_s", math.nan)) for r in self.runs]
        return statistics.fmean(ts) if ts else math.nan


def _fmt_value(v: object) -> str:
    if v is None:
        return "null"
    if isinstance(v, list | tuple):
        return "[" + ",".join(_fmt_value(x) for x in v) + "]"
    if isinstance(v, bool):
        return str(v).lower()
    return str(v)


def _parse_override(line: str) -> tuple[str, str] | None:
    line = line.strip()
    if not line or line.startswith("~") or "=" not in line:
        return None
    key, value = line.split("=", 1)
    return key.lstrip("+"), _norm(value)


def _norm(value: str) -> str:
    """One spelling per value: Hydra writes swept booleans as True/False and configs true/false, a null
    may read None or null, and a list may have spaces after its commas."""
    value = value.strip().strip("'\"")
    if value.lower() in ("true", "false"):
        return value.lower()
    if value in ("None", "null", "~"):
        return "null"
    if value.startswith("[") and value.endswith("]"):
        return value.replace(" ", "")
    return value


def canonical(value: str) -> str:
    """The grouping key of a value: numbers compare as numbers (0 and 0.0 are one setting)."""
    try:
        return repr(float(value))
    except ValueError:
        return _norm(value)


def same_value(a: str, b: str) -> bool:
    return canonical(a) == canonical(b)


def _read_overrides(lines: Iterable[object]) -> tuple[dict[str, str], dict[str, str]]:
    """(key -> value, key -> key as written) of task overrides; hydra.* and deletions (~key) left out."""
    overrides, spelled = {}, {}
    for line in lines:
        parsed = _parse_override(str(line))
        if parsed and not parsed[0].startswith("hydra."):
            overrides[parsed[0]] = parsed[1]
            spelled[parsed[0]] = str(line).strip().split("=", 1)[0]
    return overrides, spelled


def load_summary_file(path: Path) -> Run:
    """A committed summary JSON (what gyrodenoise.train writes as summary.json, copied anywhere).

    Needs `overrides` (list of KEY=VALUE strings; `queue.overrides` of benchmarks/run_queue.py is
    accepted too), `val` and `test` (dicts of metrics with val/aoe_deg and test/aoe_deg) and a seed
    (`seed`, a seed= override or config.seed); `config` (the resolved config) is optional but needed to
    tell settings apart by keys a run does not override.
    """
    path = Path(path)
    try:
        summary = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from e
    if not isinstance(summary, dict):
        raise ValueError(f"{path}: a summary is a JSON object, got {type(summary).__name__}")
    lines = summary.get("overrides")
    if lines is None and isinstance(summary.get("queue"), dict):
        lines = summary["queue"].get("overrides")
    if not isinstance(lines, list) or not all(isinstance(x, str) for x in lines):
        raise ValueError(f"{path}: field 'overrides' must be a list of KEY=VALUE strings, got {lines!r}")
    config = summary.get("config") or {}
    if not isinstance(config, dict):
        raise ValueError(f"{path}: field 'config' must be a JSON object (the resolved Hydra config)")
    for split in ("val", "test"):
        table = summary.get(split)
        if not isinstance(table, dict) or not isinstance(table.get(METRICS[split]), int | float):
            raise ValueError(f"{path}: field '{split}' must be an object with a number '{METRICS[split]}'")
    overrides, spelled = _read_overrides(lines)
    run = Run(path, overrides, config, summary, spelled)
    if run.seed is None:
        raise ValueError(f"{path}: no seed (field 'seed', a seed= override or config.seed): runs pair by seed")
    return run


def load_run(run_dir: Path) -> Run:
    hydra_dir = run_dir / ".hydra"
    overrides_file = hydra_dir / "overrides.yaml"
    if not overrides_file.is_file():
        raise FileNotFoundError(f"{run_dir}: no .hydra/overrides.yaml; is this a Hydra run folder?")
    overrides, spelled = _read_overrides(yaml.safe_load(overrides_file.read_text()) or [])
    config_file = hydra_dir / "config.yaml"
    config = (yaml.safe_load(config_file.read_text()) or {}) if config_file.is_file() else {}
    summary = json.loads((run_dir / "summary.json").read_text())
    return Run(run_dir, overrides, config, summary, spelled)


def find_runs(roots: Iterable[Path]) -> tuple[list[Run], list[Path]]:
    """Finished runs under the given folders / JSON files, and unfinished Hydra run folders.

    In a folder: every Hydra run folder (.hydra/ + summary.json) and every other *.json file, each a
    summary (a malformed one is an error naming the file and field).
    """
    runs, unfinished = [], []
    for root in roots:
        root = Path(root)
        if root.is_file():
            runs.append(load_summary_file(root))
            continue
        if not root.is_dir():
            raise FileNotFoundError(f"{root}: no such folder or file")
        run_dirs = set()
        for hydra_dir in sorted(root.rglob(".hydra")):
            run_dir = hydra_dir.parent
            run_dirs.add(run_dir)
            if (run_dir / "summary.json").is_file():
                runs.append(load_run(run_dir))
            elif (hydra_dir / "overrides.yaml").is_file() and run_dir != root:
                unfinished.append(run_dir)
        for path in sorted(root.rglob("*.json")):
            inside_run = any(parent in run_dirs for parent in path.parents)
            hidden = any(part.startswith(".") for part in path.relative_to(root).parts)  # temp files, .hydra
            if not inside_run and not hidden:
                runs.append(load_summary_file(path))
    return runs, unfinished


def ablated_keys(runs: Sequence[Run]) -> list[str]:
    """Overridden keys (not the seed) whose value differs between runs, in first-seen order."""
    keys: list[str] = []
    for r in runs:
        for k in r.overrides:
            if k not in keys and k != SEED_KEY and k not in IGNORED_KEYS:
                keys.append(k)
    return [k for k in keys if len({canonical(r.value(k)) for r in runs}) > 1]


def parse_where(items: Sequence[str]) -> list[tuple[str, str]]:
    out = []
    for item in items:
        if "=" not in item:
            raise ValueError(f"--where {item!r}: expected KEY=VALUE")
        k, v = item.split("=", 1)
        out.append((k.lstrip("+"), v))
    return out


def group(runs: Sequence[Run], keys: Sequence[str], defaults: dict[str, str] | None = None) -> list[Setting]:
    """Runs grouped by their values of `keys`, in first-seen order. A key a run does not have (a
    config-group choice left at its default, e.g. no +model/shape) takes its value from `defaults`."""
    defaults = defaults or {}
    settings: dict[tuple[str, ...], Setting] = {}
    for r in runs:
        values = tuple(defaults.get(k, MISSING) if r.value(k) == MISSING else r.value(k) for k in keys)
        settings.setdefault(tuple(canonical(v) for v in values), Setting(values)).runs.append(r)
    return list(settings.values())


def _pm(mean: float, sd: float, digits: int = 2) -> str:
    if not math.isfinite(mean):
        return "-"
    return f"{mean:.{digits}f}" if not math.isfinite(sd) else f"{mean:.{digits}f} ± {sd:.{digits}f}"


COLUMNS = [  # (split, header, csv name, digits)
    ("val", "val AOE (deg)", "val_aoe", 2),
    ("test", "test AOE (deg)", "test_aoe", 2),
    ("val_last", "last val AOE (deg)", "val_aoe_last", 2),
    ("best_epoch", "best epoch", "best_epoch", 0),
]


def markdown_table(settings: Sequence[Setting], keys: Sequence[str]) -> str:
    head = [*keys, "seeds", *(c[1] for c in COLUMNS), "val / test per seed", "train s/run"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for s in settings:
        n = s.stats("val")[2]
        cells = [_pm(*s.stats(split)[:2], digits) for split, _, _, digits in COLUMNS]
        runs = sorted(s.runs, key=lambda r: str(r.seed))
        per_seed = ", ".join(f"{r.metric('val'):.2f} / {r.metric('test'):.2f}" for r in runs)
        lines.append("| " + " | ".join([*s.values, str(n), *cells, per_seed, f"{s.wall_s():.0f}"]) + " |")
    return "\n".join(lines) + "\n"


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


def _with_ext(prefix: Path, ext: str) -> Path:
    return prefix.parent / (prefix.name + ext)


def mean_curve(setting: Setting) -> tuple[list[int], list[float]]:
    """Validation AOE vs epoch, averaged over the seeds that validated at each epoch."""
    by_epoch: dict[int, list[float]] = {}
    for r in setting.runs:
        for epoch, v in r.curve():
            by_epoch.setdefault(epoch, []).append(v)
    epochs = sorted(by_epoch)
    return epochs, [statistics.fmean(by_epoch[e]) for e in epochs]


def plot_png(settings: Sequence[Setting], keys: Sequence[str], title: str) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [
        ", ".join(f"{k.split('.')[-1].split('/')[-1]}={v}" for k, v in zip(keys, s.values, strict=True))
        for s in settings
    ]
    fig, axes = plt.subplots(1, 3, figsize=(max(11.0, 1.2 * len(settings) + 7), 4.2))
    for ax, split in zip(axes[:2], ("val", "test"), strict=True):
        for i, s in enumerate(settings):
            ys = [r.metric(split) for r in s.runs]
            ax.plot([i] * len(ys), ys, "o", color="0.6", ms=4, zorder=1)
            m, sd, _ = s.stats(split)
            err = [0.0 if not math.isfinite(sd) else sd]
            ax.errorbar([i], [m], yerr=err, fmt="s", color="C0", capsize=4, ms=6, zorder=2)
        ax.set_title(f"{split} AOE (deg), best checkpoint:\nseeds (grey), mean ± std (blue)", fontsize=9)
        ax.set_xticks(range(len(settings)))
        ax.set_xticklabels(["\n".join(lb.split(", ")) for lb in labels], fontsize=7)
        if max(len(lb) for lb in labels) > 12 * len(keys) or len(settings) > 5:  # long labels: slant them
            plt.setp(ax.get_xticklabels(), rotation=30, ha="right", rotation_mode="anchor")
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
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    return buf.getvalue()


def collect(
    dirs: Sequence[Path],
    out: Path,
    keys: Sequence[str] | None = None,
    where: Sequence[tuple[str, str]] = (),
    title: str | None = None,
) -> list[Setting]:
    runs, unfinished = find_runs(dirs)
    runs = [r for r in runs if all(same_value(r.value(k), v) for k, v in where)]
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
    if unfinished:
        md += [f"Unfinished runs left out: {len(unfinished)}", ""]
    write_text(_with_ext(out, ".md"), "\n".join(md))
    write_text(_with_ext(out, ".csv"), csv_text(settings, keys))
    write_bytes(_with_ext(out, ".png"), plot_png(settings, keys, title))
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
    from gyrodenoise import ablation_report as rep  # imports this module: here, not at the top

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
    print(_with_ext(a.out, ".md").read_text())
    print(f"wrote {a.out}.md, .csv, .png ({len(settings)} settings)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
