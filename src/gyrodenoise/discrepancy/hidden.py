"""Hidden-effect scenarios: 'measured' data simulated with the base model plus hidden effects, for
the tests and the benchmark of the discrepancy workflow.

The measured data do not share the detector's discretisation: the generator evaluates its own
trajectory spline at 10x the IMU rate, applies continuous-time effects there and averages down;
the detector only reads the ASL files and fits its own spline to the 200 Hz ground truth.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gyrodenoise.discrepancy.compare import load_fit_context
from gyrodenoise.discrepancy.workflow import decide, gap
from gyrodenoise.sim.effects import (
    Bias,
    BiasRandomWalk,
    Effect,
    GSensitivity,
    Misalignment,
    Nonlinearity,
    NonlinearityEven,
    Quantization,
    Saturation,
    ScaleAsymmetry,
    ScaleFactor,
    TimeOffset,
    Vibration,
    WarmupBias,
    WhiteNoise,
)
from gyrodenoise.sim.imu import simulate_imu, write_asl
from gyrodenoise.sim.trajectory import TRAJECTORIES, constant_rate_trajectory

BASE_NOISE = 1.7e-4  # rad/s/sqrt(Hz), ADIS16448-like
BASE_BIAS_STD = 0.01  # rad/s, per sequence
VIBRATION_FREQ_TOL_HZ = 0.5  # band-limited vibration: centre frequency and bandwidth tolerances
VIBRATION_BW_TOL_HZ = 1.0

_P3 = np.array([1.0, -0.6, 0.8])
_P6 = np.array([1.0, -0.5, 0.7, 0.0, -0.8, 0.4])
_P9 = np.array([[1.0, 0.6, 0.0], [-0.4, -0.8, 0.3], [0.0, 0.5, 1.0]])


@dataclass
class Case:
    """One hidden effect at one magnitude: the effect, the base model the workflow starts from, the
    parameter to check (name, true value) and the relative tolerance."""

    effect: Effect
    base: tuple[str, ...]
    param: str
    tol: float
    gap_metric: str | None = "residual_rms_rad_s"  # None: no gap metric can show this effect


def label(effect: Effect) -> str:
    """Name of an effect in the confusion matrix: its library name, except for the band-limited
    vibration (`vibration_band`), which is a variant of `vibration`."""
    if effect.name == "vibration" and float(effect.params["bandwidth_hz"]) > 0:
        return "vibration_band"
    return effect.name


def _rel_err(est: np.ndarray, true: np.ndarray) -> float:
    return float(np.linalg.norm(np.asarray(est) - true) / max(np.linalg.norm(true), 1e-300))


# magnitudes: index 0 small, 1 large
CASES: dict[str, Callable[[int], Case]] = {
    "bias": lambda m: Case(Bias(bias=[0.004, 0.02][m] * _P3), ("white_noise",), "bias", 0.05),
    "white_noise": lambda m: Case(
        WhiteNoise(density=np.full(3, [1.0e-4, 5e-4][m])), ("bias",), "density", 0.05, "allan_gap_log10"
    ),
    "scale_factor": lambda m: Case(ScaleFactor(scale=[1e-3, 5e-3][m] * _P3), ("bias", "white_noise"), "scale", 0.1),
    "misalignment": lambda m: Case(Misalignment(angles=[1e-3, 5e-3][m] * _P6), ("bias", "white_noise"), "angles", 0.1),
    "g_sensitivity": lambda m: Case(
        GSensitivity(matrix=[5e-5, 2e-4][m] * _P9), ("bias", "white_noise"), "matrix", 0.15
    ),
    "time_offset": lambda m: Case(TimeOffset(delta=[0.002, 0.01][m]), ("bias", "white_noise"), "delta", 0.05),
    "quantization": lambda m: Case(Quantization(step=[5e-4, 2e-3][m]), ("bias", "white_noise"), "step", 0.01, None),
    "vibration": lambda m: Case(
        Vibration(frequency_hz=[37.0, 23.0][m], amplitude=[1e-3, 5e-3][m] * np.abs(_P3)),
        ("bias", "white_noise"),
        "amplitude",
        0.1,
    ),
    # band-limited: noise, no prediction can lower the residual RMS; the re-simulation's Allan
    # deviation shows it
    "vibration_band": lambda m: Case(
        Vibration(frequency_hz=20.0, bandwidth_hz=6.0, amplitude=[1e-3, 5e-3][m] * np.abs(_P3)),
        ("bias", "white_noise"),
        "amplitude",
        0.1,
        "allan_gap_log10",
    ),
    "warmup_bias": lambda m: Case(
        WarmupBias(amplitude=[4e-3, 1.5e-2][m] * _P3, tau=[15.0, 30.0][m]), ("bias", "white_noise"), "amplitude", 0.15
    ),
    "nonlinearity": lambda m: Case(Nonlinearity(k=[5e-4, 2e-3][m] * _P3), ("bias", "white_noise"), "k", 0.1),
    "nonlinearity_even": lambda m: Case(NonlinearityEven(k=[5e-4, 2e-3][m] * _P3), ("bias", "white_noise"), "k", 0.1),
    "scale_asymmetry": lambda m: Case(
        ScaleAsymmetry(asymmetry=[1e-3, 5e-3][m] * _P3), ("bias", "white_noise"), "asymmetry", 0.1
    ),
    "saturation": lambda m: Case(Saturation(limit=[2.5, 1.5][m]), ("bias", "white_noise"), "limit", 0.01),
    "bias_random_walk": lambda m: Case(
        BiasRandomWalk(density=np.full(3, [1.5e-4, 5e-4][m])), ("bias", "white_noise"), "density", 0.3
    ),
}


def make_measured(
    root: str | Path,
    hidden: list[Effect],
    n_seqs: int = 4,
    duration_s: float = 50.0,
    seed: int = 0,
    trajectory: str = "handheld",
    base_noise: float = BASE_NOISE,
    with_noise: bool = True,
    with_bias: bool = True,
) -> list[str]:
    """Write `n_seqs` ASL sequences s0.. under root: base model (per-sequence bias, white noise)
    plus the hidden effects. Returns the sequence names."""
    names = []
    rng = np.random.default_rng(seed)
    for k in range(n_seqs):
        if trajectory == "constant_rate":
            traj = constant_rate_trajectory(duration_s + 2)
        else:
            traj = TRAJECTORIES[trajectory](duration_s + 2, int(rng.integers(1 << 30)))
        effects: list[Effect] = list(hidden)
        if with_noise:
            effects.append(WhiteNoise(density=np.full(3, base_noise)))
        if with_bias and not any(isinstance(e, Bias) for e in hidden):
            effects.append(Bias(bias=rng.normal(0.0, BASE_BIAS_STD, 3)))
        sim = simulate_imu(traj, effects, seed=int(rng.integers(1 << 30)), margin_s=0.37)
        name = f"s{k}"
        write_asl(Path(root) / name, sim)
        names.append(name)
    return names


def _delta_bic(sel, name: str) -> float:
    step = next((s for s in sel.steps if s.get("added") == name), None)
    cand = next((c for c in (step or {}).get("candidates", []) if c["effect"] == name), {})
    return float(cand.get("delta_bic", np.nan))


_SCORE_KEYS = (
    "effect",
    "variant",
    "delta_bic",
    "threshold",
    "gain",
    "holdout_gain",
    "holdout_drift_reduction_deg",
    "holdout_transfer_dloglik",
)


def _below_practical(sel) -> list[dict]:
    """Candidates that cleared their threshold but not the practical minimum, in short."""
    return [{k: c.get(k) for k in _SCORE_KEYS} for c in sel.below_practical]


def _steps(sel) -> list[dict]:
    """The selection steps in short: what was added, and the top candidates' delta BIC / threshold."""
    out = []
    for st in sel.steps:
        if "candidates" not in st:
            continue
        out.append(
            {
                "added": st.get("added"),
                "top": [{k: c.get(k) for k in _SCORE_KEYS} for c in st["candidates"][:4]],
            }
        )
    return out


