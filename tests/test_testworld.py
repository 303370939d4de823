"""The independent test world (gyrodenoise.testworld): kinematics, sensor response, recoverability of a
hidden effect, measured ground truth, file format and error messages. Small sequences, a few seconds."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrodenoise.data.readers import read_groundtruth, read_imu
from gyrodenoise.testworld import EffectSpecError, MocapConfig, ProceduralMotion, make_sequence
from gyrodenoise.testworld.__main__ import main as cli
from gyrodenoise.testworld.motion import FourierSeries, quat_product
from gyrodenoise.testworld.sensor import Bandwidth, simulate_imu
from gyrodenoise.testworld.spec import parse_effects, realise

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "gyrodenoise" / "testworld"


def _rngs(seed: int = 0) -> dict[str, np.random.Generator]:
    return {s: np.random.default_rng([seed, i]) for i, s in enumerate(("noise", "walk", "vibration", "acc", "stamps"))}


def _effects(text: str, seed: int = 0):
    return realise(parse_effects(text), np.random.default_rng(seed))


def test_constant_rate_gives_the_expected_attitude():
    w = np.array([0.3, -1.1, 0.7])
    r0 = Rotation.from_rotvec([0.2, 0.1, -0.4])
    motion = ProceduralMotion.constant_rate(w, duration=5.0, r0=r0)
    t = np.array([0.0, 0.0123, 1.0, 2.71828, 4.9999])
    expected = r0 * Rotation.from_rotvec(np.outer(t, w))  # R(t) = R0 exp(w t): body-frame rate
    err = (motion.attitude(t).inv() * expected).magnitude()
    assert err.max() < 1e-9
    kin = motion.evaluate(t)
    np.testing.assert_allclose(kin.omega, np.tile(w, (len(t), 1)))
    np.testing.assert_allclose(kin.alpha, 0.0)
    # at rest and spinning in place, the accelerometer reads gravity in the body frame
    np.testing.assert_allclose(kin.specific_force, expected.inv().apply([0.0, 0.0, 9.80665]), atol=1e-9)


def test_the_quaternion_product_is_scipys_rotation_product():
    """The prefix scan's product (numpy, for speed) composes rotations as `Rotation.__mul__` does."""
    a, b = Rotation.random(500, random_state=1), Rotation.random(500, random_state=2)
    got = Rotation.from_quat(quat_product(a.as_quat(), b.as_quat()))
    np.testing.assert_allclose(got.as_matrix(), (a * b).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(quat_product(a.as_quat(), b.as_quat()), axis=1), 1.0, atol=1e-15)


def test_magnus_integration_is_fourth_order():
    motion = ProceduralMotion.random(2.0, seed=3)
    ref = ProceduralMotion(motion.rate, motion.position, 2.0, node_hz=8000.0).attitude(np.array([1.9]))
    errs = [
        (
            ProceduralMotion(motion.rate, motion.position, 2.0, node_hz=hz).attitude(np.array([1.9])).inv() * ref
        ).magnitude()[0]
        for hz in (50.0, 100.0)
    ]
    assert 10 < errs[0] / errs[1] < 24  # 2^4 = 16 for a 4th-order scheme (2^2 = 4 for a wrong commutator sign)


@pytest.mark.parametrize("f_hz", [13.0, 37.0, 71.0])
def test_integrating_sensor_response_is_sinc(f_hz):
    amp, rate = 0.5, 200.0
    z = np.zeros((1, 3))
    motion = ProceduralMotion(
        FourierSeries(np.array([f_hz]), np.array([[amp, 0.0, 0.0]]), z.copy(), np.zeros(3)),
        FourierSeries(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(3)),
        duration=3.0,
    )
    imu = simulate_imu(motion, _effects(""), 0.5, 400, 0, _rngs(), rate, Bandwidth.parse("integrate"), oversample=20)
    # least-squares sine/cosine fit at f: gain and phase of the sampled output
    x = np.stack([np.sin(2 * np.pi * f_hz * imu.t), np.cos(2 * np.pi * f_hz * imu.t)], axis=1)
    (s, c), *_ = np.linalg.lstsq(x, imu.gyro[:, 0], rcond=None)
    gain = np.hypot(s, c) / amp
    assert gain == pytest.approx(np.sinc(f_hz / rate), abs=1e-3)  # np.sinc(x) = sin(pi x) / (pi x)
    assert abs(np.arctan2(c, s)) < 1e-3  # centred window: no delay


