"""Readers for the ASL folder format (EuRoC, TUM-VI, simulated data) with input validation.

Every error names the file, the line (1-based, as an editor shows it) or column, what is wrong,
and what to do. Nothing is dropped silently (a line that repeats the one before it exactly is kept once, with a
warning).
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gyrodenoise.data import asl_header

QUAT_NORM_TOL = 1e-3  # |q| may deviate this much (6-decimal files reach ~1e-6); renormalised after
IMU_LAYOUT = (
    "an ASL IMU text file (mav0/imu0/data.csv): a '#timestamp [ns],w_RS_S_x [rad s^-1],...' header, then lines "
    "t[ns],w_x,w_y,w_z[rad/s],a_x,a_y,a_z[m/s^2]"
)
GT_LAYOUT = (
    "an ASL ground-truth text file (mav0/state_groundtruth_estimate0/data.csv or mav0/mocap0/data.csv): "
    "lines t[ns],p_x,p_y,p_z[m],q_w,q_x,q_y,q_z"
)


class DataFormatError(ValueError):
    """A data file does not have the expected content."""


@dataclass(frozen=True)
class ImuData:
    t_ns: np.ndarray  # (N,) int64
    gyro: np.ndarray  # (N, 3) rad/s
    acc: np.ndarray  # (N, 3) m/s^2
    path: Path


@dataclass(frozen=True)
class GroundTruthData:
    t_ns: np.ndarray  # (M,) int64
    pos: np.ndarray  # (M, 3) m
    quat_xyzw: np.ndarray  # (M, 4) unit, scalar-last
    path: Path


class DataFormatWarning(UserWarning):
    """A data file that reads, but shows a sign of damage; the message names the file and line."""


def _first_undecodable(path: Path) -> tuple[int, int, int]:
    """(1-based line, byte offset, byte value) of the first byte that is not UTF-8; (0, -1, 0) if none."""
    offset = 0
    with open(path, "rb") as fh:  # line by line: the error path never holds a big file in memory at once
        for lineno, raw in enumerate(fh, start=1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as e:
                return lineno, offset + e.start, raw[e.start]
            offset += len(raw)
    return 0, -1, 0


def text_lines(path: Path, expected: str) -> Iterator[tuple[int, str]]:
    """(1-based line number, line) of a UTF-8 text file. A binary file or one in another encoding raises
    DataFormatError naming the file, the first bad byte (offset and line) and what was expected, instead of
    the bare 'utf-8 codec can't decode byte' that says neither which file nor what to do."""
    advice = (
        f"This is not a UTF-8 text CSV file; expected {expected}. A binary log (rosbag, .bin, ...) must be "
        "converted to CSV first; a text file in another encoding (e.g. Latin-1) must be saved as UTF-8."
    )
    try:
        with open(path, encoding="utf-8-sig") as fh:  # -sig: a byte-order mark (Windows editors) is not data
            lineno, line = 0, "\n"
            for lineno, line in enumerate(fh, start=1):
                if "\x00" in line:  # NUL is valid UTF-8 but never in a text CSV: a binary file
                    raise DataFormatError(f"{path}:{lineno}: NUL byte (binary data). {advice}")
                yield lineno, line
            if not line.endswith("\n") and line.strip() and not line.lstrip().startswith("#"):
                # the mark of a write that stopped mid-line: its last number may be cut (-2.1819 for -2.18198)
                warnings.warn(
                    f"{path}:{lineno}: the file does not end with a line break, so its last line may have been cut "
                    "by an interrupted write; it is read as it stands. Check that line (or end the file with a line "
                    "break if it is whole).",
                    DataFormatWarning,
                    stacklevel=2,
                )
    except UnicodeDecodeError:
        lineno, offset, byte = _first_undecodable(path)
        raise DataFormatError(f"{path}:{lineno}: byte 0x{byte:02x} at offset {offset} is not UTF-8. {advice}") from None


