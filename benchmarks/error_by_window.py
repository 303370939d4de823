"""Where along a flight does a model's attitude error arise? Orientation error per window (reports/accuracy.md).

    python benchmarks/error_by_window.py --models euroc euroc-calibrated \\
        --seqs MH_01_easy MH_02_easy V2_02_medium --window 10

For each EuRoC sequence and each model, the open-loop estimate's relative orientation error over
consecutive windows of `--window` seconds (the error made inside the window when integration starts on
ground truth at its beginning; windows are independent of what came before), beside what the body was
doing: the largest tilt of the body from its usual attitude on the flight (the angle between the world's
vertical in the body frame and its median direction) and the RMS angular rate. Models are shipped names or
model files (LABEL=FILE names a file's column). --level-gravity adds, for each model, the counterfactual
input with the gravity part of the accelerometer at its usual body direction (does the model fail on a
tilt?). Writes --out .md, .json, .png (default benchmarks/results/error_by_window). CPU only; ~5 s per
model and flight.
"""

from __future__ import annotations

import argparse
import math
import platform
import time
from pathlib import Path

import hydra
import numpy as np

from gyrodenoise import plots
from gyrodenoise.atomic import write_json, write_text
from gyrodenoise.config import compose_config
from gyrodenoise.models.denoiser import predict_gyro
from gyrodenoise.pretrained import load_model
from gyrodenoise.so3 import integrate_gyro, relative_rotvec
from gyrodenoise.tables import markdown_table

GRAVITY = 9.81  # m/s^2: only its direction matters here (the median is taken of the same vector)


def window_bounds(t: np.ndarray, window_s: float) -> list[tuple[int, int]]:
    """(start, end) sample indices of consecutive windows; a last partial window shorter than half is dropped."""
    edges = np.arange(t[0], t[-1] + 1e-9, window_s)
    idx = np.searchsorted(t, edges)
    out = [(int(a), int(b)) for a, b in zip(idx[:-1], idx[1:], strict=True)]
    if t[-1] - edges[-1] >= window_s / 2:
        out.append((int(idx[-1]), len(t) - 1))
    return out


def window_errors(R_gt: np.ndarray, R_est: np.ndarray, bounds: list[tuple[int, int]]) -> np.ndarray:
    """Relative orientation error (deg) of R_est over each window."""
    s, e = np.array(bounds).T
    T = np.swapaxes
    dR_gt = T(R_gt[s], -1, -2) @ R_gt[e]
    dR_est = T(R_est[s], -1, -2) @ R_est[e]
    return np.degrees(np.linalg.norm(relative_rotvec(dR_gt, dR_est), axis=-1))


def world_up_in_body(seq) -> np.ndarray:
    """(N, 3) unit vector of the world's vertical in the body frame (ground-truth attitude)."""
    return seq.rot[:, 2, :]  # R^T e_z: the third row of the body-to-world rotation


