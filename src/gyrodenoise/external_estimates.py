"""Other methods' orientation estimates (a VIO's output, another denoiser's) scored beside the gyro methods.

    python -m gyrodenoise.evaluate dataset=euroc +estimates.okvis=runs/okvis            # runs/okvis/<sequence>.txt
    python -m gyrodenoise.evaluate dataset=euroc '+estimates.vins=runs/vins/*/traj.txt'   # * = the sequence

Each file is a TUM trajectory on the IMU's clock (`trajectory_files.read_tum`: absolute stamps in s or ns). Its
orientation is interpolated (SLERP) at the IMU stamps it spans, aligned on ground truth at the first of them that has
ground truth (the rule of every method in evaluate's table; the alignment is a rotation of the world frame, so a VIO's
own world frame is fine) and scored on the samples it covers. Samples inside a gap of the file (a lost track) are not
covered: SLERP across it would score an estimate the method never made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gyrodenoise.data.sequence import Sequence
from gyrodenoise.trajectory_files import TrajectoryFileError, read_tum

GAP_MIN_S = 0.5  # a step of the file longer than this and than GAP_STEPS of its median step is a gap
GAP_STEPS = 5


@dataclass
class ExternalEstimate:
    R: np.ndarray  # (N, 3, 3) body to world at the sequence's IMU stamps, aligned; identity where not covered
    covered: np.ndarray  # (N,) bool: the file has an estimate there
    file: Path
    rate_hz: float  # the file's median rate

    def mask(self, seq: Sequence) -> np.ndarray:
        """The samples it is scored on: covered and with ground truth."""
        return self.covered & seq.gt_mask

    def coverage(self, seq: Sequence) -> float:
        """Fraction of the sequence's ground-truth samples it is scored on."""
        return float(self.mask(seq).sum() / max(int(seq.gt_mask.sum()), 1))


def estimate_file(spec: str, sequence: str) -> Path:
    """The file of `sequence`: `spec` with its `*` replaced by the name, or `spec/<sequence>.txt` (a folder).
    (`*`, not a `{sequence}` field: Hydra's override grammar reads braces as a dict.)"""
    if "*" in spec:
        return Path(spec.replace("*", sequence))
    return Path(spec) / f"{sequence}.txt"


def check_names(estimates: dict[str, str], taken: tuple[str, ...]) -> None:
    """Method names that clash with the table's own, and specs that cannot name a file, fail before any work."""
    for name, spec in estimates.items():
        if name in taken:
            raise ValueError(
                f"estimates.{name}: {name!r} is one of evaluate's own methods {taken}; choose another name"
            )
        if not isinstance(spec, str) or not spec:
            raise ValueError(
                f"estimates.{name}={spec!r}: give a folder holding <sequence>.txt TUM files, or a path with "
                "a * for the sequence's name in it"
            )


def check_files(estimates: dict[str, str], sequences: list[str]) -> None:
    """Every method has a file for every sequence scored, or one error lists what is missing."""
    for name, spec in estimates.items():
        missing = dict.fromkeys(str(estimate_file(spec, s)) for s in sequences if not estimate_file(spec, s).is_file())
        if missing:
            raise FileNotFoundError(
                f"estimates.{name}: no file {', '.join(missing)} (a folder holds one <sequence>.txt TUM trajectory "
                "per sequence scored; or give a path with a * for the sequence's name in it)"
            )


def load_external(name: str, spec: str, seq: Sequence) -> ExternalEstimate:
    """Read, interpolate and align the estimate of method `name` for `seq` (see the module's doc)."""
    path = estimate_file(spec, seq.name)
    t_file, R_file = read_tum(path)
    t_imu = seq.t0_ns + np.round(seq.t * 1e9).astype(np.int64)
    steps = np.diff(t_file) / 1e9
    gap = max(GAP_MIN_S, GAP_STEPS * float(np.median(steps)))
    inside = (t_imu >= t_file[0]) & (t_imu <= t_file[-1])
    after = np.clip(np.searchsorted(t_file, t_imu), 1, len(t_file) - 1)  # the file's pose at or after each stamp
    covered = inside & (steps[after - 1] <= gap)
    first = np.flatnonzero(covered & seq.gt_mask)
    if len(first) == 0:
        span = f"{t_file[0] / 1e9:.3f}-{t_file[-1] / 1e9:.3f} s"
        seq_span = f"{t_imu[0] / 1e9:.3f}-{t_imu[-1] / 1e9:.3f} s"
        raise TrajectoryFileError(
            f"{path}: its stamps ({span}) cover none of {seq.name}'s samples with ground truth ({seq_span}): the "
            "stamps must be on the IMU's clock, absolute, in s or ns"
        )
    slerp = Slerp((t_file - t_file[0]) / 1e9, Rotation.from_matrix(R_file))
    R = np.repeat(np.eye(3)[None], len(seq), axis=0)
    R[covered] = slerp((t_imu[covered] - t_file[0]) / 1e9).as_matrix()
    k = first[0]
    R[covered] = seq.rot[k] @ R[k].T @ R[covered]  # the world frame turned so that it starts on ground truth
    return ExternalEstimate(R=R, covered=covered, file=path, rate_hz=1.0 / float(np.median(steps)))


def coverage_note(name: str, label: str, est: ExternalEstimate, seq: Sequence) -> str | None:
    """A table note when the estimate is scored on fewer samples than the other methods, else None."""
    share = est.coverage(seq)
    if share >= 1.0:
        return None
    return (
        f"{name} on {label}: scored on {100 * share:.1f}% of the samples with ground truth (the others lie outside "
        f"its file's span or in its gaps; {est.file.name}, {est.rate_hz:.3g} Hz)"
    )


def nan_outside(errors: tuple[np.ndarray, np.ndarray], covered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample errors with NaN where the estimate has no value (not drawn in the figures)."""
    return tuple(np.where(covered, e, math.nan) for e in errors)  # type: ignore[return-value]
