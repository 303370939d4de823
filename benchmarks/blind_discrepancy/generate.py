"""Independent IMU + motion-capture data generator for blind tests of the discrepancy workflow.

Standalone on purpose: numpy and scipy only, nothing from gyrodenoise, so the data source is not one the project
made. It writes EuRoC/TUM-VI style ASL folders:

    ROOT/<seq>/mav0/imu0/data.csv    200 Hz: t [ns], w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]
    ROOT/<seq>/mav0/mocap0/data.csv  120 Hz: t [ns], p_x, p_y, p_z [m], q_w, q_x, q_y, q_z

Conventions: R maps the IMU (body) frame to the world frame (z up, gravity -9.81 m/s^2 along z); the gyro measures the
body-frame rate; the accelerometer the body-frame specific force R^T (a - g).

Motion (hand-held / slow-drone like): position and ZYX Euler angles are degree-5 B-splines on a 0.25 s knot grid whose
coefficients are mean-reverting random walks; still periods (1.5-3 s) hold the coefficients constant, so the body is
exactly at rest there. Body rates and accelerations come from the splines' analytic derivatives.

Sensor, the known (baseline) error model, per sequence: a turn-on gyro bias, a gyro bias random walk, gyro white
noise; accelerometer bias and white noise. The gyro and accelerometer are the mean of the true signal over a window
of one sample period centred on the stamp (anti-alias, zero delay).

Motion capture, its own clock and phase: 120 Hz, white position (0.2 mm) and orientation (0.05 deg) noise, quaternions
written in the w >= 0 hemisphere (sign flips in the stream, as some mocap systems write them); it starts 0.3 s after
and ends 0.3 s before the IMU.

Hidden effects (one per trial, ``HiddenEffect``, or several at once in the compound trials): see ``make_sequence``
and ``TRIALS``.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.interpolate import BSpline
from scipy.spatial.transform import Rotation

G = 9.80665
DEG = np.pi / 180.0
IMU_HZ = 200.0
MOCAP_HZ = 120.0
OVERSAMPLE = 10  # fine points per IMU period for the centred anti-alias mean

# The known (baseline) sensor model: what a datasheet/calibration would give the simulator.
BASELINE = {
    "gyro_noise_density_rad_s_sqrtHz": 2.0e-4,
    "gyro_bias_rw_rad_s2_sqrtHz": 2.0e-5,
    "gyro_turn_on_bias_std_rad_s": 5.0e-3,
    "acc_noise_density_m_s2_sqrtHz": 2.0e-3,
    "acc_turn_on_bias_std_m_s2": 0.05,
    "mocap_pos_noise_m": 2.0e-4,
    "mocap_rot_noise_deg": 0.05,
}


# ----------------------------------------------------------------------------------------------------- motion


def _coeff_walk(rng, n, step, revert, still_mask, clip=None):
    """Mean-reverting random walk of n spline coefficients, held constant where still_mask is True."""
    c = np.zeros(n)
    for i in range(1, n):
        if still_mask[i]:
            c[i] = c[i - 1]
            continue
        c[i] = (1.0 - revert) * c[i - 1] + step * rng.standard_normal()
        if clip is not None:
            c[i] = np.clip(c[i], -clip, clip)
    return c


@dataclass
class Motion:
    pos: list  # three BSplines (world position, m)
    eul: list  # three BSplines (yaw, pitch, roll, rad), R = Rz(yaw) Ry(pitch) Rx(roll)
    t_end: float
    still: list = field(default_factory=list)  # (t0, t1) still intervals

    def rotation(self, t):
        yaw, pitch, roll = (s(t) for s in self.eul)
        return Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], axis=-1))

    def body_rate(self, t):
        yaw, pitch, roll = (s(t) for s in self.eul)
        dy, dp, dr = (s.derivative()(t) for s in self.eul)
        wx = dr - dy * np.sin(pitch)
        wy = dp * np.cos(roll) + dy * np.sin(roll) * np.cos(pitch)
        wz = -dp * np.sin(roll) + dy * np.cos(roll) * np.cos(pitch)
        return np.stack([wx, wy, wz], axis=-1)

    def position(self, t):
        return np.stack([s(t) for s in self.pos], axis=-1)

    def specific_force(self, t):
        acc_w = np.stack([s.derivative(2)(t) for s in self.pos], axis=-1)
        acc_w[:, 2] += G  # a - g with g = (0, 0, -G)
        return self.rotation(t).inv().apply(acc_w)


def make_motion(rng, duration_s, knot_dt=0.25, margin_s=2.0):
    """Hand-held-like motion over [-margin, duration + margin] seconds."""
    k = 5
    n = int(np.ceil((duration_s + 2 * margin_s) / knot_dt)) + k + 1
    knots = -margin_s + knot_dt * (np.arange(n + k + 1) - k)
    # still periods: hold >= k+1 consecutive coefficients
    still = np.zeros(n, bool)
    intervals = []
    t = 3.0 + rng.uniform(0, 4)
    while t < duration_s - 4:
        length = rng.uniform(1.5, 3.0)
        i0 = int(np.searchsorted(knots, t))
        i1 = i0 + int(np.ceil(length / knot_dt)) + k
        still[i0 + 1 : i1 + 1] = True
        # the spline is constant where all k+1 active coefficients are equal
        intervals.append((float(knots[i0 + k]), float(knots[i1 + 1])))
        t += length + rng.uniform(8, 15)
    yaw = _coeff_walk(rng, n, 0.35, 0.0, still) + rng.uniform(-np.pi, np.pi)
    pitch = _coeff_walk(rng, n, 0.22, 0.15, still, clip=0.9)
    roll = _coeff_walk(rng, n, 0.22, 0.15, still, clip=0.9)
    pos = [_coeff_walk(rng, n, 0.18, 0.08, still) + c for c in (0.0, 0.0, 1.2)]
    mk = lambda c: BSpline(knots, c, k, extrapolate=False)  # noqa: E731
    return Motion(pos=[mk(c) for c in pos], eul=[mk(yaw), mk(pitch), mk(roll)], t_end=duration_s, still=intervals)


def window_mean(fun, t, dt):
    """Mean of fun over [t - dt/2, t + dt/2] (midpoint rule, OVERSAMPLE points)."""
    offs = (np.arange(OVERSAMPLE) + 0.5) / OVERSAMPLE * dt - dt / 2
    tt = (t[:, None] + offs[None, :]).ravel()
    v = fun(tt)
    return v.reshape(len(t), OVERSAMPLE, -1).mean(axis=1)


# ----------------------------------------------------------------------------------------------------- hidden


@dataclass
class HiddenEffect:
    """One effect the baseline model does not have. kind and params as in TRIALS."""

    kind: str
    params: dict


RATE_EFFECTS = ("sensor_lowpass", "scale_asymmetry", "nonlinearity_even")  # each replaces the sensed rate: one at most


def hidden_effects(hidden: HiddenEffect | tuple | None) -> dict:
    """kind -> params of a trial's hidden effect(s): one HiddenEffect, a tuple of them (a compound trial) or None.
    Compound trials apply them in the sensor's order (`make_sequence`); a kind twice, or two effects that each
    replace the sensed rate, are refused."""
    items = () if hidden is None else (hidden,) if isinstance(hidden, HiddenEffect) else tuple(hidden)
    kinds = [h.kind for h in items]
    if len(set(kinds)) < len(kinds) or sum(k in RATE_EFFECTS for k in kinds) > 1:
        raise ValueError(f"hidden effects {kinds}: a kind twice, or more than one of {RATE_EFFECTS}")
    return {h.kind: h.params for h in items}


def answer_key_hidden(hidden: HiddenEffect | tuple | None) -> dict | list | None:
    """The answer key's `hidden`: {kind, params} for one effect (as before compound trials), a list for several."""
    if hidden is None:
        return None
    if isinstance(hidden, HiddenEffect):
        return {"kind": hidden.kind, "params": hidden.params}
    return [{"kind": h.kind, "params": h.params} for h in hidden]


