"""A recipe's cross-validation figure in one command: the selection protocol of reports/accuracy.md.

    python -m gyrodenoise.train -m experiment=cross_validation dataset=euroc model.dropout=0.2   # 6 folds
    python -m gyrodenoise.train -m experiment=cross_validation dataset=tumvi dataset.cv_fold=0,1,2 test=false
    python -m gyrodenoise.cross_validation SWEEP_DIR [--reference OTHER_DIR] [--where KEY=VALUE] [--out PREFIX]
    python -m gyrodenoise.train dataset=euroc dataset.cv_fold=all          # the folds one after another, one folder
    python -m gyrodenoise.train hparams_search=euroc_optuna dataset.cv_fold=all   # a search on the protocol's figure

Fold k holds training flight k out and validates on it whole (`dataset.cv_fold=k`). A fold's figure is the mean
held-out AOE of its runs (several seeds per fold: `seed=0,1,2`); the recipe's figure is the mean over the folds.
Every run also fitted the 12-parameter calibrated model on the same data: the table sets the network against it fold
by fold (does the denoiser beat calibration on flights it did not see?), and `--reference` sets the recipe against
another recipe's runs (e.g. the project's default, or the committed runs in reports/accuracy_runs/), paired by fold.
Differences come with a 95% t-interval over the folds: with six folds and a fold-to-fold spread of ~1 deg only
effects of ~1.4 deg and more are resolved (reports/accuracy.md).
Writes PREFIX.md and PREFIX.json (default: SWEEP_DIR/cross_validation); experiment=cross_validation writes them
into its sweep folder when the last run has finished. `dataset.cv_fold=all` trains the folds in turn inside one run
(fold<k>/ each; a fold finished before is kept, so a requeued run goes on) and returns the figure as the run's
val/aoe_deg: what an Optuna search minimises.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict

from gyrodenoise.ablation_runs import CV_SUMMARY, Run, find_runs, mean_sd_n, parse_where, same_value, with_ext
from gyrodenoise.ablation_stats import PairedDiff
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.paths import portable_tree
from gyrodenoise.tables import markdown_table

FOLD_KEY = "dataset.cv_fold"


@dataclass
class Fold:
    """The runs of one held-out flight: held-out AOE (deg) of the network, of the calibrated model fitted on the
    same data, and of the raw IMU, one value per run (nan where a run did not record it)."""

    index: int
    held_out: str
    seeds: list[str] = field(default_factory=list)
    network: list[float] = field(default_factory=list)
    calibrated: list[float] = field(default_factory=list)
    raw: list[float] = field(default_factory=list)

    def mean(self, what: str) -> float:
        return mean_sd_n(getattr(self, what))[0]


@dataclass
class CrossValidation:
    dataset: str
    flights: list[str]  # the training flights, in fold order
    folds: dict[int, Fold]
    skipped: list[str]  # runs left out, each with its reason

    @property
    def missing(self) -> list[int]:
        return [k for k in range(len(self.flights)) if k not in self.folds]

    @property
    def unscored(self) -> list[int]:
        """Folds with runs but no finite network figure (every run's val/aoe_deg NaN or absent): left out of the
        figure, which is then not the protocol's figure over every fold."""
        return [k for k, f in self.folds.items() if not math.isfinite(f.mean("network"))]

    def figure(self, what: str = "network") -> float:
        """The protocol figure: the mean over the folds present of each fold's mean."""
        return mean_sd_n(f.mean(what) for f in self.folds.values())[0]

    def per_fold(self, what: str = "network") -> dict[str, float]:
        return {str(k): f.mean(what) for k, f in sorted(self.folds.items())}


def _number(table: object, key: str) -> float:
    v = table.get(key) if isinstance(table, dict) else None
    return float(v) if isinstance(v, int | float) else math.nan


def _data_of(run: Run) -> tuple[str, tuple[str, ...]] | None:
    """(dataset name, training flights) of a cross-validation run, None for another run."""
    ds = run.config.get("dataset") or {}
    if not isinstance(ds.get("cv_fold"), int):
        return None
    return ds.get("name", "?"), tuple(ds.get("train_seqs") or [])


def collect(runs: Sequence[Run]) -> CrossValidation:
    """Group runs by held-out flight. Runs of another dataset or training-flight list than most runs', or without
    dataset.cv_fold, are left out with the reason (never silently)."""
    if not runs:
        raise ValueError("no finished run (summary.json) to collect")
    folds: dict[int, Fold] = {}
    skipped: list[str] = []
    seen: dict[tuple[int, object], Path] = {}  # (fold, seed) -> the run counted for it
    data_of = {id(r): _data_of(r) for r in runs}
    kinds = Counter(d for d in data_of.values() if d)
    if not kinds:
        raise ValueError(
            f"none of the {len(runs)} runs is a cross-validation run (dataset.cv_fold): "
            "train them with experiment=cross_validation or dataset.cv_fold=K"
        )
    # the dataset and flight list of most runs (not of whichever run sorts first, which may be a stray one)
    dataset, flights = kinds.most_common(1)[0][0]
    for run in runs:
        fold = (run.config.get("dataset") or {}).get("cv_fold")
        if data_of[id(run)] is None:
            skipped.append(f"{run.path}: no dataset.cv_fold (not a cross-validation run)")
            continue
        if data_of[id(run)] != (dataset, flights):
            skipped.append(f"{run.path}: another dataset or list of training flights than {dataset} {flights}")
            continue
        # the same run reached twice (a folder and a file in it), a copy, or another recipe's run of that fold and
        # seed: counted once (a run without a seed is told apart by its path)
        key = (fold, str(run.seed) if run.seed is not None else str(Path(run.path).resolve()))
        if key in seen:
            skipped.append(
                f"{run.path}: fold {fold}, seed {run.seed} again (counted: {seen[key]}); a duplicate, or another "
                "recipe's run: choose the runs with --where"
            )
            continue
        seen[key] = run.path
        f = folds.setdefault(fold, Fold(fold, flights[fold] if fold < len(flights) else f"flight {fold}"))
        f.seeds.append(str(run.seed))
        f.network.append(_number(run.summary.get("val"), "val/aoe_deg"))
        f.raw.append(_number(run.summary.get("val"), "val/raw_imu_aoe_deg"))
        f.calibrated.append(_number(run.summary.get("calibrated_baseline"), "calibrated_val_aoe_deg"))
    return CrossValidation(dataset, list(flights), dict(sorted(folds.items())), skipped)


def paired_by_fold(a: dict[str, float], b: dict[str, float]) -> PairedDiff:
    """a - b over the folds both have (each a fold's mean)."""
    keys = [k for k in a if k in b and math.isfinite(a[k]) and math.isfinite(b[k])]
    return PairedDiff(tuple(keys), tuple(a[k] - b[k] for k in keys))


def _cell(x: float) -> str:
    return f"{x:.2f}" if math.isfinite(x) else "-"


def _interval(d: PairedDiff, first: str) -> str:
    if d.n == 0:
        return "no fold in common"
    lo, hi = d.t_ci
    ci = f" [{lo:+.2f}, {hi:+.2f}] (95% t-interval)" if math.isfinite(lo) else ""
    verdict = f"the {first} is {d.verdict} (resolved)" if d.direction else d.describe()
    return f"{d.mean:+.2f} deg{ci} over {d.n} folds: {verdict}"


def report(cv: CrossValidation, reference: CrossValidation | None = None, source: str = "") -> tuple[str, dict]:
    """Markdown and JSON of a cross-validation (and of its comparison with a reference recipe's)."""
    vs_cal = paired_by_fold(cv.per_fold("network"), cv.per_fold("calibrated"))
    header = ["fold: held-out flight", "runs (seeds)", "network", "calibrated (same data)", "raw IMU"]
    methods = ("network", "calibrated", "raw") if math.isfinite(cv.figure("raw")) else ("network", "calibrated")
    header = header[: 2 + len(methods)]  # runs before the raw IMU's figure was logged have none
    ref = by_held_out_flight(cv, reference) if reference else {}
    if reference:
        header.append("reference")
    rows = []
    for k, f in cv.folds.items():
        row = [f"{k}: {f.held_out}", f"{len(f.seeds)} ({', '.join(f.seeds)})"]
        row += [_cell(f.mean(w)) for w in methods]
        rows.append(row + ([_cell(ref.get(str(k), math.nan))] if reference else []))
    scored = len(cv.folds) - len(cv.unscored)
    mean_row = [f"mean over {scored} folds", "", *(_cell(cv.figure(w)) for w in methods)]
    rows.append(mean_row + ([_cell(reference.figure())] if reference else []))
    won = sum(d < 0 for d in vs_cal.diffs)
    md = [
        f"# Cross-validation: {cv.dataset}, leave one training flight out",
        "",
        *([f"Runs: {source}", ""] if source else []),
        "Held-out-flight AOE 3D (deg), each fold the mean of its runs; the recipe's figure is the mean over the folds "
        "(the selection protocol of reports/accuracy.md).",
        "",
        markdown_table(header, rows),
        f"- **The recipe's figure: {_cell(cv.figure())} deg** over {scored} of {len(cv.flights)} folds"
        + (f" (missing: {', '.join(f'{k}: {cv.flights[k]}' for k in cv.missing)})" if cv.missing else "")
        + (
            f" (no network figure in their runs: {', '.join(f'{k}: {cv.folds[k].held_out}' for k in cv.unscored)})"
            if cv.unscored
            else ""
        ),
        f"- network - calibrated: {_interval(vs_cal, 'network')}; the network wins {won} of {vs_cal.n} folds",
    ]
    out = {
        "dataset": cv.dataset,
        "flights": cv.flights,
        "figure_deg": cv.figure(),
        "calibrated_figure_deg": cv.figure("calibrated"),
        "raw_imu_figure_deg": cv.figure("raw"),
        "folds": {
            str(k): {"held_out": f.held_out, "seeds": f.seeds, "network": f.network, "calibrated": f.calibrated}
            for k, f in cv.folds.items()
        },
        "missing_folds": cv.missing,
        "unscored_folds": cv.unscored,
        "network_minus_calibrated": {"mean": vs_cal.mean, "t_ci": list(vs_cal.t_ci), "verdict": vs_cal.verdict},
        "skipped": cv.skipped,
    }
    if reference:
        d = paired_by_fold(cv.per_fold("network"), ref)  # by held-out flight, whatever the reference's fold order
        md.append(f"- recipe - reference ({_cell(reference.figure())} deg): {_interval(d, 'recipe')}")
        out["reference_figure_deg"] = reference.figure()
        out["recipe_minus_reference"] = {"mean": d.mean, "t_ci": list(d.t_ci), "verdict": d.verdict}
        if reference.flights != cv.flights:
            md.append(
                f"- warning: the reference's training flights are {reference.flights}, not {cv.flights} (folds "
                "paired by held-out flight)"
            )
    if cv.skipped:
        md += ["", "Runs left out:", "", *(f"- {s}" for s in cv.skipped)]
    return "\n".join(md) + "\n", out


def by_held_out_flight(cv: CrossValidation, reference: CrossValidation) -> dict[str, float]:
    """The reference's fold means keyed by `cv`'s fold index of the same held-out flight (a reference that lists
    the training flights in another order, or other flights, pairs only where the held-out flight is the same)."""
    ref = {f.held_out: f.mean("network") for f in reference.folds.values()}
    return {str(k): ref[f.held_out] for k, f in cv.folds.items() if f.held_out in ref}


def _read_run(path: Path) -> Run:
    summary = json.loads(path.read_text())
    return Run(path, {}, summary.get("config") or {}, summary)


def _folds_inside(run: Run) -> list[Run]:
    """A dataset.cv_fold=all run stands for the fold runs in its fold<k>/ folders."""
    if (run.config.get("dataset") or {}).get("cv_fold") != ALL_FOLDS:
        return [run]
    folder = run.path if run.path.is_dir() else run.path.parent
    return [_read_run(p) for p in sorted(folder.glob("fold*/summary.json"))]


def load(dirs: Sequence[Path], where: Sequence[tuple[str, str]] = ()) -> tuple[CrossValidation, list[Path]]:
    runs, unfinished = find_runs(dirs)
    runs = [r for r in runs if all(same_value(r.value(k), v) for k, v in where)]
    runs = [fold for r in runs for fold in _folds_inside(r)]
    if not runs:
        matching = f" matches {list(where)}" if where else ""
        raise ValueError(f"no finished run under {[str(d) for d in dirs]}{matching}")
    cv = collect(runs)
    cv.skipped += [f"{p}: unfinished (no summary.json)" for p in unfinished]
    return cv, unfinished


def write(prefix: Path, md: str, data: dict) -> None:
    write_json(with_ext(prefix, ".json"), data)
    write_text(with_ext(prefix, ".md"), md)


ALL_FOLDS = "all"


def wants_all_folds(cfg: DictConfig) -> bool:
    """Whether the config asks for every fold in one run (`dataset.cv_fold=all`)."""
    return OmegaConf.select(cfg, "dataset.cv_fold") == ALL_FOLDS


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


def _differences(kept: object, now: object, prefix: str = "") -> list[str]:
    """Keys of both configs whose values differ (a key that only one has is not counted: another code version)."""
    if prefix.rstrip(".") in RUN_ONLY_KEYS:
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
            "Give this run another output folder, or remove that run's folder to train it afresh"
        )


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
    runs = []
    for k in range(len(flights)):
        folder = out_dir / f"fold{k}"
        cfg_k = cfg.copy()
        with open_dict(cfg_k):
            cfg_k.dataset.cv_fold = k
            cfg_k.paths.output_dir = str(folder)
        if (folder / "model.pt").is_file() and (folder / "summary.json").is_file():
            kept = _read_run(folder / "summary.json")
            _check_kept_fold(folder, kept.summary, cfg_k)
            print(f"fold {k} ({flights[k]} held out): finished before, kept ({folder})")
            runs.append(kept)
            continue
        print(f"\n=== fold {k} of {len(flights)}: {flights[k]} held out ({folder}) ===")
        summary = train_one(cfg_k, folder)
        # the fold's record names its own fold, not the command line's 'all'
        summary["overrides"] = [f"dataset.cv_fold={k}" if o.lstrip("+").startswith("dataset.cv_fold=") else o
                                for o in summary.get("overrides", [])]  # fmt: skip
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
        "overrides": [o for o in first.get("overrides", []) if not o.lstrip("+").startswith("dataset.cv_fold=")]
        + [f"dataset.cv_fold={ALL_FOLDS}"],
        "config": {**first["config"], "dataset": {**first["config"]["dataset"], "cv_fold": ALL_FOLDS}},
        "output_dir": str(out_dir),
        "train_wall_time_s": sum(r.summary.get("train_wall_time_s") or 0.0 for r in runs),
        "val": {"val/aoe_deg": figure},
        "test": {},
        "cross_validation": data,
    }
    write_json(out_dir / "summary.json", summary)
    return summary


