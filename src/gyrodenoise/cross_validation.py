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
into its sweep folder when the last run has finished. Runs of several recipes (a sweep over other settings too) get
one table each, PREFIX_<i>, each paired with the first recipe (or the --reference), and PREFIX side by side.
`dataset.cv_fold=all` trains the folds in turn inside one run (gyrodenoise.all_folds).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from gyrodenoise.ablation_runs import (
    CV_SUMMARY,
    Run,
    ablated_keys,
    find_runs,
    group,
    matching,
    mean_sd_n,
    parse_where,
    read_overrides,
    with_ext,
)
from gyrodenoise.ablation_stats import FoldSeedSpread, PairedDiff, fold_seed_spread
from gyrodenoise.atomic import output_path_problem, write_json, write_text
from gyrodenoise.tables import markdown_table

FOLD_KEY = "dataset.cv_fold"
ALL_FOLDS = "all"  # dataset.cv_fold=all: every fold in turn inside one run (gyrodenoise.all_folds)


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
    runs: list[Path] = field(default_factory=list)  # each run's summary, resolved (a reference must not share them)

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
        f.runs.append(Path(run.path).resolve())
        f.network.append(_number(run.summary.get("val"), "val/aoe_deg"))
        f.raw.append(_number(run.summary.get("val"), "val/raw_imu_aoe_deg"))
        f.calibrated.append(_number(run.summary.get("calibrated_baseline"), "calibrated_val_aoe_deg"))
    return CrossValidation(dataset, list(flights), dict(sorted(folds.items())), skipped)


def paired_by_fold(a: dict[str, float], b: dict[str, float]) -> PairedDiff:
    """a - b over the folds both have (each a fold's mean)."""
    keys = [k for k in a if k in b and math.isfinite(a[k]) and math.isfinite(b[k])]
    return PairedDiff(tuple(keys), tuple(a[k] - b[k] for k in keys))


def seed_split(cv: CrossValidation, reference: CrossValidation) -> tuple[FoldSeedSpread | None, str]:
    """recipe - reference per fold and seed (runs of the same seed on the same held-out flight), split into the
    fold's effect and the seed's (`ablation_stats.fold_seed_spread`); None, with why, unless every paired fold has
    the same number (>= 2) of seeds run in both."""
    ref = {f.held_out: dict(zip(f.seeds, f.network, strict=True)) for f in reference.folds.values()}
    rows = []
    for f in cv.folds.values():
        if f.held_out in ref:
            own = dict(zip(f.seeds, f.network, strict=True))
            rows.append([own[s] - ref[f.held_out][s] for s in sorted(set(own) & set(ref[f.held_out]))])
    counts = sorted({len(r) for r in rows})
    if len(rows) < 2 or counts[0] < 2 or len(counts) > 1:
        return None, f"not split: the folds have {'/'.join(map(str, counts)) or 'no'} seeds run in both recipes"
    if not all(math.isfinite(x) for r in rows for x in r):
        return None, "not split: a run without a held-out figure"
    return fold_seed_spread(rows), ""


def _detectable_at(spread: FoldSeedSpread) -> dict[str, float]:
    """The difference detectable with 80 % power at the seeds per fold run, at 3 and 10 where more, and unlimited."""
    at = [spread.n_seeds, *(n for n in (3, 10) if n > spread.n_seeds), math.inf]
    return {"unlimited" if math.isinf(n) else str(n): spread.detectable(n) for n in at}


def _seed_split_line(spread: FoldSeedSpread) -> str:
    *counted, (_, unlimited) = _detectable_at(spread).items()
    return (
        f"what more seeds would buy: the difference's sd is {spread.between_sd:.2f} deg between folds (no number of "
        f"seeds averages it away) and {spread.within_sd:.2f} between seeds of a fold; the difference detectable with "
        "80 % power is "
        + ", ".join(f"{d:.2f} deg at {n} seeds per fold" for n, d in counted)
        + f", {unlimited:.2f} with unlimited seeds (docs/training.md, 'Cross-validating a recipe')"
    )


def _cell(x: float) -> str:
    return f"{x:.2f}" if math.isfinite(x) else "-"


def _interval(d: PairedDiff, first: str) -> str:
    if d.n == 0:
        return "no fold in common"
    lo, hi = d.t_ci
    ci = f" [{lo:+.2f}, {hi:+.2f}] (95% t-interval)" if math.isfinite(lo) else ""
    if d.direction:
        verdict = f"the {first} is {d.verdict} (resolved)"
    elif d.n_star > 1000:  # an estimate of thousands of folds says only that the difference is lost in the spread
        verdict = f"{d.verdict} (the difference is far inside the fold-to-fold spread)"
    else:
        verdict = d.describe()
    return f"{d.mean:+.2f} deg{ci} over {d.n} folds: {verdict}"


