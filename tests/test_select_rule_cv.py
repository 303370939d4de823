"""The log reading behind the select-rule decision (benchmarks/select_rule_cv.py): it must pick the epoch the
checkpoint callback would keep, judge it on the held-out flight, skip runs that have nothing to select by, and
name a malformed log instead of guessing."""

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from select_rule_cv import per_fold, run_figures  # noqa: E402

HEADER = "epoch,lr-Adam,step,train/loss,val/aoe_deg,val/loss,val_tail/aoe_deg,val_tail/loss\n"


def _run(tmp_path: Path, name: str, text: str, epochs: int = 200) -> Path:
    folder = tmp_path / name
    (folder / "csv").mkdir(parents=True)
    (folder / "csv" / "metrics.csv").write_text(text)
    (folder / "summary.json").write_text(json.dumps({"epochs": epochs}))
    return folder


def test_best_val_epoch_judged_on_the_held_out_flight(tmp_path):
    text = HEADER + (
        "0,0.01,0,,,,,\n"
        "0,,0,25.0,,,,\n"  # training-loss rows carry no validation
        "49,,49,,6.0,1.0,3.0,1.0\n"
        "99,,99,,5.0,1.0,2.0,1.0\n"  # lowest on the end of the training flights
        "149,,149,,4.0,1.0,2.0,1.0\n"  # equal minimum later: the first is kept, as ModelCheckpoint does
        "199,,199,,3.5,1.0,2.5,1.0\n"
        "200,,200,,3.5,1.0,2.5,1.0\n"  # the kept model validated again after the fit: not a checkpoint
    )
    r = run_figures(_run(tmp_path, "ref_f2_s102", text))
    assert (r["recipe"], r["fold"], r["seed"]) == ("ref", 2, 102)
    assert (r["best_epoch"], r["last_epoch"], r["validations"]) == (99, 199, 4)
    assert r["d"] == pytest.approx(5.0 - 3.5)


def test_whole_flight_runs_are_skipped_and_folds_averaged(tmp_path):
    whole = "epoch,lr-Adam,step,train/loss,val/aoe_deg,val/loss\n49,,49,,6.0,1.0\n"
    assert run_figures(_run(tmp_path, "whole_f0_s100", whole)) is None
    runs = [{"fold": 0, "d": 1.0}, {"fold": 0, "d": 3.0}, {"fold": 1, "d": -1.0}]
    d = per_fold(runs)
    assert d.seeds == ("0", "1") and d.diffs == pytest.approx((2.0, -1.0))


def test_a_log_with_one_group_of_two_is_named(tmp_path):
    text = HEADER + "49,,49,,6.0,1.0,,\n"
    with pytest.raises(SystemExit, match=r"metrics.csv:2: epoch 49 logs one validation group of two"):
        run_figures(_run(tmp_path, "ref_f0_s100", text))
