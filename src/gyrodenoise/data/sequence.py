"""A Sequence: IMU samples with ground-truth attitude at the IMU timestamps.

Building one from files: crop both streams to their common span, SLERP the ground-truth
orientation (and linearly interpolate position) at the IMU stamps, and mark the IMU samples that
fall in a ground-truth gap (TUM-VI mocap occlusions) as unavailable.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gyrodenoise.data.readers import GAP_FACTOR, DataFormatError, GroundTruthData, ImuData


@dataclass
class Sequence:
    name: str
    t0_ns: int  # absolute time of t = 0 (the first sample's, before any slice)
    t: np.ndarray  # (N,) float64 s since t0_ns
    gyro: np.ndarray  # (N, 3) rad/s
    acc: np.ndarray  # (N, 3) m/s^2
    rot: np.ndarray  # (N, 3, 3) ground-truth body-to-world rotation at each IMU stamp
    pos: np.ndarray  # (N, 3) ground-truth position (m)
    gt_mask: np.ndarray  # (N,) bool, ground truth available at this sample
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def imu(self) -> np.ndarray:
        """(N, 6) gyro then accelerometer, the network's input."""
        return np.concatenate([self.gyro, self.acc], axis=1)

    @property
    def t_ns(self) -> np.ndarray:
        """(N,) int64 ns stamps: t0_ns + t (exact for any recording under ~100 days: float64 s keeps the ns)."""
        return self.t0_ns + np.round(self.t * 1e9).astype(np.int64)

    @property
    def dt(self) -> np.ndarray:
        """(N,) dt_n = t_n - t_{n-1}; dt_0 repeats dt_1 (unused by integration)."""
        d = np.diff(self.t)
        return np.concatenate([d[:1], d])

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t)))

    def slice(self, start: int, stop: int, name: str | None = None) -> Sequence:
        """Samples [start, stop), time kept relative to the original start."""
        return Sequence(
            name=name or self.name,
            t0_ns=self.t0_ns,
            t=self.t[start:stop],
            gyro=self.gyro[start:stop],
            acc=self.acc[start:stop],
            rot=self.rot[start:stop],
            pos=self.pos[start:stop],
            gt_mask=self.gt_mask[start:stop],
            meta=dict(self.meta),
        )

    def from_first_ground_truth(self) -> Sequence:
        """The samples from the first one with ground truth on. Estimates are aligned on ground truth at their first
        instant: inside an occlusion that orientation is SLERP bridged across the gap, not measured."""
        if not self.gt_mask.any() or self.gt_mask[0]:
            return self
        return self.slice(int(np.argmax(self.gt_mask)), len(self))

    def index_at(self, seconds: float) -> int:
        """First sample index at or after `seconds` from the sequence start."""
        return int(np.searchsorted(self.t - self.t[0], seconds))


def gt_increments(seq: Sequence, step: int) -> tuple[np.ndarray, np.ndarray]:
    """dR_k = R_{k*step}^T R_{(k+1)*step} and its availability: ground truth at every sample of it, and no IMU gap
    inside (the gyro did not see the motion during a gap: a loss or a fit on such an increment learns that motion)."""
    n = (len(seq) - 1) // step
    R = seq.rot[: n * step + 1 : step]
    dR = np.swapaxes(R[:-1], -1, -2) @ R[1:]
    m = seq.gt_mask[: n * step + 1]
    dt = np.diff(seq.t)
    gap = dt[: n * step] > GAP_FACTOR * np.median(dt) if len(dt) else dt.astype(bool)
    ok = m[:-1].reshape(n, step).all(1) & m[step::step] & ~gap.reshape(n, step).any(1)
    return dR, ok


def _clock_hint(t_imu0_ns: int, t_gt0_ns: int) -> str:
    """What the first stamps of an IMU (ns, its rate checked by the reader) and of a ground truth that does not
    overlap it say: the truth's stamps in another unit (about 1e3, 1e6 or 1e9 times smaller), or counted from its
    own start while the IMU's are absolute. '' when they say neither."""
    if t_imu0_ns <= 0 or t_gt0_ns < 0:
        return ""
    if t_gt0_ns > 0:
        ratio = t_imu0_ns / t_gt0_ns
        for unit, factor in (("µs", 1e3), ("ms", 1e6), ("s", 1e9)):
            if 0.9 * factor < ratio < 1.1 * factor:
                return (
                    f" The ground truth's stamps are about {factor:.0e} times smaller than the IMU's: they look like "
                    f"{unit}; write them as integer ns (x {factor:.0e})."
                )
    if t_gt0_ns < 10**12 <= t_imu0_ns:  # under ~17 min against an absolute clock
        return (
            " The ground truth's stamps start near zero (time since its own start?) while the IMU's do not: put "
            "both on one clock (add the IMU's stamp at the truth's start to the truth's)."
        )
    return ""