def test_hidden_scale_factor_is_recovered_by_least_squares():
    motion = ProceduralMotion.random(20.5, seed=1)
    eff = _effects("bias=1deg/s,white_noise=1.6968e-4rad/s/sqrt(Hz),scale_factor=1500:-2500:4000ppm")
    imu = simulate_imu(motion, eff, 0.1, 4000, 0, _rngs(1), oversample=10)
    true_scale = np.array([1500e-6, -2500e-6, 4000e-6])
    for i in range(3):
        # y_i = b_i + (1 + s_i) w_i + noise  ->  regress y_i - w_i on [1, w_i]
        a = np.stack([np.ones(len(imu.t)), imu.omega_true[:, i]], axis=1)
        coef, res, *_ = np.linalg.lstsq(a, imu.gyro[:, i] - imu.omega_true[:, i], rcond=None)
        sigma = np.sqrt(res[0] / (len(a) - 2))
        se = sigma * np.sqrt(np.linalg.inv(a.T @ a)[1, 1])
        assert abs(coef[1] - true_scale[i]) < 4 * se, (i, coef[1], se)
        assert abs(coef[1]) > 10 * se  # and it is clearly there


def test_time_offset_is_a_stamp_shift():
    motion = ProceduralMotion.random(5.0, seed=2)
    imu = simulate_imu(motion, _effects("time_offset=4ms"), 0.5, 600, 0, _rngs(), oversample=10)
    t_stamp = imu.stamp_ns * 1e-9
    # the sample stamped t holds the motion of t - delta (up to the integrating window's curvature term)
    assert np.abs(imu.gyro - motion.evaluate(t_stamp - 4e-3).omega).max() < 5e-4
    assert np.abs(imu.gyro - motion.evaluate(t_stamp).omega).max() > 5e-3


def test_written_files_parse_and_mocap_noise_matches_config(tmp_path):
    mocap = MocapConfig(rate_hz=120.0, orientation_noise_rad=np.deg2rad(0.3), position_noise_m=2e-3, jitter_s=0.0)
    seq = make_sequence(tmp_path, "procedural", "scale_factor=2000ppm", duration=12.0, seed=4, mocap=mocap)
    imu = read_imu(seq.imu_file)
    gt = read_groundtruth(seq.groundtruth_file)
    assert seq.imu_file.read_text().splitlines()[0] == (
        "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
        "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
    )
    assert len(imu.t_ns) == 2400 and np.all(np.diff(imu.t_ns) == 5_000_000)
    assert np.median(np.diff(gt.t_ns)) == round(1e9 / 120)
    assert gt.t_ns[0] > imu.t_ns[0] and gt.t_ns[-1] < imu.t_ns[-1]  # one clock, GT inside the IMU span
    truth = json.loads(seq.truth_file.read_text())
    assert truth["hidden_effects"] == ["scale_factor"]
    assert truth["mocap"]["orientation_noise_deg"] == pytest.approx(0.3)

    # compare the written ground truth with the true motion at its stamps (jitter off)
    motion = ProceduralMotion.random(12.5, seed=4)
    t = (gt.t_ns - 1_500_000_000_000_000_000) * 1e-9
    kin = motion.evaluate(t)
    dtheta = (kin.rot.inv() * Rotation.from_quat(gt.quat_xyzw)).as_rotvec()
    np.testing.assert_allclose(np.rad2deg(dtheta.std(0)), 0.3, rtol=0.08)
    np.testing.assert_allclose((gt.pos - kin.pos).std(0), 2e-3, rtol=0.08)
    assert np.abs(dtheta.mean(0)).max() < 4 * np.deg2rad(0.3) / np.sqrt(len(t))


