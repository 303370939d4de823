"""Ensemble edges from an audit of a user who relies on the spread: a damaged member file, spread factors no
calibration gives, a mixed ensemble's reference, the worst stretch of a recording, the build's missing reference."""

from __future__ import annotations

import struct
import zipfile

import numpy as np
import pytest
from _models import random_model

from gyrodenoise import ensemble as ensemble_cli
from gyrodenoise.pretrained import ModelFileError, load_model, save_model
from gyrodenoise.spread_check import SPREAD_RATIO_LIMIT, spread_ratio, spread_warning, worst_window

TINY = {"channels": (8, 16), "kernel_size": 5, "dilations": (1, 4)}


def _member(tmp_path, seed: int):
    return save_model(random_model(seed=seed, **TINY), {"name": "denoiser", **TINY}, tmp_path / f"m{seed}.pt",
                      {"dataset": "euroc", "rate_hz": 200.0})  # fmt: skip


def _flip_a_weight_byte(src, dst) -> None:
    data = bytearray(src.read_bytes())
    info = next(i for i in zipfile.ZipFile(src).infolist() if i.filename.endswith("/data/3"))
    name_len, extra_len = struct.unpack("<HH", data[info.header_offset + 26 : info.header_offset + 30])
    data[info.header_offset + 30 + name_len + extra_len + 1] ^= 0xFF
    dst.write_bytes(bytes(data))


def test_a_model_file_with_a_changed_weight_byte_is_refused(tmp_path):
    """torch reads such weights without a word: the audit's member with one flipped byte made the ensemble's
    corrections 131 deg/s."""
    _flip_a_weight_byte(_member(tmp_path, 1), tmp_path / "flip.pt")
    with pytest.raises(ModelFileError, match="damaged: the bytes of its entry .*data/3 no longer match"):
        load_model(tmp_path / "flip.pt")


@pytest.mark.parametrize(("by", "fitted_by", "said"), [(1e-300, "x", "--by 1e-300"), (1e40, "x", "--by 1e"),
                                                       (2.0, " ", "--fitted-by is empty")])  # fmt: skip
def test_spread_factors_no_calibration_gives_are_refused(tmp_path, by, fitted_by, said):
    members = [_member(tmp_path, s) for s in (1, 2)]
    ens = ensemble_cli.build_ensemble(members, tmp_path / "ens.pt")
    with pytest.raises(ValueError, match=said):
        ensemble_cli.scale_spread(ens, by, tmp_path / "x.pt", fitted_by)


def test_a_second_factor_replaces_the_first_in_the_name_too(tmp_path):
    members = [_member(tmp_path, s) for s in (1, 2)]
    ens = ensemble_cli.build_ensemble(members, tmp_path / "ens.pt", name="mine")
    twice = ensemble_cli.scale_spread(
        ensemble_cli.scale_spread(ens, 2, tmp_path / "a.pt", "x"), 3, tmp_path / "b.pt", "y"
    )
    meta = load_model(twice, warn=False)[1]
    assert meta["name"] == "mine (spread x3)" and meta["model"]["spread_scale"] == 3


def test_a_mixed_ensembles_reference_asks_for_its_dataset(tmp_path, capsys):
    members = [_member(tmp_path, 1), save_model(random_model(seed=2, **TINY), {"name": "denoiser", **TINY},
                                                tmp_path / "t.pt", {"dataset": "tumvi", "rate_hz": 200.0})]  # fmt: skip
    assert ensemble_cli.main(["build", *map(str, members), "--out", str(tmp_path / "mix.pt"), "--allow-mixed"]) == 0
    assert "note: no spread reference yet" in capsys.readouterr().out
    assert ensemble_cli.main(["reference", str(tmp_path / "mix.pt"), "--out", str(tmp_path / "r.pt")]) == 2
    assert "dataset=euroc" in capsys.readouterr().err  # one line, not Hydra's MissingConfigException


def test_a_bad_stretch_is_seen_though_the_whole_recording_is_quiet():
    """The whole recording's median missed 20 s of a gyro in deg/s in a 2-min flight (0.69, its window 63.8)."""
    meta = {"spread_reference": {"reference_rad_s": 0.002}, "model": {"spread_scale": 1.0}, "name": "ens"}
    std = np.full((24000, 3), 0.001)  # 120 s at 200 Hz, ratio 0.87 everywhere
    std[10000:14000] *= 60  # 20 s of far more disagreement
    whole = spread_ratio(std, meta)
    window = worst_window(std, meta, 200.0)
    assert whole < SPREAD_RATIO_LIMIT < window[0] and 40.0 <= window[1] <= 60.0
    said = spread_warning(whole, "rec.csv", meta, window)
    assert said and "worst 10-s stretch" in said and spread_warning(whole, "rec.csv", meta) is None


def test_a_model_file_saved_without_checksums_loads(tmp_path):
    """torch.serialization.set_crc32_options(False) writes CRC 0 for every entry: such a file is whole."""
    import torch

    torch.serialization.set_crc32_options(False)
    try:
        path = _member(tmp_path, 1)
    finally:
        torch.serialization.set_crc32_options(True)
    assert zipfile.ZipFile(path).infolist()[0].CRC == 0
    load_model(path)


