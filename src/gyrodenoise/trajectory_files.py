"""Trajectories as TUM text files (`t tx ty tz qx qy qz qw`), the format evo and rpg_trajectory_evaluation read.

Stamps are printed exactly from the integer nanoseconds of the IMU clock (float64 absolute seconds lose ~100 ns);
`read_tum` reads them back exactly, and reads other methods' estimates (a VIO's output) for `evaluate`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gyrodenoise.data.readers import DataFormatError


def tum_text(t_ns: np.ndarray, R: np.ndarray, comment: str, pos: np.ndarray | None = None) -> str:
    """One line per sample after a `# comment` line; translation `pos` (m), or zero for an orientation-only
    estimate."""
    q = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    trans = ["0 0 0"] * len(q) if pos is None else [f"{a:.6f} {b:.6f} {c:.6f}" for a, b, c in np.asarray(pos).tolist()]
    lines = [f"# t[s] tx ty tz qx qy qz qw ({comment})"]
    for t, xyz, (x, y, z, w) in zip(np.asarray(t_ns).tolist(), trans, q.tolist(), strict=True):
        sign, a = ("-" if t < 0 else ""), abs(t)  # // and % of a negative t would give -1.005 s for -0.995 s
        lines.append(f"{sign}{a // 1_000_000_000}.{a % 1_000_000_000:09d} {xyz} {x:.9f} {y:.9f} {z:.9f} {w:.9f}")
    return "\n".join(lines) + "\n"


class TrajectoryFileError(DataFormatError):
    """A trajectory file that cannot be read as a TUM trajectory; the message names the file and line."""


NS_STAMP_MIN = 10**12  # a stamp whose integer part is at least this is in ns (1e12 s is 31,000 years)
QUAT_NORM_TOL = 1e-2  # writers round; a quaternion further from unit length is read in another column order


def _stamp_ns(text: str, in_ns: bool) -> int:
    """A stamp's text to int ns, exactly for decimal seconds with up to 9 fraction digits."""
    whole, dot, frac = text.partition(".")
    if whole.isdigit() and (not dot or frac.isdigit()):
        if in_ns:
            return int(whole) + round(float(f"0.{frac}")) if dot else int(whole)
        return int(whole) * 1_000_000_000 + int((frac + "000000000")[:9] or "0")
    value = float(text)  # exponent forms, e.g. 1.4036e9
    if not np.isfinite(value) or value < 0:
        raise ValueError(text)
    return round(value if in_ns else value * 1e9)


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """A TUM trajectory (`t tx ty tz qx qy qz qw` per line, `#` comments, stamps in s or ns: the first stamp's
    magnitude decides) -> (t_ns int64 (M,), R (M, 3, 3) body to world). Stamps must increase; quaternions are
    x, y, z, w and of unit length (within QUAT_NORM_TOL)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # -sig: a byte-order mark (Windows editors) is not data
    except UnicodeDecodeError:
        raise TrajectoryFileError(
            f"{path}: not a text file (a TUM trajectory: 't tx ty tz qx qy qz qw' per line)"
        ) from None
    stamps: list[int] = []
    quats: list[list[float]] = []
    lines: list[int] = []
    in_ns: bool | None = None
    for n, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        where = f"{path}, line {n}"
        if len(fields) != 8:
            raise TrajectoryFileError(
                f"{where}: {len(fields)} fields, expected 8 (t tx ty tz qx qy qz qw, separated by spaces: the TUM "
                "format; convert a CSV with e.g. `tr ',' ' '`)"
            )
        try:
            if in_ns is None:
                in_ns = float(fields[0]) >= NS_STAMP_MIN
            stamps.append(_stamp_ns(fields[0], in_ns))
            q = [float(v) for v in fields[4:]]
        except ValueError:
            raise TrajectoryFileError(f"{where}: not numbers: {line.strip()!r}") from None
        if not all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > QUAT_NORM_TOL:
            raise TrajectoryFileError(
                f"{where}: the quaternion {fields[4:]} is not of unit length (norm {np.linalg.norm(q):.4g}); the TUM "
                "format is t tx ty tz qx qy qz qw, scalar last"
            )
        if len(stamps) > 1 and stamps[-1] <= stamps[-2]:
            raise TrajectoryFileError(
                f"{where}: stamp {fields[0]} is not after the previous line's (line {lines[-1]}): stamps must "
                "increase (sort the file, drop repeated stamps)"
            )
        quats.append(q)
        lines.append(n)
    if len(stamps) < 2:
        raise TrajectoryFileError(f"{path}: {len(stamps)} poses; a trajectory needs at least 2")
    return np.asarray(stamps, dtype=np.int64), Rotation.from_quat(np.asarray(quats)).as_matrix()