def temperature(t, t_on, tau_s, delta_k, osc_k, osc_period_s, phase):
    """A warming-up board: exponential approach plus a slow oscillation (air flow), kelvin above start."""
    return delta_k * (1 - np.exp(-(t + t_on) / tau_s)) + osc_k * np.sin(2 * np.pi * t / osc_period_s + phase)


def lowpassed_gyro(fun, rng, t, dt, corner_hz, noise_density, warmup_s=1.5):
    """A gyro whose sense signal (true rate + white noise) passes a continuous first-order low-pass of corner
    corner_hz before the sample mean (a MEMS digital low-pass: the noise floor is shaped too). The filter is
    discretised exactly for a signal linear between the fine points (scipy's first-order hold) on the window_mean
    grid, started warmup_s early (the motion starts 2 s before the record); the white noise is drawn on that grid so
    that, unfiltered, its sample mean has the baseline's level noise_density sqrt(IMU_HZ)."""
    h = dt / OVERSAMPLE
    n_warm = int(round(warmup_s / h))
    grid = t[0] - dt / 2 + (np.arange(-n_warm, len(t) * OVERSAMPLE) + 0.5) * h
    u = fun(grid) + noise_density * np.sqrt(IMU_HZ * OVERSAMPLE) * rng.standard_normal((len(grid), 3))
    wc = 2 * np.pi * corner_hz
    b, a, _ = signal.cont2discrete(([wc], [1.0, wc]), h, method="foh")
    b = np.ravel(b)
    zi = signal.lfilter_zi(b, a)[:, None] * u[:1]
    y = signal.lfilter(b, a, u, axis=0, zi=zi)[0][n_warm:]
    return y.reshape(len(t), OVERSAMPLE, 3).mean(axis=1)


