"""A ground truth with gaps (TUM-VI's mocap occlusions) is split, not bridged (discrepancy.compare)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodenoise.data.readers import DataFormatError
from gyrodenoise.discrepancy.compare import gap_free_stretches, load_fit_context, load_fit_contexts


def _with_gaps(tmp_path, gaps_s: list[tuple[float, float]]):
    """A test-world flight (Vicon-like truth, 60 s) whose truth rows inside the given spans are deleted."""
    from gyrodenoise.testworld import MOCAP_PRESETS, make_sequence

    seq = make_sequence(tmp_path, "procedural", None, duration=60.0, seed=3, name="s", mocap=MOCAP_PRESETS["vicon"])
    mav0 = seq.imu_file.parent.parent
    gt_file = [p for p in mav0.glob("*/data.csv") if p.parent.name != "imu0"][0]
    lines = gt_file.read_text().splitlines()
    t0 = int(seq.imu_file.read_text().splitlines()[1].split(",")[0])
    keep = [lines[0]]
    for line in lines[1:]:
        t = (int(line.split(",")[0]) - t0) * 1e-9
        if not any(a < t < b for a, b in gaps_s):
            keep.append(line)
    gt_file.write_text("\n".join(keep) + "\n")
    return tmp_path


def test_gap_free_stretches():
    t = (np.r_[np.arange(0, 10, 0.01), np.arange(11, 20, 0.01)] * 1e9).astype(np.int64)
    s = gap_free_stretches(t, 0.25)
    assert [(x.start, x.stop) for x in s] == [(0, 1000), (1000, 1900)]
    assert len(gap_free_stretches(t, 2.0)) == 1


def test_a_truth_with_gaps_is_split_and_short_stretches_are_listed(tmp_path):
    root = _with_gaps(tmp_path, [(25.0, 26.0), (30.0, 30.5)])  # stretches ~0-25, 26-30 (too short), 30.5-60 s
    fcs, left = load_fit_contexts(root, "s")
    assert [fc.name.split("@")[0] for fc in fcs] == ["s", "s"] and all(fc.extra["sequence"] == "s" for fc in fcs)
    assert fcs[0].t[-1] < 25.0 and fcs[1].t[0] > 30.5  # time stays that of the recording (warm-up effects)
    assert len(left) == 1 and left[0]["why"] == "too short" and 3.5 < left[0]["seconds"] < 4.5
    for fc in fcs:  # no stretch spans a gap: the rate comes from truth samples on both sides of every IMU sample
        assert np.all(np.diff(fc.t) < 0.1)
    with pytest.raises(DataFormatError, match="gaps longer than"):
        load_fit_context(root, "s")
    # a gap shorter than the limit is bridged: one context with the recording's name
    fcs, left = load_fit_contexts(_with_gaps(tmp_path / "b", [(25.0, 25.1)]), "s")
    assert [fc.name for fc in fcs] == ["s"] and left == []


def test_on_an_occluded_tracker_a_null_sensor_gets_nothing_named_once_the_gaps_are_split(euroc_root, tmp_path):
    """Data the workflow did not make: gyrodenoise.testworld's null sensor (bias + white noise) on EuRoC V1_02 /
    V2_01 motion, measured by a 120 Hz tracker that loses the body 4 times a minute for 0.3-2 s. Bridging the
    gaps with the spline invents motion there and the selection names an effect the sensor does not have;
    split at the gaps, nothing is named."""
    from gyrodenoise.discrepancy.workflow import decide
    from gyrodenoise.testworld import MOCAP_PRESETS, make_sequence

    for name, flight, seed in (("fit", "V1_02_medium", 5), ("hold", "V2_01_easy", 6)):
        make_sequence(tmp_path, f"euroc:{flight}", None, duration=80.0, seed=seed, name=name,
                      mocap=MOCAP_PRESETS["tumvi-occluded"], euroc_root=euroc_root)  # fmt: skip

    def named(max_gap_s: float) -> list[str]:
        fit, _ = load_fit_contexts(tmp_path, "fit", max_gap_s=max_gap_s)
        hold, _ = load_fit_contexts(tmp_path, "hold", max_gap_s=max_gap_s)
        return list(decide(fit, hold, null_draws=0)[1].named)

    assert named(0.25) == []
    assert named(np.inf) != []  # the contrast: the same data with the gaps bridged
