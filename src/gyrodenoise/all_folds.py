"""`dataset.cv_fold=all`: one training run cross-validates its recipe, the folds in turn (gyrodenoise.train calls it).

Each fold trains into fold<k>/ of the run folder; the table of gyrodenoise.cross_validation goes into the run folder,
and the run's val/aoe_deg is the recipe's figure (the mean held-out AOE over the folds): what an Optuna search
minimises. A fold finished before is kept if it trained the same settings, so a requeued run goes on.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf, open_dict

from gyrodenoise.ablation_runs import CV_SUMMARY, Run
from gyrodenoise.atomic import write_json
from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.cross_validation import ALL_FOLDS, FOLD_KEY, collect, read_run, report, write
from gyrodenoise.paths import portable_path, portable_tree


def wants_all_folds(cfg: DictConfig) -> bool:
    """Whether the config asks for every fold in one run (`dataset.cv_fold=all`)."""
    return str(OmegaConf.select(cfg, "dataset.cv_fold")).lower() == ALL_FOLDS


# settings that may differ between a fold kept from before and this run without changing what the fold trained:
# where the run writes and resumes from, threads, logging, and the scoring after the fit
RUN_ONLY_KEYS = {
    "paths",
    "ckpt_path",
    "auto_resume",
    "threads",
    "retain_freed_memory",
    "task_name",
    "logger",
    "test",
    "test_other_rule",
    "dataset.cv_fold",
    "dataset.cache_dir",
}


def _run_only(key: str) -> bool:
    # a callback's class path (a code update may swap one for a subclass of the same role: the recipe is unchanged);
    # a callback added or removed (callbacks=ema) still differs by its own keys
    return key in RUN_ONLY_KEYS or (key.startswith("callbacks.") and key.endswith("._target_"))


def _differences(kept: object, now: object, prefix: str = "") -> list[str]:
    """Keys of both configs whose values differ (a key that only one has is not counted: another code version)."""
    if _run_only(prefix.rstrip(".")):
        return []
    if isinstance(kept, dict) and isinstance(now, dict):
        return [d for k in kept if k in now for d in _differences(kept[k], now[k], f"{prefix}{k}.")]
    return [] if kept == now else [f"{prefix.rstrip('.')}: {kept!r} then, {now!r} now"]


def _check_kept_fold(folder: Path, kept: dict, cfg_k: DictConfig) -> None:
    """A fold finished before is kept only if it trained what this run would train."""
    now = portable_tree(OmegaConf.to_container(cfg_k, resolve=True))
    if diffs := _differences(kept.get("config") or {}, now):
        raise ConfigError(
            f"{folder} holds a fold finished with other settings ({'; '.join(diffs[:5])}"
            f"{f'; {len(diffs) - 5} more' if len(diffs) > 5 else ''}): dataset.cv_fold=all would mix two recipes. "
            f"Give this run another output folder (hydra.run.dir=...), or delete {folder} to train that fold afresh "
            "with this run's settings"
        )


def _sets_fold(override: str) -> bool:
    return override.lstrip("+").startswith(f"{FOLD_KEY}=")


def _check_every_flight(cfg: DictConfig) -> None:
    """Every flight trains in some fold: a flight whose ground truth disagrees with its gyro (the data module's
    `inconsistent_truth` stop) stops the run now, not after the folds before the first that trains on it."""
    dataset = cfg.dataset.copy()
    with open_dict(dataset):
        dataset.cv_fold = None
    dm = hydra.utils.instantiate(dataset)
    if getattr(dm, "inconsistent_truth", None) == "stop":
        for name in cfg.dataset.train_seqs:
            dm.load(name, training=True)


def train_all_folds(cfg: DictConfig, out_dir: Path, train_one: Callable[[DictConfig, Path], dict]) -> dict:
    """`dataset.cv_fold=all`: `train_one(cfg_k, out_dir/fold<k>)` for every fold k, then the summary of the folds
    in out_dir; returns a run summary whose val/aoe_deg is the recipe's figure."""
    flights = list(cfg.dataset.train_seqs)
    if len(flights) < 2:
        raise ConfigError(f"dataset.cv_fold=all needs two training flights or more, got {flights}")
    if cfg.get("ckpt_path"):
        raise ConfigError(
            f"ckpt_path={cfg.ckpt_path} with dataset.cv_fold=all would start every fold from one checkpoint: rerun "
            "in the same folder without it (auto_resume goes on from the unfinished fold's own checkpoint), or "
            "resume that fold alone with dataset.cv_fold=K"
        )
    _check_every_flight(cfg)
    runs = []
    for k in range(len(flights)):
        folder = out_dir / f"fold{k}"
        cfg_k = cfg.copy()
        with open_dict(cfg_k):
            cfg_k.dataset.cv_fold = k
            cfg_k.paths.output_dir = str(folder)
        if (folder / "model.pt").is_file() and (folder / "summary.json").is_file():
            kept = read_run(folder / "summary.json")
            _check_kept_fold(folder, kept.summary, cfg_k)
            print(f"fold {k} ({flights[k]} held out): finished before, kept ({folder})")
            runs.append(kept)
            continue
        print(f"\n=== fold {k} of {len(flights)}: {flights[k]} held out ({folder}) ===")
        summary = train_one(cfg_k, folder)
        # the fold's record names its own fold, not the command line's 'all'
        summary["overrides"] = [f"{FOLD_KEY}={k}" if _sets_fold(o) else o for o in summary.get("overrides", [])]
        write_json(folder / "summary.json", summary)
        runs.append(Run(folder / "summary.json", {}, summary["config"], summary))
    result = collect(runs)
    # the protocol's figure is over every fold: a fold without one (NaN) makes it NaN, which an Optuna sweep records
    # as a failed trial, rather than a mean over the easier folds
    figure = result.figure() if not (result.missing or result.unscored) else math.nan
    md, data = report(result, source=str(out_dir))
    write(out_dir / CV_SUMMARY, md, data)
    print(f"\n{md}cross-validation summary: {out_dir / CV_SUMMARY}.md")
    first = runs[0].summary
    summary = {  # the run's own record: what the ablation collector and an Optuna sweep read
        **{k: first.get(k) for k in ("command", "overrides", "seed", "dataset", "model", "machine", "code_version")},
        "overrides": [o for o in first.get("overrides", []) if not _sets_fold(o)] + [f"dataset.cv_fold={ALL_FOLDS}"],
        "config": {**first["config"], "dataset": {**first["config"]["dataset"], "cv_fold": ALL_FOLDS}},
        "output_dir": portable_path(out_dir),
        "train_wall_time_s": sum(r.summary.get("train_wall_time_s") or 0.0 for r in runs),
        "val": {"val/aoe_deg": figure},
        "test": {},
        "cross_validation": data,
    }
    write_json(out_dir / "summary.json", summary)
    return summary
