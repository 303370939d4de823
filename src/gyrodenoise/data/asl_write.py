"""Write a sequence in the ASL (EuRoC) folder layout that the readers take, atomically.

The simulator and the rosbag import write through here; the test world keeps its own writer on purpose (it
shares only the file format with the rest of gyrodenoise). Values are written with `repr` (the shortest text
that reads back to the same float64), stamps as integer nanoseconds, quaternions w, x, y, z (ASL order).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
GT_HEADER = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
IMU_FILE = Path("mav0/imu0/data.csv")
GT_FILE = Path("mav0/state_groundtruth_estimate0/data.csv")


def write_csv(path: Path, header: str, t_ns: np.ndarray, values: np.ndarray) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(header + "\n")
        for t, row in zip(t_ns.tolist(), values.tolist(), strict=True):
            fh.write(str(t) + "," + ",".join(repr(v) for v in row) + "\n")


def pose_values(pos: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """(N, 7) ground-truth columns p_x, p_y, p_z, q_w, q_x, q_y, q_z, with w >= 0 (q and -q are one rotation)."""
    q = quat_xyzw * np.where(quat_xyzw[:, 3:] < 0, -1.0, 1.0)
    return np.concatenate([pos, q[:, 3:], q[:, :3]], 1)


def asl_written(folder: Path, with_groundtruth: bool = True) -> bool:
    """Whether `write_sequence` has put a sequence at `folder` (it renames a whole copy into place)."""
    return all((folder / f).is_file() for f in ((IMU_FILE, GT_FILE) if with_groundtruth else (IMU_FILE,)))


def write_sequence(
    folder: str | Path,
    t_ns: np.ndarray,
    imu: np.ndarray,
    gt_t_ns: np.ndarray | None = None,
    gt: np.ndarray | None = None,
    extra_files: dict[str, str] | None = None,
    keep_existing: bool = False,
) -> Path:
    """<folder>/mav0/imu0/data.csv (t, gyro rad/s, acc m/s^2: `imu` is (N, 6)), the ground truth's
    <folder>/mav0/state_groundtruth_estimate0/data.csv when given (`gt` is (M, 7), see `pose_values`) and
    `extra_files` ({name: text}) beside mav0.

    The folder is assembled under a temporary name beside it and renamed into place, so a reader never sees a
    half-written sequence. An existing sequence is replaced, unless `keep_existing` and another process wrote one
    meanwhile (the same settings: the same content)."""
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.tmp"))
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(tmp, 0o777 & ~mask)  # mkdtemp makes 0700: others sharing the cache could not read the sequence
    with_gt = gt is not None
    try:
        for rel, header, stamps, values in ((IMU_FILE, IMU_HEADER, t_ns, imu), (GT_FILE, GT_HEADER, gt_t_ns, gt)):
            if values is not None:
                (tmp / rel).parent.mkdir(parents=True)
                write_csv(tmp / rel, header, stamps, values)
        for name, text in (extra_files or {}).items():
            (tmp / name).write_text(text, encoding="utf-8")
        if keep_existing and asl_written(folder, with_gt):
            return folder
        if folder.exists():
            shutil.rmtree(folder, ignore_errors=True)
        try:
            os.replace(tmp, folder)
        except OSError:  # ENOTEMPTY/EEXIST: another process renamed its copy in first
            if not (keep_existing and asl_written(folder, with_gt)):
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return folder
