"""Ablation runs: read run summaries (Hydra run folders or committed summary JSON files), their
settings (overrides, else the resolved config) and metrics; group them by setting. Used by the
mean +- std tables (gyrodenoise.ablation) and the paired report (gyrodenoise.ablation_report).
"""

from __future__ import annotations

import csv
import difflib
import json
import math
import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import yaml

SEED_KEY = "seed"
IGNORED_KEYS = {"experiment", "hparams_search"}  # the sweep's own selectors, never a setting
# val: the validation figure of the run's protocol (a held-out training flight with dataset.cv_fold, else
# the end of the training flights); val_tail: the end of the training flights in a cv_fold run
METRICS = {"val": "val/aoe_deg", "test": "test/aoe_deg", "val_tail": "val_tail/aoe_deg"}
MISSING = "-"  # the value of a key a run neither overrides nor has in its config
CV_SUMMARY = "cross_validation"  # gyrodenoise.cross_validation's outputs in a sweep folder (cross_validation*.json)


@dataclass
class Run:
    path: Path  # the Hydra run folder, or the summary JSON file
    overrides: dict[str, str]  # key (without +/++ prefix) -> value as written
    config: dict
    summary: dict
    spelled: dict[str, str] = field(default_factory=dict)  # key -> as written on the command line (+model/shape)

    @property
    def seed(self) -> object:
        # seed=null: the run drew its seed and recorded it in summary.json (runs of drawn seeds are not one seed)
        if SEED_KEY in self.overrides and self.overrides[SEED_KEY] != "null":
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
        if isinstance(node, dict) and key in self.group_choices:  # a group's content (logger, trainer): its name
            return str(self.group_choices[key])
        return _fmt_value(node)

    @cached_property
    def group_choices(self) -> dict:
        """The config-group choices Hydra recorded (.hydra/hydra.yaml runtime.choices; {} without one), read once:
        `value` asks for them per key and table."""
        hydra_file = Path(self.path) / ".hydra" / "hydra.yaml"
        if not hydra_file.is_file():
            return {}
        choices = ((yaml.safe_load(hydra_file.read_text()) or {}).get("hydra") or {}).get("runtime", {}).get("choices")
        return {k: v for k, v in (choices or {}).items() if v is not None}

    def curve(self) -> list[tuple[int, float]]:
        """(epoch, val AOE) of the validations during fitting, from the CSV log when there is one.

        Runs before 2026-11-24 also logged the post-fit validation of the kept model, at epoch index = the
        number of epochs: left out (a validation during the fit has a smaller index).
        """
        path = self.path / "csv" / "metrics.csv"
        if not path.is_file():
            return []
        epochs = self.summary.get("epochs")
        with open(path, newline="") as fh:
            rows = [r for r in csv.DictReader(fh) if r.get(METRICS["val"]) and r.get("epoch")]
        if epochs is None:  # no summary: the older layout, whose last validation row is the post-fit one
            rows = rows[:-1]
        return [
            (int(float(r["epoch"])) + 1, float(r[METRICS["val"]]))
            for r in rows
            if epochs is None or int(float(r["epoch"])) < epochs
        ]

    def metric(self, split: str) -> float:
        """'val' / 'test': AOE (deg) of the weights the run kept (its `select` rule; final weights by default);
        'val_last': the last validation AOE of the fit (overfitting shows as val_last > val); 'best_epoch': the
        epoch of the best validation."""
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
        return mean_sd_n([r.metric(split) for r in self.runs])

    def wall_s(self) -> float:
        return mean_wall_s(self.runs)


def mean_sd_n(values: Iterable[float]) -> tuple[float, float, int]:
    """(mean, sample sd, n) of the finite values; nan where undefined (sd needs two)."""
    xs = [x for x in values if math.isfinite(x)]
    if not xs:
        return math.nan, math.nan, 0
    return statistics.fmean(xs), (statistics.stdev(xs) if len(xs) > 1 else math.nan), len(xs)


def mean_wall_s(runs: Iterable[Run]) -> float:
    """Mean training wall time (s) of the runs that recorded one; nan if none did."""
    ts = [float(r.summary["train_wall_time_s"]) for r in runs if r.summary.get("train_wall_time_s")]
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