def test_a_bad_stretch_at_the_very_end_is_judged():
    """Windows stepped by half their length from the start left up to half a window at the end out of any."""
    meta = {"spread_reference": {"reference_rad_s": 0.002}, "model": {"spread_scale": 1.0}, "name": "ens"}
    std = np.full((2990, 3), 0.001)  # 29.9 s at 100 Hz
    std[2090:] *= 60
    ratio, start = worst_window(std, meta, 100.0)
    assert ratio > SPREAD_RATIO_LIMIT and start == pytest.approx(19.9)


def test_the_sweeps_ensemble_says_its_members_warnings_in_one_line(tmp_path, monkeypatch):
    """experiment=ensemble's callback printed a member that did not beat the calibrated baseline as Python's
    '<file>:<line>: ModelQualityWarning: ...' plus the source line, where `ensemble build` says 'warning: ...'.
    (pytest records warnings instead of printing them: the format in force during the build is what is checked.)"""
    import warnings

    from omegaconf import OmegaConf

    from gyrodenoise.pretrained import ModelQualityWarning

    sweep = tmp_path / "sweep"
    for k in (0, 1):
        (sweep / str(k) / ".hydra").mkdir(parents=True)
        save_model(random_model(seed=k + 1, **TINY), {"name": "denoiser", **TINY}, sweep / str(k) / "model.pt",
                   {"dataset": "euroc", "rate_hz": 200.0, "beats_calibrated": False})  # fmt: skip
    said = []
    build = ensemble_cli.build_ensemble

    def build_and_format(*args, **kwargs):
        said.append(warnings.formatwarning("members did not beat it", ModelQualityWarning, "/site/ensemble.py", 1))
        return build(*args, **kwargs)

    monkeypatch.setattr(ensemble_cli, "build_ensemble", build_and_format)
    config = OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}, "dataset": {"_target_": "builtins.dict"}})
    ensemble_cli.BuildEnsembleCallback().on_multirun_end(config)
    assert said == ["warning: members did not beat it\n"] and (sweep / "ensemble.pt").is_file()


@pytest.mark.parametrize("where", ["folder", "under_a_file"])
def test_an_out_path_that_cannot_be_written_is_one_line_before_the_work(tmp_path, capsys, monkeypatch, where):
    """`--out DIR` (a folder) ended build and scale with IsADirectoryError's traceback when the file was saved, and
    `reference` after reading the whole training data; a path under a file likewise. Asked first, as correct and export
    do: one line naming --out, status 2, and nothing read."""
    members = [_member(tmp_path, 1), _member(tmp_path, 2)]
    ens = ensemble_cli.build_ensemble(members, tmp_path / "ens.pt")
    out = tmp_path / "outdir" if where == "folder" else tmp_path / "ens.pt" / "x.pt"
    if where == "folder":
        out.mkdir()
    monkeypatch.setattr(ensemble_cli, "_save_with_reference", lambda *a: pytest.fail("the data were read"))
    for args in (
        ["build", *map(str, members), "--out", str(out)],
        ["scale", str(ens), "--by", "1.5", "--fitted-by", "a test", "--out", str(out)],
        ["reference", str(ens), "--out", str(out), "dataset=euroc"],
    ):
        assert ensemble_cli.main(args) == 2, args
        err = capsys.readouterr().err
        assert err.startswith(f"error: --out {out}: ") and err.count("\n") == 1 and "Traceback" not in err, err


def test_a_build_from_one_ensemble_file_says_its_members_and_that_it_has_no_reference(tmp_path, capsys, monkeypatch):
    """`build ENS.pt --out NEW.pt` (one file of several members: re-saved under another name, say) wrote no spread
    reference (the new file records none) but said "(1 member files)" and left out the note that says how to add it:
    correct and evaluate then cannot tell a recording unlike the training data. The count is the members', taken
    from what was built (the file just written was read back for it)."""
    ens = ensemble_cli.build_ensemble([_member(tmp_path, 1), _member(tmp_path, 2)], tmp_path / "ens.pt")
    capsys.readouterr()
    loads = []
    monkeypatch.setattr(ensemble_cli, "load_model", lambda p, **kw: loads.append(str(p)) or load_model(p, **kw))
    assert ensemble_cli.main(["build", str(ens), "--out", str(tmp_path / "new.pt")]) == 0
    assert loads == [str(ens)]
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'new.pt'} (2 members from 1 file)" in out, out
    assert "note: no spread reference yet" in out, out


def test_the_default_out_of_a_multirun_build_is_checked_before_the_work(tmp_path, capsys):
    """`build --from-multirun DIR` writes DIR/ensemble.pt unless told otherwise; where that is a folder, the build
    ended in IsADirectoryError's traceback when the file was saved. Now one line naming the default."""
    sweep = tmp_path / "multirun"
    for job in (0, 1):
        (sweep / str(job)).mkdir(parents=True)
        _member(tmp_path, job + 1).rename(sweep / str(job) / "model.pt")
    (sweep / "ensemble.pt").mkdir()
    assert ensemble_cli.main(["build", "--from-multirun", str(sweep)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {sweep / 'ensemble.pt'} (the default --out): ") and "Traceback" not in err, err