def comment_header(comments: list[list[str]], n_fields: int, min_fields: int) -> int | None:
    """Which of the comment lines above the data (each split into its fields) is the header: the last with as many
    fields as the first data line, else the last with at least `min_fields` (a header naming only the columns read),
    else None. The nearest the data wins: a note above the header is not it, nor is a note below it with another
    number of fields. Shared by every reader of a table with '#' comments, so that they agree on a file."""
    for ok in (lambda f: len(f) == n_fields, lambda f: len(f) >= min_fields):
        k = next((i for i in reversed(range(len(comments))) if ok(comments[i])), None)
        if k is not None:
            return k
    return None


def read_csv_table(
    path: Path,
    min_cols: int,
    what: str,
    expected: str = "a comma-separated ASL file",
    check_header: Callable[[Path, int, list[str]], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a comma-separated numeric table with '#' comment lines.

    Returns (t_ns int64, values float64 with the `min_cols - 1` columns after the time, line numbers).
    Columns beyond `min_cols` are ignored (optional extras such as velocity and biases).
    `check_header(path, line, names)` sees the header: of the comment lines before the first data line, the last
    with as many comma-separated fields as that data line (a note below the header is not it), else the last that
    names at least the `min_cols` columns read.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: {what} file not found. Expected the ASL layout <sequence>/mav0/...; "
            "check the dataset root and sequence name in the config."
        )
    stamps: list[int] = []
    rows: list[list[str]] = []
    line_numbers: list[int] = []
    comments: list[tuple[int, list[str]]] = []  # the comment lines before the data, split at commas
    for lineno, line in text_lines(path, expected):
        s = line.strip()
        if not s or s.startswith("#"):
            if s and not rows:
                text = s.lstrip("#")  # a header written with tabs or semicolons is still the header
                comments.append((lineno, [f.strip() for f in re.split("," if "," in text else r"[;\t]", text)]))
            continue
        fields = [f.strip() for f in s.split(",")]
        if not rows and check_header is not None:
            # the header: the last comment line with as many fields as the data (not a note below it), else one that
            # names at least the columns read (a header of t, p, q over data with more columns: velocity, biases)
            k = comment_header([c[1] for c in comments], len(fields), min_cols)
            if k is not None:
                check_header(path, *comments[k])
        if len(fields) < min_cols:
            other = next((d for d in (";", "\t") if len(s.split(d)) >= min_cols), None) if len(fields) == 1 else None
            spaces = len(fields) == 1 and other is None and len(s.split()) >= min_cols  # e.g. a TUM trajectory
            raise DataFormatError(
                f"{path}:{lineno}: {what} line has {len(fields)} columns, expected at least {min_cols}. "
                + (
                    f"Its columns are separated by {other!r}: the ASL format separates them by commas; convert the "
                    f"file (e.g. sed 's/{other}/,/g'; gyrodenoise-correct --delimiter reads it as it is)."
                    if other
                    else "Its columns are separated by spaces: the ASL format separates them by commas (expected: "
                    f"{expected}); convert the file (a TUM trajectory 't tx ty tz qx qy qz qw' has its time in s and "
                    "its quaternion x, y, z, w: convert and reorder those too)."
                    if spaces
                    else "Fix or remove the truncated line."
                )
            )
        try:
            stamps.append(int(fields[0]))
        except ValueError:
            named = not rows and any(c.isalpha() for c in s) and not _is_float(fields[0])  # a header without its '#'
            raise DataFormatError(
                f"{path}:{lineno}: column 1 (timestamp) is {fields[0]!r}; expected an integer number of nanoseconds."
                + (" A header line must start with '#'." if named else _decimal_stamp_hint(fields[0]))
            ) from None
        if not -(2**63) <= stamps[-1] < 2**63:  # else np.int64 raises a bare OverflowError naming no file
            raise DataFormatError(
                f"{path}:{lineno}: column 1 (timestamp) is {fields[0]}, beyond what int64 nanoseconds hold (the year "
                "2262): a stamp with extra digits (two lines run together?); fix or remove that line."
            )
        rows.append(fields[1:min_cols])
        line_numbers.append(lineno)
    if not rows:
        raise DataFormatError(f"{path}: no data lines in {what} file (only comments or empty).")
    try:
        values = np.array(rows, dtype=np.float64)
    except ValueError:
        for lineno, r in zip(line_numbers, rows, strict=True):
            for col, f in enumerate(r, start=2):
                try:
                    float(f)
                except ValueError:
                    raise DataFormatError(
                        f"{path}:{lineno}: column {col} is {f!r}, not a number; fix or remove that line."
                    ) from None
        raise
    t_ns = np.array(stamps, dtype=np.int64)
    lines = np.array(line_numbers)
    _check_values(path, values, lines, what)
    t_ns, values, lines = _drop_repeated_lines(path, t_ns, values, lines, what)
    _check_time(path, t_ns, lines, what)
    return t_ns, values, lines


def _is_float(field: str) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def _decimal_stamp_hint(field: str) -> str:
    """What a timestamp written as a decimal number says of its unit ('' when it is no number)."""
    try:
        value = float(field)
    except ValueError:
        return ""
    if abs(value) < 1e11:  # up to ~3000 years in s; ns are 1e18 today, and an IMU's first s or ms are small too
        return (
            " It reads as a decimal number: stamps in seconds (or ms)? Write them as integer nanoseconds "
            "(seconds x 1e9, rounded), the IMU's and the ground truth's alike."
        )
    if abs(value) < 1e17:  # since 1970 in ms (~1.7e12) or µs (~1.7e15); ns are ~1.7e18
        return (
            " It reads as a decimal number: stamps in milli- or microseconds (since 1970: ~1.7e12 ms, ~1.7e15 µs)? "
            "Write them as integer nanoseconds (ms x 1e6, µs x 1e3, rounded), the IMU's and the ground truth's alike."
        )
    return " It reads as a decimal number: write the nanoseconds as integers (a float64 drops the last digits)."


def _such_lines(n: int) -> str:
    return "1 such line" if n == 1 else f"{n} such lines"


def _check_values(path: Path, values: np.ndarray, lines: np.ndarray, what: str) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise DataFormatError(
            f"{path}:{lines[r]}: column {c + 2} of the {what} is {values[r, c]} (NaN/inf) "
            f"({_such_lines(int(bad.any(1).sum()))}). Remove or repair these samples; gyrodenoise does not "
            "fill them in silently."
        )


def _drop_repeated_lines(
    path: Path, t_ns: np.ndarray, values: np.ndarray, lines: np.ndarray, what: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A line that repeats the one before it exactly (same stamp, same values: a logger or a merge that wrote the
    sample twice) is kept once, with a warning naming the file, the first such line and how many (as the bag import
    does); a repeated stamp with other values stays an error (`_check_time`)."""
    same = (np.diff(t_ns) == 0) & np.all(values[1:] == values[:-1], axis=1)
    if not same.any():
        return t_ns, values, lines
    k = int(np.argmax(same)) + 1
    n = int(same.sum())
    warnings.warn(
        DataFormatWarning(
            f"{path}:{lines[k]}: {n} {what} line{'s' if n > 1 else ''} repeat{'' if n > 1 else 's'} the line before "
            f"exactly (same timestamp, same values; the first is a copy of line {lines[k - 1]}): each sample is "
            "kept once"
        ),
        stacklevel=3,
    )
    keep = np.concatenate([[True], ~same])
    return t_ns[keep], values[keep], lines[keep]


def back_in_time_advice(t_ns: np.ndarray, lines: np.ndarray) -> str | None:
    """For stamps that go back at exactly one place, by far more than a sample period, and run forward on either side
    of it: a clock that restarted or a counter that wrapped, which sorting would make worse (the later part would be
    put before the earlier one). None otherwise."""
    d = np.diff(t_ns)
    back = np.flatnonzero(d < 0)
    if back.size != 1 or (d > 0).sum() < 2:
        return None
    k = int(back[0])
    period = float(np.median(d[d > 0]))
    if -d[k] < 100 * period:
        return None
    return (
        f"The stamps go back once, by {-d[k] * 1e-9:.6g} s, at line {lines[k + 1]} and run forward on either side: the "
        "clock restarted there, or a counter wrapped. Sorting would put the later part first; split the file at that "
        "line into two recordings (each corrected on its own), or unwrap the counter (add its range to the stamps "
        "after the line)."
    )


def _check_time(path: Path, t_ns: np.ndarray, lines: np.ndarray, what: str) -> None:
    d = np.diff(t_ns)
    if (d == 0).any():
        k = int(np.argmax(d == 0))
        n = int((d == 0).sum())
        raise DataFormatError(
            f"{path}:{lines[k + 1]}: duplicate timestamp {t_ns[k + 1]} (same as line {lines[k]}) with other values "
            f"in the {what} ({_such_lines(n)}; exact repeats of a line are kept once by "
            "themselves). Keep one sample per timestamp: the one the sensor really measured then."
        )
    if (d < 0).any():
        k = int(np.argmax(d < 0))
        raise DataFormatError(
            f"{path}:{lines[k + 1]}: timestamp {t_ns[k + 1]} goes back in time (previous line {lines[k]} "
            f"has {t_ns[k]}). " + (back_in_time_advice(t_ns, lines) or f"The {what} must be sorted by time.")
        )


def _header_check(problem: Callable[[list[str]], str | None]) -> Callable[[Path, int, list[str]], None]:
    def check(path: Path, line: int, names: list[str]) -> None:
        why = problem(names)
        if why:
            raise DataFormatError(f"{path}:{line}: {why}")

    return check


# an IMU sampling outside this has its stamps in another unit (µs stamps at 200 Hz read as ns: 200 kHz); shared
# by the ASL reader and the corrector's checks (`checks.check_time_unit`)
IMU_RATE_RANGE_HZ = (5.0, 20_000.0)
GAP_FACTOR = 3.0  # an IMU step longer than this x the median period is a gap
BURST_FACTOR = 3.0  # a mean step this many times the median: stamps in bursts


def burst_rate_hz(t_ns: np.ndarray) -> float | None:
    """The mean sample rate (Hz) when the stamps come in bursts (the mean step over BURST_FACTOR x the median: a
    driver that stamps each FIFO read, not each sample, leaves a few steps of ~0 and one long one); else None."""
    d = np.diff(t_ns)
    mean = float(t_ns[-1] - t_ns[0]) / len(d) if len(d) else 0.0
    return 1e9 / mean if mean > BURST_FACTOR * float(np.median(d)) else None


def burst_advice(median_step_ns: float, mean_rate_hz: float) -> str:
    return (
        f"the stamps come in bursts: the median step is {median_step_ns:g} ns but the samples arrive at "
        f"{mean_rate_hz:.4g} Hz on average, as when a driver stamps each FIFO read rather than each sample. "
        "Give each sample its own time (e.g. spread each burst's samples evenly over the time since the one before)"
    )


def _check_imu_period(path: Path, t_ns: np.ndarray) -> None:
    if len(t_ns) < 2:
        return
    step = float(np.median(np.diff(t_ns)))
    lo, hi = IMU_RATE_RANGE_HZ
    if step < 1e9 / hi:
        burst = burst_rate_hz(t_ns)
        if burst is not None and lo <= burst <= hi:
            raise DataFormatError(f"{path}: {burst_advice(step, burst)}.")
        guess = next((u for u, f in (("µs", 1e3), ("ms", 1e6)) if lo <= 1e9 / (step * f) <= hi), None)
        raise DataFormatError(
            f"{path}: the median step between IMU timestamps is {step:g}, which in ns is a rate of {1e9 / step:.0f} "
            f"Hz (an IMU samples at {lo:g} Hz - {hi / 1000:g} kHz); the ASL format's stamps are integer nanoseconds"
            + (f" and these look like {guess}: convert them (and the ground truth's) to ns." if guess else ".")
        )
    if step > 1e9 / lo:  # e.g. picoseconds read as ns: each sample would be integrated over seconds
        ps = lo <= 1e12 / step <= hi
        raise DataFormatError(
            f"{path}: the median step between IMU timestamps is {step:g}, which in ns is a rate of {1e9 / step:.2g} Hz "
            f"(an IMU samples at {lo:g} Hz - {hi / 1000:g} kHz); the ASL format's stamps are integer nanoseconds"
            + (" and these look like ps: convert them (and the ground truth's) to ns." if ps else ".")
        )


def read_imu(path: str | Path) -> ImuData:
    """ASL IMU file: t[ns], w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]."""
    t, v, lines = read_csv_table(Path(path), 7, "IMU", IMU_LAYOUT, _header_check(asl_header.imu_header_problem))
    _check_imu_period(Path(path), t)
    return ImuData(t_ns=t, gyro=v[:, 0:3], acc=v[:, 3:6], path=Path(path))


def quaternion_norms(q: np.ndarray, tol: float = QUAT_NORM_TOL) -> tuple[np.ndarray, int | None, int]:
    """|q| of each row, the index of the first row more than `tol` from 1 (None: none is) and how many are."""
    norm = np.linalg.norm(q, axis=1)
    bad = np.abs(norm - 1.0) > tol
    return norm, (int(np.argmax(bad)) if bad.any() else None), int(bad.sum())


def read_groundtruth(path: str | Path) -> GroundTruthData:
    """ASL ground truth: t[ns], p_x, p_y, p_z [m], q_w, q_x, q_y, q_z, then optional columns."""
    path = Path(path)
    t, v, lines = read_csv_table(
        path, 8, "ground truth", GT_LAYOUT, _header_check(asl_header.groundtruth_header_problem)
    )
    q_wxyz = v[:, 3:7]
    norm, k, count = quaternion_norms(q_wxyz)
    zero = norm == 0.0
    if zero.any():  # a tracker that lost the body: not a column order
        k = int(np.argmax(zero))
        raise DataFormatError(
            f"{path}:{lines[k]}: quaternion (columns 5-8, w x y z) is zero ({_such_lines(int(zero.sum()))}): no pose "
            "there (the tracker lost the body?). Remove those lines: the gap they leave is masked where it spans "
            "more than dataset.max_gap_factor (3 by default) ground-truth periods, and bridged by SLERP where shorter."
        )
    if k is not None:
        raise DataFormatError(
            f"{path}:{lines[k]}: quaternion (columns 5-8, w x y z) has norm {norm[k]:.6f}, more than "
            f"{QUAT_NORM_TOL} from 1 ({_such_lines(count)}). Check the column order "
            "(t, p_x, p_y, p_z, q_w, q_x, q_y, q_z) and the file's units."
        )
    q_wxyz = q_wxyz / norm[:, None]
    quat_xyzw = np.concatenate([q_wxyz[:, 1:], q_wxyz[:, :1]], axis=1)
    return GroundTruthData(t_ns=t, pos=v[:, 0:3], quat_xyzw=quat_xyzw, path=path)


def find_groundtruth_file(mav0: Path) -> Path:
    """EuRoC keeps ground truth in state_groundtruth_estimate0/, TUM-VI in mocap0/."""
    for sub in ("state_groundtruth_estimate0", "mocap0"):
        p = mav0 / sub / "data.csv"
        if p.is_file():
            return p
    raise FileNotFoundError(
        f"{mav0}: no ground truth found (looked for state_groundtruth_estimate0/data.csv and "
        "mocap0/data.csv). Training and evaluation need ground truth: a file under another name is given per "
        f"sequence with +dataset.gt_files.{mav0.parent.name}=FOLDER/data.csv (relative to mav0); use "
        "gyrodenoise-correct for IMU-only recordings."
    )