def read_overrides(lines: Iterable[object]) -> tuple[dict[str, str], dict[str, str]]:
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
    accepted too), `val` and `test` (dicts of metrics with val/aoe_deg and test/aoe_deg; `test` may be {}, a run
    with test=false) and a seed
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
    if not {"overrides", "queue", "val"} & set(summary):
        raise ValueError(
            f"{path}: not a run summary written by gyrodenoise.train (no 'overrides' or 'val' field): give run "
            "folders, sweep folders or their summary.json files"
        )
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
        if split == "test" and table == {}:  # a run with test=false (e.g. a cross-validation fold): no test figure
            continue
        if not isinstance(table, dict) or not isinstance(table.get(METRICS[split]), int | float):
            raise ValueError(f"{path}: field '{split}' must be an object with a number '{METRICS[split]}'")
    overrides, spelled = read_overrides(lines)
    run = Run(path, overrides, config, summary, spelled)
    if run.seed is None:
        raise ValueError(f"{path}: no seed (field 'seed', a seed= override or config.seed): runs pair by seed")
    return run


def load_run(run_dir: Path) -> Run:
    hydra_dir = run_dir / ".hydra"
    overrides_file = hydra_dir / "overrides.yaml"
    if not overrides_file.is_file():
        raise FileNotFoundError(f"{run_dir}: no .hydra/overrides.yaml; is this a Hydra run folder?")
    overrides, spelled = read_overrides(yaml.safe_load(overrides_file.read_text()) or [])
    summary = json.loads((run_dir / "summary.json").read_text())
    # the config the run trained with, resolved (as a summary file is read): .hydra/config.yaml is Hydra's copy with
    # its interpolations unresolved (an ablation's dataset.cv_fold: ${seed}) and seed=null's seed not drawn yet
    config = summary.get("config") if isinstance(summary, dict) else None
    if not isinstance(config, dict):  # a summary without one: Hydra's copy
        config_file = hydra_dir / "config.yaml"
        config = (yaml.safe_load(config_file.read_text()) or {}) if config_file.is_file() else {}
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
            if not inside_run and not hidden and not path.stem.startswith(CV_SUMMARY):
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


def _config_keys(node: object, prefix: str = "") -> Iterable[str]:
    if isinstance(node, dict):
        for k, v in node.items():
            yield f"{prefix}{k}"
            yield from _config_keys(v, f"{prefix}{k}.")


def matching(runs: Sequence[Run], where: Sequence[tuple[str, str]], flag: str = "--where") -> list[Run]:
    """The runs whose value of every KEY of `where` is its VALUE. A key no run has (a misspelling, e.g.
    model.dropuot) is an error naming the setting it was probably meant to be, not "no run matches"."""
    for key, value in where:
        if runs and all(r.value(key) == MISSING for r in runs):
            known = {k for r in runs for k in (*_config_keys(r.config), *r.overrides)}
            close = difflib.get_close_matches(key, sorted(known), n=1)
            hint = f": did you mean {close[0]}?" if close else " (a config key, e.g. model.dropout, or an override)"
            raise ValueError(f"{flag} {key}={value}: none of the {len(runs)} runs has a setting {key}{hint}")
    return [r for r in runs if all(same_value(r.value(k), v) for k, v in where)]


def group(runs: Sequence[Run], keys: Sequence[str], defaults: dict[str, str] | None = None) -> list[Setting]:
    """Runs grouped by their values of `keys`, in first-seen order. A key a run does not have (a
    config-group choice left at its default, e.g. no +model/shape) takes its value from `defaults`."""
    defaults = defaults or {}
    settings: dict[tuple[str, ...], Setting] = {}
    for r in runs:
        values = tuple(defaults.get(k, MISSING) if r.value(k) == MISSING else r.value(k) for k in keys)
        settings.setdefault(tuple(canonical(v) for v in values), Setting(values)).runs.append(r)
    return list(settings.values())


def plus_minus(mean: float, sd: float, digits: int = 2) -> str:
    if not math.isfinite(mean):
        return "-"
    return f"{mean:.{digits}f}" if not math.isfinite(sd) else f"{mean:.{digits}f} ± {sd:.{digits}f}"


def with_ext(prefix: Path, ext: str) -> Path:
    return prefix.parent / (prefix.name + ext)