def report(
    cv: CrossValidation, reference: CrossValidation | None = None, source: str = "", recipe: str = ""
) -> tuple[str, dict]:
    """Markdown and JSON of a cross-validation (and of its comparison with a reference recipe's); `recipe` names
    the settings that tell it from the other recipes of the same runs."""
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
        f"# Cross-validation: {cv.dataset}, leave one training flight out" + (f": {recipe}" if recipe else ""),
        "",
        *([f"Runs: {source}", ""] if source else []),
        "Held-out-flight AOE 3D (deg), each fold the mean of its runs; the recipe's figure is the mean over the folds "
        "(the selection protocol of reports/accuracy.md). The network's figure is the run's val/aoe_deg (the flight "
        "cut to 1 + a multiple of the loss's longest increment), the calibrated model's is scored on the whole "
        "flight: they can differ in the last digit.",
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
        "recipe": recipe,
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
        out["reference_per_fold"] = ref
        out["reference_seeds"] = {str(k): f.seeds for k, f in reference.folds.items()}
        out["recipe_minus_reference"] = {"mean": d.mean, "t_ci": list(d.t_ci), "verdict": d.verdict}
        spread, why = seed_split(cv, reference)
        md.append(f"- {_seed_split_line(spread) if spread else why}")
        out["seed_split"] = (
            {
                "seeds_per_fold": spread.n_seeds,
                "between_folds_sd": spread.between_sd,
                "within_fold_sd": spread.within_sd,
                "fold_effect_p": spread.interaction_p,
                "detectable_deg": _detectable_at(spread),
            }
            if spread
            else {"why_not": why}
        )
        if reference.flights != cv.flights:
            warning = (
                f"the reference's training flights are {reference.flights}, not {cv.flights} (folds paired by "
                "held-out flight)"
            )
            md.append(f"- warning: {warning}")
            out["warnings"] = [warning]
    if cv.skipped:
        md += ["", "Runs left out:", "", *(f"- {s}" for s in cv.skipped)]
    return "\n".join(md) + "\n", out


def reference_problem(cv: CrossValidation, reference: CrossValidation) -> str | None:
    """Why `reference` cannot be set against `cv` fold by fold (another dataset, no held-out flight in common)."""
    if reference.dataset != cv.dataset:
        return (
            f"the reference's runs are of {reference.dataset}, these of {cv.dataset}: a reference is another "
            "recipe on the same flights"
        )
    if not {f.held_out for f in reference.folds.values()} & {f.held_out for f in cv.folds.values()}:
        return f"the reference holds out none of the flights these runs hold out ({', '.join(cv.flights)})"
    shared = {p for f in cv.folds.values() for p in f.runs} & {p for f in reference.folds.values() for p in f.runs}
    if shared:  # a recipe against its own runs: a difference of 0 +- 0 that says nothing
        return (
            f"{len(shared)} run(s) are both the recipe's and the reference's (e.g. {min(shared)}): give the "
            "reference recipe's own runs, or pick them apart with --where and --reference-where"
        )
    return None


def by_held_out_flight(cv: CrossValidation, reference: CrossValidation) -> dict[str, float]:
    """The reference's fold means keyed by `cv`'s fold index of the same held-out flight (a reference that lists
    the training flights in another order, or other flights, pairs only where the held-out flight is the same)."""
    ref = {f.held_out: f.mean("network") for f in reference.folds.values()}
    return {str(k): ref[f.held_out] for k, f in cv.folds.items() if f.held_out in ref}


def read_run(path: Path) -> Run:
    """A run's summary.json as a Run (no validation of its fields: a fold of a dataset.cv_fold=all run)."""
    summary = json.loads(path.read_text())
    overrides, spelled = read_overrides(summary.get("overrides") or [])
    return Run(path, overrides, summary.get("config") or {}, summary, spelled)


def _folds_inside(run: Run) -> list[Run]:
    """A dataset.cv_fold=all run stands for the fold runs in its fold<k>/ folders."""
    if (run.config.get("dataset") or {}).get("cv_fold") != ALL_FOLDS:
        return [run]
    folder = run.path if run.path.is_dir() else run.path.parent
    return [read_run(p) for p in sorted(folder.glob("fold*/summary.json"))]


def _is_group(run: Run, key: str) -> bool:
    """Whether `key` is a config group in the run's config (dataset=..., model=...): a group choice is compared by
    the keys under it that runs override, not as a whole (its content holds the fold)."""
    node: object = run.config
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    return isinstance(node, dict)


