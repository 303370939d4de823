"""One test-world sequence: truth motion -> IMU with hidden effects + measured ground truth -> ASL folder
with truth.json.

Seeds: the hidden effects' values (signs of magnitudes) depend on `seed` only, so sequences generated
with one seed share one sensor, as the sequences of a real dataset do; every noise realisation also
depends on the sequence name, so two sequences never share noise.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyrodenoise.testworld.asl import imu_csv, pose_csv, write_sequence
from gyrodenoise.testworld.mocap import MocapConfig, MocapPoses, fuse_with_gyro, measure_poses
from gyrodenoise.testworld.motion import MotionSource, ProceduralMotion
from gyrodenoise.testworld.replay import EurocReplay
from gyrodenoise.testworld.sensor import AccelModel, Bandwidth, ImuSamples, simulate_imu
from gyrodenoise.testworld.spec import NULL_EFFECTS, PRESETS, EffectSpecError, merge, parse_effects, realise
from gyrodenoise.testworld.units import to_si

FORMAT = "gyrodenoise.testworld/1"
MAX_JITTER_PERIODS = 0.1  # IMU stamp jitter (std) at most this many periods: the 0.4-period clip is then 4 sigma
PROCEDURAL_T0_NS = 1_500_000_000_000_000_000
_STREAMS = ("noise", "walk", "vibration", "acc", "stamps", "mocap", "phase", "flicker")  # new streams last


@dataclass
class WorldSequence:
    path: Path  # <out>/<name>
    imu_file: Path
    groundtruth_file: Path
    truth_file: Path
    truth: dict
    imu: ImuSamples | None = field(default=None, repr=False)
    mocap: MocapPoses | None = field(default=None, repr=False)


def make_motion(
    trajectory: str,
    duration: float | None,
    seed: int,
    euroc_root: str | Path | None = None,
    smoothing_hz: float = 15.0,
    lead_s: float = 0.0,
) -> MotionSource:
    """'procedural' (motion drawn from `seed`), 'procedural:<K>' (motion drawn from K: other motion, same
    sensor) or 'euroc:<SEQ>' -> a continuous-time motion source. lead_s: motion needed before the first IMU sample
    (a filtering sensor's start-up), added to a procedural motion's length."""
    kind, _, arg = trajectory.partition(":")
    if kind == "procedural" and (not arg or arg.isdigit()):
        return ProceduralMotion.random((duration or 60.0) + 0.5 + lead_s, int(arg) if arg else seed)
    if kind == "euroc" and arg:
        return EurocReplay(arg, euroc_root, cutoff_hz=smoothing_hz, duration=duration)
    raise ValueError(
        f"trajectory {trajectory!r}: expected 'procedural', 'procedural:<motion seed>' or 'euroc:<SEQ>'"
        " (e.g. euroc:V1_02_medium)"
    )


def _check_imu_settings(rate_hz: float, oversample: int, jitter_s: float) -> None:
    """One line for an IMU rate, oversampling or stamp jitter no sensor has (a ZeroDivisionError before, or a jitter
    clipped to another size than `truth.json` records)."""
    if not (np.isfinite(rate_hz) and 0 < rate_hz <= 1e5):
        raise ValueError(f"--imu-rate {rate_hz:g}: the IMU rate in Hz, above 0 and at most 1e5 (e.g. 200)")
    if oversample < 1:
        raise ValueError(f"--oversample {oversample}: internal samples per IMU period, an integer >= 1 (e.g. 20)")
    if not 0 <= jitter_s <= MAX_JITTER_PERIODS / rate_hz:
        raise ValueError(
            f"--imu-jitter {jitter_s * 1e6:g}us: the stamps' standard deviation, from 0 to {MAX_JITTER_PERIODS:g} of "
            f"a period ({MAX_JITTER_PERIODS / rate_hz * 1e6:g}us at {rate_hz:g} Hz): the draws are clipped at 0.4 of a "
            "period to keep the stamps in order, so a larger one would not be the jitter truth.json records"
        )


def make_sequence(
    out: str | Path,
    trajectory: str | MotionSource = "procedural",
    effects: str | Mapping[str, str] | None = None,
    preset: str = "null",
    duration: float | None = None,
    seed: int = 0,
    name: str | None = None,
    imu_rate_hz: float = 200.0,
    bandwidth: str = "integrate",
    oversample: int = 20,
    imu_jitter: str = "0us",
    mocap: MocapConfig | None = None,
    euroc_root: str | Path | None = None,
    smoothing_hz: float = 15.0,
    overwrite: bool = False,
) -> WorldSequence:
    """Generate one sequence and write it as `<out>/<name>/mav0/...` plus `<out>/<name>/truth.json`.

    effects: "scale_factor=2000ppm,time_offset=1.5ms" (see `spec.describe()`), added to the preset's
    effects ("null": constant bias + white noise; "none": nothing). duration: seconds of IMU data (default:
    60 s procedural, the whole recording for euroc). name: the folder name (default: the EuRoC sequence,
    or procedural_s<seed>)."""
    if preset not in PRESETS:
        raise EffectSpecError(f"unknown preset {preset!r}; presets: {', '.join(PRESETS)}")
    spec = merge(parse_effects(PRESETS[preset]), parse_effects(effects))
    eff = realise(spec, np.random.default_rng([seed, 1]))
    bw = Bandwidth.parse(bandwidth)
    jitter_s = float(to_si(imu_jitter, "time", "imu_jitter")[0])
    _check_imu_settings(imu_rate_hz, oversample, jitter_s)
    lead = bw.start_up_s(imu_rate_hz)
    mocap = mocap or MocapConfig()

    if isinstance(trajectory, str):
        motion = make_motion(trajectory, duration, seed, euroc_root, smoothing_hz, lead)
        kind, _, arg = trajectory.partition(":")
        default_name = (arg if kind == "euroc" else f"procedural{arg}_s{seed}") if arg else f"procedural_s{seed}"
    else:
        motion, default_name = trajectory, f"custom_s{seed}"
    name = name or default_name
    if not name or "/" in name or name.startswith("."):
        raise ValueError(f"sequence name {name!r} must be a plain folder name")
    tag = zlib.crc32(name.encode())
    rng = {s: np.random.default_rng([seed, 2 + i, tag]) for i, s in enumerate(_STREAMS)}
    t0_ns = getattr(motion, "t0_ns", PROCEDURAL_T0_NS)

    # the IMU runs over the whole span (after a filter's start-up); the mocap starts and ends a little inside it, at
    # its own phase
    period = 1.0 / imu_rate_hz
    span = motion.t_end - motion.t_start - lead
    if duration is not None:
        span = min(span, duration + 2 * period)
    n = int((span - 2 * period) / period)
    if n < 100:
        raise ValueError(f"only {n} IMU samples fit in the trajectory span of {span:.2f} s")
    t_first = motion.t_start + lead + period
    imu = simulate_imu(motion, eff, t_first, n, t0_ns, rng, imu_rate_hz, bw, oversample, jitter_s, AccelModel())
    t_imu_end = imu.t[-1]
    first = motion.t_start + lead + 0.2 + rng["phase"].uniform(0, 1.0 / mocap.rate_hz)
    poses = measure_poses(motion, mocap, first, min(t_imu_end, motion.t_end) - 0.2, t0_ns, rng["mocap"])
    if mocap.fuse_tau_s > 0:
        poses = fuse_with_gyro(poses, imu.t, imu.gyro, mocap.fuse_tau_s, (poses.stamp_ns - t0_ns) * 1e-9)

    truth = _truth(name, seed, preset, motion, eff, imu, poses, bw)
    path = write_sequence(
        Path(out),
        name,
        imu_csv(imu.stamp_ns, imu.gyro, imu.acc),
        pose_csv(poses.stamp_ns, poses.pos, poses.rot),
        truth,
        overwrite,
    )
    return WorldSequence(
        path=path,
        imu_file=path / "mav0" / "imu0" / "data.csv",
        groundtruth_file=path / "mav0" / "state_groundtruth_estimate0" / "data.csv",
        truth_file=path / "truth.json",
        truth=truth,
        imu=imu,
        mocap=poses,
    )


def _vibration_at_output(eff, imu, bw) -> dict:
    """A vibration's RMS as the samples carry it: `level` is at the sensor input, and the bandwidth (the integrating
    sensor's period mean included) passes gain(center) of it; the discrepancy workflow measures, and its
    error_model.yaml writes, the output's (amplitude = sqrt(2) x this RMS). Empty without a vibration."""
    if "vibration" not in eff.si:
        return {}
    center = float(eff.get("vibration", "center"))
    rate = 1.0 / float(np.median(np.diff(imu.t)))
    gain = float(bw.response(np.array([center]), rate, imu.info["bandwidth"]["internal_rate_hz"])[0])
    level = np.asarray(eff.get("vibration", "level"), dtype=float)
    return {"vibration_at_output": {"center_hz": center, "gain": gain, "rms_rad_s": (gain * level).tolist()}}


def _truth(name, seed, preset, motion, eff, imu, poses, bw) -> dict:
    delta = float(eff.get("time_offset"))
    delay = imu.info["bandwidth"]["group_delay_s"]
    hidden = sorted(n for n in eff.si if n not in NULL_EFFECTS)
    return {
        "format": FORMAT,
        "sequence": name,
        "seed": seed,
        "preset": preset,
        "hidden_effects": hidden,  # the answer key: effects beyond the workflow's base model
        "effects": eff.to_json(),
        "gyro_model": {
            "equation": "y = M w + G f + N(w) + b + b_rw(t) + v(t) + n(t); clip; bandwidth; quantise",
            "M": eff.sensor_matrix().tolist(),
            "G_rad_s_per_m_s2": eff.g_matrix().tolist(),
            "bias_rad_s": np.asarray(eff.get("bias")).tolist(),
        },
        "timing": {
            "time_offset_s": delta,  # stamp error: the sample taken at t is stamped t + delta
            "sensor_delay_s": delay,  # the bandwidth's group delay at low frequency
            "apparent_time_offset_s": delta + delay,  # what a delay estimator comparing with the truth sees
        },
        "imu": imu.info,
        **_vibration_at_output(eff, imu, bw),
        "imu_span_ns": [int(imu.stamp_ns[0]), int(imu.stamp_ns[-1])],
        "mocap": poses.info,
        "trajectory": motion.describe(),
        "conventions": "time int ns on disk; R body->world; Rdot = R [w]x (body rate); ASL quaternions w,x,y,z; "
        "gravity (0, 0, -9.80665) m/s^2 in the world frame; per-axis datasheet values in the order x, y, z; "
        "misalignment = sensor-matrix entries (M01, M02, M10, M12, M20, M21)",
        "shares_with_gyrodenoise": "nothing but the ASL file format (and the effect names of truth.json)",
    }
