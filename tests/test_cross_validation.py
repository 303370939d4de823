"""The cross-validation figure of a recipe (gyrodenoise.cross_validation): it reproduces a committed round of the
selection protocol from the committed runs, names the runs it leaves out, and experiment=cross_validation writes it
into the sweep folder."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from _asl import TINY_TRAINING, run_train, write_asl_sequence
from scipy import stats

from gyrodenoise import cross_validation as cv
from gyrodenoise.ablation_stats import detectable_difference

REPO = Path(__file__).resolve().parents[1]
RUNS = REPO / "reports"


def _files(*patterns: str) -> list[Path]:
    return sorted(p for pattern in patterns for p in RUNS.glob(pattern))


def test_reproduces_round_2_of_the_selection_from_the_committed_runs(tmp_path):
    """Round 2 of reports/accuracy.md (whole flights against ref, 3 seeds per fold), as benchmarks/accuracy_report.py
    computed it into reports/accuracy/summary.json, from the same summary files through the command line."""
    # round 1's ablation runs are seeds 0, 2, 3, 5 (seeds 1 and 4, added later, are the ablation report's only)
    ref = _files(
        "ablation_runs/reference/gelu_s[0235].json",
        "accuracy_runs/euroc_cv/ref_f*.json",
        "accuracy_runs/euroc_cv2/ref_*",
    )
    whole = _files(
        "ablation_runs/train_duration/whole_s[0235].json",
        "accuracy_runs/euroc_cv/whole_f*.json",
        "accuracy_runs/euroc_cv2/whole_*",
    )
    assert len(ref) == len(whole) == 18
    out = tmp_path / "round2"
    assert cv.main([*map(str, whole), "--reference", *map(str, ref), "--out", str(out)]) == 0
    got = json.loads(out.with_suffix(".json").read_text())
    committed = json.loads((RUNS / "accuracy" / "summary.json").read_text())["cv_round2"]
    assert got["recipe_minus_reference"]["mean"] == pytest.approx(committed["whole_minus_ref"], abs=1e-9)
    assert got["recipe_minus_reference"]["t_ci"] == pytest.approx(committed["t_interval_95"], abs=1e-9)
    assert got["figure_deg"] == pytest.approx(6.23, abs=0.005) and got["reference_figure_deg"] == pytest.approx(
        5.90, abs=0.005
    )
    assert [len(f["seeds"]) for f in got["folds"].values()] == [3] * 6 and got["missing_folds"] == []
    md = out.with_suffix(".md").read_text()
    assert "| 0: MH_01_easy | 3 (" in md and "not resolved at n=6" in md
    # the split of the difference into fold and seed: together they make the fold means' spread, which the interval
    # of the paired difference was taken from (t_{0.975,5} sd / sqrt(6) its half-width)
    split = got["seed_split"]
    assert split["seeds_per_fold"] == 3 and "what more seeds would buy" in md
    lo, hi = got["recipe_minus_reference"]["t_ci"]
    fold_means_sd = (hi - lo) / 2 / stats.t.ppf(0.975, 5) * math.sqrt(6)
    assert math.hypot(split["between_folds_sd"], split["within_fold_sd"] / math.sqrt(3)) == pytest.approx(fold_means_sd)
    assert split["detectable_deg"]["3"] == pytest.approx(detectable_difference(fold_means_sd, 6))
    assert split["detectable_deg"]["unlimited"] == pytest.approx(detectable_difference(split["between_folds_sd"], 6))


def _summary(path: Path, fold: int | None, val: float, cal: float, seed: int = 0) -> Path:
    ds = {"name": "mine", "train_seqs": ["a", "b", "c"], "cv_fold": fold}
    s = {
        "overrides": [f"seed={seed}"] + ([f"dataset.cv_fold={fold}"] if fold is not None else []),
        "config": {"dataset": ds, "seed": seed},
        "val": {"val/aoe_deg": val, "val/raw_imu_aoe_deg": val + 1},
        "test": {"test/aoe_deg": 1.0},
        "calibrated_baseline": {"calibrated_val_aoe_deg": cal},
    }
    path.write_text(json.dumps(s))
    return path


def test_folds_left_out_and_runs_that_are_not_cross_validation_are_named(tmp_path):
    files = [
        _summary(tmp_path / "f0s0.json", 0, 2.0, 3.0),
        _summary(tmp_path / "f0s1.json", 0, 4.0, 3.0, seed=1),
        _summary(tmp_path / "f2.json", 2, 1.0, 2.0),
        _summary(tmp_path / "plain.json", None, 9.0, 9.0),
    ]
    result, _ = cv.load(files)
    assert result.figure() == pytest.approx((3.0 + 1.0) / 2) and result.figure("calibrated") == pytest.approx(2.5)
    assert result.figure("raw") == pytest.approx(3.0) and result.missing == [1]
    assert len(result.skipped) == 1 and "plain.json: no dataset.cv_fold" in result.skipped[0]
    md, data = cv.report(result)
    assert "over 2 of 3 folds (missing: 1: b)" in md and "plain.json" in md
    assert data["network_minus_calibrated"]["mean"] == pytest.approx(-0.5)
    with pytest.raises(ValueError, match="none of the 1 runs is a cross-validation run"):
        cv.load([files[-1]])
    assert cv.main([str(tmp_path / "no such folder")]) == 2


def test_the_seed_split_needs_the_same_seeds_in_both_recipes_on_every_fold(tmp_path):
    arm = [_summary(tmp_path / f"a{k}{s}.json", k, 3.0 + k + s / 10, 5.0, seed=s) for k in range(3) for s in (0, 1)]
    ref = [_summary(tmp_path / f"r{k}{s}.json", k, 3.0 + s / 5, 5.0, seed=s) for k in range(3) for s in (0, 1)]
    (result, _), (reference, _) = cv.load(arm), cv.load(ref)
    spread, why = cv.seed_split(result, reference)
    assert spread.n_seeds == 2 and why == "" and spread.mean == pytest.approx(1.0 - 0.05)
    assert spread.within_sd == pytest.approx(0.05 * math.sqrt(2)) and spread.between_sd > 0.9
    (fewer, _) = cv.load(ref[:-1])  # fold 2 has one seed left
    spread, why = cv.seed_split(result, fewer)
    assert spread is None and why == "not split: the folds have 1/2 seeds run in both recipes"
    md, data = cv.report(result, fewer)
    assert f"- {why}" in md and data["seed_split"] == {"why_not": why}


def _tiny(tmp_path: Path) -> list[str]:
    """Three 6-s synthetic flights and a network small enough to train in a second."""
    root = tmp_path / "asl"
    for i, name in enumerate(["a", "b", "c"]):
        write_asl_sequence(root / name, seconds=6.0, seed=i)
    return [
        "dataset=asl_folder",
        f"dataset.root={root}",
        "dataset.train_seqs=[a,b,c]",
        "dataset.test_seqs=[a]",
        *TINY_TRAINING,
    ]


def test_cross_validation_experiment_writes_the_figure_into_the_sweep(tmp_path):
    """-m experiment=cross_validation over the three flights of a tiny synthetic folder: one run per held-out
    flight, then <sweep>/cross_validation.md/.json, which the ablation collector does not take for a run."""
    sweep = tmp_path / "multirun"
    args = ["-m", "experiment=cross_validation", "dataset.cv_fold=0,1,2", *_tiny(tmp_path), f"hydra.sweep.dir={sweep}"]
    run_train(args, cwd=tmp_path)
    data = json.loads((sweep / "cross_validation.json").read_text())
    assert data["flights"] == ["a", "b", "c"] and data["missing_folds"] == []
    assert [f["held_out"] for f in data["folds"].values()] == ["a", "b", "c"]
    assert all(math.isfinite(x) for f in data["folds"].values() for x in f["network"] + f["calibrated"])
    from gyrodenoise.ablation_runs import find_runs

    assert len(find_runs([sweep])[0]) == 3


def test_all_folds_in_one_run_return_the_figure_and_resume(tmp_path):
    """dataset.cv_fold=all: the folds in turn in fold<k>/ of one run, whose summary's val/aoe_deg (what an Optuna
    sweep minimises) is the mean over the folds; run again in its folder it keeps the finished folds."""
    run_dir = tmp_path / "run"
    # experiment=cross_validation without -m: dataset.cv_fold=all, and a note that says so
    args = ["experiment=cross_validation", *_tiny(tmp_path), f"hydra.run.dir={run_dir}"]
    assert "without -m this run trains every fold in turn" in run_train(args, cwd=tmp_path).stdout
    top = json.loads((run_dir / "summary.json").read_text())
    folds = [json.loads((run_dir / f"fold{k}" / "summary.json").read_text()) for k in range(3)]
    assert [f["config"]["dataset"]["cv_fold"] for f in folds] == [0, 1, 2]
    assert all("dataset.cv_fold=all" not in f["overrides"] for f in folds)
    assert top["val"]["val/aoe_deg"] == pytest.approx(sum(f["val"]["val/aoe_deg"] for f in folds) / 3)
    assert top["cross_validation"]["figure_deg"] == top["val"]["val/aoe_deg"]
    again = run_train(args, cwd=tmp_path)
    assert again.stdout.count("finished before, kept") == 3
    assert json.loads((run_dir / "summary.json").read_text())["val"] == top["val"]
    # the collector reads the run folder as its folds
    assert cv.main([str(run_dir), "--out", str(tmp_path / "again")]) == 0
    assert json.loads((tmp_path / "again.json").read_text())["figure_deg"] == pytest.approx(top["val"]["val/aoe_deg"])
    with pytest.raises(ValueError, match="dataset.cv_fold=all trains every fold"):
        from gyrodenoise.data.datamodule import ImuDataModule

        ImuDataModule("x", "/nowhere", ["a", "b"], [], cv_fold="all")


def test_a_stray_run_of_other_flights_does_not_set_the_flights(tmp_path):
    """The flights are those of most runs: a stray run that sorts first is the one left out, not the others."""
    stray = _summary(tmp_path / "0_stray.json", 0, 5.0, 5.0)
    data = json.loads(stray.read_text())
    data["config"]["dataset"]["train_seqs"] = ["x", "y"]
    stray.write_text(json.dumps(data))
    files = [stray, _summary(tmp_path / "f0.json", 0, 2.0, 3.0), _summary(tmp_path / "f1.json", 1, 1.0, 2.0)]
    result, _ = cv.load(files)
    assert result.flights == ["a", "b", "c"] and result.figure() == pytest.approx(1.5)
    assert len(result.skipped) == 1 and "0_stray.json: another dataset or list of training flights" in result.skipped[0]


def test_runs_of_several_recipes_get_a_table_each_and_one_side_by_side(tmp_path):
    """A sweep over a setting and the folds (model.dropout=0.1,0.2 x 3 folds): one table per recipe, the second
    paired with the first by fold, and the side-by-side table; asking for one recipe names them."""
    for dropout, values in (("0.1", [2.0, 3.0, 4.0]), ("0.2", [1.0, 2.5, 3.0])):
        for k, v in enumerate(values):
            path = _summary(tmp_path / f"d{dropout}_f{k}.json", k, v, 5.0)
            data = json.loads(path.read_text())
            data["overrides"].append(f"model.dropout={dropout}")
            path.write_text(json.dumps(data))
    with pytest.raises(
        ValueError, match=r"2 recipes \(model.dropout=0.1; model.dropout=0.2\): choose one with --where"
    ):
        cv.load([tmp_path])
    assert cv.load([tmp_path], [("model.dropout", "0.2")])[0].figure() == pytest.approx(6.5 / 3)
    out = tmp_path / "out" / "cv"
    assert cv.main([str(tmp_path), "--out", str(out)]) == 0
    second = json.loads((out.parent / "cv_2.json").read_text())
    assert second["recipe"] == "model.dropout=0.2" and second["recipe_minus_reference"]["mean"] == pytest.approx(
        -2.5 / 3
    )
    side = (out.parent / "cv.md").read_text()
    assert "| model.dropout=0.1 | 3.00 |" in side and "| model.dropout=0.2 | 2.17 | 5.00 | -0.83 [" in side


def test_a_fold_list_beyond_the_flights_stops_the_sweep_before_training(tmp_path):
    """experiment=cross_validation sweeps EuRoC's six folds: on three flights the sweep ends before any job, saying
    which folds to give (Hydra would train folds 0-2 and fail on 3 with no table)."""
    from omegaconf import DictConfig, OmegaConf

    def config(task: list[str]) -> DictConfig:
        return OmegaConf.create(
            {
                "dataset": {"name": "tumvi", "train_seqs": ["r1", "r3", "r5"]},
                "hydra": {"overrides": {"task": task}, "sweeper": {"params": {"dataset.cv_fold": "0,1,2,3,4,5"}}},
            }
        )

    assert "give dataset.cv_fold=0,1,2" in cv.fold_list_problem(config(["dataset=tumvi"]))
    assert cv.fold_list_problem(config(["dataset.cv_fold=0,1,2"])) is None
    assert cv.fold_list_problem(config(["dataset.cv_fold=range(0,3)"])) is None
    assert "sweeps range(0,4)" in cv.fold_list_problem(config(["dataset.cv_fold=range(0,4)"]))
    with pytest.raises(SystemExit):
        cv.FoldSweepCheck().on_multirun_start(config(["dataset=tumvi"]))
    # every training multirun has the check: a search whose trials each train all folds, or none, passes it
    search = OmegaConf.create(
        {
            "dataset": {"name": "euroc", "train_seqs": ["a", "b", "c"], "cv_fold": None},
            "hydra": {"overrides": {"task": ["dataset.cv_fold=all"]}, "sweeper": {"params": {"optim.lr": "0.1,0.2"}}},
        }
    )
    assert cv.fold_list_problem(search) is None  # hparams_search=euroc_optuna dataset.cv_fold=all (docs/training.md)
    search.hydra.overrides.task = ["dataset.cv_fold=null"]
    assert cv.fold_list_problem(search) is None


def test_an_ablation_whose_seeds_exceed_the_flights_stops_before_training():
    """An ablation holds out fold = seed (dataset.cv_fold=${seed}, seeds 0,2,3,5): on three own flights its seeds 3
    and 5 failed after the others had trained (audit 63); the sweep now ends first, advising seeds, not folds."""
    from omegaconf import OmegaConf

    def config(task: list[str]) -> object:
        return OmegaConf.create(
            {
                "seed": 0,
                "dataset": {"name": "mine", "train_seqs": ["a", "b", "c"], "cv_fold": "${seed}"},
                "hydra": {
                    "overrides": {"task": task},
                    "sweeper": {"params": {"model.act": "gelu,relu", "seed": "0,2,3,5"}},
                },
            }
        )

    problem = cv.fold_list_problem(config([]))
    assert problem.startswith("seed sweeps 0,2,3,5 (the held-out flight is the seed: dataset.cv_fold=${seed})")
    assert "give seed=0,1,2 (the ablations sweep EuRoC's seeds 0,2,3,5)" in problem
    assert cv.fold_list_problem(config(["seed=0,1,2"])) is None
    with pytest.raises(SystemExit):
        cv.FoldSweepCheck().on_multirun_start(config([]))


def test_a_reference_of_another_dataset_or_not_a_summary_is_refused(tmp_path, capsys):
    mine = [_summary(tmp_path / f"m{k}.json", k, 1.0, 2.0) for k in range(3)]
    other = tmp_path / "other"
    other.mkdir()
    for k in range(2):
        path = _summary(other / f"o{k}.json", k, 1.0, 2.0)
        data = json.loads(path.read_text())
        data["config"]["dataset"] |= {"name": "tumvi", "train_seqs": ["r1", "r3"]}
        path.write_text(json.dumps(data))
    assert cv.main([*map(str, mine), "--reference", str(other), "--out", str(tmp_path / "x")]) == 2
    assert "the reference's runs are of tumvi, these of mine" in capsys.readouterr().err
    # a recipe against its own runs (or some of them) would print a difference of 0 +- 0
    assert cv.main([*map(str, mine), "--reference", str(mine[0]), "--out", str(tmp_path / "x")]) == 2
    assert "1 run(s) are both the recipe's and the reference's" in capsys.readouterr().err
    # a misspelt --where key is named with the setting it was probably meant to be, not "no run matches"
    assert cv.main([*map(str, mine), "--where", "dataset.nme=mine"]) == 2
    assert "--where dataset.nme=mine: none of the 3 runs has a setting dataset.nme: did you mean dataset.name?" in (
        capsys.readouterr().err
    )
    stray = tmp_path / "stray"
    stray.mkdir()
    (stray / "notes.json").write_text('{"a": 1}')
    assert cv.main([str(stray)]) == 2
    assert "notes.json: not a run summary written by gyrodenoise.train" in capsys.readouterr().err


def test_a_launcher_sweeper_or_logger_without_its_package_says_what_to_install(monkeypatch):
    import importlib.util

    from gyrodenoise.cli_errors import missing_plugin_message

    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    assert "pip install 'gyrodenoise[sweep]'" in missing_plugin_message(["-m", "hydra/launcher=local"])
    assert "hparams_search=euroc_optuna needs a package" in missing_plugin_message(["hparams_search=euroc_optuna"])
    assert "[slurm]" in missing_plugin_message(["hydra/launcher=slurm"])
    assert "logger=[tensorboard,mlflow] needs" in missing_plugin_message(["logger=[tensorboard,mlflow]"])
    assert "gyrodenoise[mlflow]" in missing_plugin_message(["logger=mlflow"])
    assert missing_plugin_message(["dataset=euroc"]) is None
    # without any Hydra plugin the parent package hydra_plugins is missing too: find_spec raises instead of answering
    monkeypatch.undo()

    def no_parent(name):
        raise ModuleNotFoundError(f"No module named '{name.split('.')[0]}'")

    monkeypatch.setattr(importlib.util, "find_spec", no_parent)
    assert "pip install 'gyrodenoise[sweep]'" in missing_plugin_message(["-m", "hydra/launcher=local"])
    assert missing_plugin_message(["logger=csv"]) is None


def test_each_job_leaves_the_table_of_the_folds_finished_so_far(tmp_path):
    """Hydra stops a sweep at a failed job without on_multirun_end: the table after each job names what is missing."""
    from hydra.types import RunMode
    from omegaconf import OmegaConf

    _summary(tmp_path / "f0.json", 0, 2.0, 3.0)
    _summary(tmp_path / "f2.json", 2, 1.0, 2.0)
    config = OmegaConf.create({"hydra": {"mode": RunMode.MULTIRUN, "sweep": {"dir": str(tmp_path)}}})
    cv.CrossValidationCallback().on_job_end(config)
    data = json.loads((tmp_path / "cross_validation.json").read_text())
    assert data["missing_folds"] == [1] and data["figure_deg"] == pytest.approx(1.5)
    config.hydra.mode = RunMode.RUN  # a plain run: nothing written
    (tmp_path / "cross_validation.json").unlink()
    cv.CrossValidationCallback().on_job_end(config)
    assert not (tmp_path / "cross_validation.json").exists()


def test_the_seed_and_fold_split_of_the_rounds_reads_the_runs_the_screens_read(monkeypatch):
    """benchmarks/cv_power.py pairs the committed runs as the screen of the same round did (its mean d is the
    screen's), and its committed result is what it computes from them."""
    import importlib.util

    import numpy as np

    from gyrodenoise.ablation_stats import fold_seed_spread

    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))  # it imports its sibling euroc_cv_screen
    spec = importlib.util.spec_from_file_location("cv_power", REPO / "benchmarks" / "cv_power.py")
    cv_power = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cv_power)
    monkeypatch.chdir(REPO)  # the script reads reports/... from the repository root
    arm, ref = cv_power.trained_pairs("wdiff", "euroc_whole_diff")
    screen = json.loads((REPO / "benchmarks/results/euroc_whole_diff_round.json").read_text())
    spread = fold_seed_spread(arm - ref)
    assert spread.mean == pytest.approx(screen["d_val_wdiff"]["mean"], abs=1e-9)
    committed = json.loads((REPO / "benchmarks/results/cv_power.json").read_text())["arms"]
    (label,) = [k for k in committed if k.startswith("wdiff:")]
    assert committed[label]["deg"]["between_sd"] == pytest.approx(spread.between_sd, abs=1e-9)
    assert committed[label]["log"]["within_sd"] == pytest.approx(
        fold_seed_spread(np.log(arm) - np.log(ref)).within_sd, abs=1e-9
    )
    tracked, plain = cv_power.tracker_pairs()
    round8 = json.loads((REPO / "benchmarks/results/cv_tracker_confirm.json").read_text())["decision"]
    assert fold_seed_spread(tracked - plain).mean == pytest.approx(round8["diff_mean"], abs=1e-9)


