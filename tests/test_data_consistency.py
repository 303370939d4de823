"""Training and evaluation data: the IMU is checked against its ground truth (deg/s, gaps, another clock)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from _asl import write_asl_sequence

from gyrodenoise.data import consistency
from gyrodenoise.data.cache import load_sequence
from gyrodenoise.data.readers import DataFormatError


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root = tmp_path_factory.mktemp("consistency")
    write_asl_sequence(root / "s", seconds=40.0, seed=3)
    return load_sequence(root, "s", cache_dir="")


def test_a_consistent_sequence_passes_silently(seq):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = consistency.check(seq)
    assert m.gaps == 0 and 0.9 < m.rate_ratio < 1.1 and abs(m.best_lag_s) <= 0.005


def test_gyro_in_deg_s_is_an_error(seq):
    with pytest.raises(DataFormatError, match="looks like deg/s"):
        consistency.check(dataclasses.replace(seq, gyro=np.degrees(seq.gyro)))


def test_gaps_and_a_shifted_truth_warn(seq):
    keep = np.ones(len(seq.t), bool)
    keep[2000:2400] = False  # 2 s of IMU missing
    gap = dataclasses.replace(
        seq,
        t=seq.t[keep],
        gyro=seq.gyro[keep],
        acc=seq.acc[keep],
        rot=seq.rot[keep],
        pos=seq.pos[keep],
        gt_mask=seq.gt_mask[keep],
    )
    with pytest.warns(consistency.DataConsistencyWarning, match="1 gap"):
        consistency.check(gap)
    shift = 600  # the IMU 3 s ahead of its truth
    late = dataclasses.replace(
        seq,
        t=seq.t[shift:],
        gyro=seq.gyro[shift:],
        acc=seq.acc[shift:],
        rot=seq.rot[:-shift],
        pos=seq.pos[:-shift],
        gt_mask=seq.gt_mask[shift:],
    )
    with pytest.warns(consistency.DataConsistencyWarning, match=r"best -[23]\.\d+ s away .* not on the IMU"):
        consistency.check(late)


def test_a_truth_about_other_axes_warns(seq):
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(seq.rot).as_quat()  # scalar last: a file of x, y, z, w read as w, x, y, z
    swapped = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    said = r"(turns about axes \d+ deg away|mirror image) .* quaternion order"
    with pytest.warns(consistency.DataConsistencyWarning, match=said):
        m = consistency.check(dataclasses.replace(seq, rot=swapped))
    assert m.axes_angle_deg > 30 and 0.5 < m.rate_ratio < 2  # the magnitude checks alone pass it
    tilted = (Rotation.from_matrix(seq.rot) * Rotation.from_euler("x", 20, degrees=True)).as_matrix()
    fitted = r"20 deg away.*quaternion w, x, y, z = 0\.98\d\d, 0\.17\d\d, -?0\.0\d\d\d, -?0\.0\d\d\d; right-multiply"
    with pytest.warns(consistency.DataConsistencyWarning, match=fitted):  # the pose of another body, and its rotation
        consistency.check(dataclasses.replace(seq, rot=tilted))
    assert consistency.measure(seq).axes_angle_deg < 1.0


def test_motion_about_one_axis_and_a_noisy_truth_pass(seq):
    """A turntable fixes one axis only (any turn about it maps the rates equally well), and a raw tracker's
    orientation noise is large over one IMU step: neither is a data problem."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    rate = 0.8 + 0.3 * np.sin(seq.t)  # rad/s about z only
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(seq.t))])
    rot = Rotation.from_euler("z", angle[:, None]).as_matrix()
    gyro = np.stack([0 * rate, 0 * rate, rate], 1) + 1e-3 * rng.standard_normal((len(rate), 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = consistency.check(dataclasses.replace(seq, rot=rot, gyro=gyro))
    assert m.axes_angle_deg < 1.0
    flipped = dataclasses.replace(seq, rot=rot, gyro=-gyro)  # the same axis, turning the other way
    with pytest.warns(consistency.DataConsistencyWarning, match="180 deg away"):
        consistency.check(flipped)
    noisy = (
        Rotation.from_matrix(seq.rot) * Rotation.from_rotvec(2e-3 * rng.standard_normal((len(seq), 3)))
    ).as_matrix()
    with warnings.catch_warnings():  # 2 mrad per sample: ~0.6 rad/s of noise over one 5-ms step
        warnings.simplefilter("error")
        assert 0.9 < consistency.check(dataclasses.replace(seq, rot=noisy)).rate_ratio < 1.1


def test_noisy_trackers_on_one_axis_or_at_rest_pass(seq):
    """A turntable seen by a tracker with 0.05 deg of noise per sample (TUM-VI's level), and a recording at rest
    with 0.2 deg: the truth's own spread is noise, not motion about other axes or a scale."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(1)
    for rate, noise_deg in ((0.3, 0.05), (0.0, 0.2)):
        rot = Rotation.from_rotvec(np.outer(rate * seq.t, [0, 0, 1])) * Rotation.from_rotvec(
            np.radians(noise_deg) * rng.standard_normal((len(seq), 3))
        )
        gyro = np.array([0.01, -0.005, rate]) + 3e-3 * rng.standard_normal((len(seq), 3))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            m = consistency.check(dataclasses.replace(seq, rot=rot.as_matrix(), gyro=gyro))
        assert (m.axes_angle_deg < 5) if rate else np.isnan(m.axes_angle_deg), (rate, m)


def test_a_truth_100_ms_late_warns_with_the_shift_to_apply(seq):
    shift = 20  # 100 ms at 200 Hz: the truth's stamps late by that much
    late = dataclasses.replace(
        seq, t=seq.t[shift:], gyro=seq.gyro[shift:], acc=seq.acc[shift:], rot=seq.rot[:-shift],
        pos=seq.pos[:-shift], gt_mask=seq.gt_mask[shift:],
    )  # fmt: skip
    with pytest.warns(
        consistency.DataConsistencyWarning, match=r"add -0\.(095|100|105) s to the ground truth's timestamps"
    ):
        consistency.check(late)


def test_a_clock_offset_is_named_before_the_comparisons_it_spoils(seq):
    """Half a second off the clock, the axes compared at the stamps were 'over 100 deg away' and that came first, with
    the offset after an 'Also'."""
    shift = 100
    late = dataclasses.replace(
        seq, t=seq.t[shift:], gyro=seq.gyro[shift:], acc=seq.acc[shift:], rot=seq.rot[:-shift],
        pos=seq.pos[:-shift], gt_mask=seq.gt_mask[shift:],
    )  # fmt: skip
    with pytest.raises(consistency.InconsistentTruthError) as e:
        consistency.check(late, stop=True)
    said = str(e.value)
    assert said.index("add -0.") < min(said.find(w) % len(said) for w in ("deg away", "times the rate", "mirror"))
    assert "right-multiply" not in said  # off the clock, a fitted rotation is no frame's


def test_a_large_gyro_about_other_axes_is_not_called_deg_s(seq):
    """57 times the truth's rate about other axes (e.g. the accelerometer's columns read as the gyro) is not a
    unit problem to fix by pi/180: it warns about the scale and the axes instead."""
    from scipy.spatial.transform import Rotation

    turned = Rotation.from_euler("x", 90, degrees=True).apply(np.degrees(seq.gyro))
    with pytest.warns(consistency.DataConsistencyWarning) as caught:
        consistency.check(dataclasses.replace(seq, gyro=turned))
    said = " ".join(str(w.message) for w in caught)
    assert "accelerometer" in said and "deg away" in said
    with pytest.raises(DataFormatError, match=r"looks like deg/s.*pi/180"):
        consistency.check(dataclasses.replace(seq, gyro=np.degrees(seq.gyro)))


def test_a_flipped_or_swapped_gyro_axis_is_a_mirror(seq):
    """A flipped axis is a reflection no rotation undoes; with little motion about that axis the best rotation
    is only a few degrees off (TUM-VI room 1, y flipped: 7.8 deg), so the handedness is what tells."""
    quiet_y = dataclasses.replace(seq, gyro=seq.gyro * [1.0, 0.15, 1.0], rot=seq.rot)  # little motion about y
    for gyro in (seq.gyro * [1, -1, 1], seq.gyro[:, [1, 0, 2]], -seq.gyro):
        with pytest.warns(consistency.DataConsistencyWarning, match="mirror image .* flipped in sign") as caught:
            m = consistency.check(dataclasses.replace(seq, gyro=gyro))
        assert m.mirrored and not any("deg away" in str(w.message) for w in caught)  # one message, not two
    assert not consistency.measure(seq).mirrored and not consistency.measure(quiet_y).mirrored


def test_a_gyro_far_smaller_than_the_truths_rate_warns(seq):
    """A gyro 1000 times too small rarely exceeds the moving threshold; it follows the truth, so it is a scale."""
    with pytest.warns(consistency.DataConsistencyWarning, match=r"the gyro is 0\.00(1|099\d*) times the rate"):
        consistency.check(dataclasses.replace(seq, gyro=seq.gyro * 1e-3))


def _xyzw_truth(folder):
    """The ground truth's quaternion written x, y, z, w where the ASL files hold w, x, y, z (no header to say so)."""
    gt = folder / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    lines = gt.read_text().splitlines()
    rows = [ln.split(",") for ln in lines[1:]]
    gt.write_text("\n".join([lines[0]] + [",".join(r[:4] + r[5:8] + [r[4]]) for r in rows]) + "\n")


def test_a_training_sequence_whose_truth_disagrees_stops_training_unless_told(tmp_path):
    from gyrodenoise.cli_errors import ConfigError
    from gyrodenoise.data.datamodule import ImuDataModule

    for i, name in enumerate(["good", "swapped"]):
        write_asl_sequence(tmp_path / name, seconds=20.0, seed=20 + i)
    _xyzw_truth(tmp_path / "swapped")

    def module(train, test, **kw):
        return ImuDataModule(name="mine", root=str(tmp_path), train_seqs=train, test_seqs=test, window=256,
                             cache_dir="", train_duration_s=15, **kw)  # fmt: skip

    with pytest.raises(consistency.InconsistentTruthError) as stop:
        module(["good", "swapped"], []).setup("fit")
    said = str(stop.value)
    assert "swapped (" in said and "state_groundtruth_estimate0/data.csv" in said and "quaternion order" in said
    assert "dataset.inconsistent_truth=warn" in said
    with pytest.warns(consistency.DataConsistencyWarning, match="quaternion order"):
        module(["good", "swapped"], [], inconsistent_truth="warn").setup("fit")
    with pytest.warns(consistency.DataConsistencyWarning, match="quaternion order"):  # a test sequence: said only
        module(["good"], ["swapped"]).check_sequences()
    with pytest.raises(ConfigError, match="inconsistent_truth='halt'"):
        module(["good"], [], inconsistent_truth="halt")


@pytest.mark.parametrize("dataset", ["sim", "euroc", "tumvi", "asl_folder"])
def test_every_dataset_config_takes_the_override_the_stop_names(dataset):
    """The stop says 'give dataset.inconsistent_truth=warn': that override composes with every dataset config (a
    config without the key refused it: 'Key inconsistent_truth is not in struct')."""
    from hydra import compose, initialize_config_dir

    from gyrodenoise.config import CONF_DIR

    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = compose("train", overrides=[f"dataset={dataset}", "dataset.inconsistent_truth=warn"])
    assert cfg.dataset.inconsistent_truth == "warn"


@pytest.mark.parametrize(("factor", "unit"), [(1 / 9.80665, "g"), (1000 / 9.80665, "mg")])
def test_an_accelerometer_in_g_or_milli_g_is_an_error(seq, factor, unit):
    """Training read an accelerometer in g as m/s^2 silently (inputs 9.8 times too small) while the corrector refused
    the same file: both stop now, naming the factor."""
    with pytest.raises(consistency.AccUnitError, match=rf"looks like {unit}\. .* multiply the accelerometer"):
        consistency.check(dataclasses.replace(seq, acc=seq.acc * factor))
    with pytest.warns(consistency.DataConsistencyWarning, match="accelerometer's norm is 4.9"):
        consistency.check(dataclasses.replace(seq, acc=seq.acc * 0.5))


def test_increments_across_an_imu_gap_are_left_out(seq):
    """An increment that spans a gap in the IMU stamps holds motion the gyro never saw: the loss and the calibrated fit
    leave it out, as they leave out increments without ground truth (a 1-s gap made a calibrated fit 15 x worse)."""
    from gyrodenoise.data.sequence import gt_increments

    keep = np.ones(len(seq.t), bool)
    keep[2005:2205] = False  # 1 s of IMU missing between samples 2004 and 2205
    gap = dataclasses.replace(
        seq, t=seq.t[keep], gyro=seq.gyro[keep], acc=seq.acc[keep], rot=seq.rot[keep], gt_mask=seq.gt_mask[keep]
    )
    _, ok_whole = gt_increments(seq, 16)
    dR, ok = gt_increments(gap, 16)
    assert ok_whole.all() and len(dR) == len(ok) == (len(gap) - 1) // 16
    assert np.flatnonzero(~ok).tolist() == [2004 // 16]  # the step 2004 -> 2005 (after the cut) lies in increment 125
    masked = dataclasses.replace(gap, gt_mask=np.r_[np.ones(100, bool), False, np.ones(len(gap) - 101, bool)])
    assert np.flatnonzero(~gt_increments(masked, 16)[1]).tolist() == [6, 2004 // 16]  # sample 100: 96..112