def build_sequence(name: str, imu: ImuData, gt: GroundTruthData, max_gap_factor: float = 3.0) -> Sequence:
    """Align ground truth to the IMU stamps.

    A sample has ground truth when the ground-truth samples around it are at most
    `max_gap_factor` x the median ground-truth period apart; elsewhere SLERP would bridge an
    occlusion and the mask is False.
    """
    t_imu, t_gt = imu.t_ns, gt.t_ns
    if len(t_gt) < 2:
        raise DataFormatError(f"{gt.path}: fewer than 2 ground-truth samples.")
    lo, hi = max(t_imu[0], t_gt[0]), min(t_imu[-1], t_gt[-1])
    if hi <= lo:
        raise DataFormatError(
            f"{gt.path}: ground truth [{t_gt[0]}, {t_gt[-1]}] ns does not overlap the IMU "
            f"{imu.path} [{t_imu[0]}, {t_imu[-1]}] ns. Both must use the same clock (ns)."
            + _clock_hint(int(t_imu[0]), int(t_gt[0]))
        )
    keep = (t_imu >= lo) & (t_imu <= hi)
    if keep.sum() < 2:  # touching at one instant: not a sequence to integrate
        raise DataFormatError(
            f"{gt.path}: ground truth [{t_gt[0]}, {t_gt[-1]}] ns overlaps the IMU {imu.path} [{t_imu[0]}, {t_imu[-1]}] "
            f"ns in {int(keep.sum())} IMU sample(s) only. Both must use the same clock (ns) and cover the same motion."
            + _clock_hint(int(t_imu[0]), int(t_gt[0]))
        )
    t_ns = t_imu[keep]
    t0 = int(t_ns[0])
    # float64 seconds relative to a common origin: exact enough (sub-ns for hours)
    ts_imu = (t_ns - t0) * 1e-9
    ts_gt = (t_gt - t0) * 1e-9
    rots = Rotation.from_quat(gt.quat_xyzw)
    rot = Slerp(ts_gt, rots)(ts_imu).as_matrix()
    pos = np.stack([np.interp(ts_imu, ts_gt, gt.pos[:, k]) for k in range(3)], axis=1)

    period = float(np.median(np.diff(ts_gt)))
    right = np.clip(np.searchsorted(ts_gt, ts_imu, side="left"), 1, len(ts_gt) - 1)
    span = ts_gt[right] - ts_gt[right - 1]
    exact = ts_gt[right] == ts_imu  # an IMU stamp on a ground-truth stamp is always covered
    gt_mask = exact | (span <= max_gap_factor * period)
    return Sequence(
        name=name,
        t0_ns=t0,
        t=ts_imu,
        gyro=imu.gyro[keep],
        acc=imu.acc[keep],
        rot=rot,
        pos=pos,
        gt_mask=gt_mask,
        meta={
            "imu_file": str(imu.path),
            "gt_file": str(gt.path),
            "imu_samples_cropped": int((~keep).sum()),
            "gt_period_s": period,
        },
    )


def misspelt(name: str, names: list[str]) -> str | None:
    """The folder name `name` is probably a typo of: close, with the same digits (MH_02 is not a typo of MH_01)."""
    digits = re.findall(r"\d", name)
    close = [c for c in difflib.get_close_matches(name, names, n=3, cutoff=0.8) if re.findall(r"\d", c) == digits]
    return close[0] if close else None


def sequences_in(root: str | Path) -> list[str]:
    """The sequence folders (<name>/mav0) a data root holds, sorted."""
    return sorted(p.parent.name for p in Path(root).glob("*/mav0") if p.is_dir())


def not_asl_note(root: str | Path, name: str) -> str:
    """'' unless <root>/<name> exists without mav0/: then what it holds (a folder of other files is not missing)."""
    folder = Path(root) / name
    if not folder.is_dir():
        return ""
    held = sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir())
    listed = ", ".join(held[:8]) + (f" and {len(held) - 8} more" if len(held) > 8 else "") if held else "nothing"
    return (
        f"{folder} exists but is not in the ASL layout: it has no mav0/ (it holds {listed}); put the IMU in "
        f"{name}/mav0/imu0/data.csv and the truth in {name}/mav0/state_groundtruth_estimate0/data.csv. "
    )


def sequence_folder(root: str | Path, name: str) -> Path:
    """<root>/<name>/mav0, with an error that says what was looked for and what the root holds."""
    mav0 = Path(root) / name / "mav0"
    if not mav0.is_dir():
        if note := not_asl_note(root, name):
            raise FileNotFoundError(f"{mav0}: sequence folder not found. {note.rstrip()}")
        here = sequences_in(root)
        typo = misspelt(name, here)
        raise FileNotFoundError(
            f"{mav0}: sequence folder not found. "
            + (f"Did you mean {typo}? " if typo else "")
            + (
                f"{root} holds {', '.join(here)}. "
                if here
                else f"{root} holds no sequence folder. "
                if Path(root).is_dir()
                else f"{root} does not exist (relative paths start at {Path.cwd()}). "
            )
            + root_level_hint(Path(root), name)
            + f"The data root must be the folder that holds '{name}/mav0/imu0/data.csv' (ASL layout)."
        )
    return mav0


def root_one_level_off(root: Path, name: str) -> Path | None:
    """The root to give when `root` is one level off: its parent when it is a sequence folder itself (it holds
    mav0), the folder below it that holds `name`/mav0 when it is a folder of datasets; None otherwise."""
    if (root / "mav0").is_dir():
        return root.parent
    below = sorted(p.parent.parent for p in root.glob(f"*/{name}/mav0") if p.is_dir())
    return below[0] if below else None


def root_level_hint(root: Path, name: str, setting: str = "the root") -> str:
    """A sentence naming the root to give (as `setting`) when `root` is one level off (`root_one_level_off`), or ''."""
    fix = root_one_level_off(root, name)
    if fix is None:
        return ""
    if (root / "mav0").is_dir():
        return f"{root} is itself a sequence folder (it holds mav0): give its parent, {fix}, as {setting}. "
    return f"{name} is one level further down: give {fix} as {setting}. "