def test_spec_errors_are_clear(tmp_path):
    with pytest.raises(EffectSpecError, match="unknown effect 'scale'.*scale_factor"):
        parse_effects("scale=2000ppm")
    with pytest.raises(EffectSpecError, match="no parameter 'centre'.*center"):
        parse_effects("vibration.centre=19Hz")
    with pytest.raises(EffectSpecError, match="unknown unit 'pm'.*ppm"):
        _effects("scale_factor=2000pm")
    with pytest.raises(EffectSpecError, match="has no unit"):
        _effects("time_offset=2")
    with pytest.raises(EffectSpecError, match="expected 1 or 6"):
        _effects("misalignment=1:2:3mrad")
    with pytest.raises(EffectSpecError, match="no '='"):
        parse_effects("scale_factor")
    with pytest.raises(EffectSpecError, match=r"time_offset.value is given twice \('3ms' and '4ms'\)"):
        parse_effects("time_offset=3ms,time_offset=4ms")
    with pytest.raises(ValueError, match="bandwidth 'butter:50'"):
        Bandwidth.parse("butter:50")
    assert cli(["--out", str(tmp_path), "--effects", "foo=1ppm"]) == 2
    assert not any(tmp_path.iterdir())  # nothing half-written


def test_datasheet_units_and_signs():
    eff = _effects("g_sensitivity=0.1:0.2:0.3deg/s/g,misalignment=2mrad,nonlinearity=0.1%FS,bias=0.5deg/s", seed=7)
    g = eff.g_matrix()
    np.testing.assert_allclose(np.diag(g), np.deg2rad([0.1, 0.2, 0.3]) / 9.80665)
    assert np.count_nonzero(g - np.diag(np.diag(g))) == 0
    m = eff.sensor_matrix()
    np.testing.assert_allclose(np.abs(m[~np.eye(3, dtype=bool)]), 2e-3)
    np.testing.assert_allclose(eff.nonlinearity_k(), 1e-3 / np.deg2rad(1000.0))  # 0.1 % of 1000 deg/s at FS
    np.testing.assert_allclose(np.abs(eff.get("bias")), np.deg2rad(0.5))


def test_sequence_is_written_atomically(tmp_path):
    make_sequence(tmp_path, "procedural", duration=2.0, name="seq")
    with pytest.raises(FileExistsError):
        make_sequence(tmp_path, "procedural", duration=2.0, name="seq")
    make_sequence(tmp_path, "procedural", duration=2.0, name="seq", seed=1, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]  # no temporary folders left
    assert json.loads((tmp_path / "seq" / "truth.json").read_text())["seed"] == 1


def test_testworld_shares_no_code_with_the_workflow():
    for path in PACKAGE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            for n in names:
                assert not n.startswith("gyrodenoise") or n.startswith("gyrodenoise.testworld"), (path.name, n)