def run_case(
    root: str | Path,
    effect_name: str,
    magnitude: int,
    seed: int,
    n_fit: int = 3,
    duration_s: float = 50.0,
    trajectory: str = "handheld",
    null_draws: int = 0,
) -> dict:
    """Generate, run the selection on n_fit sequences (thresholds from `null_draws` null
    re-simulations; 0: the fixed BIC threshold) and the gap on one held-out sequence."""
    if effect_name == "none":
        case = None
        hidden: list[Effect] = []
        base: tuple[str, ...] = ("bias", "white_noise")
    else:
        case = CASES[effect_name](magnitude)
        hidden, base = [case.effect], case.base
    names = make_measured(
        root,
        hidden,
        n_fit + 1,
        duration_s,
        seed,
        trajectory,
        with_noise=not (case and "white_noise" not in case.base and effect_name == "white_noise"),
    )
    fcs = [load_fit_context(root, n) for n in names]
    fit, hold = fcs[:n_fit], fcs[n_fit:]
    sel_base, sel, null = decide(fit, hold, base, null_draws=null_draws, seed=seed)
    out = {
        "effect": effect_name,
        "magnitude": magnitude,
        "seed": seed,
        "named": list(sel.named),
        "named_labels": [label(sel.fitted[n]) if n in sel.fitted else n for n in sel.named],
        "not_identifiable": list(sel.not_identifiable),
        "steps": _steps(sel),
        "below_practical": _below_practical(sel),
    }
    if null is not None:
        out["null_p_values"] = {n: null.p_value(n, _delta_bic(sel, n)) for n in sel.named if n in null.delta_bic}
    if case is not None:
        name = case.effect.name
        true = np.asarray(case.effect.params[case.param])
        est = sel.params.get(name, {}).get(case.param)
        out["fitted_params"] = {k: np.asarray(v).tolist() for k, v in sel.params.get(name, {}).items()}
        out["param"] = case.param
        out["true"] = true.tolist()
        out["estimate"] = None if est is None else np.asarray(est).tolist()
        out["rel_error"] = None if est is None else _rel_err(est, true)
        out["tol"] = case.tol
        out["ok_param"] = out["rel_error"] is not None and out["rel_error"] < case.tol
        if label(case.effect) == "vibration_band" and est is not None:
            fp = out["fitted_params"]
            out["frequency_error_hz"] = abs(fp["frequency_hz"] - float(case.effect.params["frequency_hz"]))
            out["bandwidth_error_hz"] = abs(fp["bandwidth_hz"] - float(case.effect.params["bandwidth_hz"]))
            out["ok_param"] = bool(
                out["ok_param"]
                and out["frequency_error_hz"] < VIBRATION_FREQ_TOL_HZ
                and out["bandwidth_error_hz"] < VIBRATION_BW_TOL_HZ
            )
        if case.gap_metric:
            gb, ga = gap(sel_base, hold, seed), gap(sel, hold, seed)
            out["gap_metric"] = case.gap_metric
            out["gap_before"], out["gap_after"] = gb[case.gap_metric], ga[case.gap_metric]
            out["gaps_before"] = {k: v for k, v in gb.items() if k != "per_sequence"}
            out["gaps_after"] = {k: v for k, v in ga.items() if k != "per_sequence"}
    return out
