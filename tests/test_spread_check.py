"""The spread check: an ensemble file's reference spread on its training recordings, and the warning of correct and
evaluate on a recording whose members disagree far more (gyrodenoise.spread_check)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _asl import write_asl_sequence
from _models import random_model

from gyrodenoise import ensemble as ensemble_cli
from gyrodenoise.correct import main as correct_main
from gyrodenoise.models.ensemble import EnsembleCorrection, predict_with_spread
from gyrodenoise.pretrained import load_model, save_model
from gyrodenoise.spread_check import SPREAD_RATIO_LIMIT, spread_ratio, spread_reference, spread_warning

TINY = {"channels": (8, 16), "kernel_size": 5, "dilations": (1, 4)}
CFG = {"name": "ensemble", "members": [{"name": "denoiser", **TINY}] * 2}


def smooth_imu(n: int = 1200, seed: int = 0) -> np.ndarray:
    t = np.arange(n) / 200.0
    gyro = 0.5 * np.sin(2 * np.pi * np.array([0.3, 0.5, 0.7]) * t[:, None])
    acc = np.array([0.0, 0.0, 9.80665]) + 0.01 * np.random.default_rng(seed).standard_normal((n, 3))
    return np.concatenate([gyro, acc], axis=1)


def two_members(scale: float = 1.0) -> EnsembleCorrection:
    return EnsembleCorrection([random_model(seed=1, **TINY), random_model(seed=2, **TINY)], scale).eval()


def test_reference_ratio_and_warning():
    imu = smooth_imu()
    ref = spread_reference(two_members(), [("a", imu), ("b", smooth_imu(seed=3))])
    assert ref["reference_rad_s"] == max(ref["per_recording_rad_s"].values()) > 0
    meta = {"name": "ens", "spread_reference": ref, "model": CFG}
    std = predict_with_spread(two_members(), imu)[1]
    assert spread_ratio(std, meta) == pytest.approx(ref["per_recording_rad_s"]["a"] / ref["reference_rad_s"])
    # a spread factor scales the std output, not the members' disagreement the reference is taken on
    scaled = two_members(2.0)
    assert spread_reference(scaled, [("a", imu)])["reference_rad_s"] == pytest.approx(ref["per_recording_rad_s"]["a"])
    meta_scaled = {**meta, "model": {**CFG, "spread_scale": 2.0}}
    assert spread_ratio(predict_with_spread(scaled, imu)[1], meta_scaled) == pytest.approx(spread_ratio(std, meta))

    tiny = {**meta, "spread_reference": {**ref, "reference_rad_s": ref["reference_rad_s"] / 10}}
    ratio = spread_ratio(predict_with_spread(two_members(), smooth_imu(seed=3))[1], tiny)
    assert ratio == pytest.approx(10.0)
    assert "rec.csv: the members of ens disagree 10.0 times more" in spread_warning(ratio, "rec.csv", tiny)
    assert spread_warning(SPREAD_RATIO_LIMIT * 0.99, "rec.csv", tiny) is None
    assert spread_ratio(std, {"model": CFG}) is None and spread_ratio(None, meta) is None  # no reference / no spread
    with pytest.raises(TypeError, match="two or more members"):
        spread_reference(random_model(seed=1, **TINY), [("a", imu)])


def write_imu_csv(path, imu: np.ndarray) -> None:
    t_ns = 1_600_000_000_000_000_000 + np.round(np.arange(len(imu)) / 200.0 * 1e9).astype(np.int64)
    rows = [f"{t}," + ",".join(repr(x) for x in v) for t, v in zip(t_ns.tolist(), imu.tolist(), strict=True)]
    path.write_text("#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n" + "\n".join(rows) + "\n")


def test_correct_warns_when_the_members_disagree_far_more_than_on_their_training_data(tmp_path, capsys):
    imu = smooth_imu()
    ref = spread_reference(two_members(), [("a", imu)])
    f = tmp_path / "data.csv"
    write_imu_csv(f, imu)
    for name, reference in (("same", ref["reference_rad_s"]), ("unlike", ref["reference_rad_s"] / 10)):
        meta = {"rate_hz": 200.0, "spread_reference": {**ref, "reference_rad_s": reference}}
        model = save_model(two_members(), CFG, tmp_path / f"{name}.pt", meta)
        assert correct_main([str(f), "-m", str(model), "-o", str(tmp_path / name)]) == 0
        err = capsys.readouterr().err
        summary = json.loads((tmp_path / name / "correct_summary.json").read_text())
        if name == "same":
            assert summary["spread_ratio_to_training"] == pytest.approx(1.0) and "disagree" not in err
        else:
            assert summary["spread_ratio_to_training"] == pytest.approx(10.0)
            assert "disagree 10.0 times more" in err and any("disagree" in w for w in summary["warnings"])


def test_reference_cli_reads_the_members_training_recordings(tmp_path, monkeypatch, capsys):
    root = tmp_path / "data"
    for k, name in enumerate(("walk", "run")):
        write_asl_sequence(root / name, seconds=8.0, seed=k)
    monkeypatch.setenv("GYRODENOISE_CACHE", str(tmp_path / "cache"))
    meta = {"rate_hz": 200.0, "dataset": "mine", "train_seqs": ["walk", "run"], "name": "ens"}
    ens = save_model(two_members(), CFG, tmp_path / "ens.pt", meta)
    out = tmp_path / "ens_ref.pt"
    overrides = ["dataset=asl_folder", f"dataset.root={root}", "dataset.train_seqs=[walk,run]"]
    assert ensemble_cli.main(["reference", str(ens), "--out", str(out), *overrides]) == 0  # overrides after --out
    assert "spread reference" in capsys.readouterr().out
    model, meta = load_model(out)
    ref = meta["spread_reference"]
    assert list(ref["per_recording_rad_s"]) == ["walk", "run"] and "reference" in ref["command"]
    assert len(model) == 2 and meta["train_seqs"] == ["walk", "run"]  # the rest of the metadata kept
    single = save_model(random_model(seed=1, **TINY), {"name": "denoiser", **TINY}, tmp_path / "one.pt", meta)
    assert ensemble_cli.main(["reference", str(single), "--out", str(out), *overrides]) == 2
    assert "single model has no spread" in capsys.readouterr().err


def test_reference_of_an_own_data_ensemble_needs_only_the_folder(tmp_path, monkeypatch, capsys):
    """Members trained with dataset=asl_folder: `reference FILE --out OUT` ended in omegaconf's MissingMandatoryValue
    traceback (dataset.root '???'), and with dataset.root given in another one (dataset.train_seqs '???', which the
    reference does not read: it takes the members' recorded training sequences)."""
    root = tmp_path / "data"
    for k, name in enumerate(("walk", "run")):
        write_asl_sequence(root / name, seconds=8.0, seed=k)
    monkeypatch.setenv("GYRODENOISE_CACHE", str(tmp_path / "cache"))
    meta = {"rate_hz": 200.0, "dataset": "asl_folder", "train_seqs": ["walk", "run"], "name": "ens"}
    ens = save_model(two_members(), CFG, tmp_path / "ens.pt", meta)
    out = tmp_path / "ens_ref.pt"
    assert ensemble_cli.main(["reference", str(ens), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: dataset.root has no value") and "(walk, run)" in err and "dataset.root=FOLDER" in err
    overrides = ["dataset=asl_folder", f"dataset.root={root}"]  # as docs/deployment.md gives them
    assert ensemble_cli.main(["reference", str(ens), "--out", str(out), *overrides]) == 0
    assert list(load_model(out)[1]["spread_reference"]["per_recording_rad_s"]) == ["walk", "run"]


def test_reference_of_a_fold_ensemble_is_taken_on_the_union_of_its_members_flights(tmp_path, monkeypatch, capsys):
    """Members trained on different flights (a cross-validation's folds) record no common training list: the
    reference stopped with 'names no training sequences'. It is now taken on the union of the members' flights, in
    the members' order, and the file says so."""
    root = tmp_path / "data"
    for k, name in enumerate(("walk", "run", "jog")):
        write_asl_sequence(root / name, seconds=8.0, seed=k)
    monkeypatch.setenv("GYRODENOISE_CACHE", str(tmp_path / "cache"))
    members = [{"train_seqs": ["walk", "run"]}, {"train_seqs": ["run", "jog"]}]
    meta = {"rate_hz": 200.0, "dataset": "asl_folder", "train_seqs": None, "members": members, "name": "ens"}
    ens = save_model(two_members(), CFG, tmp_path / "ens.pt", meta)
    out = tmp_path / "ens_ref.pt"
    assert (
        ensemble_cli.main(["reference", str(ens), "--out", str(out), "dataset=asl_folder", f"dataset.root={root}"]) == 0
    )
    ref = load_model(out)[1]["spread_reference"]
    assert list(ref["per_recording_rad_s"]) == ["walk", "run", "jog"]
    assert ref["recordings"].startswith("the union of the members' training recordings")
    from gyrodenoise.ensemble import reference_recordings

    same = [{"train_seqs": ["walk", "run"]}, {"train_seqs": ["run", "walk"]}]  # a seed ensemble, listed otherwise
    assert reference_recordings({"members": same}) == (["walk", "run"], "the members' training recordings")
    assert reference_recordings({"members": [*members, {"train_seqs": None}]})[0] == []  # one records none


@pytest.mark.parametrize(
    ("typo", "said"), [("dataset.rot=x", "did you mean dataset.root?"), ("dataset=asl_foldr", "Could not find")]
)
def test_a_misspelt_reference_override_is_an_error_line_not_a_traceback(tmp_path, capsys, typo, said):
    meta = {"rate_hz": 200.0, "dataset": "asl_folder", "train_seqs": ["walk"], "name": "ens"}
    ens = save_model(two_members(), CFG, tmp_path / "ens.pt", meta)
    assert ensemble_cli.main(["reference", str(ens), "--out", str(tmp_path / "o.pt"), "dataset=asl_folder", typo]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and said in err


def test_evaluate_writes_the_spread_warning_into_its_outputs(tmp_path, monkeypatch):
    from test_evaluate import run_evaluate_asl

    from gyrodenoise.models.build import build_model

    root = tmp_path / "data"
    write_asl_sequence(root / "seq", seconds=20.0, seed=4)
    monkeypatch.setenv("GYRODENOISE_CACHE", str(tmp_path / "cache"))
    ref = {"per_recording_rad_s": {"x": 1e-9}, "reference_rad_s": 1e-9, "statistic": "test"}  # far below any spread
    ens = save_model(two_members(), CFG, tmp_path / "ens.pt", {"rate_hz": 200.0, "spread_reference": ref})
    cal = save_model(build_model("calibrated"), {"name": "calibrated"}, tmp_path / "cal.pt", {"rate_hz": 200.0})
    out = tmp_path / "out"
    run_evaluate_asl(root, ens, cal, out, "figures=false")
    results = json.loads((out / "results.json").read_text())
    assert results["uncertainty"]["spread_ratio_to_training"]["seq"] > 1e3
    assert "disagree" in (out / "table.md").read_text() and any("disagree" in w for w in results["warnings"])


def test_onnx_metadata_carries_the_spread_check_for_onboard_code():
    from gyrodenoise.export import onnx_metadata

    props = onnx_metadata(two_members(), {"spread_reference": {"reference_rad_s": 0.0024031}})
    assert f"above {SPREAD_RATIO_LIMIT:g} x 0.0024031 rad/s" in props["gyrodenoise.spread_check"]
    assert "gyrodenoise.spread_check" not in onnx_metadata(two_members(), {})  # no reference recorded: nothing said


def test_onnx_metadata_says_when_no_member_beat_the_calibrated_baseline():
    """An ensemble whose members all lost to the calibrated baseline has beats_calibrated None (it is not compared as
    a whole): `correct` and the C header warned, the ONNX file said nothing."""
    from gyrodenoise.export import onnx_metadata

    meta = {"name": "ens", "beats_calibrated": None, "members_beat_calibrated": [False, False]}
    said = onnx_metadata(two_members(), meta)["gyrodenoise.quality_warning"]
    assert "none of its 2 members" in said
    assert "gyrodenoise.quality_warning" not in onnx_metadata(
        two_members(), {**meta, "members_beat_calibrated": [True, False]}
    )
