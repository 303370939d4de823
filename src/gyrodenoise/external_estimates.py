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

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gyrodenoise.cli_errors import ConfigError
from gyrodenoise.data import consistency
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
            raise ConfigError(
                f"estimates.{name}: {name!r} is one of evaluate's own methods {taken}; choose another name"
            )
        if not isinstance(spec, str) or not spec:
            raise ConfigError(
                f"estimates.{name}={spec!r}: give a folder holding <sequence>.txt TUM files, or a path with "
                "a * for the sequence's name in it"
            )


def check_files(estimates: dict[str, str], recordings: list[str]) -> None:
    """Every method has a file for every recording scored, or one error lists what is missing."""
    for name, spec in estimates.items():
        if "*" not in spec and Path(spec).is_file():
            raise FileNotFoundError(
                f"estimates.{name}={spec} is a file: give the folder that holds one <sequence>.txt per sequence "
                f"({Path(spec).parent}), or a path with a * for the sequence's name ({Path(spec).parent}/*.txt)"
            )
        files = [estimate_file(spec, r) for r in recordings]
        missing = dict.fromkeys(str(f) for f in files if not f.is_file())
        if missing:
            raise FileNotFoundError(
                f"estimates.{name}: no file {', '.join(missing)} (a folder holds one <sequence>.txt TUM trajectory "
                "per sequence scored; or give a path with a * for the sequence's name in it)"
            )


def load_external(name: str, spec: str, seq: Sequence, recording: str | None = None) -> ExternalEstimate:
    """Read, interpolate and align the estimate of method `name` for `seq` (see the module's doc); the file is
    `recording`'s (the name of the recording `seq` is a part of; default its own name)."""
    path = estimate_file(spec, recording or seq.name)
    t_file, R_file = read_tum(path)
    t_imu = seq.t0_ns + np.round(seq.t * 1e9).astype(np.int64)
    steps = np.diff(t_file) / 1e9
    gap = max(GAP_MIN_S, GAP_STEPS * float(np.median(steps)))
    # an IMU stamp within half an IMU period of the file's ends is covered (stamps written to 1 us: not one
    # sample left out with a "99.99%" note)
    edge = int(0.5e9 * float(np.median(np.diff(seq.t)))) if len(seq) > 1 else 0
    inside = (t_imu >= t_file[0] - edge) & (t_imu <= t_file[-1] + edge)
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
    t_rel = np.clip(t_imu[covered], t_file[0], t_file[-1])  # the edge samples take the file's end poses
    R[covered] = slerp((t_rel - t_file[0]) / 1e9).as_matrix()
    k = first[0]
    R[covered] = seq.rot[k] @ R[k].T @ R[covered]  # the world frame turned so that it starts on ground truth
    return ExternalEstimate(R=R, covered=covered, file=path, rate_hz=1.0 / float(np.median(steps)))


def frame_problems(name: str, label: str, est: ExternalEstimate, seq: Sequence) -> list[str]:
    """What the gyro says of the file, as for a ground truth (`consistency`): its orientation must be the IMU's, on
    the IMU's clock. A camera's pose, another quaternion order or a clock offset score without complaint and
    mean nothing (an independent check: 92, 109 and 8 deg of AOE against exact trajectories)."""
    m = consistency.measure(dataclasses.replace(seq, rot=est.R, gt_mask=est.covered & seq.gt_mask))
    where = f"{name} on {label} ({est.file})"
    if consistency.clock_offset(m):  # rates compared at the wrong instants: the axes and scale below mean nothing
        return [
            f"{where}: the file's rotation matches the gyro's best {m.best_lag_s:+.3f} s away from its stamps "
            f"(correlation {m.corr_at_best:.2f} there, {m.corr_at_zero:.2f} at zero lag): its stamps are not on the "
            f"IMU's clock; add {m.best_lag_s:+.3f} s to them"
        ]
    out = []
    if m.mirrored or m.axes_angle_deg > consistency.AXES_MAX_DEG:
        angle = "a mirror image of" if m.mirrored else f"{m.axes_angle_deg:.0f} deg away from"
        out.append(
            f"{where}: the file's orientation turns about axes {angle} the gyro's: it is the pose of another body "
            "than the IMU (a camera: compose it with the camera-IMU extrinsic), or its quaternion is not x y z w "
            "(TUM order); its score means nothing"
        )
    if np.isfinite(m.rate_ratio) and not consistency.RATIO_RANGE[0] <= m.rate_ratio <= consistency.RATIO_RANGE[1]:
        out.append(f"{where}: the gyro turns {m.rate_ratio:.3g} times as fast as the file's orientation")
    return out


def coverage_note(name: str, label: str, est: ExternalEstimate, seq: Sequence) -> str | None:
    """A table note when the estimate is scored on fewer samples than the other methods, else None."""
    scored, total = int(est.mask(seq).sum()), int(seq.gt_mask.sum())
    if scored >= total:
        return None
    return (
        f"{name} on {label}: scored on {scored} of the {total} samples with ground truth ({100 * scored / total:.1f}"
        f"%; the others lie outside its file's span or in its gaps; {est.file.name}, {est.rate_hz:.3g} Hz)"
    )


def nan_outside(errors: tuple[np.ndarray, np.ndarray], covered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample errors with NaN where the estimate has no value (not drawn in the figures)."""
    return tuple(np.where(covered, e, math.nan) for e in errors)  # type: ignore[return-value]
