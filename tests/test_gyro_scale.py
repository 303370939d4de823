"""The gyro's unit read off gravity (`data.gyro_scale`): a deg/s gyro on a slow platform, whose rates stay under
the range check's 15 rad/s, is named; real rad/s recordings never are."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrodenoise.data.checks import SanityCheckError, SanityWarning, run_checks
from gyrodenoise.data.gyro_scale import gyro_scale_verdict
from gyrodenoise.data.imu_csv import ImuRecording
from gyrodenoise.data.readers import read_imu
from gyrodenoise.models.denoiser import CalibratedImu
from gyrodenoise.streaming import GYRO_PROBE_S, StreamingCorrector

RATE = 200.0


def slow_tilting_body(seconds: float = 60.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(gyro rad/s, acc m/s^2) of a body that rests and tilts slowly in turn (a ground robot on uneven floor, a
    camera on a slow gimbal): rates under 0.3 rad/s (17 deg/s), so a deg/s gyro stays far below any range check.
    Made here with scipy's rotations, not the project's integration."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t = np.arange(n) / RATE
    rate = np.zeros((n, 3))
    for k in range(0, n, int(2 * RATE)):  # a 1-s tilt about a random horizontal axis every 2 s, then rest
        axis = np.r_[rng.normal(size=2), 0.0]
        seg = slice(k, min(k + int(RATE), n))
        rate[seg] = 0.25 * np.sin(np.pi * (t[seg] - t[k]))[:, None] * axis / np.linalg.norm(axis)
    rot = [Rotation.identity()]
    for w in rate[:-1]:
        rot.append(rot[-1] * Rotation.from_rotvec(w / RATE))
    r = Rotation.concatenate(rot)
    acc = r.inv().apply([0.0, 0.0, 9.81]) + rng.normal(0, 0.02, (n, 3))
    gyro = rate + 0.002 + rng.normal(0, 0.003, (n, 3))
    return gyro, acc


def test_a_deg_s_gyro_on_a_slow_body_is_named_and_rad_s_is_not():
    gyro, acc = slow_tilting_body()
    assert gyro_scale_verdict(acc, gyro, RATE).unit in ("rad/s", None)
    assert not gyro_scale_verdict(acc, gyro, RATE).wrong_unit
    verdict = gyro_scale_verdict(acc, np.degrees(gyro), RATE)
    assert verdict.unit == "deg/s" and verdict.windows >= 4


def test_noise_that_does_not_follow_the_motion_gives_no_verdict():
    rng = np.random.default_rng(1)
    acc = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.02, (12000, 3))
    assert gyro_scale_verdict(acc, rng.normal(0, 0.3, (12000, 3)), RATE).unit != "deg/s"


def _recording(gyro: np.ndarray, acc: np.ndarray) -> ImuRecording:
    n = len(gyro)
    return ImuRecording(
        t_ns=np.arange(n, dtype=np.int64) * 5_000_000,
        gyro=gyro,
        acc=acc,
        lines=np.arange(n) + 2,
        path="slow.csv",
        columns={k: k for k in ("t", "wx", "wy", "wz", "ax", "ay", "az")},
        units={"gyro": "rad/s", "acc": "m/s^2", "time": "ns"},
    )


def test_correct_refuses_a_deg_s_file_the_range_check_passes():
    """Before, a deg/s gyro under 15 (its 99th percentile, as rad/s) passed every check and was corrected as
    rad/s: 57 times the rotation."""
    gyro, acc = slow_tilting_body()
    run_checks(_recording(gyro, acc), RATE)  # rad/s: no complaint
    with pytest.raises(SanityCheckError, match="probably in deg/s: pass --gyro-unit deg/s"):
        run_checks(_recording(np.degrees(gyro), acc), RATE)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run_checks(_recording(np.degrees(gyro), acc), RATE, force=True)
    assert any("deg/s" in str(w.message) for w in caught)


def test_a_stream_in_deg_s_warns_once_after_its_probe():
    gyro, acc = slow_tilting_body(GYRO_PROBE_S + 5)
    x = np.concatenate([np.degrees(gyro), acc], 1)
    sc = StreamingCorrector(CalibratedImu())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sc.push_chunk(x)
    said = [w for w in caught if issubclass(w.category, SanityWarning) and "pi/180" in str(w.message)]
    assert len(said) == 1
    sc.reset()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for row in np.concatenate([gyro, acc], 1):
            sc.push(row)
    assert not [w for w in caught if "pi/180" in str(w.message)]


@pytest.mark.parametrize("dataset", ["euroc", "tumvi"])
def test_real_recordings_in_rad_s_are_never_called_deg_s(dataset, request):
    """The guard against false alarms: every EuRoC and TUM-VI recording, as recorded and converted to deg/s."""
    root = request.getfixturevalue(f"{dataset}_root")
    files = sorted(root.glob("*/mav0/imu0/data.csv"))
    assert files
    named = 0
    for path in files:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # TUM-VI's files without a final line break
            d = read_imu(path)
        rate = 1e9 / float(np.median(np.diff(d.t_ns)))
        assert not gyro_scale_verdict(d.acc, d.gyro, rate).wrong_unit, path
        named += gyro_scale_verdict(d.acc, np.degrees(d.gyro), rate).unit == "deg/s"
    assert named >= len(files) // 3  # where rests or slow tilts are long enough to judge


def test_a_stream_in_deg_s_moving_fast_is_told_after_its_first_samples():
    """A fresh-user audit pushed 35 s of V1_01 in deg/s (99th percentile 42 rad/s as read) and got no warning, where
    `correct` refuses the file at once: the range check now runs on the stream's first UNIT_PROBE samples, once."""
    from gyrodenoise.streaming import UNIT_PROBE

    t = np.arange(UNIT_PROBE + 50) / RATE
    gyro = 0.6 * np.sin(2 * np.pi * 0.7 * t[:, None] + np.arange(3))  # ~1 rad/s of motion, read in deg/s
    acc = np.tile([0.0, 0.0, 9.81], (len(t), 1))
    sc = StreamingCorrector(CalibratedImu())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sc.push_chunk(np.concatenate([np.degrees(gyro), acc], 1))
        sc.push_chunk(np.concatenate([np.degrees(gyro), acc], 1))
    said = [w for w in caught if "99th-percentile" in str(w.message)]
    assert len(said) == 1 and "pi/180" in str(said[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        StreamingCorrector(CalibratedImu()).push_chunk(np.concatenate([gyro, acc], 1))