def recipes(runs: Sequence[Run]) -> list[tuple[str, list[Run]]]:
    """The runs grouped by the overridden settings that differ between them, other than the fold and the seed
    (e.g. a sweep over model.dropout=0.1,0.2 and the folds): (label, runs) per recipe, in first-seen order."""
    keys = [k for k in ablated_keys(runs) if k != FOLD_KEY and not any(_is_group(r, k) for r in runs)]
    if not keys:
        return [("", list(runs))]
    return [(", ".join(f"{k}={v}" for k, v in zip(keys, s.values, strict=True)), s.runs) for s in group(runs, keys)]


def load_recipes(
    dirs: Sequence[Path], where: Sequence[tuple[str, str]] = (), flag: str = "--where"
) -> tuple[list[tuple[str, CrossValidation]], list[Path]]:
    """The cross-validations of the recipes found under `dirs` (runs matching every KEY=VALUE of `where`), and the
    unfinished run folders."""
    runs, unfinished = find_runs(dirs)
    # a cv_fold=all run as its folds before filtering: a fold's own summary says what it trained (the run folder's
    # .hydra/overrides.yaml is rewritten by any later command in that folder that runs, e.g. a resume)
    runs = [fold for r in runs for fold in _folds_inside(r)]
    runs = matching(runs, where, flag)
    if not runs:
        matches = f" matches {list(where)}" if where else ""
        raise ValueError(f"no finished run under {[str(d) for d in dirs]}{matches}")
    if not any(_data_of(r) for r in runs):  # said of all the runs, not of the first recipe's ('none of the 1 runs')
        raise ValueError(
            f"none of the {len(runs)} runs is a cross-validation run (dataset.cv_fold): "
            "train them with experiment=cross_validation or dataset.cv_fold=K"
        )
    found = [(label, collect(rs)) for label, rs in recipes(runs)]
    for _, cv in found:
        cv.skipped += [f"{p}: unfinished or failed (no summary.json; its train.log says which)" for p in unfinished]
    return found, unfinished


def load(
    dirs: Sequence[Path], where: Sequence[tuple[str, str]] = (), flag: str = "--where"
) -> tuple[CrossValidation, list[Path]]:
    """The cross-validation of the one recipe found under `dirs`; several recipes are an error naming them and the
    option (`flag`) that picks one."""
    found, unfinished = load_recipes(dirs, where, flag)
    if len(found) > 1:
        labels = "; ".join(label for label, _ in found)
        raise ValueError(f"the runs hold {len(found)} recipes ({labels}): choose one with {flag} KEY=VALUE")
    return found[0][1], unfinished


def write_recipes(
    found: list[tuple[str, CrossValidation]], prefix: Path, source: str, reference: CrossValidation | None = None
) -> str:
    """PREFIX.md/.json for one recipe; for several, PREFIX_<i>.md/.json each (against `reference`, else against
    the first recipe) and PREFIX.md/.json with their figures side by side. Returns the Markdown of PREFIX.md."""
    if len(found) == 1:
        md, data = report(found[0][1], reference, source, found[0][0])
        write(prefix, md, data)
        return md
    base_label, base = ("reference", reference) if reference else found[0]
    rows, index = [], []
    for i, (label, cv) in enumerate(found, 1):
        against = reference if reference else (None if i == 1 else base)
        md, data = report(cv, against, source, label)
        part = prefix.parent / f"{prefix.name}_{i}"
        write(part, md, data)
        d = data.get("recipe_minus_reference")
        vs = "-" if d is None else f"{d['mean']:+.2f} [{d['t_ci'][0]:+.2f}, {d['t_ci'][1]:+.2f}]: {d['verdict']}"
        rows.append([label, _cell(cv.figure()), _cell(cv.figure("calibrated")), vs, f"{part.name}.md"])
        index.append({"recipe": label, "file": f"{part.name}.json", **data})
    header = ["recipe", "figure (deg)", "calibrated (deg)", f"minus {base_label} (95% t-interval)", "table"]
    md = "\n".join(
        [
            f"# Cross-validation of {len(found)} recipes: {found[0][1].dataset}",
            "",
            f"Runs: {source}. Each recipe's figure is its mean held-out-flight AOE over the folds; differences are "
            "paired by held-out flight.",
            "",
            markdown_table(header, rows),
        ]
    )
    write(prefix, md, {"recipes": index})
    return md


def write(prefix: Path, md: str, data: dict) -> None:
    write_json(with_ext(prefix, ".json"), data)
    write_text(with_ext(prefix, ".md"), md)