def motion(seq, bounds: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Per window: the largest tilt from the flight's median attitude (deg) and the RMS gyro rate (deg/s)."""
    up = world_up_in_body(seq)
    ref = np.median(up, axis=0)
    tilt = np.degrees(np.arccos(np.clip(up @ (ref / np.linalg.norm(ref)), -1.0, 1.0)))
    rate = np.degrees(np.linalg.norm(seq.gyro, axis=1))
    return (
        np.array([tilt[a:b].max() for a, b in bounds]),
        np.array([math.sqrt(np.mean(rate[a:b] ** 2)) for a, b in bounds]),
    )


def gravity_levelled(seq) -> np.ndarray:
    """The IMU input with the gravity part of the accelerometer moved to its median body direction on the flight
    (ground-truth attitude; the dynamic acceleration is kept): what the network would read at its usual tilt."""
    g_body = GRAVITY * world_up_in_body(seq)
    imu = seq.imu.copy()
    imu[:, 3:] += np.median(g_body, axis=0) - g_body
    return imu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--models",
        nargs="+",
        default=["euroc", "euroc-calibrated"],
        help="shipped names or model files, each optionally LABEL=MODEL",
    )
    ap.add_argument("--seqs", nargs="+", default=["MH_01_easy", "MH_02_easy", "V2_02_medium"])
    ap.add_argument("--window", type=float, default=10.0, help="window length in s (default: %(default)s)")
    ap.add_argument(
        "--level-gravity",
        action="store_true",
        help="also run each model on the input with gravity at its usual body direction (a counterfactual)",
    )
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/error_by_window"))
    args = ap.parse_args()
    start = time.time()
    dm = hydra.utils.instantiate(compose_config("train", ["dataset=euroc"]).dataset)
    models = {}
    for arg in args.models:
        label, _, name = arg.rpartition("=")
        models[label or name] = load_model(name)[0]
    result = {
        "command": "python benchmarks/error_by_window.py --models "
        + " ".join(args.models)
        + " --seqs "
        + " ".join(args.seqs)
        + f" --window {args.window:g}"
        + (" --level-gravity" if args.level_gravity else ""),
        "machine": f"{platform.node()} ({platform.machine()}, CPU)",
        "sequences": {},
    }
    fig, axs = plots.subplots(len(args.seqs), 1, figsize=(9, 2.8 * len(args.seqs)), squeeze=False)
    lines = []
    for seq_name, ax in zip(args.seqs, axs[:, 0], strict=True):
        seq = dm.load(seq_name)
        bounds = window_bounds(seq.t, args.window)
        tilt, rate = motion(seq, bounds)
        errs = {}
        inputs = {"": seq.imu} | ({" (gravity levelled)": gravity_levelled(seq)} if args.level_gravity else {})
        for name, model in models.items():
            for suffix, imu in inputs.items():
                R = integrate_gyro(seq.rot[0], predict_gyro(model, imu).numpy(), seq.dt)
                errs[name + suffix] = window_errors(seq.rot, R, bounds)
        t0 = [float(seq.t[a]) for a, _ in bounds]
        result["sequences"][seq_name] = {
            "window_start_s": t0,
            "tilt_max_deg": tilt.tolist(),
            "rate_rms_deg_s": rate.tolist(),
            "error_deg": {n: e.tolist() for n, e in errs.items()},
        }
        header = ["window (s)", "tilt max (deg)", "rate RMS (deg/s)", *[f"{n} (deg)" for n in errs]]
        rows = []
        for i, a in enumerate(t0):
            motion_cells = [f"{a:.0f}-{a + args.window:.0f}", f"{tilt[i]:.0f}", f"{rate[i]:.0f}"]
            rows.append(motion_cells + [f"{e[i]:.2f}" for e in errs.values()])
        lines += [f"## {seq_name}", "", markdown_table(header, rows)]
        width = args.window / (len(errs) + 1)
        for j, (n, e) in enumerate(errs.items()):
            ax.bar(np.array(t0) + (j + 0.5) * width, e, width=width, label=n, align="edge")
        ax.set_ylabel("error in window (deg)")
        ax.set_title(seq_name, fontsize=10)
        ax2 = ax.twinx()
        ax2.plot(np.array(t0) + args.window / 2, tilt, "k.-", lw=1, label="tilt max")
        ax2.set_ylabel("tilt max (deg)")
        ax.legend(loc="upper left", fontsize=7)
    axs[-1, 0].set_xlabel("window start (s)")
    fig.tight_layout()
    plots.save(fig, args.out.with_suffix(".png"), dpi=100)
    result["wall_s"] = time.time() - start
    head = [
        f"# Orientation error per {args.window:g}-s window",
        "",
        f"`{result['command']}` on {result['machine']}, {result['wall_s']:.0f} s. Error: relative orientation "
        "error over the window (integration restarted on ground truth at its start). Tilt: largest angle of "
        "the body from its median attitude on the flight. Rate: RMS of the raw gyro norm.",
        "",
        f"![per-window error]({args.out.with_suffix('.png').name})",
        "",
    ]
    write_text(args.out.with_suffix(".md"), "\n".join(head + lines))
    write_json(args.out.with_suffix(".json"), result)


if __name__ == "__main__":
    main()