@pytest.mark.parametrize("fold", [0, 3])
def test_a_fold_of_a_single_training_flight_is_refused_in_one_line(fold):
    """One training flight held out leaves none to train on: dataset.cv_fold=0 stopped in Lightning's setup with numpy's
    'need at least one array to concatenate', and cv_fold=3's message advised cv_fold=0."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.data.datamodule import ImuDataModule

    with pytest.raises(ConfigError, match=r"needs two training flights or more.*\['walk'\].*dataset.cv_fold=null"):
        ImuDataModule("x", "/nowhere", ["walk"], [], cv_fold=fold)


def test_a_fold_sweep_over_a_single_flight_stops_before_training():
    """One training flight: the sweep's own check said 'give dataset.cv_fold=0', a fold that cannot train."""
    from omegaconf import OmegaConf

    config = OmegaConf.create(
        {
            "dataset": {"name": "mine", "train_seqs": ["walk"]},
            "hydra": {"overrides": {"task": ["dataset.cv_fold=0"]}, "sweeper": {"params": {}}},
        }
    )
    problem = cv.fold_list_problem(config)
    assert "has 1 training flight(s) (walk)" in problem and "two or more" in problem
    assert "give dataset.cv_fold=0" not in problem


def test_a_search_folder_is_named_as_all_its_runs_not_the_first_recipes(tmp_path, capsys):
    """An hparams_search sweep (two trials, other settings each) given to the collector: it said 'none of the 1 runs',
    the first recipe's count, of a folder of 2."""
    for k, dropout in enumerate(("0.1", "0.2")):
        (tmp_path / str(k)).mkdir()
        path = _summary(tmp_path / str(k) / "summary.json", None, 5.0, 3.0)
        data = json.loads(path.read_text())
        data["overrides"].append(f"model.dropout={dropout}")
        path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="none of the 2 runs is a cross-validation run"):
        cv.load([tmp_path])
    assert cv.main([str(tmp_path), "--out", str(tmp_path / "cv")]) == 2
    assert "none of the 2 runs" in capsys.readouterr().err