try:  # the Hydra hook of experiment=cross_validation
    from hydra.experimental.callback import Callback as _HydraCallback
except ImportError:  # pragma: no cover
    _HydraCallback = object  # type: ignore[assignment,misc]


class CrossValidationCallback(_HydraCallback):
    """Hydra callback: after a multirun over folds, `<sweep dir>/cross_validation.{md,json}`."""

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep = Path(config.hydra.sweep.dir)
        try:
            cv, _ = load([sweep])
        except (ValueError, FileNotFoundError) as e:
            print(f"no cross-validation summary: {e}", file=sys.stderr)
            return
        md, data = report(cv, source=str(sweep))
        write(sweep / CV_SUMMARY, md, data)
        print(md)
        print(f"cross-validation summary: {sweep / CV_SUMMARY}.md")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m gyrodenoise.cross_validation",
        description="A recipe's leave-one-flight-out cross-validation figure from its runs.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__.split("\n\n", 1)[1],
    )
    ap.add_argument("dirs", nargs="+", type=Path, help="sweep folders, run folders or summary JSON files")
    ap.add_argument("--where", action="append", default=[], metavar="KEY=VALUE", help="keep matching runs only")
    ap.add_argument("--reference", nargs="+", type=Path, help="another recipe's runs, paired with these by fold")
    ap.add_argument(
        "--reference-where", action="append", default=[], metavar="KEY=VALUE", help="keep matching reference runs"
    )
    ap.add_argument("--out", type=Path, help=f"output prefix (default: the first folder's {CV_SUMMARY})")
    args = ap.parse_args(argv)
    try:
        cv, _ = load(args.dirs, parse_where(args.where))
        ref = load(args.reference, parse_where(args.reference_where))[0] if args.reference else None
    except (ValueError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    md, data = report(cv, ref, source=", ".join(str(d) for d in args.dirs))
    prefix = args.out or (args.dirs[0] if args.dirs[0].is_dir() else args.dirs[0].parent) / CV_SUMMARY
    write(prefix, md, data)
    print(md)
    print(f"written: {prefix}.md, {prefix}.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
