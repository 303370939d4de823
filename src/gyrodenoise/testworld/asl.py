"""Minimal ASL (EuRoC) file reading and writing with numpy only: the file format is all the test world
shares with the rest of gyrodenoise.

A sequence is written into a hidden temporary folder beside the target and renamed into place, so
a reader never sees a half-written sequence.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

# header spelling of the EuRoC release files (imu0/data.csv, state_groundtruth_estimate0/data.csv)
IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
GT_HEADER = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []"


def read_asl_pose(path: str | Path) -> tuple[np.ndarray, np.ndarray, Rotation]:
    """ASL ground truth -> (t_ns int64, position (N, 3), rotation body->world). Columns past the 8th ignored.

    Time stamps are parsed as integers: float64 cannot hold 19-digit nanosecond stamps exactly."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: ground-truth file not found (expected <root>/<SEQ>/mav0/...)")
    t_ns = np.loadtxt(path, delimiter=",", comments="#", usecols=0, dtype=np.int64, ndmin=1)
    v = np.loadtxt(path, delimiter=",", comments="#", usecols=range(1, 8), dtype=np.float64, ndmin=2)
    if len(t_ns) < 10 or (np.diff(t_ns) <= 0).any():
        raise ValueError(f"{path}: need at least 10 poses with strictly increasing time stamps")
    q_wxyz = v[:, 3:7]
    return t_ns, v[:, :3], Rotation.from_quat(np.concatenate([q_wxyz[:, 1:], q_wxyz[:, :1]], axis=1))


def _rows(t_ns: np.ndarray, values: np.ndarray, fmt: str) -> str:
    body = "\n".join(f"{t}," + ",".join(fmt % x for x in row) for t, row in zip(t_ns.tolist(), values, strict=True))
    return body + "\n"


def imu_csv(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> str:
    # 17 significant digits: exact float64 round trip, so a quantisation lattice survives the file
    return IMU_HEADER + "\n" + _rows(t_ns, np.hstack([gyro, acc]), "%.17g")


def pose_csv(t_ns: np.ndarray, pos: np.ndarray, rot: Rotation) -> str:
    q = rot.as_quat(canonical=True)  # x y z w, w >= 0
    return GT_HEADER + "\n" + _rows(t_ns, np.hstack([pos, q[:, 3:], q[:, :3]]), "%.9f")


def write_sequence(out: Path, name: str, imu: str, groundtruth: str, truth: dict, overwrite: bool = False) -> Path:
    """<out>/<name>/{mav0/imu0/data.csv, mav0/state_groundtruth_estimate0/data.csv, truth.json}, atomically."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    final = out / name
    if final.exists() and not overwrite:
        raise FileExistsError(f"{final} exists; choose another --out or pass --overwrite")
    tmp = Path(tempfile.mkdtemp(dir=out, prefix=f".{name}."))
    try:
        (tmp / "mav0" / "imu0").mkdir(parents=True)
        (tmp / "mav0" / "state_groundtruth_estimate0").mkdir(parents=True)
        (tmp / "mav0" / "imu0" / "data.csv").write_text(imu, encoding="utf-8")
        (tmp / "mav0" / "state_groundtruth_estimate0" / "data.csv").write_text(groundtruth, encoding="utf-8")
        (tmp / "truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
        os.chmod(tmp, 0o755)  # mkdtemp makes 0700
        if final.exists():  # overwrite: move the old one aside first, so that the swap is two renames
            old = Path(tempfile.mkdtemp(dir=out, prefix=f".{name}.old."))
            os.replace(final, old / name)
            os.replace(tmp, final)
            shutil.rmtree(old)
        else:
            os.replace(tmp, final)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return final
