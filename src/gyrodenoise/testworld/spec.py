"""The hidden-effect vocabulary of the test world: parse "scale_factor=2000ppm,vibration.center=19Hz" into
SI parameters, with datasheet units at the edge.

Syntax: comma-separated `NAME=VALUE` (the effect's main parameter) or `NAME.PARAM=VALUE` items. A VALUE
is a number or ':'-separated numbers followed by a unit, e.g. `bias=0.1:-0.3:0.2deg/s`. For signed
per-axis quantities (bias, scale factor, misalignment, g-sensitivity) a single number is a magnitude:
every component gets it with a sign drawn from the seed, so that a scalar does not make the three
axes identical. Positive quantities (noise densities, vibration level) are copied to all axes.

The effect names are those the discrepancy workflow uses, so that a judge can compare its answer
with truth.json; the parameterisation and the implementation are the test world's own.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from gyrodenoise.testworld.units import UnitError, from_si, to_si


@dataclass(frozen=True)
class Param:
    quantity: str  # key of units.UNITS (or "choice")
    unit: str  # datasheet unit of truth.json
    size: int  # number of components: 1, 3, 6 (off-diagonal entries) or 9 (3x3 row-major)
    default: str | None = None  # None: required when the effect is on
    signed: bool = False  # a single number is a magnitude with seeded random signs per component
    choices: tuple[str, ...] = ()


# effect -> (main parameter, {parameter: Param})
VOCABULARY: dict[str, tuple[str, dict[str, Param]]] = {
    "bias": ("value", {"value": Param("rate", "deg/s", 3, signed=True)}),
    "white_noise": ("density", {"density": Param("rate_density", "deg/s/sqrt(Hz)", 3)}),
    "bias_random_walk": ("density", {"density": Param("rate_walk", "deg/h/sqrt(h)", 3)}),
    # flicker bias: the flat floor of the Allan deviation (a datasheet's "bias instability"), out to tau_max
    "bias_instability": (
        "value",
        {"value": Param("rate", "deg/h", 3), "tau_max": Param("time", "s", 1, default="1000s")},
    ),
    "scale_factor": ("value", {"value": Param("ratio", "ppm", 3, signed=True)}),
    # off-diagonal entries of the sensor matrix: (xy, xz, yx, yz, zx, zy), i.e. M[0,1], M[0,2], M[1,0] ...
    "misalignment": ("value", {"value": Param("angle", "mrad", 6, signed=True)}),
    # 3x3 matrix row-major (9 numbers), its diagonal (3 numbers), or a magnitude
    "g_sensitivity": ("value", {"value": Param("g_sens", "deg/s/g", 9, signed=True)}),
    # the IMU sample stamped t holds the motion of t - value (value > 0: IMU stamps late)
    "time_offset": ("value", {"value": Param("time", "ms", 1, signed=True)}),  # either sign: early or late stamps
    "nonlinearity": (
        "value",
        {
            "value": Param("nonlinearity", "ppm/(deg/s)", 3, signed=False),
            "full_scale": Param("rate", "deg/s", 1, default="1000deg/s"),
            "shape": Param("choice", "", 1, default="odd", choices=("odd", "even")),
        },
    ),
    "vibration": (
        "level",  # RMS per axis of the vibration's rate at the sensor input
        {
            "level": Param("rate", "deg/s", 3),
            "center": Param("frequency", "Hz", 1, default="30Hz"),
            "width": Param("frequency", "Hz", 1, default="0Hz"),  # 0: a sinusoid
        },
    ),
    "quantization": ("value", {"value": Param("rate", "deg/s", 1)}),
    "saturation": ("value", {"value": Param("rate", "deg/s", 1)}),
}

PRESETS: dict[str, str] = {
    # ADIS16448-like white noise (EuRoC sensor.yaml: 1.6968e-4 rad/s/sqrt(Hz)) and a constant bias
    "null": "bias=1deg/s,white_noise=1.6968e-4rad/s/sqrt(Hz)",
    "none": "",
}
NULL_EFFECTS = ("bias", "white_noise")  # what the workflow's base model already holds


class EffectSpecError(ValueError):
    """An effect specification names an unknown effect or parameter, or has a bad value."""


def parse_effects(spec: str | Mapping[str, str] | None) -> dict[str, dict[str, str]]:
    """'a=1ppm,b.p=2Hz' or {'a': '1ppm', 'b.p': '2Hz'} -> {'a': {'value': '1ppm'}, 'b': {'p': '2Hz'}}.

    Only names and parameter names are checked here; values are checked by `realise`."""
    if spec is None:
        return {}
    if isinstance(spec, str):
        items = []
        for part in (p.strip() for p in spec.split(",")):
            if not part:
                continue
            if "=" not in part:
                raise EffectSpecError(f"effect item {part!r} has no '='; write NAME=VALUE, e.g. scale_factor=2000ppm")
            key, value = part.split("=", 1)
            items.append((key.strip(), value.strip()))
    else:
        items = [(str(k), str(v)) for k, v in spec.items()]
    out: dict[str, dict[str, str]] = {}
    for key, value in items:
        name, _, param = key.partition(".")
        if name not in VOCABULARY:
            raise EffectSpecError(f"unknown effect {name!r}; the test world knows: {', '.join(VOCABULARY)}")
        main, params = VOCABULARY[name]
        param = param or main
        if param not in params:
            raise EffectSpecError(f"effect {name!r} has no parameter {param!r}; it has: {', '.join(params)}")
        if param in out.get(name, {}):  # one spec, one value: a second would silently win
            raise EffectSpecError(f"{name}.{param} is given twice ({out[name][param]!r} and {value!r}); give it once")
        out.setdefault(name, {})[param] = value
    return out


def merge(*specs: dict[str, dict[str, str]]) -> dict[str, dict[str, str]]:
    """Later specs override earlier ones parameter by parameter (a preset, then the user's effects)."""
    out: dict[str, dict[str, str]] = {}
    for s in specs:
        for name, params in s.items():
            out.setdefault(name, {}).update(params)
    return out


@dataclass
class Effects:
    """The realised hidden effects, SI. `raw` keeps the text they came from, for truth.json."""

    si: dict[str, dict[str, np.ndarray | str]] = field(default_factory=dict)
    raw: dict[str, dict[str, str]] = field(default_factory=dict)

    def has(self, name: str) -> bool:
        return name in self.si

    def get(self, name: str, param: str | None = None):
        main, params = VOCABULARY[name]
        p = param or main
        if name in self.si:
            return self.si[name][p]
        spec = params[p]
        if spec.quantity == "choice":
            return spec.default
        return np.zeros(spec.size) if spec.size > 1 else np.asarray(0.0)

    def sensor_matrix(self) -> np.ndarray:
        """M of y = M w + ...: identity + scale factor (diagonal) + misalignment (off-diagonal)."""
        m = np.eye(3) + np.diag(self.get("scale_factor"))
        m[_OFFDIAG] += self.get("misalignment")
        return m

    def g_matrix(self) -> np.ndarray:
        return np.asarray(self.get("g_sensitivity")).reshape(3, 3)

    def nonlinearity_k(self) -> np.ndarray:
        """k of y_i += k_i w_i |w_i| (odd) or k_i w_i^2 (even), 1/(rad/s)."""
        return np.asarray(self.get("nonlinearity"))

    def to_json(self) -> dict:
        out = {}
        for name, params in self.si.items():
            entry: dict = {"spec": self.raw[name]}
            for p, v in params.items():
                spec = VOCABULARY[name][1][p]
                if spec.quantity == "choice":
                    entry[p] = v
                    continue
                entry[f"{p}_si"] = np.asarray(v).tolist()
                entry[f"{p}_datasheet"] = from_si(v, spec.quantity, spec.unit)
                entry[f"{p}_unit"] = spec.unit
            out[name] = entry
        return out


_OFFDIAG = (np.array([0, 0, 1, 1, 2, 2]), np.array([1, 2, 0, 2, 0, 1]))


def realise(spec: dict[str, dict[str, str]], rng: np.random.Generator) -> Effects:
    """Parse every value into SI, fill defaults, draw the seeded signs of magnitudes."""
    eff = Effects(raw={k: dict(v) for k, v in spec.items()})
    for name in VOCABULARY:  # fixed order: the signs drawn do not depend on the order of the items
        if name not in spec:
            continue
        given = spec[name]
        _, params = VOCABULARY[name]
        values: dict[str, np.ndarray | str] = {}
        for p, ps in params.items():
            text = given.get(p, ps.default)
            if text is None:
                raise EffectSpecError(f"effect {name!r} needs {name}.{p} (in {ps.unit or 'one of ' + str(ps.choices)})")
            values[p] = _value(name, p, ps, text, rng)
        if name == "nonlinearity":
            values["value"] = _nonlinearity_k(given.get("value", ""), values)
        eff.si[name] = values
    return eff


def _value(name: str, p: str, ps: Param, text: str, rng: np.random.Generator) -> np.ndarray | str:
    what = f"{name}.{p}"
    if ps.quantity == "choice":
        if text not in ps.choices:
            raise EffectSpecError(f"{what}={text!r}: expected one of {', '.join(ps.choices)}")
        return text
    try:
        x = to_si(text, ps.quantity, what)
    except UnitError as e:
        raise EffectSpecError(str(e)) from None
    if ps.size == 9 and len(x) == 3:  # g-sensitivity: the diagonal only
        x = np.diag(x).ravel()
    elif len(x) == 1 and ps.size > 1:
        x = np.full(ps.size, x[0])
        if ps.signed:
            x = x * rng.choice([-1.0, 1.0], ps.size)
    if len(x) != ps.size:
        raise EffectSpecError(f"{what}={text!r}: expected 1 or {ps.size} ':'-separated numbers, got {len(x)}")
    if not ps.signed and ps.quantity != "nonlinearity" and (x < 0).any():
        raise EffectSpecError(f"{what}={text!r} must not be negative")
    return x if ps.size > 1 else np.asarray(x[0])


def _nonlinearity_k(text: str, values: dict) -> np.ndarray:
    """Deviation "of full scale" (a fraction d of FS at w = FS) -> k = d / FS; per-rate units as they are."""
    unit = text.rstrip().split()[-1] if text else ""
    if text.endswith("FS") or unit.endswith("FS"):
        return np.asarray(values["value"]) / float(values["full_scale"])
    return np.asarray(values["value"])


def describe() -> str:
    """The vocabulary as text, for --help and error messages."""
    lines = []
    for name, (main, params) in VOCABULARY.items():
        ps = ", ".join(
            f"{name}.{p} [{s.unit or '|'.join(s.choices)}]" + (f" (default {s.default})" if s.default else "")
            for p, s in params.items()
            if p != main
        )
        lines.append(f"  {name}=VALUE [{params[main].unit}]" + (f"; {ps}" if ps else ""))
    return "\n".join(lines)
