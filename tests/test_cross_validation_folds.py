"""Cross-validation's grouping of runs into folds (gyrodenoise.cross_validation): a run reached twice counts once, a
fold without a figure is named rather than averaged away, a reference pairs by held-out flight, and
dataset.cv_fold=all keeps a finished fold only if it trained the same recipe (fake training: no network trained)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from omegaconf import DictConfig, OmegaConf

from gyrodenoise import all_folds
from gyrodenoise import cross_validation as cv
from gyrodenoise.atomic import write_json
from gyrodenoise.cli_errors import ConfigError


def _summary(path: Path, fold: int, val: float, seed: int = 0, flights: tuple[str, ...] = ("a", "b", "c")) -> Path:
    ds = {"name": "mine", "train_seqs": list(flights), "cv_fold": fold}
    s = {
        "overrides": [f"seed={seed}", f"dataset.cv_fold={fold}"],
        "config": {"dataset": ds, "seed": seed},
        "val": {"val/aoe_deg": val},
        "test": {"test/aoe_deg": 1.0},
        "calibrated_baseline": {"calibrated_val_aoe_deg": 3.0},
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(s))
    return path


def test_a_run_reached_twice_counts_once(tmp_path):
    for k, v in enumerate([1.0, 2.0, 3.0]):
        _summary(tmp_path / "runs" / f"f{k}.json", k, v)
    _summary(tmp_path / "copy" / "f0.json", 0, 1.0)  # a copy of fold 0, seed 0
    result, _ = cv.load([tmp_path / "runs", tmp_path / "runs" / "f0.json", tmp_path / "copy"])
    assert [len(f.seeds) for f in result.folds.values()] == [1, 1, 1]
    assert len(result.skipped) == 2 and all("fold 0, seed 0 again" in s for s in result.skipped)
    _summary(tmp_path / "runs" / "f0s1.json", 0, 5.0, seed=1)  # another seed of fold 0 is another run
    result, _ = cv.load([tmp_path / "runs"])
    assert result.folds[0].network == [1.0, 5.0] and result.skipped == []


def test_a_fold_without_a_figure_is_named_not_averaged_away(tmp_path):
    files = [_summary(tmp_path / f"f{k}.json", k, v) for k, v in enumerate([1.0, 2.0, math.nan])]
    result, _ = cv.load(files)
    assert result.unscored == [2] and result.figure() == pytest.approx(1.5)
    md, data = cv.report(result)
    assert "over 2 of 3 folds (no network figure in their runs: 2: c)" in md and "| mean over 2 folds |" in md
    assert data["unscored_folds"] == [2]


def test_a_reference_pairs_by_held_out_flight(tmp_path):
    files = [_summary(tmp_path / "recipe" / f"f{k}.json", k, v) for k, v in enumerate([1.0, 2.0, 3.0])]
    # the reference lists the flights the other way round: its fold 0 holds out c
    ref = [_summary(tmp_path / "ref" / f"f{k}.json", k, v, flights=("c", "b", "a")) for k, v in enumerate([30, 20, 10])]
    md, data = cv.report(cv.load(files)[0], cv.load(ref)[0])
    assert data["recipe_minus_reference"]["mean"] == pytest.approx(-18.0)  # a: 1 - 10, b: 2 - 20, c: 3 - 30
    assert "| 0: a | 1 (0) | 1.00 | 3.00 | 10.00 |" in md and "paired by held-out flight" in md


def _cfg(dropout: float = 0.1, ckpt_path: str | None = None) -> DictConfig:
    return OmegaConf.create(
        {
            "dataset": {"name": "mine", "train_seqs": ["a", "b", "c"], "cv_fold": "all"},
            "paths": {"output_dir": "unused"},
            "model": {"dropout": dropout},
            "seed": 0,
            "threads": None,
            "ckpt_path": ckpt_path,
        }
    )


def _fake_training(vals: list[float], trained: list[int]):
    def train_one(cfg: DictConfig, folder: Path) -> dict:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "model.pt").write_bytes(b"weights")
        trained.append(cfg.dataset.cv_fold)
        with_resume = OmegaConf.to_container(cfg, resolve=True) | {"ckpt_path": str(folder / "last.ckpt")}
        summary = {
            "overrides": ["++dataset.cv_fold=all"],
            "config": with_resume,  # as auto_resume records it
            "seed": 0,
            "val": {"val/aoe_deg": vals[cfg.dataset.cv_fold]},
            "test": {},
        }
        write_json(folder / "summary.json", summary)
        return summary

    return train_one


def test_all_folds_figure_is_nan_when_a_fold_has_none(tmp_path):
    summary = all_folds.train_all_folds(_cfg(), tmp_path, _fake_training([1.0, math.nan, 2.0], []))
    assert math.isnan(summary["val"]["val/aoe_deg"])  # not 1.5, the mean of the other folds
    assert summary["cross_validation"]["unscored_folds"] == [1]
    assert json.loads((tmp_path / "fold0" / "summary.json").read_text())["overrides"] == ["dataset.cv_fold=0"]


def test_all_folds_keeps_a_fold_only_if_it_trained_the_same_recipe(tmp_path):
    trained: list[int] = []
    all_folds.train_all_folds(_cfg(), tmp_path, _fake_training([1.0, 2.0, 3.0], trained))
    (tmp_path / "fold2" / "model.pt").unlink()  # fold 2 unfinished: a requeued run trains it again
    again = _cfg()
    again.threads = 4  # another node's threads: the same recipe
    summary = all_folds.train_all_folds(again, tmp_path, _fake_training([1.0, 2.0, 3.0], trained))
    assert trained == [0, 1, 2, 2] and summary["val"]["val/aoe_deg"] == pytest.approx(2.0)
    with pytest.raises(ConfigError, match=r"fold0 holds a fold finished with other settings \(model.dropout: 0.1"):
        all_folds.train_all_folds(_cfg(dropout=0.5), tmp_path, _fake_training([1.0, 2.0, 3.0], trained))
    assert trained == [0, 1, 2, 2]


def test_all_folds_refuses_one_checkpoint_for_every_fold(tmp_path):
    trained: list[int] = []
    with pytest.raises(ConfigError, match="would start every fold from one checkpoint"):
        all_folds.train_all_folds(
            _cfg(ckpt_path="x/fold1/last.ckpt"), tmp_path, _fake_training([1.0, 2.0, 3.0], trained)
        )
    assert trained == []


def test_all_folds_checks_every_flights_truth_before_the_first_fold(tmp_path):
    """Fold 0 holds flight a out (validates on it: a disagreeing truth only warns there), so a's truth would stop the
    run only at fold 1, after fold 0 trained: it is checked before fold 0 trains."""
    from _asl import write_asl_sequence
    from test_data_consistency import _xyzw_truth

    from gyrodenoise.config import compose_config
    from gyrodenoise.data.consistency import InconsistentTruthError

    for i, name in enumerate(["a", "b", "c"]):
        write_asl_sequence(tmp_path / "data" / name, seconds=20.0, seed=30 + i)
    _xyzw_truth(tmp_path / "data" / "a")
    args = ["dataset=asl_folder", f"dataset.root={tmp_path / 'data'}", "dataset.train_seqs=[a,b,c]",
            "dataset.cv_fold=all", "+dataset.cache_dir=", f"paths.output_dir={tmp_path / 'run'}"]  # fmt: skip
    trained: list[int] = []
    with pytest.raises(InconsistentTruthError, match=r"a \(.*quaternion order"):
        all_folds.train_all_folds(compose_config("train", args), tmp_path / "run", _fake_training([1, 2, 3], trained))
    assert trained == []