def vibration(rng, t, f0_hz, wander_hz, amp_rad_s):
    """A band-limited line: a carrier whose frequency wanders slowly by +-wander_hz around f0_hz (motor speed),
    amplitude slowly modulated +-20 %, independent phase per axis. amp_rad_s: the three axes' peak amplitudes."""
    fw = rng.uniform(0.05, 0.15)
    f = f0_hz + wander_hz * np.sin(2 * np.pi * fw * t + rng.uniform(0, 2 * np.pi))
    phase = 2 * np.pi * np.cumsum(f) * np.gradient(t)
    am = 1 + 0.2 * np.sin(2 * np.pi * 0.07 * t + rng.uniform(0, 2 * np.pi))
    amp = np.asarray(amp_rad_s, float)
    return np.stack([amp[i] * am * np.cos(phase + rng.uniform(0, 2 * np.pi)) for i in range(3)], axis=-1)


# ----------------------------------------------------------------------------------------------------- writing


def _write_csv(path, header, t_ns, values, fmt):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as f:
        f.write(header + "\n")
        for ti, row in zip(t_ns, values, strict=True):
            f.write(f"{ti}," + ",".join(fmt % v for v in row) + "\n")


IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
MOCAP_HEADER = "#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []"


def make_sequence(out_dir: Path, seed: int, duration_s: float, hidden: HiddenEffect | tuple | None) -> dict:
    """Write one sequence; return what was drawn (baseline values and motion statistics)."""
    rng = np.random.default_rng(seed)
    motion = make_motion(rng, duration_s)
    dt = 1.0 / IMU_HZ
    n = int(round(duration_s * IMU_HZ))
    t = np.arange(n) * dt  # true measurement times of the samples
    stamp_t = t.copy()  # what the IMU writes as their time
    t0_ns = int(1_600_000_000_000_000_000 + rng.integers(0, 10**15))
    b = BASELINE

    effects = hidden_effects(hidden)
    t_meas = t
    if "time_offset" in effects:
        # The sample stamped t_k was measured at t_k - delay: IMU stamps late by delay_ms against the mocap.
        t_meas = t - effects["time_offset"]["imu_stamp_late_ms"] * 1e-3

    w_true = window_mean(motion.body_rate, t_meas, dt)
    f_true = window_mean(motion.specific_force, t_meas, dt)

    # baseline gyro: turn-on bias + bias random walk + white noise
    b0 = b["gyro_turn_on_bias_std_rad_s"] * rng.standard_normal(3)
    rw = np.cumsum(b["gyro_bias_rw_rad_s2_sqrtHz"] * np.sqrt(dt) * rng.standard_normal((n, 3)), axis=0)
    wn = b["gyro_noise_density_rad_s_sqrtHz"] * np.sqrt(IMU_HZ) * rng.standard_normal((n, 3))
    ab0 = b["acc_turn_on_bias_std_m_s2"] * rng.standard_normal(3)
    an = b["acc_noise_density_m_s2_sqrtHz"] * np.sqrt(IMU_HZ) * rng.standard_normal((n, 3))

    gmat = None
    if "g_sensitivity" in effects:
        gmat = np.asarray(effects["g_sensitivity"]["matrix_deg_s_per_g"], float) * DEG / G  # rad/s per m/s^2
    w_sensed = w_true.copy()
    extra = np.zeros((n, 3))
    drawn: dict = {}
    # the effects of the instantaneous rate (at most one of them: checked by hidden_effects)
    if "sensor_lowpass" in effects:  # the rate, the g-sensitivity and the white noise through the sensor's low-pass
        sensed = motion.body_rate
        if gmat is not None:  # the sensing element's g-sensitivity passes the filter with the rate
            sensed = lambda tt: motion.body_rate(tt) + motion.specific_force(tt) @ gmat.T  # noqa: E731
        corner = effects["sensor_lowpass"]["corner_hz"]
        w_sensed = lowpassed_gyro(sensed, rng, t_meas, dt, corner, b["gyro_noise_density_rad_s_sqrtHz"])
        wn = np.zeros((n, 3))
    elif "scale_asymmetry" in effects:  # scale factor +a on positive rates, -a on negative ones, before the sample mean
        a = np.asarray(effects["scale_asymmetry"]["asymmetry_ppm"], float) * 1e-6
        w_sensed = window_mean(lambda tt: (w := motion.body_rate(tt)) + a * np.abs(w), t_meas, dt)
    elif "nonlinearity_even" in effects:  # an even quadratic error k w^2 of the instantaneous rate, before the mean
        k = np.asarray(effects["nonlinearity_even"]["k_ppm_per_deg_s"], float) * 1e-6 / DEG  # per rad/s
        w_sensed = window_mean(lambda tt: (w := motion.body_rate(tt)) + k * w**2, t_meas, dt)
    # linear in the sensed rate (behind a low-pass they scale its noise too: 0.3 % at most, below the noise fit's SE)
    if "misalignment" in effects:
        m = np.asarray(effects["misalignment"]["matrix_mrad"], float) * 1e-3
        w_sensed = w_sensed @ (np.eye(3) + m).T
    if "scale_factor" in effects:
        w_sensed = w_sensed * (1.0 + np.asarray(effects["scale_factor"]["scale_ppm"], float) * 1e-6)
    # added to the sensed rate (behind a low-pass the g-sensitivity went through it above)
    if gmat is not None and "sensor_lowpass" not in effects:
        extra = extra + f_true @ gmat.T
    if "vibration" in effects:
        p = effects["vibration"]
        extra = extra + vibration(rng, t, p["f0_hz"], p["wander_hz"], p["amp_rad_s"])
    if "temperature_drift" in effects:
        p = effects["temperature_drift"]
        t_on = rng.uniform(*p["t_on_range_s"])
        temp = temperature(t, t_on, p["tau_s"], p["delta_k"], p["osc_k"], p["osc_period_s"], rng.uniform(0, 6.28))
        extra = extra + np.outer(temp, np.asarray(p["coeff_deg_s_per_k"]) * DEG)
        drawn["t_on_s"] = float(t_on)
        drawn["bias_change_rad_s"] = (extra[-1] - extra[0]).tolist()

    gyro = w_sensed + b0 + rw + wn + extra
    acc = f_true + ab0 + an
    if "saturation" in effects:  # the output register's full scale: every sample beyond it reads the full-scale value
        lim = effects["saturation"]["range_deg_s"] * DEG
        gyro = np.clip(gyro, -lim, lim)
    if "quantization" in effects:
        p = effects["quantization"]
        gyro = np.round(gyro / p["gyro_lsb_rad_s"]) * p["gyro_lsb_rad_s"]
        acc = np.round(acc / p["acc_lsb_m_s2"]) * p["acc_lsb_m_s2"]

    imu_ns = t0_ns + np.round(stamp_t * 1e9).astype(np.int64)
    _write_csv(out_dir / "mav0" / "imu0" / "data.csv", IMU_HEADER, imu_ns, np.hstack([gyro, acc]), "%.10g")

    # motion capture: own phase, 120 Hz, inside the IMU span
    phase = rng.uniform(0, 1 / MOCAP_HZ)
    tm = np.arange(0.3 + phase, duration_s - 0.3, 1 / MOCAP_HZ)
    rot = motion.rotation(tm)
    noise = Rotation.from_rotvec(b["mocap_rot_noise_deg"] * DEG * rng.standard_normal((len(tm), 3)))
    q = (rot * noise).as_quat()  # x, y, z, w (scipy)
    q = np.where(q[:, 3:4] < 0, -q, q)  # w >= 0 hemisphere
    pos = motion.position(tm) + b["mocap_pos_noise_m"] * rng.standard_normal((len(tm), 3))
    mocap_ns = t0_ns + np.round(tm * 1e9).astype(np.int64)
    _write_csv(
        out_dir / "mav0" / "mocap0" / "data.csv",
        MOCAP_HEADER,
        mocap_ns,
        np.hstack([pos, q[:, [3, 0, 1, 2]]]),
        "%.9f",
    )
    rate = np.linalg.norm(w_true, axis=1)
    return {
        "seed": seed,
        "gyro_turn_on_bias_rad_s": b0.tolist(),
        "rate_rms_rad_s": float(np.sqrt(np.mean(rate**2))),
        "rate_max_rad_s": float(rate.max()),
        "still_intervals_s": motion.still,
        "tilt_max_deg": float(np.degrees(np.arccos(np.clip(motion.rotation(t).apply([0, 0, 1.0])[:, 2], -1, 1)).max())),
        **drawn,
    }


