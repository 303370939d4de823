"""`python -m gyrodenoise.shipped`: the shipped models listed from their files, and their cards."""

from __future__ import annotations

from gyrodenoise.pretrained import available_models
from gyrodenoise.shipped import card_path, main


def test_lists_every_shipped_model_with_its_facts(capsys):
    assert main([]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split(":")[0] for ln in lines[:-1]] == available_models()
    said = dict(ln.split(": ", 1) for ln in lines[:-1])
    assert said["euroc"].startswith("ensemble of 8, trained on euroc (ADIS16448) at 200 Hz")
    assert "did NOT beat the calibrated model" in said["tumvi-denoiser"]
    assert said["tumvi"].startswith("12-parameter calibrated model, trained on tumvi (BMI160)")


def test_prints_a_card_and_names_the_shipped_ones_for_a_wrong_name(capsys):
    assert card_path("tumvi-denoiser").name == "tumvi.md"  # the family's card
    assert main(["euroc-calibrated"]) == 0
    assert capsys.readouterr().out.startswith("# Model card: `euroc` (and `euroc-calibrated`)")
    assert main(["eurok"]) == 2
    assert "shipped: euroc, euroc-calibrated" in capsys.readouterr().err