def test_euroc_replay_follows_the_recording(euroc_root):
    from gyrodenoise.testworld.asl import read_asl_pose
    from gyrodenoise.testworld.replay import EurocReplay

    replay = EurocReplay("V1_02_medium", euroc_root, duration=8.0)
    t_ns, pos, rot = read_asl_pose(euroc_root / "V1_02_medium" / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    t = (t_ns - replay.t0_ns) * 1e-9
    keep = (t > replay.t_start) & (t < replay.t_end)
    kin = replay.evaluate(t[keep])
    assert np.rad2deg((kin.rot.inv() * rot[keep]).magnitude()).max() < 1.0  # smoothed, not refitted away
    assert np.abs(kin.pos - pos[keep]).max() < 0.01
    # RotationSpline's first derivative is the body-frame rate: check against a finite difference
    tc, d = np.array([replay.t_start + 3.0]), 1e-5
    fd = (replay.rot_spline(tc - d).inv() * replay.rot_spline(tc + d)).as_rotvec() / (2 * d)
    np.testing.assert_allclose(replay.evaluate(tc).omega, fd, atol=1e-4)


def test_motion_seed_gives_other_motion_with_the_same_sensor(tmp_path):
    """'procedural:K': the motion drawn from K, the sensor (hidden effect values) from --seed."""
    a = make_sequence(tmp_path, "procedural:1", "scale_factor=3000ppm", duration=5.0, seed=3)
    b = make_sequence(tmp_path, "procedural:2", "scale_factor=3000ppm", duration=5.0, seed=3)
    assert (a.path.name, b.path.name) == ("procedural1_s3", "procedural2_s3")
    assert a.truth["effects"] == b.truth["effects"]  # one sensor
    gyro_a, gyro_b = read_imu(a.imu_file).gyro, read_imu(b.imu_file).gyro
    assert np.abs(gyro_a - gyro_b).mean() > 0.1  # other motion (rad/s), not only other noise
    with pytest.raises(ValueError, match="procedural:<motion seed>"):
        make_sequence(tmp_path, "procedural:x", duration=5.0)


@pytest.mark.parametrize("bandwidth", ["butter2:50Hz", "bessel4:40Hz"])
def test_filter_bandwidth_on_a_procedural_trajectory(tmp_path, bandwidth):
    """A filtering sensor needs motion before its first sample (its start-up): the IMU starts after it, so a
    procedural trajectory (which starts at 0) works, and the samples still span the duration asked for."""
    seq = make_sequence(tmp_path, "procedural", duration=5.0, seed=2, bandwidth=bandwidth)
    imu = read_imu(seq.imu_file)
    assert len(imu.t_ns) == 1000 and np.all(np.isfinite(imu.gyro))
    assert read_groundtruth(seq.groundtruth_file).t_ns[0] > imu.t_ns[0]  # the truth inside the IMU span


def test_time_offset_may_be_negative():
    """A stamp error has either sign: -3 ms (early stamps) is taken as given, no random sign."""
    assert float(_effects("time_offset=-3ms").get("time_offset")) == pytest.approx(-0.003)
    assert float(_effects("time_offset=3ms").get("time_offset")) == pytest.approx(0.003)


def test_the_fusions_quaternion_steps_are_scipys():
    """The complementary filter's per-sample quaternion arithmetic (plain floats, for speed) is scipy's Rotation:
    product, inverse, rotation vector to quaternion and back, small angles included."""
    from gyrodenoise.testworld.mocap import _conj, _exp, _log, _mul

    rng = np.random.default_rng(4)
    a, b = Rotation.random(2, random_state=5)
    qa, qb = tuple(a.as_quat()), tuple(b.as_quat())
    assert np.allclose(_mul(qa, qb), (a * b).as_quat(), atol=1e-15)
    assert np.allclose(_log(_mul(_conj(qa), qb)), (a.inv() * b).as_rotvec(), atol=1e-14)
    for angle in (0.0, 1e-9, 1e-4, 9e-4, 2e-3, 0.5, 3.0):
        v = rng.standard_normal(3)
        v *= angle / np.linalg.norm(v)
        assert np.allclose(_exp(tuple(v)), Rotation.from_rotvec(v).as_quat(), rtol=0, atol=1e-16)
        assert np.allclose(_log(tuple(Rotation.from_rotvec(v).as_quat())), v, rtol=1e-14, atol=1e-20)


def test_truth_states_the_vibration_the_samples_carry(tmp_path):
    """`level` is the RMS at the sensor input; the period mean passes ~0.86 of it at 60 Hz and 200 Hz, and the
    discrepancy workflow measures the output's: truth.json says both (an audit compared the two directly)."""
    from scipy.signal import welch

    seq = make_sequence(tmp_path, duration=30.0, effects="vibration=0.3deg/s,vibration.center=60Hz", preset="none")
    truth = json.loads(seq.truth_file.read_text())["vibration_at_output"]
    gyro = read_imu(seq.imu_file).gyro
    f, p = welch(gyro - gyro.mean(0), fs=200.0, nperseg=800, axis=0)
    rms = np.sqrt(p[np.abs(f - 60.0) <= 1.0].sum(0) * (f[1] - f[0]))
    assert np.allclose(rms, truth["rms_rad_s"], rtol=0.05) and truth["gain"] == pytest.approx(0.859, abs=0.002)
