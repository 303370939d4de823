"""Does a dataset's ground truth follow its own gyro? Coherence of the ground truth's rate with the gyro.

The discrepancy workflow compares the gyro with the rate of the ground truth; that comparison only
shows the gyro's errors where the ground truth is independent of the gyro. A motion tracker (Vicon,
OptiTrack) is; a batch estimate that fuses the same IMU (EuRoC's `state_groundtruth_estimate0`)
is not, at the frequencies where the IMU dominates the estimate. This script measures it: per
sequence, the rate between consecutive ground-truth poses (finite rotation / dt) against the gyro
averaged over the same interval (exact integral of the linearly interpolated samples), and per
frequency band the magnitude-squared coherence of the two and the share of the gyro's power that
the ground truth reproduces (1 - PSD(gyro - truth) / PSD(gyro)).

Where the gyro sees motion no tracker resolves (a MAV's rotor vibration at 20-40 Hz: rotations of
hundredths of a milliradian), a coherence near 1 says the ground truth carries the gyro itself:
then the gyro's own noise and vibration are partly in the "truth", and a residual against it
underestimates them. Writes <out>/gt_gyro_coherence.{json,md}.

    python benchmarks/gt_gyro_coherence.py [--euroc ../shared/data/euroc] [--tumvi ../shared/data/tumvi]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.spatial.transform import Rotation

from gyrodenoise import atomic
from gyrodenoise.data.readers import find_groundtruth_file, read_groundtruth, read_imu
from gyrodenoise.paths import portable_command

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
BANDS_HZ = [(2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 80.0)]
NPERSEG_S = 2.5  # Welch segment


def _pairs(t_ns: np.ndarray, quat_xyzw: np.ndarray, imu) -> tuple[np.ndarray, np.ndarray, float]:
    """(gyro averaged over each ground-truth interval, truth's rate over it, truth rate in Hz) on the
    longest run of regular intervals inside the IMU record (ground-truth gaps end a run)."""
    dt = np.diff(t_ns) * 1e-9
    med = float(np.median(dt))
    rot = Rotation.from_quat(quat_xyzw)
    w_gt = (rot[:-1].inv() * rot[1:]).as_rotvec() / dt[:, None]
    ti = imu.t_ns
    step = np.diff(ti)[:, None] * 1e-9
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (imu.gyro[1:] + imu.gyro[:-1]) * step, 0)])
    a = np.stack([np.interp(t_ns[:-1], ti, cum[:, k]) for k in range(3)], 1)
    b = np.stack([np.interp(t_ns[1:], ti, cum[:, k]) for k in range(3)], 1)
    gyro = (b - a) / dt[:, None]
    ok = (np.abs(dt - med) < 0.1 * med) & (t_ns[:-1] >= ti[0]) & (t_ns[1:] <= ti[-1])
    idx = np.flatnonzero(ok)
    if len(idx) == 0:
        raise ValueError("no ground-truth interval inside the IMU record")
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    run = max(runs, key=len)
    return gyro[run], w_gt[run], 1.0 / med


def measure(mav0: Path) -> dict:
    imu = read_imu(mav0 / "imu0" / "data.csv")
    gt_path = find_groundtruth_file(mav0)
    gt = read_groundtruth(gt_path)
    gyro, truth, fs = _pairs(gt.t_ns, gt.quat_xyzw, imu)
    nper = min(int(NPERSEG_S * fs), len(gyro))
    f, coh = signal.coherence(gyro, truth, fs, nperseg=nper, axis=0)
    _, p_gyro = signal.welch(gyro - gyro.mean(0), fs, nperseg=nper, axis=0)
    _, p_res = signal.welch(gyro - truth - (gyro - truth).mean(0), fs, nperseg=nper, axis=0)
    bands = []
    for lo, hi in BANDS_HZ:
        m = (f >= lo) & (f < min(hi, 0.9 * fs / 2))
        if m.sum() < 2:
            continue
        # power-weighted over the band: where the gyro has content
        w = p_gyro[m] / p_gyro[m].sum(0)
        bands.append(
            {
                "band_hz": [lo, float(min(hi, 0.9 * fs / 2))],
                "coherence": (w * coh[m]).sum(0).tolist(),
                "reproduced_share": (1 - p_res[m].sum(0) / p_gyro[m].sum(0)).tolist(),
                "gyro_rms_rad_s": np.sqrt(p_gyro[m].sum(0) * (f[1] - f[0])).tolist(),
            }
        )
    return {
        "ground_truth": os.path.relpath(gt_path, ROOT),
        "truth_rate_hz": fs,
        "seconds": len(gyro) / fs,
        "bands": bands,
    }


def _sequences(root: Path | None) -> list[Path]:
    if root is None or not root.is_dir():
        return []
    return sorted(p.parent for p in root.glob("*/mav0/imu0"))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--euroc", type=Path, default=ROOT / ".." / "shared" / "data" / "euroc")
    p.add_argument("--tumvi", type=Path, default=ROOT / ".." / "shared" / "data" / "tumvi")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args()
    t0 = time.time()
    rows = {}
    for name, root in (("euroc", args.euroc), ("tumvi", args.tumvi)):
        for mav0 in _sequences(root):
            rows[f"{name}/{mav0.parent.name}"] = measure(mav0)
            print(mav0.parent.name, flush=True)
    if not rows:
        sys.exit(f"no sequences under {args.euroc} or {args.tumvi}: give --euroc / --tumvi")
    result = {
        "command": "python " + portable_command(sys.argv),
        "machine": f"{platform.node()} ({platform.machine()}, {os.cpu_count()} CPU threads)",
        "wall_time_s": time.time() - t0,
        "sequences": rows,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "gt_gyro_coherence.json", json.dumps(result, indent=2) + "\n")
    heads = [f"{lo:g}-{hi:g} Hz" for lo, hi in BANDS_HZ]
    lines = [
        "# Does the ground truth follow the gyro?",
        "",
        f"`{result['command']}` ({result['machine']}, {result['wall_time_s']:.0f} s). Method: the script's docstring.",
        "",
        "Per band: coherence of the ground truth's rate with the gyro (power-weighted over the band, per axis "
        "x/y/z) / the share of the gyro's power the ground truth reproduces (mean over axes; negative: the "
        "ground truth's own noise is larger than what the gyro sees). Bands above 90% of the ground truth's "
        "Nyquist frequency are left out.",
        "",
        "| sequence | ground truth | " + " | ".join(heads) + " |",
        "|---|---|" + "---|" * len(heads),
    ]
    for seq, r in rows.items():
        cells = {f"{b['band_hz'][0]:g}": b for b in r["bands"]}
        out = []
        for lo, _ in BANDS_HZ:
            b = cells.get(f"{lo:g}")
            if b is None:
                out.append("-")
            else:
                c = "/".join(f"{x:.2f}" for x in b["coherence"])
                out.append(f"{c} / {np.mean(b['reproduced_share']):+.2f}")
        lines.append(f"| {seq} | {r['truth_rate_hz']:.0f} Hz | " + " | ".join(out) + " |")
    lines += [
        "",
        "Reading: a motion tracker's orientation noise (tenths of a milliradian at best) hides the rotations a "
        "gyro sees at tens of Hz on a flying MAV; a ground truth whose rate is coherent with the gyro there "
        "carries the gyro itself (EuRoC's ground truth is a batch estimate fusing this IMU: see "
        "../shared/data/README.md). The discrepancy workflow's residual then underestimates the gyro's noise "
        "and vibration wherever the truth follows it.",
    ]
    atomic.write_text(args.out / "gt_gyro_coherence.md", "\n".join(lines) + "\n")
    print((args.out / "gt_gyro_coherence.md").read_text())


if __name__ == "__main__":
    main()