# ----------------------------------------------------------------------------------------------------- trials

# One effect hidden per trial (plus a null). Values in datasheet-like units; the generator converts to SI.
TRIALS = {
    "null": None,
    "g_sensitivity": HiddenEffect(
        "g_sensitivity",
        {"matrix_deg_s_per_g": [[0.04, 0.01, 0.0], [-0.01, -0.03, 0.015], [0.0, 0.02, 0.05]]},
    ),
    "time_offset": HiddenEffect("time_offset", {"imu_stamp_late_ms": 4.0}),
    "misalignment": HiddenEffect(
        "misalignment",
        {"matrix_mrad": [[0.0, 3.0, -2.0], [1.5, 0.0, 2.5], [-2.5, 1.0, 0.0]]},
    ),
    "vibration": HiddenEffect("vibration", {"f0_hz": 41.0, "wander_hz": 0.8, "amp_rad_s": [0.010, 0.006, 0.012]}),
    "quantization": HiddenEffect(
        "quantization", {"gyro_lsb_rad_s": 2000.0 / 32768 * DEG, "acc_lsb_m_s2": 16 * G / 32768}
    ),
    "temperature_drift": HiddenEffect(
        "temperature_drift",
        {
            "coeff_deg_s_per_k": [0.008, -0.006, 0.010],
            "tau_s": 120.0,
            "delta_k": 10.0,
            "t_on_range_s": [0.0, 60.0],
            "osc_k": 0.5,
            "osc_period_s": 45.0,
        },
    ),
    # added after the first blind run (benchmarks/results/blind_discrepancy.md), at the end so that the trials above
    # keep their seeds: the other side of the time-offset trial (a low-pass of about the same delay), offsets of
    # other sizes
    "time_offset_2ms": HiddenEffect("time_offset", {"imu_stamp_late_ms": 2.0}),
    "time_offset_8ms": HiddenEffect("time_offset", {"imu_stamp_late_ms": 8.0}),
    "sensor_lowpass_40hz": HiddenEffect("sensor_lowpass", {"corner_hz": 40.0}),
    "sensor_lowpass_25hz": HiddenEffect("sensor_lowpass", {"corner_hz": 25.0}),
    # added at session 44, at the end (the trials above keep their seeds): effects the workflow models that no blind
    # trial had hidden. Saturation at the smallest range of a BMI160 (+-125 deg/s): the hand-held motion goes beyond
    # it on some axis in every sequence (tens to hundreds of samples)
    "scale_factor": HiddenEffect("scale_factor", {"scale_ppm": [3000.0, -2000.0, 4000.0]}),
    "saturation": HiddenEffect("saturation", {"range_deg_s": 125.0}),
    # added at session 45, at the end (the trials above keep their seeds): a scale factor that differs between
    # positive and negative rates, +a and -a (so no symmetric scale-factor error beside it), an effect the
    # workflow's vocabulary did not have when the trial was written; run first on the vocabulary without it
    "scale_asymmetry": HiddenEffect("scale_asymmetry", {"asymmetry_ppm": [1500.0, -1000.0, 2500.0]}),
    # added at session 45 after it, at the end: the other even error, quadratic in the rate (k w^2), which the
    # independent test world showed named as a bias random walk by the vocabulary without it
    "nonlinearity_even": HiddenEffect("nonlinearity_even", {"k_ppm_per_deg_s": [20.0, -15.0, 30.0]}),
}

