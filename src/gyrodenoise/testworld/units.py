"""Datasheet units at the edge, SI inside: parse "2000ppm", "0.2deg", "1:-2:3mrad" into SI numbers.

Each physical quantity has its own table of accepted unit strings and their factor to SI
(SI value = number x factor). Unknown units are errors that list what is accepted, never guesses.
"""

from __future__ import annotations

import re

import numpy as np

DEG = np.pi / 180.0
G0 = 9.80665  # standard gravity, m/s^2 (the "g" of deg/s/g)
HOUR = 3600.0

# quantity -> {unit string: factor to SI}
UNITS: dict[str, dict[str, float]] = {
    "rate": {"rad/s": 1.0, "deg/s": DEG, "mdeg/s": 1e-3 * DEG, "deg/h": DEG / HOUR},
    "rate_density": {  # white rate noise: rad/s/sqrt(Hz); deg/sqrt(h) is the same as angle random walk
        "rad/s/sqrt(Hz)": 1.0,
        "deg/s/sqrt(Hz)": DEG,
        "deg/h/sqrt(Hz)": DEG / HOUR,
        "deg/sqrt(h)": DEG / 60.0,
    },
    "rate_walk": {  # bias random walk: rad/s/sqrt(s) (= rad/s^2/sqrt(Hz))
        "rad/s/sqrt(s)": 1.0,
        "rad/s^2/sqrt(Hz)": 1.0,
        "deg/s/sqrt(s)": DEG,
        "deg/h/sqrt(h)": DEG / HOUR / 60.0,
    },
    "ratio": {"ppm": 1e-6, "%": 1e-2, "1": 1.0},
    "angle": {"rad": 1.0, "mrad": 1e-3, "urad": 1e-6, "deg": DEG, "arcmin": DEG / 60.0},
    "g_sens": {"deg/s/g": DEG / G0, "rad/s/(m/s^2)": 1.0},
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9},
    "frequency": {"Hz": 1.0, "kHz": 1e3},
    "length": {"m": 1.0, "mm": 1e-3, "cm": 1e-2},
    "accel_density": {"m/s^2/sqrt(Hz)": 1.0, "ug/sqrt(Hz)": 1e-6 * G0, "mg/sqrt(Hz)": 1e-3 * G0},
    "accel": {"m/s^2": 1.0, "mg": 1e-3 * G0, "g": G0},
    # nonlinearity: relative error per unit rate, 1/(rad/s); "of full scale" units ("%FS", "ppmFS") give the
    # deviation at full scale relative to full scale and are divided by the full scale in spec.py
    "nonlinearity": {"ppm/(deg/s)": 1e-6 / DEG, "1/(rad/s)": 1.0, "%FS": 1e-2, "ppmFS": 1e-6},
}

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_VALUE = re.compile(rf"^\s*({_NUMBER}(?:\s*:\s*{_NUMBER})*)\s*(.*?)\s*$")


class UnitError(ValueError):
    """A value has a missing or unknown unit, or a malformed number."""


def split_value(text: str) -> tuple[np.ndarray, str]:
    """'1:-2:3 mrad' -> (array([1., -2., 3.]), 'mrad'). Components are separated by ':'."""
    m = _VALUE.match(text)
    if not m:
        raise UnitError(f"{text!r} is not a number (or ':'-separated numbers) followed by a unit, e.g. '2000ppm'")
    numbers = np.array([float(x) for x in m.group(1).split(":")], dtype=np.float64)
    return numbers, m.group(2)


def to_si(text: str, quantity: str, what: str = "value") -> np.ndarray:
    """Parse `text` as numbers in one of the units of `quantity`; return the SI numbers."""
    numbers, unit = split_value(text)
    table = UNITS[quantity]
    if unit not in table:
        accepted = ", ".join(table)
        if not unit:
            raise UnitError(f"{what} {text!r} has no unit; accepted units: {accepted}")
        raise UnitError(f"{what} {text!r}: unknown unit {unit!r}; accepted units: {accepted}")
    return numbers * table[unit]


def from_si(value: float | np.ndarray, quantity: str, unit: str) -> float | list:
    """SI -> the given datasheet unit (for truth.json); lists for arrays so that JSON can hold them."""
    out = np.asarray(value, dtype=np.float64) / UNITS[quantity][unit]
    return float(out) if out.ndim == 0 else out.tolist()
