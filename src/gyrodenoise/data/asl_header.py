"""What an ASL file's header line says about its columns, checked against the order the readers assume.

The readers take columns by position (IMU: t, w_x, w_y, w_z, a_x, a_y, a_z; ground truth: t, p_x, p_y, p_z,
q_w, q_x, q_y, q_z). A file written in another order or unit reads without complaint and trains on garbage;
its header often says so. Each column name is classified (gyro / accelerometer / position / quaternion /
something else, and its axis) from its name and unit; a column whose name says neither is not judged, so a
header in a form not known here never refuses a file. Returns a sentence naming the problem, or None.
"""

from __future__ import annotations

import re

IMU_ORDER = [("gyro", "x"), ("gyro", "y"), ("gyro", "z"), ("acc", "x"), ("acc", "y"), ("acc", "z")]
GT_ORDER = [("pos", "x"), ("pos", "y"), ("pos", "z"), ("quat", "w"), ("quat", "x"), ("quat", "y"), ("quat", "z")]
_KINDS = [  # (kind, pattern on the lowercased name without its unit); the first that matches
    ("gyro", re.compile(r"^(w|omega|gyr|gyro|ang|rot)[_ .]|gyr|angular|ang_?vel|rot_?vel|rate")),
    ("acc", re.compile(r"^(a|acc)[_ .]|acc|lin_?acc")),
    ("pos", re.compile(r"^(p|pos|position)[_ .]")),  # a bare x, y, z says nothing of the kind
    ("quat", re.compile(r"^(q|quat|orientation)[_ .]|^q[wxyz]$")),
    ("other", re.compile(r"temp|^mag(?!nitude)|baro|press|^seq$|header\.seq|count")),  # only names that say so
]
_DEG_RATE = re.compile(r"deg|dps|°")
_G_UNIT = re.compile(r"^\[?\s*m?g\s*\]?$")
_SHORT = re.compile(r"^([gwapq])_?([wxyz])$")
_SHORT_KIND = {"g": "gyro", "w": "gyro", "a": "acc", "p": "pos", "q": "quat"}
# an axis letter glued to a quantity's name, as phone and logger apps write them (accX, gyroZ, userAccelerationY,
# rotationRateX; lowercased here): only after these words, so a name that merely ends in x (a 'max') is not one
_GLUED_AXIS = re.compile(
    r"(acc|accel|accelerometer|acceleration|gyr|gyro|gyroscope|omega|angvel|rate|pos|position|quat)[wxyz]$"
)
_TIME_UNITS = {"us": "µs", "µs": "µs", "ms": "ms", "s": "s", "sec": "s", "secs": "s", "seconds": "s"}


# a unit written into the name ('gyro_x_dps', 'acc_x_g', 'time_us'); bare 's' and 'm' are not taken (w_RS_S)
_UNIT_SUFFIX = re.compile(
    r"^(.+?)[_ ]((?:deg|rad)_?(?:per_?)?s(?:ec)?|dps|rps|mps2|m_?s_?2|m_?per_?s_?2|m?g|[nuµm]s)$", re.IGNORECASE
)


# seconds glued to a time column's name ('time_s', 't_sec', 'timestamp_seconds', or 'seconds' alone): only after a time
# word, since a bare 's' suffix elsewhere is a frame's name (w_RS_S)
_SECONDS_SUFFIX = re.compile(r"^(?:(t|time|times?tamp|stamp|ts)[_ ])?(s|sec|secs|seconds)$")


def _split(name: str) -> tuple[str, str]:
    """'w_RS_S_x [rad s^-1]' -> ('w_rs_s_x', 'rad s^-1'); 'gyro_x_dps' -> ('gyro_x', 'dps');
    'time_s' -> ('time', 's')."""
    name = name.strip().strip("\"'")
    m = re.match(r"^\s*#?\s*([^\[(]*?)\s*(?:[\[(]([^\])]*)[\])])?\s*$", name)
    if not m:
        return name.lower(), ""
    base, unit = m.group(1).lower(), (m.group(2) or "").strip().lower()
    seconds = None if unit else _SECONDS_SUFFIX.match(base.lstrip("#").strip())
    if seconds and (seconds.group(1) or seconds.group(2) != "s"):  # a column named 's' alone says nothing
        return seconds.group(1) or "time", "s"
    suffix = None if unit else _UNIT_SUFFIX.match(base)
    return (suffix.group(1), suffix.group(2)) if suffix else (base, unit)


def classify(name: str) -> tuple[str | None, str | None]:
    """(kind, axis) of a column name; None where the name does not say."""
    base, unit = _split(name)
    short = _SHORT.match(base)  # gx, ax, px, qw
    if short:
        return _SHORT_KIND[short.group(1)], short.group(2)
    kind = next((k for k, pat in _KINDS if pat.search(base)), None)
    if kind is None and unit:  # by the unit alone
        kind = "gyro" if re.search(r"rad\s*/?\s*s|deg\s*/?\s*s|dps", unit) else None
        kind = kind or ("acc" if re.search(r"m\s*/?\s*s\s*\^?-?2|m s\^-2", unit) or _G_UNIT.match(unit) else None)
    axis = base[-1] if base and base[-1] in "wxyz" and (len(base) == 1 or not base[-2].isalpha()) else None
    if axis is None and kind is not None and _GLUED_AXIS.search(base):  # accX, gyroZ, rotationRateY, qW
        axis = base[-1]
    return kind, axis