# Added at session 49, at the end (the trials above keep their seeds): several effects at once, as a real sensor has
# them, each with the values of its single trial above. Written, with the runner's verdict rule for them, before
# their first run.
_ONE = {k: v for k, v in TRIALS.items() if v is not None}
TRIALS |= {
    # the classic calibration errors together: a full 3x3 rate matrix and a g-sensitivity
    "calibration_triple": (_ONE["scale_factor"], _ONE["misalignment"], _ONE["g_sensitivity"]),
    # a delay beside an effect that is linear in the rate
    "time_offset_scale_factor": (_ONE["time_offset"], _ONE["scale_factor"]),
    # a low-pass shapes the noise in the g-sensitivity's rows (regression SEs under coloured noise)
    "lowpass_40hz_g_sensitivity": (_ONE["sensor_lowpass_40hz"], _ONE["g_sensitivity"]),
    # both ways a gyro lags the truth at once: the stamps and the sensor's filter
    "lowpass_40hz_time_offset": (_ONE["sensor_lowpass_40hz"], _ONE["time_offset"]),
    # a consumer MEMS gyro: filter, axes, scale, g-sensitivity and a 16-bit output at +-2000 deg/s
    "consumer_imu": (
        _ONE["sensor_lowpass_40hz"],
        _ONE["misalignment"],
        _ONE["scale_factor"],
        _ONE["g_sensitivity"],
        _ONE["quantization"],
    ),
}
# Added at session 50, at the end (the trials above keep their seeds): a low-pass well below the compared band's
# reach (a consumer gyro's slowest setting). Seen on a dev seed (11) before it was added: it was named as a 7.4 Hz
# low-pass with the stamps 5.5 ms early and a scale factor, as the sensor's floor was read from the base residual.
TRIALS |= {"sensor_lowpass_10hz": HiddenEffect("sensor_lowpass", {"corner_hz": 10.0})}