def test_a_sequence_named_twice_is_refused():
    """train_seqs=[a,a,b] with cv_fold=0 held out one 'a' and trained on the other: the held-out flight was trained on
    and validated nothing (NaN), without a word."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.data.datamodule import ImuDataModule

    with pytest.raises(ConfigError, match="dataset.train_seqs names a more than once: give each sequence once"):
        ImuDataModule("x", "/nowhere", ["a", "a", "b"], [], cv_fold=0)
    with pytest.raises(ConfigError, match="dataset.test_seqs names c more than once"):
        ImuDataModule("x", "/nowhere", ["a", "b"], ["c", "c"])


def test_a_fold_beyond_the_flights_names_the_ablations_too():
    """-m experiment=ablation_activation on three own flights: its seed 3 is fold 3, and the error spoke of
    experiment=cross_validation alone, which the user had not run."""
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.data.datamodule import ImuDataModule

    said = r"choose 0\.\.2 .*cross_validation .*dataset.cv_fold=0,1,2 .*an ablation holds out fold = seed, so give "
    said += "it seed=0,1,2"
    with pytest.raises(ConfigError, match=said):  # the fold swept beside the ablation's seeds crossed them (review)
        ImuDataModule("x", "/nowhere", ["a", "b", "c"], [], cv_fold=3)
    with pytest.raises(ConfigError, match=r"needs two training flights or more"):  # not 'give one fold, 0..0'
        ImuDataModule("x", "/nowhere", ["a"], [], cv_fold="all")
    with pytest.raises(ConfigError, match=r"dataset.cv_fold=True: choose 0\.\.1"):  # held out flight 1 (review 63)
        ImuDataModule("x", "/nowhere", ["a", "b"], [], cv_fold=True)
    from gyrodenoise.data.datamodule import check_sequence_lists

    with pytest.raises(ConfigError, match=r"needs two training flights or more"):  # a bare TypeError on None
        check_sequence_lists(None, [], None, 0)
    with pytest.raises(ConfigError, match=r"dataset.val_seqs=\[\] names no validation sequence"):  # crashed later
        ImuDataModule("x", "/nowhere", ["a", "b"], [], val_seqs=[])


def test_runs_of_a_drawn_seed_count_by_the_seed_they_drew(tmp_path):
    """seed=null draws a seed and records it in summary.json (the override stays 'seed=null'): two sweeps run that
    way are two seeds per fold, not one seed 'null' twice (the second sweep's runs were left out as duplicates)."""

    def drawn(path: Path, fold: int, val: float, seed: int) -> Path:
        _summary(path, fold, val, 5.0, seed=seed)
        s = json.loads(path.read_text())
        s["overrides"] = ["seed=null", f"dataset.cv_fold={fold}"]
        s["seed"] = seed
        path.write_text(json.dumps(s))
        return path

    files = [drawn(tmp_path / f"f{k}_{s}.json", k, 2.0 + s, seed) for k in range(3) for s, seed in ((0, 811), (1, 97))]
    result, _ = cv.load(files)
    assert result.skipped == []
    assert [sorted(f.seeds) for f in result.folds.values()] == [["811", "97"]] * 3
    assert result.figure() == pytest.approx(2.5)


def test_an_ablation_sweeps_run_folders_are_read_as_their_summaries(tmp_path):
    """An ablation's run folder holds the config as Hydra saved it, unresolved (dataset.cv_fold: ${seed}); the run's
    summary.json records what it trained (cv_fold 0). Given the sweep folder, the runs are cross-validation runs as
    their summary files are (the folder was refused: 'none of the 2 runs is a cross-validation run')."""
    import yaml

    sweep = tmp_path / "multirun"
    for job, (seed, val) in enumerate([(0, 2.0), (1, 3.0)]):
        run = sweep / str(job)
        (run / ".hydra").mkdir(parents=True)
        _summary(run / "summary.json", seed, val, 4.0, seed=seed)
        saved = json.loads((run / "summary.json").read_text())
        saved["overrides"] = ["model.act=gelu", f"seed={seed}", "experiment=ablation_activation"]
        (run / "summary.json").write_text(json.dumps(saved))
        unresolved = {"seed": seed, "dataset": {**saved["config"]["dataset"], "cv_fold": "${seed}"}}
        (run / ".hydra" / "config.yaml").write_text(yaml.safe_dump(unresolved))
        (run / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(saved["overrides"]))
    result, _ = cv.load([sweep])
    assert sorted(result.folds) == [0, 1] and result.figure() == pytest.approx(2.5)
    assert cv.load(sorted(sweep.glob("*/summary.json")))[0].per_fold() == result.per_fold()