def fold_list_problem(config: DictConfig) -> str | None:
    """What is wrong with the folds a multirun sweeps (its dataset.cv_fold override, else the experiment's sweep),
    or None."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    swept = {o.split("=", 1)[0].lstrip("+"): o.split("=", 1)[1] for o in config.hydra.overrides.task if "=" in o}
    params = config.hydra.sweeper.get("params") or {}
    key = FOLD_KEY
    value = swept.get(key, params.get(key))
    raw = OmegaConf.to_container(config.dataset, resolve=False).get("cv_fold") if "dataset" in config else None
    if value is None and isinstance(raw, str) and raw.replace(" ", "") == "${seed}":  # the ablations: fold = seed
        key = "seed"
        value = swept.get(key, params.get(key))
    flights = OmegaConf.select(config, "dataset.train_seqs", throw_on_missing=False, default=None)
    if value is None or not isinstance(flights, Sequence) or isinstance(flights, str):
        return None
    try:
        override = OverridesParser.create().parse_override(f"{key}={value}")
        folds = list(override.sweep_iterator()) if override.is_sweep_override() else [override.value()]
    except Exception:  # noqa: BLE001 - an unusual sweep: the jobs themselves will say what is wrong
        return None
    folds = [k for k in folds if k is not None]  # null: a job without cross-validation
    if not folds:
        return None
    n, name = len(flights), config.dataset.get("name", "the dataset")
    what = f"{key} sweeps {value}" + (
        " (the held-out flight is the seed: dataset.cv_fold=${seed})" if key == "seed" else ""
    )
    if n < 2:  # its one flight held out leaves none to train on: each job would stop on it
        return (
            f"{what}, but {name} has {n} training flight(s) ({', '.join(map(str, flights))}): cross-validation holds "
            "one out and trains on the others, so it needs two or more in dataset.train_seqs"
        )

    def fits(k: object) -> bool:  # 'all': each job trains every fold in turn (hparams_search's figure)
        every = isinstance(k, str) and k.lower() == "all" and key == FOLD_KEY
        return every or (isinstance(k, int) and not isinstance(k, bool) and 0 <= k < n)

    if all(fits(k) for k in folds):
        return None
    hint = (
        "the ablations sweep EuRoC's seeds 0,2,3,5"
        if key == "seed"
        else "experiment=cross_validation sweeps EuRoC's six"
    )
    return (
        f"{what}, but {name} has {n} training flights ({', '.join(map(str, flights))}): give "
        f"{key}={','.join(map(str, range(n)))} ({hint})"
        + ("" if key == "seed" else ", or run the folds in turn without -m")
    )


class FoldSweepCheck(Callback):
    """Hydra callback of every training multirun (conf/train.yaml): folds beyond the dataset's training flights, swept
    as dataset.cv_fold (experiment=cross_validation) or as the seed an ablation holds out (dataset.cv_fold=${seed}),
    end the sweep before any training, not after the valid folds have trained."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        if message := fold_list_problem(config):
            print(f"error: {message}", file=sys.stderr)
            raise SystemExit(2)  # Hydra turns a callback's exceptions into warnings and goes on


class CrossValidationCallback(Callback):
    """Hydra callback: after a multirun over folds, `<sweep dir>/cross_validation.{md,json}` (the folds are checked
    before the sweep by `FoldSweepCheck`, which every training multirun has)."""

    def on_job_end(self, config: DictConfig, **kwargs: Any) -> None:
        """After each job of the sweep, finished or failed: the table of the folds finished so far, so that a sweep
        Hydra stops at a failed job (it then skips on_multirun_end) still leaves one, naming what is missing."""
        from hydra.types import RunMode

        if OmegaConf.select(config, "hydra.mode") != RunMode.MULTIRUN:
            return
        sweep = Path(config.hydra.sweep.dir)
        try:
            found, _ = load_recipes([sweep])
            write_recipes(found, sweep / CV_SUMMARY, str(sweep))
        except (ValueError, FileNotFoundError, OSError):  # nothing finished yet, or a concurrent job's half state
            return

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep = Path(config.hydra.sweep.dir)
        try:
            found, _ = load_recipes([sweep])
        except (ValueError, FileNotFoundError) as e:
            print(f"no cross-validation summary: {e}", file=sys.stderr)
            return
        print(write_recipes(found, sweep / CV_SUMMARY, str(sweep)))
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
    if args.out is not None and (problem := output_path_problem(f"{args.out}.md")):  # a folder on the way is a file
        ap.error(f"--out {args.out}: {problem}")
    try:
        found, _ = load_recipes(args.dirs, parse_where(args.where))
        ref = None
        if args.reference:
            ref = load(args.reference, parse_where(args.reference_where), "--reference-where")[0]
            for _, cv in found:
                if problem := reference_problem(cv, ref):
                    raise ValueError(problem)
    except (ValueError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    prefix = args.out or (args.dirs[0] if args.dirs[0].is_dir() else args.dirs[0].parent) / CV_SUMMARY
    print(write_recipes(found, prefix, ", ".join(str(d) for d in args.dirs), ref))
    print(f"written: {prefix}.md, {prefix}.json" + (f" and {prefix.name}_1..{len(found)}" if len(found) > 1 else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