def make_trial(root: Path, trial: str, n_seqs: int, duration_s: float, seed: int) -> list[dict]:
    hidden = TRIALS[trial]
    drawn = []
    for i in range(n_seqs):
        name = f"seq{i:02d}"
        info = make_sequence(root / name, seed * 1000 + i, duration_s, hidden)
        drawn.append({"name": name, **info})
    return drawn


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder; one subfolder per trial")
    ap.add_argument("--trials", nargs="+", default=list(TRIALS), choices=list(TRIALS))
    ap.add_argument("--n-seqs", type=int, default=5)
    ap.add_argument("--duration", type=float, default=60.0, help="seconds per sequence")
    ap.add_argument("--seed", type=int, default=1, help="the k-th trial of TRIALS uses seed + k")
    a = ap.parse_args(argv)
    for trial in a.trials:
        root = a.out / trial
        drawn = make_trial(root, trial, a.n_seqs, a.duration, a.seed + list(TRIALS).index(trial))
        h = TRIALS[trial]
        key = {"trial": trial, "hidden": answer_key_hidden(h)}
        key["baseline"] = BASELINE
        key["sequences"] = drawn
        (root / "answer_key.json").write_text(json.dumps(key, indent=1))
        print(trial, root)


if __name__ == "__main__":
    main()