def _mismatches(names: list[str], order: list[tuple[str, str]]) -> str:
    out = []
    for col, (name, (kind, axis)) in enumerate(zip(names, order, strict=False), start=2):
        k, a = classify(name)
        if (k is not None and k != kind) or (k == kind and a is not None and a != axis):
            out.append(f"column {col} is '{name}' where {kind} {axis} is expected")
    return "; ".join(out[:3]) + (f" (and {len(out) - 3} more)" if len(out) > 3 else "")


def time_unit_problem(name: str) -> str | None:
    unit = _split(name)[1]
    if unit in _TIME_UNITS:
        return (
            f"the header gives the timestamps in {_TIME_UNITS[unit]} ('{name}'); the ASL format's unit is ns. "
            "Convert them to integer nanoseconds"
        )
    return None


def imu_header_problem(names: list[str]) -> str | None:
    """Why the header of an ASL IMU file (split at commas, the timestamp first) does not fit the readers."""
    if not names or len(names) < 2:
        return None
    problems = [p for p in [time_unit_problem(names[0])] if p]
    wrong = _mismatches(names[1:7], IMU_ORDER)
    if wrong:
        problems.append(
            wrong + ". gyrodenoise reads t, w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2] by position: "
            "reorder the columns (gyrodenoise.data.imu_csv.read_imu_csv(path, columns=...) reads any order, and "
            "asl_text writes the ASL layout), or, if the data are in that order already, correct the header line"
        )
    units = {classify(n)[0]: (n, _split(n)[1]) for n in reversed(names[1:7])}  # the first column of each kind
    if "gyro" in units and _DEG_RATE.search(units["gyro"][1]):
        problems.append(
            f"'{units['gyro'][0]}' is in deg/s; gyrodenoise reads rad/s: multiply the gyro by pi/180 (0.0174533)"
        )
    if "acc" in units and _G_UNIT.match(units["acc"][1]):
        unit, factor = ("mg", "0.00980665") if "mg" in units["acc"][1] else ("g", "9.80665")
        problems.append(
            f"'{units['acc'][0]}' is in {unit}; gyrodenoise reads m/s^2: multiply the accelerometer by {factor}"
        )
    return "; ".join(problems) + "." if problems else None


def groundtruth_header_problem(names: list[str]) -> str | None:
    """Why the header of an ASL ground-truth file does not fit the readers (quaternion w first)."""
    if not names or len(names) < 2:
        return None
    problems = [p for p in [time_unit_problem(names[0])] if p]
    wrong = _mismatches(names[1:8], GT_ORDER)
    if wrong:
        quats = [classify(n)[1] for n in names[4:8]]
        hint = (
            "the quaternion is stored x, y, z, w: move its w column before x"
            if quats == ["x", "y", "z", "w"]
            else "reorder the columns, or, if the data are in that order already, correct the header line"
        )
        problems.append(wrong + f". gyrodenoise reads t, p_x, p_y, p_z [m], q_w, q_x, q_y, q_z by position: {hint}")
    return "; ".join(problems) + "." if problems else None


_RAD_RATE = re.compile(r"rad\s*/?\s*s|rad\s+s\^-1|rps")
_SI_ACC = re.compile(r"m\s*/?\s*s\s*\^?-?2|m s\^-2|mps2|m_?s_?2")
_TIME_FLAG = {"ns": "ns", "µs": "us", "ms": "ms", "s": "s"}


def declared_units(time_name: str, gyro_names: list[str], acc_names: list[str]) -> dict[str, str]:
    """{'time' | 'gyro' | 'acc': unit in the reader's spelling} for what the named columns' units say (brackets,
    parentheses or a suffix like `_dps`); a quantity whose columns say nothing (or disagree) is left out."""
    out = {}
    t_unit = _split(time_name)[1]
    t = _TIME_UNITS.get(t_unit) or ("ns" if t_unit == "ns" else None)
    if t:
        out["time"] = _TIME_FLAG[t]

    def one(names: list[str], unit_of) -> str | None:
        units = {unit_of(_split(n)[1]) for n in names}
        return units.pop() if len(units) == 1 else None

    gyro = one(gyro_names, lambda u: "deg/s" if _DEG_RATE.search(u) else "rad/s" if _RAD_RATE.search(u) else None)
    acc = one(
        acc_names,
        lambda u: ("mg" if "mg" in u else "g") if _G_UNIT.match(u) else "m/s^2" if _SI_ACC.search(u) else None,
    )
    out |= {k: v for k, v in (("gyro", gyro), ("acc", acc)) if v}
    return out


_TIME_NAME = re.compile(r"^(t|time|times?tamp|stamp|ts|t_?ns|header\.stamp)$")


def columns_from_names(names: list[str]) -> str | None:
    """A `--columns` value (t, gyro x y z, acc x y z as 1-based numbers) read off a header whose names say each of
    the seven unambiguously; None otherwise."""
    found: dict[tuple[str, str], int] = {}
    time_cols = [i for i, n in enumerate(names) if _TIME_NAME.match(_split(n)[0].lstrip("#").strip())]
    for i, n in enumerate(names):
        kind, axis = classify(n)
        if kind in ("gyro", "acc") and axis and axis in "xyz":  # a column of no axis (gyro_norm) is not one
            if (kind, axis) in found:
                return None
            found[(kind, axis)] = i
    if len(time_cols) != 1 or len(found) != 6:
        return None
    return ",".join(str(i + 1) for i in [time_cols[0], *(found[k] for k in IMU_ORDER)])
