"""Read an IMU recording from any CSV: ASL `imu0/data.csv` by default, or columns mapped by name or
number with units given, converted at this edge to the conventions inside (int ns, rad/s, m/s^2).

    rec = read_imu_csv("imu.csv", columns="time,gx,gy,gz,ax,ay,az", time_unit="us", gyro_unit="deg/s")

Nothing is checked for plausibility here (units, rate, gaps): that is gyrodenoise.data.checks. This
module only refuses what it cannot parse, naming the file, the line and the column.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from gyrodenoise.data import asl_header
from gyrodenoise.data.asl_write import IMU_HEADER as ASL_HEADER
from gyrodenoise.data.readers import IMU_RATE_RANGE_HZ, DataFormatError, comment_header, text_lines

G0 = 9.80665  # standard gravity, m/s^2 per g
TIME_UNITS = {"ns": 1, "us": 1_000, "ms": 1_000_000, "s": 1_000_000_000}  # ns per unit
GYRO_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
ACC_UNITS = {"m/s^2": 1.0, "g": G0, "mg": G0 / 1000.0}
FIELDS = ("t", "wx", "wy", "wz", "ax", "ay", "az")
CSV_LAYOUT = (
    f"a text CSV of IMU samples: by default ASL imu0/data.csv with the header '{ASL_HEADER}', or any delimited "
    "text with --columns and its units"
)


@dataclass
class ImuRecording:
    t_ns: np.ndarray  # (N,) int64
    gyro: np.ndarray  # (N, 3) rad/s
    acc: np.ndarray  # (N, 3) m/s^2
    lines: np.ndarray  # (N,) 1-based line numbers in the file (-1 for resampled samples)
    path: Path
    columns: dict[str, str]  # field (t, wx, ...) -> how the file names it, for messages
    units: dict[str, str]
    units_from_header: list[str] = dataclass_field(default_factory=list)  # quantities whose unit the header declared

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def imu(self) -> np.ndarray:
        return np.concatenate([self.gyro, self.acc], axis=1)

    def describe(self, *fields: str) -> str:
        """'column 2 (w_RS_S_x [rad s^-1]) ...' for messages."""
        return ", ".join(self.columns[f] for f in fields)


def check_units(time_unit: str | None, gyro_unit: str | None, acc_unit: str | None) -> None:
    """ValueError naming a unit these readers do not know, with the ones they do (None: not given)."""
    for name, val, table in (
        ("time_unit", time_unit, TIME_UNITS),
        ("gyro_unit", gyro_unit, GYRO_UNITS),
        ("acc_unit", acc_unit, ACC_UNITS),
    ):
        if val is not None and val not in table:
            raise ValueError(f"{name}={val!r}; choose one of {', '.join(table)}")


def _split(line: str, delimiter: str | None) -> list[str]:
    """The fields of a line; a field in double quotes (a spreadsheet's or pandas' QUOTE_ALL export) without them."""
    fields = [f.strip() for f in (line.split(delimiter) if delimiter else line.split())]
    return [f[1:-1].strip() if len(f) >= 2 and f[0] == f[-1] == '"' else f for f in fields]


COARSEST_STAMP_NS = 100_000  # a stamp written in exponent form whose last digit is worth this or more lost its time


def _exponent_stamp_step_ns(field: str, ns_per: int) -> float | None:
    """What the last digit of a stamp written in exponent form ('1.403715e+18') is worth in ns; None otherwise."""
    if "e" not in field.lower():
        return None
    try:
        exponent = Decimal(field).as_tuple().exponent
    except InvalidOperation:
        return None
    return 10.0 ** int(exponent) * ns_per if isinstance(exponent, int) else None


def _stamp_ns(field: str, ns_per: int) -> int:
    """A time field in int ns, exact for integers and for decimals ('1403715273.262142' s: a float would move it by up
    to ~100 ns); ValueError when it is not a finite number."""
    try:
        return int(field) * ns_per
    except ValueError:
        pass
    try:
        value = Decimal(field)
    except InvalidOperation:
        raise ValueError(field) from None
    if not value.is_finite():
        raise ValueError(field)
    return int((value * ns_per).to_integral_value())


INT64_MAX = np.iinfo(np.int64).max  # int64 ns end in the year 2262


def time_units_for_period(period: float) -> list[str]:
    """The time units in which a median step of `period` (the file's own numbers) is an IMU's sample period."""
    lo, hi = IMU_RATE_RANGE_HZ
    return [u for u, ns in TIME_UNITS.items() if lo <= 1e9 / (period * ns) <= hi]


def beyond_int64_advice(steps: np.ndarray, unit: str) -> str:
    """What to say of stamps that overflow int64 ns when read in `unit` (nanoseconds read as seconds); `steps`: the
    differences of the stamps in the file's own numbers. Worded for the command line (`--time-unit`)."""
    fits = [u for u in (time_units_for_period(float(np.median(steps))) if len(steps) else []) if u != unit]
    if unit == "ns" or not fits:  # read as ns already: no finer unit to offer; the column is not a time in ns
        return (
            f"beyond what int64 nanoseconds hold (the year 2262) read as {unit}: check the time column (--columns) and "
            "its unit (--time-unit)"
        )
    return (
        f"beyond what int64 nanoseconds hold (the year 2262): the stamps are in a finer unit than {unit}; "
        f"pass --time-unit {fits[0]}"
    )


def _refuse_stamps_beyond_int64(stamps: list[int], lines: np.ndarray, path: Path, unit: str) -> None:
    """Stamps that do not fit int64 ns were read in too coarse a unit (nanoseconds read as seconds)."""
    if max(stamps) <= INT64_MAX and min(stamps) >= -INT64_MAX:
        return
    k = next(i for i, s in enumerate(stamps) if abs(s) > INT64_MAX)
    steps = (np.diff(np.array(stamps, dtype=object)) / TIME_UNITS[unit]).astype(np.float64)
    raise DataFormatError(
        f"{path}:{lines[k]}: the time column read as {unit} is {stamps[k] / 1e9:.3g} s, "
        f"{beyond_int64_advice(steps, unit)}."
    )


def _guess_delimiter(line: str) -> str | None:
    for d in (",", ";", "\t"):
        if d in line:
            return d
    return None  # whitespace


def _comment_header(
    comments: list[tuple[int, str]], delimiter: str | None, n_fields: int, path: Path
) -> list[str] | None:
    """The header among the comment lines (line number, text) above the data (`readers.comment_header`'s rule: the
    nearest the data with as many fields as the first line below them, else with at least the seven columns read),
    else None. Warns when another comment line has as many fields: which one declares the units is then a guess."""
    split = [_split(c, delimiter) for _, c in comments]
    k = comment_header(split, n_fields, len(FIELDS))
    if k is None:
        return None
    others = [comments[i][0] for i, f in enumerate(split) if i != k and len(f) == len(split[k])]
    if others:
        warnings.warn(
            f"{path}: comment lines {', '.join(map(str, others))} and {comments[k][0]} have as many fields as the "
            f"header; line {comments[k][0]}, the nearest the data, is taken as it. If it is not, give the units "
            "(--gyro-unit, --time-unit, --acc-unit) and --columns by number",
            stacklevel=3,
        )
    return split[k]


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _resolve_columns(spec: str, header: list[str] | None, path: Path) -> list[int]:
    """7 comma-separated names (from the header) or 1-based numbers -> 0-based indices."""
    items = [s.strip() for s in spec.split(",")]
    if len(items) != len(FIELDS):
        raise ValueError(
            f"--columns {spec!r}: give {len(FIELDS)} columns in the order {','.join(FIELDS)} "
            "(header names or 1-based column numbers)"
        )
    names = [h.lstrip("#").strip().lower() for h in header] if header else []
    short = [n.split("[")[0].strip() for n in names]  # 'w_rs_s_x [rad s^-1]' -> 'w_rs_s_x'
    out = []
    for field, item in zip(FIELDS, items, strict=True):
        if item.isdigit():
            if int(item) < 1:  # 0 would read the last column (Python's index -1)
                raise ValueError(
                    f"--columns {spec!r}: column numbers count from 1 (the first column is 1); or give header names"
                )
            out.append(int(item) - 1)
            continue
        key = item.lower()
        if key in names:
            out.append(names.index(key))
        elif key in short:
            out.append(short.index(key))
        else:
            raise DataFormatError(
                f"{path}: column {item!r} (for {field}) is not in the header "
                f"{header if header else '(the file has no header line)'}; give a header name or a "
                "1-based column number in --columns."
            )
    return out


POSE_NAME = re.compile(r"^[pqv]_rs_|\[m\]")  # ASL ground truth / mocap (lowercased): p_rs_r_x [m], q_rs_w [], v_rs_r_x


def _refuse_pose_columns(header: list[str] | None, idx: list[int], path: Path) -> None:
    """A ground-truth (pose) file read as IMU samples passes the unit checks' advice into garbage: refuse it by its
    header when the gyro or accelerometer columns carry pose names."""
    if not header:
        return
    named = [header[i].lstrip("#").strip() for i in idx[1:] if i < len(header)]
    pose = [n for n in named if POSE_NAME.search(n.lower())]
    if pose:
        raise DataFormatError(
            f"{path}: the gyro/accelerometer columns are named {', '.join(pose[:4])}: a pose (ground-truth) file, "
            "not IMU samples. Give the IMU's file (ASL: mav0/imu0/data.csv), or map its columns with --columns."
        )


DEFAULT_UNITS = {"time": "ns", "gyro": "rad/s", "acc": "m/s^2"}  # the ASL format's


def _header_units(
    header: list[str] | None, idx: list[int], path: Path, given: dict[str, str | None]
) -> tuple[dict[str, str], list[str]]:
    """The units to read (each one given, else the one the header's mapped column names declare, else the ASL
    format's) and the quantities whose unit came from the header. Mapped columns whose header names are other
    quantities or axes are refused in one message, with a --columns read off the header where it can be."""
    names = [header[i] for i in idx] if header and max(idx) < len(header) else []
    kinds = [asl_header.classify(n) for n in names[1:]]
    pairs = zip(FIELDS[1:], names[1:], kinds, asl_header.IMU_ORDER, strict=True) if names else []
    wrong = [
        f"{name} <- '{n}'"
        for name, n, (kind, axis), (want, want_axis) in pairs
        if (kind in ("gyro", "acc") and kind != want) or (kind == want and axis not in (None, want_axis))
    ]
    if wrong:
        fix = asl_header.columns_from_names(header)
        raise DataFormatError(
            f"{path}: the columns mapped to {', '.join(wrong)} are other quantities or axes by their header names "
            f"(the order read: {','.join(FIELDS)}). "
            + (f"Pass --columns {fix} (read off the header)." if fix else "Map them with --columns.")
        )
    said = asl_header.declared_units(names[0], names[1:4], names[4:7]) if names else {}
    units = {k: given[k] or said.get(k) or default for k, default in DEFAULT_UNITS.items()}
    return units, [k for k in said if not given[k] and said[k] != DEFAULT_UNITS[k]]


def read_imu_csv(
    path: str | Path,
    columns: str | list[str | int] = "1,2,3,4,5,6,7",
    time_unit: str | None = None,
    gyro_unit: str | None = None,
    acc_unit: str | None = None,
    delimiter: str | None = None,
) -> ImuRecording:
    """Parse the file; values in SI, time in int ns. Comment lines start with '#'; a first line
    with non-numeric fields, or a comment line above the data with as many fields as it (`_comment_header`: a note
    above the header, or below it with another number of fields, is not it), is taken as the header. A unit not
    given is the one the header's names declare for the mapped columns ('gx [deg/s]', 't (s)', 'acc_x_g'), else the
    ASL format's (ns, rad/s, m/s^2); `ImuRecording.units_from_header` names those taken from the header."""
    path = Path(path)
    check_units(time_unit, gyro_unit, acc_unit)
    if isinstance(columns, list | tuple):  # from Python a list reads as naturally as the command line's string
        columns = ",".join(str(c) for c in columns)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: IMU file not found.")
    header: list[str] | None = None
    idx: list[int] | None = None
    stamps: list[int] = []
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    problems: list[tuple[int, str]] = []  # (line, message) of every bad line, reported together
    short_lines, short_fields = 0, 0  # lines with too few columns, and the first one's count
    given = {"time": time_unit, "gyro": gyro_unit, "acc": acc_unit}
    units, units_from_header = dict(DEFAULT_UNITS), []
    ns_per = TIME_UNITS[units["time"]]
    comments: list[tuple[int, str]] = []  # the comment lines before the first data line: one may be the header
    for lineno, raw in text_lines(path, CSV_LAYOUT):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            if header is None and idx is None:
                comments.append((lineno, s.lstrip("#")))
            continue
        if delimiter is None:  # from the first line that is not a comment: a note above the header has no say
            delimiter = _guess_delimiter(s)
        fields = _split(s, delimiter)
        if idx is None:
            if header is None:
                header = _comment_header(comments, delimiter, len(fields), path)
            if header is None and not all(_is_number(f) for f in fields if f):  # '' : a line ending in a delimiter
                header = fields
                continue
            idx = _resolve_columns(columns, header, path)
            _refuse_pose_columns(header, idx, path)
            units, units_from_header = _header_units(header, idx, path, given)
            ns_per = TIME_UNITS[units["time"]]
        if len(fields) <= max(idx):
            short_lines += 1
            short_fields = short_fields or len(fields)
            problems.append(
                (
                    lineno,
                    f"{path}:{lineno}: {len(fields)} columns, but column {max(idx) + 1} is mapped. Fix or "
                    "remove the truncated line, or check --columns/--delimiter.",
                )
            )
            continue
        t_field = fields[idx[0]]
        if units["time"] == "ns" and "." in t_field and _is_number(t_field) and float(t_field) % 1:
            raise DataFormatError(
                f"{path}:{lineno}: the time column is {t_field!r}, with a fractional part, in nanoseconds "
                "(--time-unit ns, the default): the stamps are likely seconds (or ms/us); pass --time-unit s "
                "(ms, us) as they are."
            )
        step = _exponent_stamp_step_ns(t_field, ns_per)
        if step is not None and step >= COARSEST_STAMP_NS:
            raise DataFormatError(
                f"{path}:{lineno}: the time column is {t_field!r}, in exponent form with too few digits: its last "
                f"digit is worth {step * 1e-9:g} s, so the samples' times were rounded away when the file was written. "
                "Write the stamps with all their digits: integer nanoseconds, or seconds with 9 decimals "
                "(--time-unit s)."
            )
        try:
            stamp = _stamp_ns(t_field, ns_per)
            row = [float(fields[i]) for i in idx[1:]]
        except ValueError:
            bad = next((i for i in idx if not _is_number(fields[i])), idx[0])  # else a stamp 'nan' or 'inf'
            problems.append(
                (
                    lineno,
                    f"{path}:{lineno}: column {bad + 1} is {fields[bad]!r}, not a "
                    + ("finite time" if bad == idx[0] else "number")
                    + "; fix or remove that line, or check --columns/--delimiter.",
                )
            )
            continue
        stamps.append(stamp)
        rows.append(row)
        line_numbers.append(lineno)
    if short_lines and short_lines == len(problems) and not rows:  # every line short: the file lacks the columns
        first = problems[0][0]
        raise DataFormatError(
            f"{path}:{first}: {short_fields} columns, but the mapping reads column {max(idx) + 1} (time, gyro "
            "x/y/z, accelerometer x/y/z). The models read the accelerometer as well as the gyro: a recording "
            "without it cannot be corrected. If the columns are there, check --columns/--delimiter."
        )
    names = header or []
    if rows:
        values = np.array(rows, dtype=np.float64)
        lines = np.array(line_numbers)
        bad = ~np.isfinite(values)
        for r in np.flatnonzero(bad.any(1)):  # NaN/inf, after the lines that do not parse: all in one report
            c = int(np.flatnonzero(bad[r])[0])
            name = f" ({names[idx[c + 1]]})" if idx[c + 1] < len(names) else ""
            problems.append(
                (
                    int(lines[r]),
                    f"{path}:{lines[r]}: column {idx[c + 1] + 1}{name} is {values[r, c]}. Remove or repair NaN/inf "
                    "samples; gyrodenoise does not fill them in silently.",
                )
            )
    if problems:
        messages = [m for _, m in sorted(problems)]
        more = "" if len(messages) == 1 else f"\n({len(messages)} lines to fix in all; the first ones:)\n"
        raise DataFormatError(messages[0] + more + "\n".join(messages[1:6]))
    if not rows:
        raise DataFormatError(f"{path}: no data lines (only comments, a header or empty lines).")
    _refuse_stamps_beyond_int64(stamps, lines, path, units["time"])
    desc = {
        f: f"column {i + 1}" + (f" ({names[i]})" if i < len(names) else "") for f, i in zip(FIELDS, idx, strict=True)
    }
    return ImuRecording(
        t_ns=np.array(stamps, dtype=np.int64),
        gyro=values[:, 0:3] * GYRO_UNITS[units["gyro"]],
        acc=values[:, 3:6] * ACC_UNITS[units["acc"]],
        lines=lines,
        path=path,
        columns=desc,
        units=units,
        units_from_header=units_from_header,
    )


def asl_text(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> str:
    """ASL imu0/data.csv content (header line + one line per sample). The gyro gets 10 significant
    digits (it comes from a float32 network); acc is written exactly (shortest round-trip repr)."""
    out = [ASL_HEADER]
    for t, w, a in zip(t_ns.tolist(), gyro.tolist(), acc.tolist(), strict=True):
        out.append(f"{t},{w[0]:.10g},{w[1]:.10g},{w[2]:.10g},{a[0]!r},{a[1]!r},{a[2]!r}")
    return "\n".join(out) + "\n"


def resample(rec: ImuRecording, rate_hz: float) -> ImuRecording:
    """Gyro and acc on a uniform grid at `rate_hz` over the recording's span.

    Downsampling averages each signal over the output period around each new stamp (the difference of its
    cumulative integral): a box filter against aliasing that keeps the integrated angle, where point interpolation
    kept all the noise above the new Nyquist (1 kHz white noise to 200 Hz: sqrt(5) times the noise of a filtered
    decimation). Upsampling, or a rate within 5 %, interpolates linearly."""
    period_ns = 1e9 / rate_hz
    n = int((rec.t_ns[-1] - rec.t_ns[0]) // period_ns) + 1
    t_ns = rec.t_ns[0] + np.round(np.arange(n) * period_ns).astype(np.int64)
    t_old = (rec.t_ns - rec.t_ns[0]) * 1e-9  # float64 seconds relative to the start (sub-ns exact)
    t_new = (t_ns - rec.t_ns[0]) * 1e-9
    if len(t_old) > 1 and np.median(np.diff(t_old)) < 0.95 * period_ns * 1e-9:
        interp = lambda x: _box_average(t_old, x, t_new, period_ns * 1e-9)  # noqa: E731
    else:
        interp = lambda x: np.stack([np.interp(t_new, t_old, x[:, k]) for k in range(3)], axis=1)  # noqa: E731
    return ImuRecording(
        t_ns=t_ns,
        gyro=interp(rec.gyro),
        acc=interp(rec.acc),
        lines=np.full(n, -1),
        path=rec.path,
        columns=rec.columns,
        units=rec.units,
    )


def _box_average(t_old: np.ndarray, x: np.ndarray, t_new: np.ndarray, period_s: float) -> np.ndarray:
    """Mean of x (N, 3), linear between its stamps t_old (s), over [t - period/2, t + period/2] around each of t_new,
    clipped to the recording's span."""
    steps = np.diff(t_old)[:, None]
    cum = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(0.5 * (x[1:] + x[:-1]) * steps, axis=0)])
    lo = np.clip(t_new - period_s / 2, t_old[0], t_old[-1])
    hi = np.clip(t_new + period_s / 2, t_old[0], t_old[-1])

    def integral(tq: np.ndarray) -> np.ndarray:  # exact for x linear between stamps: a quadratic within each step
        k = np.clip(np.searchsorted(t_old, tq, side="right") - 1, 0, len(t_old) - 2)
        u = (tq - t_old[k])[:, None]
        slope = (x[k + 1] - x[k]) / steps[k]
        return cum[k] + x[k] * u + 0.5 * slope * u**2

    return (integral(hi) - integral(lo)) / (hi - lo)[:, None]
